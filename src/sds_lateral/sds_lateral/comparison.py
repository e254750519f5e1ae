"""The top camera's surface along the wall, against the side camera's contact line.

The top camera's modal fit of each frame (mean level, lateral and axisymmetric modes:
`sds_recon.surface_fit`) is a surface over the whole disc; at the wall (r = R) it is evaluated
at the azimuths the side camera measured, at the side frame's time on the top clock (each
amplitude interpolated between top frames by a cubic spline: linear interpolation of a 3 Hz
wave sampled at 30 fps would be off by 5 % of its amplitude). The fit's σ there comes from
its own covariance: (Aᵀ W A)⁻¹ scaled by its weighted residuals' variance, so a frame whose
points the modes do not explain (higher modes, a wrong point) claims less.

The difference side − top has a mean that neither fit is meant to remove: the meniscus (the
contact line stands above the surface the top fit extrapolates to the wall) and the side
camera's pose (its σ, the same in every frame). It is reported with the pose's σ; the
difference's scatter about it is what the side's image noise, the top fit's σ and the clock
link's σ (times the surface's rate of change: 2.3 ms of a 3 Hz, 4 mm wave is 0.17 mm) predict.

The same comparison times the two cameras a third way: the shift of the side frames that best
lays the top surface's motion over the side's. Its difference from the LED clock, in their σ,
checks the LED link; once shifted, what is left is the heights' own disagreement.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import CubicSpline
from sds_model.errors import InputError
from sds_recon.surface_fit import DEFAULT_MODES, HEIGHT_SIGMA_FLOOR_MM, modal_design

LINE_LASER_ID = 65535
MIN_TOP_FRAMES = 4
"""Top frames with a modal fit needed before the top surface can be interpolated in time."""


@dataclass(frozen=True)
class TopSurfaceSeries:
    """The top camera's modal fits over time: times [s], amplitudes (frames × terms, mm), the
    terms' names and each frame's amplitude covariance (frames × terms × terms, mm²)."""

    time_s: np.ndarray
    amplitudes_mm: np.ndarray
    names: tuple[str, ...]
    covariance_mm2: np.ndarray
    radius_mm: float

    @cached_property
    def _spline(self) -> CubicSpline:
        return CubicSpline(self.time_s, self.amplitudes_mm, axis=0)

    def nearest_frame(self, time_s: float) -> int:
        """The index of the top frame nearest a time (among the fitted ones)."""
        return int(np.argmin(np.abs(self.time_s - time_s)))

    def wall(self, time_s: float, azimuth_rad: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The fitted surface at the wall at the azimuths and a time: its height [mm] (NaN
        outside the fits' time span), its σ [mm] (the nearest top frame's covariance) and its
        rate of change [mm/s] (what a clock error turns into a height error)."""
        nan = np.full(len(azimuth_rad), np.nan)
        if not self.time_s[0] <= time_s <= self.time_s[-1]:
            return nan, nan, nan
        wall_xy = self.radius_mm * np.column_stack([np.cos(azimuth_rad), np.sin(azimuth_rad)])
        design, _ = modal_design(wall_xy, self.radius_mm, DEFAULT_MODES)
        nearest = self.nearest_frame(time_s)
        variance = np.einsum("ij,jk,ik->i", design, self.covariance_mm2[nearest], design)
        return (design @ self._spline(time_s), np.sqrt(np.maximum(variance, 0.0)),
                design @ self._spline(time_s, 1))


def top_surface_series(fits: np.ndarray, points: np.ndarray, radius_mm: float
                       ) -> TopSurfaceSeries:
    """The top run's modal fits (`fits` table) with each frame's covariance from its points
    (`points` table: the laser spots that were not rejected, weighted as the fit weighs them:
    1/σ² with σ floored at HEIGHT_SIGMA_FLOOR_MM). ValueError with too few fitted frames."""
    probe, names = modal_design(np.zeros((1, 2)), radius_mm, DEFAULT_MODES)
    columns = [f"{name}_mm" for name in names]
    missing = [c for c in columns if c not in (fits.dtype.names or ())]
    if missing:
        raise InputError(f"the top camera's fits have no modal amplitudes {missing}")
    amplitudes = np.column_stack([fits[c] for c in columns])
    spots = points[(points["laser_id"] != LINE_LASER_ID) & (points["rejected"] == 0)]
    order = np.argsort(spots["frame"], kind="stable")
    spots = spots[order]
    starts = np.searchsorted(spots["frame"], fits["frame"], side="left")
    ends = np.searchsorted(spots["frame"], fits["frame"], side="right")
    terms = probe.shape[1]
    covariance = np.full((len(fits), terms, terms), np.nan)
    for row, (start, end) in enumerate(zip(starts, ends, strict=True)):
        frame = spots[start:end]
        if end - start <= terms or not np.all(np.isfinite(amplitudes[row])):
            continue
        xyz = np.column_stack([frame["X_mm"], frame["Y_mm"], frame["Z_mm"]])
        design, _ = modal_design(xyz, radius_mm, DEFAULT_MODES)
        weight = np.maximum(frame["sigma_Z_mm"], HEIGHT_SIGMA_FLOOR_MM) ** -2.0
        residual = xyz[:, 2] - design @ amplitudes[row]
        scale = float(weight @ residual**2) / (len(frame) - terms)
        covariance[row] = np.linalg.inv(design.T @ (design * weight[:, None])) * scale
    fitted = np.all(np.isfinite(amplitudes), axis=1) & np.all(np.isfinite(covariance),
                                                                  axis=(1, 2))
    if np.count_nonzero(fitted) < MIN_TOP_FRAMES:
        raise InputError(f"{np.count_nonzero(fitted)} top frames with a modal fit, too few "
                         "to compare with the side camera")
    return TopSurfaceSeries(fits["t_s"][fitted], amplitudes[fitted], tuple(names),
                            covariance[fitted], radius_mm)


@dataclass(frozen=True)
class FrameComparison:
    """One side frame against the top surface at its wall points (azimuths [rad]): the side's
    heights and their σ from the image and from the pose, the top's heights, σ and rate of
    change [mm, mm/s] (NaN where the top has no surface then), the clock link's σ [s] and the
    nearest top frame (whose fit the top's errors share)."""

    azimuth_rad: np.ndarray
    side_mm: np.ndarray
    side_sigma_mm: np.ndarray
    side_pose_sigma_mm: np.ndarray
    top_mm: np.ndarray
    top_sigma_mm: np.ndarray
    top_rate_mm_s: np.ndarray
    clock_sigma_s: float
    top_frame: int

    @property
    def difference_mm(self) -> np.ndarray:
        """Side minus top at each wall point [mm]."""
        return self.side_mm - self.top_mm

    @property
    def aligned_sigma_mm(self) -> np.ndarray:
        """What the side's image noise and the top fit predict for the difference's scatter
        at each point once the clock is right [mm]."""
        return np.hypot(self.side_sigma_mm, self.top_sigma_mm)

    @property
    def predicted_sigma_mm(self) -> np.ndarray:
        """What the side's image noise, the top fit and the clock link's σ (times the
        surface's rate of change) predict for the difference's scatter at each point [mm]."""
        return np.hypot(self.aligned_sigma_mm, self.top_rate_mm_s * self.clock_sigma_s)

    @property
    def rms_difference_mm(self) -> float:
        """The RMS of side − top over the points compared [mm] (NaN: none)."""
        return _rms(self.difference_mm)

    @property
    def rms_predicted_mm(self) -> float:
        """What the σ predict for that RMS [mm] (NaN: no point compared)."""
        return _rms(np.where(np.isfinite(self.difference_mm), self.predicted_sigma_mm, np.nan))


def _rms(values: np.ndarray) -> float:
    """The RMS of the finite values (NaN if none)."""
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else float("nan")


@dataclass(frozen=True)
class ComparisonSummary:
    """Over a run: the points compared, the mean of side − top [mm] and the pose's σ of it
    [mm], its RMS [mm], its RMS about the mean [mm], and what both σ predict for that scatter
    [mm]: the side's image noise, the top fit's σ and the clock's. Then the wave's own clock:
    the time shift [s] of the side frames that best lays the top surface's motion over the
    side's (weighted least squares of the difference on the surface's rate of change, its σ
    robust to the errors each top frame's fit shares), and the scatter left once shifted
    against what the side's noise and the top fit alone predict [mm]."""

    points: int
    frames: int
    mean_difference_mm: float
    pose_sigma_mm: float
    rms_difference_mm: float
    scatter_mm: float
    predicted_mm: float
    wave_shift_s: float
    wave_shift_sigma_s: float
    tilt_deg: tuple[float, float]
    tilt_sigma_deg: tuple[float, float]
    aligned_scatter_mm: float
    aligned_predicted_mm: float

    def summary(self) -> str:
        """One line for the console and the report."""
        return (f"top surface at the wall against the side camera, {self.frames} frames: "
                f"side − top {self.mean_difference_mm:+.3f} mm on average (the meniscus, and "
                f"the side camera's pose: σ {self.pose_sigma_mm:.3f} mm), RMS "
                f"{self.rms_difference_mm:.3f} mm; about the mean {self.scatter_mm:.3f} mm "
                f"where both σ predict {self.predicted_mm:.3f} mm")

    def wave_summary(self, clock_sigma_s: float) -> str:
        """One line: the wave's clock check, the tilt between the two, and the scatter once
        both are taken out."""
        pull = self.wave_shift_s / np.hypot(self.wave_shift_sigma_s, clock_sigma_s)
        tilt = ", ".join(f"{v:+.3f} ± {e:.3f}°" for v, e in zip(self.tilt_deg,
                                                                 self.tilt_sigma_deg,
                                                                 strict=True))
        return (f"the wave's own timing: the side frames {self.wave_shift_s * 1e3:+.2f} ± "
                f"{self.wave_shift_sigma_s * 1e3:.2f} ms from the LED clock ({pull:+.1f} σ of "
                f"both); side − top tilts by γx, γy = {tilt}; with both taken out, side − top "
                f"scatters {self.aligned_scatter_mm:.3f} mm about its mean where the side's "
                f"noise and the top fit predict {self.aligned_predicted_mm:.3f} mm")


def summarise(frames: list[FrameComparison], radius_mm: float) -> ComparisonSummary:
    """The run's summary over every wall point compared (on the wall of `radius_mm`)."""
    nan = float("nan")
    rows = [(f, np.isfinite(f.difference_mm) & np.isfinite(f.predicted_sigma_mm)) for f in frames]
    rows = [(f, used) for f, used in rows if used.any()]
    if not rows:
        return ComparisonSummary(0, 0, *(nan,) * 7, (nan, nan), (nan, nan), nan, nan)

    def joined(name: str) -> np.ndarray:
        return np.concatenate([getattr(f, name)[used] for f, used in rows])

    difference, sigma, pose = (joined(n) for n in ("difference_mm", "predicted_sigma_mm",
                                                  "side_pose_sigma_mm"))
    aligned, rate = joined("aligned_sigma_mm"), joined("top_rate_mm_s")
    azimuth = joined("azimuth_rad")
    cluster = np.concatenate([np.full(np.count_nonzero(used), f.top_frame) for f, used in rows])
    mean = float(np.mean(difference))
    # difference = offset + a cos θ + b sin θ + rate · shift, a = −R tan γx, b = −R tan γy
    design = np.column_stack([np.ones_like(rate), np.cos(azimuth), np.sin(azimuth), rate])
    solution, sigma_of, residual = _clustered_least_squares(design, difference, aligned,
                                                            cluster)
    tilt = tuple(float(np.degrees(-np.arctan(v / radius_mm))) for v in solution[1:3])
    tilt_sigma = tuple(float(np.degrees(e / radius_mm)) for e in sigma_of[1:3])
    return ComparisonSummary(int(difference.size), len(rows), mean,
                             float(np.sqrt(np.mean(pose**2))),
                             float(np.sqrt(np.mean(difference**2))),
                             float(np.sqrt(np.mean((difference - mean) ** 2))),
                             float(np.sqrt(np.mean(sigma**2))), float(solution[3]),
                             float(sigma_of[3]), (tilt[0], tilt[1]),
                             (tilt_sigma[0], tilt_sigma[1]),
                             float(np.sqrt(np.mean(residual**2))),
                             float(np.sqrt(np.mean(aligned**2))))


def _clustered_least_squares(design: np.ndarray, values: np.ndarray, sigma: np.ndarray,
                             cluster: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted (1/σ²) least squares: the solution, its σ (cluster-robust: the points of one
    cluster, one top fit, share its error, so they are not independent) and the residuals."""
    weight = sigma**-2.0
    normal = design.T @ (design * weight[:, None])
    solution = np.linalg.solve(normal, design.T @ (weight * values))
    residual = values - design @ solution
    scores = design * (weight * residual)[:, None]
    groups = np.unique(cluster, return_inverse=True)[1]
    per_cluster = np.zeros((groups.max() + 1, design.shape[1]))
    np.add.at(per_cluster, groups, scores)
    inverse = np.linalg.inv(normal)
    covariance = inverse @ (per_cluster.T @ per_cluster) @ inverse
    return solution, np.sqrt(np.diag(covariance)), residual
