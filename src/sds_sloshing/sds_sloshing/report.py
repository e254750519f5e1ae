"""`sds analyze`'s outputs: analysis.json, report.html and its figures."""

from __future__ import annotations

import base64
import html
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib
from sds_model.errors import InputError

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from sds_model.mode_theory import mode_name

from sds_sloshing.analysis import ModeResult, SloshingAnalysis
from sds_sloshing.estimators import amplitude_spectrum, finite_window

FIGURE_DPI = 110
MARGINS_IN = (0.85, 0.2, 0.55, 0.35, 0.45)
"""Figure margins [in]: left, right, bottom, top, and the gap between stacked panels (room
for the tick labels, the axis labels and each panel's title)."""

Truth = dict[str, tuple[float, float]]
"""Mode name → (natural frequency [Hz], damping ratio), e.g. from a simulation's run.json."""


@dataclass(frozen=True)
class ReportFiles:
    """Paths of what `write_report` wrote, and the results it wrote into the JSON."""

    json: Path
    html: Path
    figures: tuple[Path, ...]
    results: dict[str, Any]


def truth_from_run(path: str | Path) -> Truth:
    """The modes of a simulation's truth/run.json."""
    try:
        run = json.loads(Path(path).read_text())
        return {mode_name(m["order"], m["index"]): (float(m["frequency_hz"]),
                                                      float(m["damping_ratio"]))
                for m in run["modes"]}
    except (ValueError, KeyError, TypeError) as error:
        raise InputError(f"{path}: not a simulation's run.json ({error})") from None


def _errors_pct(estimate: dict[str, Any], truth: tuple[float, float] | None
               ) -> dict[str, Any]:
    if truth is None:
        return {}
    frequency, damping = truth
    return {"frequency_error_pct": 100 * (estimate["frequency_hz"] / frequency - 1),
            "damping_error_pct": 100 * (estimate["damping_ratio"] / damping - 1)
            if damping else float("nan")}


def results_dict(analysis: SloshingAnalysis, truth: Truth | None = None) -> dict[str, Any]:
    """The analysis as JSON, each estimate with its error against the truth when given."""
    result = analysis.as_dict()
    truth = truth or {}
    for group in ("modes", "tof"):
        for mode in result[group]:
            reference = truth.get(mode["mode"])
            if reference is not None:
                mode["truth"] = {"frequency_hz": reference[0], "damping_ratio": reference[1]}
            for estimate in mode["estimates"]:
                estimate.update(_errors_pct(estimate, reference))
    return result


def _json_safe(value: Any) -> Any:
    """NaN and infinity become null (strict JSON)."""
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.generic):
        return _json_safe(value.item())
    return value


def spectrum_limit_hz(analysis: SloshingAnalysis) -> float:
    """The spectrum plot's upper frequency [Hz]: 1.3 × the highest theoretical or measured
    mode frequency (a measured mode the theory does not expect stays on the plot)."""
    measured = [e.frequency_hz for m in analysis.modes + analysis.tof for e in m.estimates[:1]]
    return 1.3 * max([m.frequency_hz for m in analysis.theory] + measured + [1.0])


def _save(fig: plt.Figure, path: Path) -> None:
    """Write a figure as PNG with fixed margins (MARGINS_IN) and close it; fixed margins
    because matplotlib's tight layout measured every label and cost half the report's time."""
    left, right, bottom, top, gap = MARGINS_IN
    width, height = fig.get_size_inches()
    rows = len(fig.axes)
    panel = (height - bottom - top - (rows - 1) * gap) / rows
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, hspace=gap / panel)
    fig.savefig(path, dpi=FIGURE_DPI)
    plt.close(fig)


def _plot_modes(modes: tuple[ModeResult, ...], tof: tuple[ModeResult, ...],
                window: tuple[float, float], path: Path) -> None:
    """Each mode's samples (modal coordinate q, or the ToF's range), fitted model and decay
    envelope, against the time since the first sample of the first series [s]."""
    panels = [(m, m.name, f"q [{m.unit}]") for m in modes] + \
        [(m, f"{m.name} (ToF)", f"ToF range [{m.unit}]") for m in tof]
    first = panels[0][0]
    origin = float(np.nanmin(first.time_s)) if len(first.time_s) else 0.0
    window = (window[0] - origin, window[1] - origin)
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 2.6 * len(panels)), squeeze=False,
                             sharex=True)
    for ax, (mode, name, ylabel) in zip(axes[:, 0], panels, strict=True):
        ax.plot(mode.time_s - origin, mode.values, ".", ms=2.5, color="0.35", label="measured")
        ax.axvspan(*window, color="tab:blue", alpha=0.06, label="analysis window")
        if mode.fit is not None and mode.component is not None:
            t = np.linspace(mode.fit.start_s, mode.fit.end_s, 2000)
            ax.plot(t - origin, mode.fit.evaluate(t), lw=0.9, color="tab:red",
                    label="fitted model")
            tau = t - mode.fit.start_s
            envelope = mode.component.amplitude * np.exp(-mode.component.decay_rate_s * tau)
            for sign in (1, -1):
                ax.plot(t - origin, mode.fit.offset + sign * envelope, "--", lw=1.0,
                        color="tab:orange", label="envelope" if sign == 1 else None)
            best = mode.estimates[0]
            ax.set_title(f"{name}: f = {best.frequency_hz:.4f} Hz, "
                         f"ζ = {best.damping_ratio:.4f} ({best.method})", fontsize=9)
        else:
            ax.set_title(f"{name}: {'; '.join(mode.notes)}", fontsize=9)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    if axes[0, 0].get_legend_handles_labels()[0]:
        axes[0, 0].legend(fontsize=7, loc="upper right", ncol=4)
    axes[-1, 0].set_xlabel("time since the first frame [s]")
    _save(fig, path)


def _plot_spectrum(analysis: SloshingAnalysis, path: Path) -> None:
    """Amplitude spectra in the window, the theory's modes and the estimates drawn over them."""
    fig, ax = plt.subplots(figsize=(10, 4))
    top = 0.0
    labelled = [(m, m.name) for m in analysis.modes] + [(m, f"{m.name} (ToF)")
                                                         for m in analysis.tof]
    for mode, label in labelled:
        try:
            t, y = finite_window(mode.time_s, mode.values, *mode_window(mode, analysis))
        except ValueError:
            continue
        freqs, amplitude = amplitude_spectrum(t, y)
        line, = ax.semilogy(freqs, amplitude, lw=1.0, label=label)
        top = max(top, float(amplitude.max()))
        for estimate in mode.estimates[:1]:
            ax.axvline(estimate.frequency_hz, color=line.get_color(), lw=0.8)
    for row, theory in enumerate(sorted(analysis.theory, key=lambda m: m.frequency_hz)):
        ax.axvline(theory.frequency_hz, color="k", ls=":", lw=1.0)
        ax.text(theory.frequency_hz, top * 0.2 ** (row % 2),
                f" {theory.name}\n {theory.frequency_hz:.2f} Hz", fontsize=7, va="top")
    ax.set_xlim(0, spectrum_limit_hz(analysis))
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("amplitude")
    gravity = analysis.gravity_m_s2
    ax.set_title(f"Spectra of the mode coordinates (Hann window); dotted: linear theory at "
                 f"g = {gravity:g} m/s²" + (" (flat capillary surface, see notes)"
                                             if gravity == 0 else ""), fontsize=9)
    ax.grid(alpha=0.3, which="both")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    _save(fig, path)


def mode_window(mode: ModeResult, analysis: SloshingAnalysis) -> tuple[float, float | None]:
    """The window a mode was analysed on (the ToF has its own clock and start)."""
    if mode.fit is not None:
        return mode.fit.start_s, mode.fit.end_s
    return analysis.window_s


def _plot_meniscus(analysis: SloshingAnalysis, path: Path) -> None:
    radius, height, count = analysis.meniscus
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(radius, height, "o-", ms=3)
    ax.set_xlabel("radius [mm]")
    ax.set_ylabel("mean height [mm]")
    ax.set_title(f"Meniscus: radial profile ({analysis.meniscus_source}, "
                 f"{int(count.sum())} points)", fontsize=9)
    ax.grid(alpha=0.3)
    _save(fig, path)


def _format(value: float, digits: int) -> str:
    return "—" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def _sigma(value: float) -> str:
    """An uncertainty to two significant digits."""
    return "—" if value is None or not np.isfinite(value) else f"{value:.2g}"


def _estimate_rows(result: dict[str, Any]) -> list[str]:
    rows = []
    for group in ("modes", "tof"):
        for mode in result[group]:
            truth = mode.get("truth", {})
            name = mode["mode"] + (" (ToF)" if group == "tof" else "")
            if not mode["estimates"]:
                rows.append(f"<tr><td>{html.escape(name)}</td><td colspan=8>"
                            f"{html.escape('; '.join(mode['notes']))}</td></tr>")
            for e in mode["estimates"]:
                cells = [name, e["method"],
                         f"{_format(e['frequency_hz'], 4)} ± {_sigma(e['frequency_sigma_hz'])}",
                         f"{_format(e['damping_ratio'], 4)} ± {_sigma(e['damping_ratio_sigma'])}",
                         _format(truth.get("frequency_hz", float("nan")), 4),
                         _format(truth.get("damping_ratio", float("nan")), 4),
                         _format(e.get("frequency_error_pct", float("nan")), 2),
                         _format(e.get("damping_error_pct", float("nan")), 1), e["note"]]
                rows.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
                            + "</tr>")
    return rows


def _tilt_rows(analysis: SloshingAnalysis) -> list[str]:
    return ["<tr>" + "".join(f"<td>{c}</td>" for c in (
        f"{s.start_s:.2f}–{s.end_s:.2f}", f"{s.tilt_x_deg:.2f}", f"{s.tilt_y_deg:.2f}",
        f"{s.p00_mm:.3f}", f"{s.p10:.4f}", f"{s.p01:.4f}", f"{s.r_squared:.4f}",
        f"{s.rmse_mm:.3f}", f"{s.sse_mm2:.2f}", s.point_count)) + "</tr>"
        for s in analysis.tilt_steps]


def _image(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<p><img src="data:image/png;base64,{data}" style="max-width:100%"></p>'


REPORT_FILES = ("analysis.json", "report.html", "modes.png", "spectrum.png", "meniscus.png")
"""Every file `write_report` may write (meniscus.png only when the line saw a meniscus)."""


def write_report(analysis: SloshingAnalysis, directory: str | Path,
                 truth: Truth | None = None) -> ReportFiles:
    """analysis.json, figures (PNG) and report.html (figures embedded) in `directory`."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    result = results_dict(analysis, truth)
    json_path = directory / "analysis.json"
    json_path.write_text(json.dumps(_json_safe(result), indent=2) + "\n")
    figures = [directory / "modes.png", directory / "spectrum.png"]
    _plot_modes(analysis.modes, analysis.tof, analysis.window_s, figures[0])
    _plot_spectrum(analysis, figures[1])
    if np.isfinite(analysis.meniscus[1]).any():
        figures.append(directory / "meniscus.png")
        _plot_meniscus(analysis, figures[-1])
    theory = "".join(f"<tr><td>{m.name}</td><td>{m.xi:.4f}</td><td>{m.frequency_hz:.3f}</td></tr>"
                     for m in analysis.theory)
    sections = [
        f"<h1>Sloshing analysis</h1><p>Source: {html.escape(analysis.source)}<br>"
        f"Free-decay window: {analysis.window_s[0]:.3f}–{analysis.window_s[1]:.3f} s</p>",
        "<h2>Frequencies and damping ratios, by estimator</h2>"
        "<table border=1 cellpadding=3 style='border-collapse:collapse'><tr><th>mode</th>"
        "<th>method</th><th>f<sub>n</sub> [Hz]</th><th>ζ</th><th>truth f [Hz]</th>"
        "<th>truth ζ</th><th>f error [%]</th><th>ζ error [%]</th><th>note</th></tr>"
        + "".join(_estimate_rows(result)) + "</table>"
        "<p>Uncertainties are one sigma: matrix pencil and log decrement from their fits' "
        "residuals; FFT peak and half-power from the spectrum's resolution 1/T.</p>",
        _image(figures[0]), _image(figures[1]),
        f"<h2>Linear theory at g = {analysis.gravity_m_s2:g} m/s²</h2>"
        "<table border=1 cellpadding=3 style='border-collapse:collapse'><tr><th>mode</th>"
        f"<th>ξ</th><th>f [Hz]</th></tr>{theory}</table>",
    ]
    if analysis.tilt_steps:
        sections.append(
            "<h2>Tilt series (in the manner of the seed's Table 3)</h2>"
            "<table border=1 cellpadding=3 style='border-collapse:collapse'><tr><th>time [s]</th>"
            "<th>γx [deg]</th><th>γy [deg]</th><th>p00 [mm]</th><th>p10</th><th>p01</th>"
            "<th>R²</th><th>RMSE [mm]</th><th>SSE [mm²]</th><th>points</th></tr>"
            + "".join(_tilt_rows(analysis)) + "</table>")
    if len(figures) > 2:
        sections.append("<h2>Meniscus</h2>" + _image(figures[2]))
    html_path = directory / "report.html"
    html_path.write_text("<!doctype html><meta charset=utf-8><title>SDS sloshing analysis"
                         "</title><body style='font-family:sans-serif;max-width:1100px'>"
                         + "".join(sections) + "</body>\n")
    return ReportFiles(json_path, html_path, tuple(figures), result)


def summary_lines(result: dict[str, Any]) -> list[str]:
    """One line per estimate, for the terminal."""
    lines = []
    for group in ("modes", "tof"):
        for mode in result[group]:
            name = mode["mode"] + (" (ToF)" if group == "tof" else "")
            if not mode["estimates"]:
                lines.append(f"{name:16s} {'; '.join(mode['notes'])}")
                continue
            for e in mode["estimates"]:
                error = ""
                damping = (f"ζ = {e['damping_ratio']:.4f} ± {_sigma(e['damping_ratio_sigma'])}"
                           if np.isfinite(e["damping_ratio"]) else "ζ —")
                if "frequency_error_pct" in e:
                    error = f"  error f {e['frequency_error_pct']:+.2f} %"
                    if np.isfinite(e["damping_error_pct"]):
                        error += f", ζ {e['damping_error_pct']:+.1f} %"
                lines.append(f"{name:16s} {e['method']:14s} f = {e['frequency_hz']:.4f} ± "
                             f"{_sigma(e['frequency_sigma_hz'])} Hz  {damping}{error}")
            lines += [f"{'':16s} note: {note}" for note in mode["notes"]]
    return lines


def add_report_section(directory: str | Path, heading: str, lines: list[str],
                       figure: Path | None, key: str, content: dict[str, Any]) -> None:
    """Append a section (a heading, one paragraph per line, a figure) to the report.html that
    `write_report` wrote in `directory`, and `content` to its analysis.json under `key`."""
    directory = Path(directory)
    html_path, json_path = directory / "report.html", directory / "analysis.json"
    section = f"<h2>{html.escape(heading)}</h2>" + "".join(
        f"<p>{html.escape(line)}</p>" for line in lines) + (_image(figure) if figure else "")
    page = html_path.read_text() if html_path.exists() else (
        "<!doctype html><meta charset=utf-8><title>SDS sloshing analysis</title>"
        "<body style='font-family:sans-serif;max-width:1100px'></body>\n")
    html_path.write_text(page.replace("</body>", section + "</body>", 1))
    result = json.loads(json_path.read_text()) if json_path.exists() else {}
    result[key] = content
    json_path.write_text(json.dumps(_json_safe(result), indent=2) + "\n")
