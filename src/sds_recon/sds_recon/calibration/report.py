"""Calibration report: per-image and overall reprojection errors as JSON, text and a PNG plot."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sds_recon.calibration.camera_calibration import CalibrationRun


def report_content(run: CalibrationRun) -> dict[str, Any]:
    """The report as plain data: board, images, per-image and overall errors [px], corrections."""
    calibration = run.calibration
    distances = [np.linalg.norm(e.residuals_px, axis=1) for e in calibration.errors]
    everything = np.concatenate(distances)
    return {
        "model": run.model,
        "image_size": [calibration.camera.width_px, calibration.camera.height_px],
        "board": {"columns": run.board.columns, "rows": run.board.rows,
                  "square_mm": run.board.square_mm},
        "images_used": len(calibration.views),
        "converged": calibration.converged,
        "images_without_board": run.rejected_images,
        "overall": {"points": int(everything.size), "mean_px": calibration.mean_px,
                    "rms_px": calibration.rms_px, "max_px": float(everything.max())},
        "per_image": [{"image": e.name, "points": int(d.size), "mean_px": e.mean_px,
                       "rms_px": e.rms_px, "max_px": float(d.max())}
                      for e, d in zip(calibration.errors, distances, strict=True)],
        "corner_corrections": [{"image": c.image, "corner": c.corner,
                                "residual_before_px": c.residual_before_px, "action": c.action}
                               for c in run.corrections],
        "camera": calibration.camera.to_dict(),
    }


def report_text(content: dict[str, Any]) -> str:
    """A readable table of the report."""
    overall = content["overall"]
    lines = [f"{content['model']} calibration, {content['images_used']} images, "
             f"{overall['points']} corners: mean {overall['mean_px']:.3f} px, "
             f"RMS {overall['rms_px']:.3f} px, max {overall['max_px']:.3f} px",
             f"{'image':<28} {'points':>6} {'mean px':>8} {'rms px':>8} {'max px':>8}"]
    lines += [f"{row['image']:<28} {row['points']:>6} {row['mean_px']:>8.3f} {row['rms_px']:>8.3f} "
              f"{row['max_px']:>8.3f}" for row in content["per_image"]]
    if not content["converged"]:
        lines.insert(0, "THE FIT DID NOT CONVERGE: it stopped at its limit of evaluations; the "
                        "camera below is not the best the corners give (check the images)")
    if content["images_without_board"]:
        lines.append("no complete board found in: " + ", ".join(content["images_without_board"]))
    for correction in content["corner_corrections"]:
        lines.append(f"corner {correction['corner']} of {correction['image']} was "
                     f"{correction['residual_before_px']:.1f} px off: {correction['action']}")
    return "\n".join(lines)


def plot_residuals(run: CalibrationRun, path: Path) -> Path:
    """PNG: residual vectors, per-image RMS, and residual against distance from the image centre."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    calibration = run.calibration
    residuals = np.concatenate([e.residuals_px for e in calibration.errors])
    points = np.concatenate([v.image_points for v in calibration.views])
    camera = calibration.camera
    centre = np.array([(camera.width_px - 1) / 2, (camera.height_px - 1) / 2])
    figure, (scatter, bars, radial) = plt.subplots(1, 3, figsize=(15, 4.5))
    for error in calibration.errors:
        scatter.plot(error.residuals_px[:, 0], error.residuals_px[:, 1], ".", ms=3)
    scatter.set(xlabel="x residual [px]", ylabel="y residual [px]", aspect="equal",
                title=f"reprojected − detected (RMS {calibration.rms_px:.3f} px)")
    scatter.grid(True, alpha=0.3)
    names = [e.name for e in calibration.errors]
    bars.bar(range(len(names)), [e.rms_px for e in calibration.errors])
    bars.set_xticks(range(len(names)), names, rotation=90, fontsize=7)
    bars.set(ylabel="RMS [px]", title="per image")
    radial.plot(np.linalg.norm(points - centre, axis=1), np.linalg.norm(residuals, axis=1), ".",
                ms=3)
    radial.set(xlabel="distance from the image centre [px]", ylabel="|residual| [px]",
               title="residual against image radius")
    radial.grid(True, alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def write_report(run: CalibrationRun, directory: Path, stem: str) -> dict[str, Path]:
    """Write <stem>.report.json, <stem>.report.txt and <stem>.residuals.png into `directory`."""
    content = report_content(run)
    paths = {"json": directory / f"{stem}.report.json", "text": directory / f"{stem}.report.txt",
             "plot": directory / f"{stem}.residuals.png"}
    paths["json"].write_text(json.dumps(content, indent=2) + "\n")
    paths["text"].write_text(report_text(content) + "\n")
    plot_residuals(run, paths["plot"])
    return paths
