"""Ideal vertical resolution of a laser spot seen by a downward camera (seed Sec. 4.2, Fig. 7)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from sds_model.camera.model import CameraModel
from sds_model.errors import InputError

HEIGHT_STEP_MM = 0.01
"""Surface displacement of the central difference that gives d(pixel)/dZ."""
AZIMUTH_SAMPLES = 72


@dataclass(frozen=True)
class ResolutionTable:
    """mm/px per radius: along +x (image columns), and the range over every azimuth."""

    radii_mm: np.ndarray
    along_x_mm_per_px: np.ndarray
    best_mm_per_px: np.ndarray
    worst_mm_per_px: np.ndarray
    height_mm: float
    beam_tilt_rad: float

    def rows(self) -> list[tuple[float, float, float, float]]:
        """(radius mm, along x, best, worst mm/px) per radius."""
        return list(zip(self.radii_mm.tolist(), self.along_x_mm_per_px.tolist(),
                        self.best_mm_per_px.tolist(), self.worst_mm_per_px.tolist(), strict=True))


def spot_points(radii_mm: np.ndarray, azimuth_rad: np.ndarray, depth_mm: float, height_mm: float,
                beam_tilt_rad: float) -> np.ndarray:
    """Where the beams meet a flat surface `depth_mm` below the camera (camera frame, z down).

    Each beam crosses the reference surface (`height_mm` below the camera) at `radii_mm` from
    the optical axis and leans outwards by `beam_tilt_rad` from the vertical.
    """
    radial = radii_mm[:, None] + (depth_mm - height_mm) * np.tan(beam_tilt_rad)
    x = radial * np.cos(azimuth_rad)[None, :]
    y = radial * np.sin(azimuth_rad)[None, :]
    return np.stack([x, y, np.full_like(x, depth_mm)], axis=-1)


def vertical_resolution(camera: CameraModel, radii_mm: ArrayLike, height_mm: float,
                        beam_tilt_rad: float = 0.0) -> ResolutionTable:
    """dZ/dpixel [mm/px] of a spot as the surface moves, camera looking straight down (Fig. 7).

    The optical axis is vertical and meets the surface `height_mm` below the camera; infinite
    where the spot does not move in the image (a vertical beam on the axis). ValueError for a
    camera height that is not positive, a negative radius or a beam tilt of 90° or more.
    """
    radii = np.asarray(radii_mm, dtype=float)
    if not height_mm > 0 or np.any(radii < 0) or not abs(beam_tilt_rad) < np.pi / 2:
        raise InputError(f"camera height {height_mm:g} mm, beam tilt "
                         f"{np.degrees(beam_tilt_rad):g}°, radii from {np.min(radii, initial=0):g}"
                         " mm: the height must be positive, the tilt below 90°, no radius "
                         "negative")
    azimuths = np.linspace(0.0, 2 * np.pi, AZIMUTH_SAMPLES, endpoint=False)
    pixels = [camera.project(spot_points(radii, azimuths, height_mm + sign * HEIGHT_STEP_MM,
                                         height_mm, beam_tilt_rad).reshape(-1, 3))
              for sign in (-1.0, 1.0)]
    moved_px = np.linalg.norm(pixels[1] - pixels[0], axis=1).reshape(len(radii), -1)
    speed = moved_px / (2 * HEIGHT_STEP_MM)
    with np.errstate(divide="ignore"):
        mm_per_px = 1.0 / speed
    return ResolutionTable(radii, mm_per_px[:, 0], mm_per_px.min(axis=1), mm_per_px.max(axis=1),
                           float(height_mm), float(beam_tilt_rad))


def table_text(table: ResolutionTable) -> str:
    """The table as aligned text (CSV-friendly with its header)."""
    lines = [f"# camera {table.height_mm:g} mm above a flat surface, beams tilted "
             f"{np.degrees(table.beam_tilt_rad):g} deg outwards",
             "radius_mm, along_x_mm_per_px, best_mm_per_px, worst_mm_per_px"]
    lines += [f"{r:9.2f}, {x:17.4f}, {b:14.4f}, {w:15.4f}" for r, x, b, w in table.rows()]
    return "\n".join(lines)


def plot_resolution(table: ResolutionTable, path: Path, rings_mm: ArrayLike = ()) -> Path:
    """PNG of mm/px against radius (Fig. 7), with dashed lines at the diode rings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(7, 4.5))
    axes.plot(table.radii_mm, table.along_x_mm_per_px, label="along image x")
    axes.fill_between(table.radii_mm, table.best_mm_per_px, table.worst_mm_per_px, alpha=0.25,
                      label="range over azimuth")
    for ring in np.asarray(rings_mm, dtype=float):
        axes.axvline(ring, color="k", linestyle="--", linewidth=0.8)
    finite = table.worst_mm_per_px[np.isfinite(table.worst_mm_per_px)]
    if finite.size:
        axes.set_ylim(0, min(float(finite.max()) * 1.05, 5.0))
    axes.set(xlabel="radial position of the laser spot [mm]", ylabel="vertical resolution [mm/px]",
             title=f"camera {table.height_mm:g} mm above the surface, beam tilt "
                   f"{np.degrees(table.beam_tilt_rad):g}°")
    axes.grid(True, alpha=0.3)
    axes.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
