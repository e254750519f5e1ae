"""Modal separation: the ring measurements projected on the container's modes, frame by frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sds_model.errors import InputError
from sds_recon.surface_fit import DEFAULT_MODES, fit_modes


@dataclass(frozen=True)
class ModalSeries:
    """Per frame: least-squares modal amplitudes [mm] (NaN where too few points) and fit RMSE."""

    time_s: np.ndarray          # (F,)
    names: tuple[str, ...]      # "mean", "lateral_1_cos", "lateral_1_sin", …, "axisymmetric_1"
    amplitudes_mm: np.ndarray   # (F, K)
    rmse_mm: np.ndarray         # (F,)

    def column(self, name: str) -> np.ndarray:
        """One amplitude's time series [mm]."""
        return self.amplitudes_mm[:, self.names.index(name)]


@dataclass(frozen=True)
class ModeCoordinate:
    """A mode's coordinate q(t) [mm] (wall elevation) along its principal azimuth [rad]."""

    name: str
    azimuth_rad: float
    time_s: np.ndarray
    values_mm: np.ndarray


def modal_series(time_s: np.ndarray, points_mm: np.ndarray, radius_mm: float,
                 modes: tuple[tuple[int, int], ...] = DEFAULT_MODES) -> ModalSeries:
    """Fit the mean level and the modes to every frame's points (F × L × 3 mm, NaN = missing)."""
    names: tuple[str, ...] = ()
    amplitudes: list[np.ndarray | None] = []
    rmse = np.full(len(time_s), np.nan)
    for frame, points in enumerate(points_mm):
        try:
            fit = fit_modes(points, radius_mm, modes)
        except ValueError:
            amplitudes.append(None)
            continue
        names = fit.names
        amplitudes.append(fit.amplitudes_mm)
        rmse[frame] = fit.rmse_mm
    if not names:
        raise InputError("no frame has enough surface points for the modal fit")
    table = np.array([a if a is not None else np.full(len(names), np.nan) for a in amplitudes])
    return ModalSeries(np.asarray(time_s, dtype=float), names, table, rmse)


def mode_coordinates(series: ModalSeries) -> list[ModeCoordinate]:
    """One coordinate per mode: axisymmetric as fitted, lateral along its principal azimuth.

    A lateral mode's (cos, sin) amplitudes are q (cos mφ, sin mφ) for sloshing along azimuth φ;
    the principal axis of their scatter gives φ and q their projection on it, so a planar
    slosh in any direction is one coordinate (a swirl leaves the other axis's share out).
    """
    coordinates = []
    for name in series.names:
        if name == "mean" or name.endswith("_sin"):
            continue
        if not name.endswith("_cos"):
            coordinates.append(ModeCoordinate(name, 0.0, series.time_s, series.column(name)))
            continue
        base = name.removesuffix("_cos")
        pair = np.column_stack([series.column(name), series.column(f"{base}_sin")])
        finite = np.isfinite(pair).all(axis=1)
        centred = pair[finite] - np.median(pair[finite], axis=0)
        _, vectors = np.linalg.eigh(centred.T @ centred)
        axis = vectors[:, -1] * np.sign(vectors[np.argmax(np.abs(vectors[:, -1])), -1])
        coordinates.append(ModeCoordinate(base, float(np.arctan2(axis[1], axis[0]) / _order(base)),
                                          series.time_s, pair @ axis))
    return coordinates


def _order(name: str) -> int:
    """Azimuthal order m of a mode named by `theory.mode_name`."""
    if name.startswith("lateral_"):
        return 1
    if name.startswith("axisymmetric_"):
        return 0
    return int(name[1:name.index("n")])
