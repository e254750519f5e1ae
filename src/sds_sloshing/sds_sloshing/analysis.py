"""The sloshing analysis of one recording: modes, estimators side by side, tilts, meniscus."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from sds_model.errors import InputError
from sds_model.mode_theory import TheoreticalMode, mode_name, theoretical_modes
from sds_model.rig import Rig
from sds_recon.surface_fit import DEFAULT_MODES, fit_plane, radial_profile

from sds_sloshing.estimators import (
    DampedSinusoid,
    DampedSinusoidFit,
    DecayError,
    ModeEstimate,
    excitation_onset,
    fft_peaks,
    fit_damped_sinusoids,
    free_decay_start,
    half_power,
    log_decrement,
)
from sds_sloshing.gravity import gravity_regime
from sds_sloshing.modal import ModeCoordinate, modal_series, mode_coordinates
from sds_sloshing.surface_series import RecordingError, SurfaceSeries

MATCH_TOLERANCE = 0.15
"""A component matches an expected frequency within ±15 %."""
ANALYSED_MODES = tuple(mode_name(order, index) for order, index in DEFAULT_MODES)
"""The modes the analysis separates (the surface fit's), the names `expected_hz` may use."""
TILT_STEP_DEG = 0.5
"""Frames whose tilt stays within this of a plateau's median belong to it."""
MIN_PLATEAU_S = 0.5
"""A tilt table holds each angle this long or more (as `sds calibrate rig --video` asks); a
sloshing surface holds a tilt for a few frames around each extreme (at most 0.27 s in the
simulated drops)."""
STILL_MM = 0.1
"""Largest median over the spots of a plateau's height standard deviation [mm] (noise: 0.02)."""
MIN_MENISCUS_POINTS = 200
MIN_CYCLES = 3
"""A component with fewer cycles than this in the window is noted as doubtful."""


@dataclass(frozen=True)
class AnalysisOptions:
    """Analysis window and model inputs.

    The free decay starts at `start_s`; else `forcing_s` after the excitation's onset (a forced
    motion of known duration, e.g. a robot's); else at the largest swing (an impulsive kick).
    `gravity_m_s2` overrides the rig's for the theory; `expected_hz` (mode name → Hz) supplies
    frequencies where the theory does not hold (microgravity, a magnetised ferrofluid).
    `damping_caveat` is noted on every mode of the surface whose damping ratio is estimated:
    what the source does to it that its σ does not include (a compressed video's).
    """

    start_s: float | None = None
    end_s: float | None = None
    forcing_s: float | None = None
    gravity_m_s2: float | None = None
    expected_hz: dict[str, float] = field(default_factory=dict)
    max_components: int = 4
    min_snr: float = 8.0
    damping_caveat: str = ""

    def __post_init__(self) -> None:
        """InputError for a value the analysis cannot use, naming it (before any work)."""
        for name in ("start_s", "end_s", "forcing_s", "gravity_m_s2"):
            value = getattr(self, name)
            if value is not None and not np.isfinite(value):
                raise InputError(f"{name} {value} is not a finite number")
        if self.gravity_m_s2 is not None and self.gravity_m_s2 < 0:
            raise InputError(f"gravity {self.gravity_m_s2:g} m/s² is negative: give its "
                             "magnitude (0 for weightlessness)")
        if self.forcing_s is not None and self.forcing_s < 0:
            raise InputError(f"forcing duration {self.forcing_s:g} s is negative")
        for mode, hz in self.expected_hz.items():
            if mode not in ANALYSED_MODES:
                raise InputError(f"expected frequency of {mode!r}: the analysis separates "
                                 f"{', '.join(ANALYSED_MODES)}")
            if not (np.isfinite(hz) and hz > 0):
                raise InputError(f"expected frequency of {mode} {hz:g} Hz: give one above 0")


def with_gravity_regime(options: AnalysisOptions,
                        accelerometers: dict[str, tuple[np.ndarray, np.ndarray]]
                        ) -> tuple[AnalysisOptions, str]:
    """The options, with microgravity where no gravity was given and an accelerometer (name →
    times [s], N×3 m/s²) shows a free fall; and the note that says so (empty otherwise)."""
    if options.gravity_m_s2 is not None:
        return options, ""
    gravity, note = gravity_regime(accelerometers)
    return replace(options, gravity_m_s2=gravity), note


@dataclass(frozen=True)
class ModeResult:
    """One mode's (or series component's) estimates by every method, with the fitted model."""

    name: str
    time_s: np.ndarray
    values: np.ndarray
    unit: str
    fit: DampedSinusoidFit | None
    component: DampedSinusoid | None
    estimates: tuple[ModeEstimate, ...]
    notes: tuple[str, ...] = ()
    azimuth_deg: float = float("nan")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no samples)."""
        return {"mode": self.name, "unit": self.unit, "azimuth_deg": self.azimuth_deg,
                "estimates": [e.as_dict() for e in self.estimates], "notes": list(self.notes)}


@dataclass(frozen=True)
class TiltStep:
    """One static plateau of a tilt series: the plane of Eq. 12 through all its points."""

    start_s: float
    end_s: float
    frames: int
    p00_mm: float
    p10: float
    p01: float
    tilt_x_deg: float
    tilt_y_deg: float
    r_squared: float
    rmse_mm: float
    sse_mm2: float
    point_count: int


@dataclass(frozen=True)
class SloshingAnalysis:
    """Everything `sds analyze` reports."""

    source: str
    window_s: tuple[float, float]
    gravity_m_s2: float
    theory: tuple[TheoreticalMode, ...]
    modes: tuple[ModeResult, ...]
    tof: tuple[ModeResult, ...]
    tilt_steps: tuple[TiltStep, ...]
    meniscus: tuple[np.ndarray, np.ndarray, np.ndarray]   # radius [mm], height [mm], count
    meniscus_source: str

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready results."""
        radius, height, count = self.meniscus
        return {
            "source": self.source, "window_s": list(self.window_s),
            "gravity_m_s2": self.gravity_m_s2,
            "theory": [{"mode": m.name, "xi": m.xi, "frequency_hz": m.frequency_hz}
                       for m in self.theory],
            "modes": [m.as_dict() for m in self.modes],
            "tof": [m.as_dict() for m in self.tof],
            "tilt_steps": [vars(s) for s in self.tilt_steps],
            "meniscus": {"source": self.meniscus_source, "radius_mm": radius.tolist(),
                         "height_mm": [None if not np.isfinite(h) else float(h) for h in height],
                         "count": count.tolist()},
        }


def _significant(fit: DampedSinusoidFit, component: DampedSinusoid, min_snr: float) -> bool:
    """Matched-filter SNR of a component, √(Σ c(τ)²) / residual RMS, at least `min_snr`."""
    return fit.window_norm(component) >= min_snr * max(fit.residual_rms, np.finfo(float).tiny)


def _pick(fit: DampedSinusoidFit, expected_hz: float | None, min_snr: float
          ) -> tuple[DampedSinusoid | None, str]:
    """The significant component nearest the expected frequency (within 15 %), else the
    largest over the window: the dominant oscillation is always reported, with a note when the
    theory expected another frequency."""
    candidates = [c for c in fit.components if _significant(fit, c, min_snr)]  # largest first
    if not candidates:
        return None, ""
    if expected_hz is None:
        return candidates[0], ""
    near = [c for c in candidates
            if abs(c.natural_frequency_hz / expected_hz - 1) <= MATCH_TOLERANCE]
    if near:
        return min(near, key=lambda c: abs(c.natural_frequency_hz - expected_hz)), ""
    dominant = candidates[0]
    off = dominant.natural_frequency_hz / expected_hz - 1
    return dominant, (f"the theory expects {expected_hz:.3f} Hz; the dominant oscillation is "
                      f"{off:+.0%} from it (wrong gravity, fill level or rig?)")


def analyze_series(name: str, time_s: np.ndarray, values: np.ndarray, unit: str,
                   start_s: float, end_s: float | None, options: AnalysisOptions,
                   expected_hz: float | None = None, pencil_method: str = "matrix_pencil",
                   ) -> ModeResult:
    """One mode of one series: matrix pencil, FFT peak, half-power and log decrement."""
    notes: list[str] = []
    fit = component = None
    try:
        fit = fit_damped_sinusoids(time_s, values, options.max_components, start_s, end_s)
        component, disagreement = _pick(fit, expected_hz, options.min_snr)
        notes += [disagreement] if disagreement else []
    except DecayError as error:
        notes.append(f"{pencil_method}: {error}")
    if component is None or fit is None:
        if fit is not None:
            notes.append(f"no oscillation above the noise (SNR < {options.min_snr:g})")
        return ModeResult(name, time_s, values, unit, fit, None, (), tuple(notes))
    frequency = component.natural_frequency_hz
    estimates = [fit.estimate(component, pencil_method)]
    _, damping_sigma = component.sigmas()
    if component.damping_ratio < -3 * damping_sigma:
        notes.append("growing (ζ < 0 beyond 3σ): not a free decay")
    if frequency * (fit.end_s - fit.start_s) < MIN_CYCLES:
        notes.append(f"fewer than {MIN_CYCLES} cycles in the window")
    try:
        peaks = fft_peaks(time_s, values, 4, start_s=start_s, end_s=end_s)
        if peaks:
            estimates.append(min(peaks, key=lambda p: abs(p.frequency_hz - frequency)))
    except DecayError as error:
        notes.append(f"fft_peak: {error}")
    for estimator in (half_power, log_decrement):
        try:
            estimates.append(estimator(time_s, values, frequency, start_s=start_s, end_s=end_s))
        except DecayError as error:
            notes.append(f"{estimator.__name__}: {error}")
    return ModeResult(name, time_s, values, unit, fit, component, tuple(estimates), tuple(notes))


def check_window(start_s: float, end_s: float) -> None:
    """A one-line error (ValueError) for a window that ends before it starts."""
    if not end_s > start_s:
        raise InputError(f"the analysis window {start_s:.3f}–{end_s:.3f} s ends before it "
                         "starts (times are seconds from the first frame)")


def decay_start(time_s: np.ndarray, values: np.ndarray, options: AnalysisOptions) -> float:
    """Start of the free decay [s] by the rule `AnalysisOptions` describes."""
    if options.start_s is not None:
        return options.start_s
    if options.forcing_s is not None:
        return excitation_onset(time_s, values) + options.forcing_s
    return free_decay_start(time_s, values)


def tof_quick_estimate(time_s: np.ndarray, range_mm: np.ndarray, options: AnalysisOptions,
                       expected_hz: float | None = None,
                       camera_window_s: tuple[float, float] | None = None) -> ModeResult:
    """The fundamental from the ToF range alone (between drops).

    The ToF sees the mean level over its footprint, so it sees the lateral mode only where the
    footprint is off-centre, and its clock is the Arduino's: the window starts at the series'
    own excitation (largest swing, or onset + forcing), not the camera's — unless its stamps
    are on the camera's clock (the bridge aligned them with the sync LED) and cover the camera's
    decay window, which it then shares. If its stamps step back (the alignment), the part
    after the step is used.
    """
    time_s, range_mm = np.asarray(time_s, dtype=float), np.asarray(range_mm, dtype=float)
    backwards = np.flatnonzero(np.diff(time_s) <= 0)
    if len(backwards):   # the clock was re-aligned (sync LED): the part after the last step
        time_s, range_mm = time_s[backwards[-1] + 1:], range_mm[backwards[-1] + 1:]
    try:
        if camera_window_s is not None and time_s[0] <= camera_window_s[0] < time_s[-1]:
            start = camera_window_s[0]
        else:
            start = decay_start(time_s, range_mm, replace(options, start_s=None))
    except DecayError as error:
        return ModeResult("lateral_1", time_s, range_mm, "mm", None, None, (),
                          (f"tof: {error}",))
    return analyze_series("lateral_1", time_s, range_mm, "mm", start, None, options,
                          expected_hz, pencil_method="tof")


def tilt_steps(recording: SurfaceSeries) -> list[TiltStep]:
    """Still plateaus of the per-frame plane tilt; two or more apart make a tilt series."""
    tilts = np.full((len(recording.time_s), 2), np.nan)
    for frame, points in enumerate(recording.points_mm):
        if np.isfinite(points).all(axis=1).sum() >= 3:
            plane = fit_plane(points)
            tilts[frame] = np.degrees([plane.tilt_x_rad, plane.tilt_y_rad])
    plateaus: list[list[int]] = []
    for still in np.flatnonzero(np.isfinite(tilts).all(axis=1)).tolist():
        current = plateaus[-1] if plateaus else None
        if current and np.all(np.abs(tilts[still] - np.median(tilts[current], axis=0))
                              <= TILT_STEP_DEG):
            current.append(still)
        else:
            plateaus.append([still])
    period_s = float(np.median(np.diff(recording.time_s))) if len(recording.time_s) > 1 else 1.0
    steps = []
    for frames in (p for p in plateaus if len(p) * period_s >= MIN_PLATEAU_S - 1e-9):
        # a tilt-table plateau is still; a sloshing surface passes through tilts it holds for
        # a few frames while every spot's height moves by millimetres
        if np.nanmedian(np.nanstd(recording.points_mm[frames, :, 2], axis=0)) > STILL_MM:
            continue
        plane = fit_plane(recording.points_mm[frames].reshape(-1, 3))
        steps.append(TiltStep(float(recording.time_s[frames[0]]),
                              float(recording.time_s[frames[-1]]), len(frames), plane.p00_mm,
                              plane.p10, plane.p01, float(np.degrees(plane.tilt_x_rad)),
                              float(np.degrees(plane.tilt_y_rad)), plane.r_squared,
                              plane.rmse_mm, plane.sse_mm2, plane.point_count))
    angles = np.array([[s.tilt_x_deg, s.tilt_y_deg] for s in steps]).reshape(-1, 2)
    spread = np.ptp(angles, axis=0).max() if len(steps) >= 2 else 0.0
    return steps if spread > 2 * TILT_STEP_DEG else []


def meniscus_profile(recording: SurfaceSeries, radius_mm: float, before_s: float
                     ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], str]:
    """Radial profile of the line laser's points before `before_s` (the excitation) if there are
    enough, else over the whole record (the oscillation then averages out only partly)."""
    points, times = recording.line_points_mm, recording.line_time_s
    source = "line laser, whole record"
    if (times < before_s).sum() >= MIN_MENISCUS_POINTS:
        points, source = points[times < before_s], f"line laser before {before_s:.2f} s"
    if len(points) == 0:
        spots = recording.points_mm.reshape(-1, 3)
        points, source = spots, "laser spots, whole record (no line points)"
    return radial_profile(points, radius_mm), source


def rig_theory(rig: Rig, options: AnalysisOptions) -> tuple[float, list[TheoreticalMode]]:
    """Gravity [m/s²] (the rig's unless overridden) and the linear modes of its container."""
    gravity = rig.gravity_m_s2 if options.gravity_m_s2 is None else options.gravity_m_s2
    return gravity, theoretical_modes(rig.container.radius_mm, rig.container.fill_height_mm,
                                      gravity, rig.fluid.surface_tension_n_m,
                                      rig.fluid.density_kg_m3)


def analyze(recording: SurfaceSeries, rig: Rig, options: AnalysisOptions | None = None
            ) -> SloshingAnalysis:
    """Separate the modes, estimate each one's frequency and damping, tilt table, meniscus."""
    options = options or AnalysisOptions()
    gravity, theory = rig_theory(rig, options)
    expected = {m.name: m.frequency_hz for m in theory} if gravity > 0 else {}
    expected.update(options.expected_hz)
    modal = modal_series(recording.time_s, recording.points_mm, rig.container.radius_mm)
    coordinates = mode_coordinates(modal)
    first: ModeCoordinate = coordinates[0]
    try:
        start = decay_start(first.time_s, first.values_mm, options)
    except DecayError:
        start = float(recording.time_s[0])   # no decay to find: each mode says why below
    if options.end_s is None and not float(recording.time_s[-1]) > start:
        raise RecordingError(f"the recording ends at {float(recording.time_s[-1]):.3f} s, where "
                             "its free decay starts: too short to analyse")
    end = options.end_s if options.end_s is not None else float(recording.time_s[-1])
    check_window(start, end)
    modes = []
    for coordinate in coordinates:
        result = analyze_series(coordinate.name, coordinate.time_s, coordinate.values_mm, "mm",
                                start, options.end_s, options, expected.get(coordinate.name))
        caveat = (options.damping_caveat,) if options.damping_caveat and result.component \
            else ()
        modes.append(replace(result, azimuth_deg=float(np.degrees(coordinate.azimuth_rad)),
                             notes=result.notes + caveat))
    tof: tuple[ModeResult, ...] = ()
    if len(recording.tof_time_s) >= 16:
        tof = (tof_quick_estimate(recording.tof_time_s, recording.tof_range_mm, options,
                                  expected.get("lateral_1"), (float(start), end)),)
    try:
        quiet_until = excitation_onset(first.time_s, first.values_mm)
    except DecayError:
        quiet_until = start
    meniscus, meniscus_source = meniscus_profile(recording, rig.container.radius_mm,
                                                 min(quiet_until, start))
    return SloshingAnalysis(recording.source, (float(start), end), gravity, tuple(theory),
                            tuple(modes), tof, tuple(tilt_steps(recording)), meniscus,
                            meniscus_source)


def analyze_table(source: str, time_s: np.ndarray, series: dict[str, np.ndarray], rig: Rig,
                  options: AnalysisOptions | None = None, unit: str = "",
                  tof: bool = False) -> SloshingAnalysis:
    """Each column of a time-series table as one record (single-point mode, seed Sec. 4.4).

    Without expected frequencies a column reports its largest oscillation; with them (or the
    1 g theory), one result per expected mode found in it. `tof`: the columns are ToF ranges.
    """
    options = options or AnalysisOptions()
    gravity, theory = rig_theory(rig, options)
    expected = dict(options.expected_hz) or (
        {m.name: m.frequency_hz for m in theory[:2]} if gravity > 0 else {})
    results, windows = [], []
    for column, values in series.items():
        start = decay_start(time_s, values, options)
        if options.end_s is not None:
            check_window(start, options.end_s)
        windows.append(start)
        targets = expected.items() if expected else [(column, None)]
        for mode, frequency in targets:
            name = mode if len(series) == 1 or not expected else f"{column}:{mode}"
            results.append(analyze_series(name, time_s, values, unit, start, options.end_s,
                                          options, frequency, "tof" if tof else "matrix_pencil"))
    end = options.end_s if options.end_s is not None else float(np.nanmax(time_s))
    empty = (np.empty(0), np.empty(0), np.empty(0, dtype=int))
    modes, tof_results = (tuple(results), ()) if not tof else ((), tuple(results))
    return SloshingAnalysis(source, (float(min(windows)), end), gravity, tuple(theory), modes,
                            tof_results, (), empty, "none")
