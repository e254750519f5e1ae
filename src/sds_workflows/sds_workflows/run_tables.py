"""A run's result files and what its analysis needs, row by row (`sds process`, `sds export`).

`RunTables` writes every row of a run (spots, points, line, fits, IMU, ToF) as it comes and keeps
what the analysis reads; `finish_analysis` analyses them and closes the tables.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sds_camera.camera_imu import CameraImu, imu_samples
from sds_model.errors import InputError
from sds_model.rig import Rig
from sds_recon.instant import sample_offsets_s
from sds_recon.reconstruction import LINE_LASER_ID, SurfaceFits, SurfacePoints
from sds_recon.results import TABLE_FILES, ResultsWriter
from sds_sloshing.analysis import AnalysisOptions, analyze, with_gravity_regime
from sds_sloshing.report import REPORT_FILES, Truth, add_report_section, write_report
from sds_sloshing.surface_series import (
    RecordingError,
    SurfaceSeries,
    surface_series_from_rows,
)
from sds_tracker.path_scatter import PathScatter, SigmaCheck
from sds_tracker.spots import is_measured

from sds_workflows.lateral import LATERAL_FILES
from sds_workflows.pipeline import PipelineStep

CAMERA_IMU_TOPIC = "/camera/imu"
LINE_FRAMES_IN_FULL = 1800
LINE_FRAME_STEP = 10
"""The analysis keeps the line's points of the first LINE_FRAMES_IN_FULL frames (a minute at
30 fps), then of every LINE_FRAME_STEP-th: they serve only the meniscus, a mean radial profile,
and all of a 10-minute 4K run's would hold 0.8 GB (the result files keep every one)."""

SIGMA_CHECK_KEY = "spot_sigma_check"
"""analysis.json's key for the spots' own check of their σ (`sds_tracker.path_scatter`)."""

RUN_FILES = (*TABLE_FILES, *REPORT_FILES, *LATERAL_FILES)
"""What a run of `sds process` or `sds export` writes into its folder: all of it is replaced
together (`staging.staged_folder`), so that no earlier run's file (a side camera's) is left
beside the new results."""


def _camera_imu_row(time_s: float, accel, gyro) -> tuple:
    """A camera_imu.csv row: time, accelerometer and gyroscope cells (empty where None)."""
    empty = (np.nan,) * 3
    return (time_s, *(empty if accel is None else accel), *(empty if gyro is None else gyro))


class RunTables:
    """The rows of one run, written as they come; what the analysis needs is kept: the points
    the fits kept, the ToF ranges and every accelerometer."""

    def __init__(self, writer: ResultsWriter, rig: Rig) -> None:
        self.writer = writer
        self.rig = rig
        self._timed = rig.camera_shutter.readout_s > 0
        if self._timed:
            writer.time_points()
        self._kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # time, id, X Y Z
        self._tof: list[tuple[float, float]] = []                         # time [s], [mm]
        self._accelerations: dict[str, list[np.ndarray]] = defaultdict(list)  # t, ax, ay, az
        self._line_frames = 0
        self.path_scatter = PathScatter.for_rig(rig)

    def add_spots(self, frame: int, time_s: float, rows: list[tuple]) -> None:
        """Spot rows (laser_id, x, y, x_raw, y_raw, sigma, intensity, flags) of a frame."""
        self.writer.add("spots", [(frame, time_s, i, x, y, xr, yr, s, p, int(is_measured(f)),
                                   f) for i, x, y, xr, yr, s, p, f in rows])
        measured = np.array([(i, xr, yr, s) for i, _, _, xr, yr, s, _, f in rows
                             if is_measured(f)], dtype=float).reshape(-1, 4)
        self.path_scatter.add(measured[:, 0].astype(int), measured[:, 1:3], measured[:, 3])

    def add_points(self, frame: int, time_s: float, points: SurfacePoints,
                   rejected: np.ndarray | None = None,
                   recorded_offsets_s: np.ndarray | None = None,
                   analysed: SurfacePoints | None = None) -> None:
        """Point rows; `rejected` marks those left out of the frame's fits (and the analysis);
        under a rolling shutter each row's sample time is its row's (`recorded_offsets_s` after
        the frame, a recorded cloud's, else from the points' image rows). The analysis takes
        `analysed` (the same points carried to the frame's time, `sds_recon.instant`) where
        given, else the points."""
        count = len(points.laser_ids)
        flags = np.zeros(count, int) if rejected is None else np.asarray(rejected, dtype=int)
        xyz = np.asarray(points.points_mm, dtype=float).reshape(count, 3)
        columns: list[ArrayLike] = [frame, time_s, points.laser_ids, xyz[:, 0], xyz[:, 1],
                                    xyz[:, 2], points.height_sigma_mm,
                                    points.miss_distance_mm, flags]
        if self._timed:
            columns.append(time_s + (recorded_offsets_s if recorded_offsets_s is not None
                                     else sample_offsets_s(self.rig, points)))
        self.writer.add_columns("points", columns)
        kept = flags == 0
        if count and np.all(np.asarray(points.laser_ids) == LINE_LASER_ID):
            self._line_frames += 1
            if (self._line_frames > LINE_FRAMES_IN_FULL
                    and self._line_frames % LINE_FRAME_STEP):
                return
        at_frame_time = xyz if analysed is None else np.asarray(analysed.points_mm, dtype=float)
        self._kept.append((np.full(int(kept.sum()), time_s),
                           np.asarray(points.laser_ids)[kept], at_frame_time[kept]))

    def add_line(self, frame: int, time_s: float, x, y, sigma, peak, flags) -> None:
        """The line's samples of a frame (arrays, one per image row)."""
        self.writer.add_columns("line", [frame, time_s, x, y, sigma, peak, flags])

    def add_fit(self, frame: int, time_s: float, fits: SurfaceFits) -> None:
        """One frame's fits row: plane, points used and rejected, modal amplitudes."""
        plane = fits.plane
        values = (np.nan,) * 8 if plane is None else (
            plane.p00_mm, plane.p10, plane.p01, np.degrees(plane.tilt_x_rad),
            np.degrees(plane.tilt_y_rad), plane.r_squared, plane.rmse_mm, plane.sse_mm2)
        used = len(fits.rejected) - fits.rejected_count
        names = fits.modal.names if fits.modal is not None else ()
        amplitudes = list(fits.modal.amplitudes_mm) if fits.modal is not None else []
        self.writer.add_fit((frame, time_s, *values, used, fits.rejected_count), names,
                            amplitudes)

    def add_step(self, step: PipelineStep) -> None:
        """A pipeline step's rows: each released frame's spots, points and fits, then the
        line's samples and points."""
        for spot_frame in step.spot_frames:
            index, time_s = spot_frame.index, spot_frame.time_s
            self.add_spots(index, time_s, [(s.laser_id, s.x_px, s.y_px, s.x_raw_px, s.y_raw_px,
                                            s.sigma_px, s.peak, s.flags)
                                           for s in spot_frame.spots])
            self.add_points(index, time_s, spot_frame.points, spot_frame.fits.rejected,
                            analysed=spot_frame.instant_points)
            self.add_fit(index, time_s, spot_frame.fits)
        if step.line is not None:
            line = step.line
            self.add_line(line.index, line.time_s, line.line.x_px, line.line.y_px,
                          line.line.sigma_px, line.line.peak, line.line.flags)
            self.add_points(line.index, line.time_s, line.points)

    def add_imu(self, name: str, time_s: float, accel_m_s2: tuple[float, float, float]) -> None:
        """One sample of the Arduino's accelerometer (specific force [m/s²]), stream `name`."""
        self.writer.add("imu", [(time_s, *accel_m_s2)])
        self._accelerations[name].append(np.array([time_s, *accel_m_s2]))

    def add_tof(self, time_s: float, range_mm: float) -> None:
        """One time-of-flight range [mm] (NaN: the sensor flagged the reading)."""
        self.writer.add("tof", [(time_s, range_mm)])
        if np.isfinite(range_mm):
            self._tof.append((time_s, range_mm))

    def add_camera_imu(self, imu: CameraImu) -> None:
        """The camera's own IMU samples in time order from the first frame on, one row each
        (the other sensor's cells empty): the span the graph's frame source publishes, so
        that `sds process` and `sds export` of its recording give the same table."""
        self.writer.add("camera_imu", [
            _camera_imu_row(t, value if sensor == "accel" else None,
                            value if sensor == "gyro" else None)
            for t, sensor, value in imu_samples(imu) if t >= 0])
        self.add_accelerations("camera IMU", imu.accel_time_s, imu.accel_m_s2)

    def add_camera_imu_message(self, msg, time_s: float) -> None:
        """A recorded /camera/imu message (one sensor each, the other's covariance[0] −1)."""
        a, g = msg.linear_acceleration, msg.angular_velocity
        accel = None if msg.linear_acceleration_covariance[0] == -1 else (a.x, a.y, a.z)
        self.writer.add("camera_imu", [_camera_imu_row(
            time_s, accel, None if msg.angular_velocity_covariance[0] == -1 else (g.x, g.y, g.z))])
        if accel is not None:
            self._accelerations[CAMERA_IMU_TOPIC].append(np.array([time_s, *accel]))

    def add_accelerations(self, name: str, time_s: np.ndarray, accel_m_s2: np.ndarray) -> None:
        """A whole accelerometer stream (times [s], N×3 m/s²) for the gravity regime, not for
        the tables (e.g. a recording's, when `sds process` tracks its images again)."""
        self._accelerations[name] += list(np.column_stack([time_s, accel_m_s2]))

    def accelerations(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Every accelerometer stream kept: times [s] and specific force (N×3 m/s²)."""
        return {name: (np.array(rows)[:, 0], np.array(rows)[:, 1:])
                for name, rows in self._accelerations.items() if rows}

    def surface_series(self, source: str) -> SurfaceSeries:
        """The points the fits kept and the ToF ranges, as the analysis reads them."""
        if not any(len(ids) for _, ids, _ in self._kept):
            raise RecordingError(f"{source}: no surface point was reconstructed")
        time_s, ids, xyz = (np.concatenate(parts) for parts in zip(*self._kept, strict=True))
        tof = np.array(self._tof).reshape(-1, 2)
        return surface_series_from_rows(time_s, ids.astype(int), xyz, source,
                                        (tof[:, 0], tof[:, 1]))


@dataclass(frozen=True)
class RunAnalysis:
    """A run's analysis: the report's results (None when there was nothing to analyse), what
    the console should say about it (the gravity regime, why there is no analysis) and the
    spots' own check of their σ (None when too few spots were measured)."""

    results: dict[str, Any] | None
    note: str
    sigma_check: SigmaCheck | None = None   # the spots' own check of their σ


def finish_analysis(tables: RunTables, source: str, out: Path, options: AnalysisOptions,
                    truth: Truth | None = None) -> RunAnalysis:
    """The analysis of the run's points and ToF ranges (report, analysis.json), the tables
    closed; data that give no analysis leave `results` None and say why in `note` (no report
    is written), anything else that fails is raised. Without a gravity in `options`, a free
    fall in any accelerometer the run holds means microgravity (`sds process`, `sds export`,
    `sds run` and the demo alike). The report and analysis.json also hold the spots' own
    check of their σ (`SIGMA_CHECK_KEY`)."""
    options, regime = with_gravity_regime(options, tables.accelerations())
    results, note = None, ""
    check = tables.path_scatter.check()
    try:   # data that give no analysis (no point, no oscillation); a fault is raised
        analysis = analyze(tables.surface_series(source), tables.rig, options)
    except InputError as error:
        note = f"NO ANALYSIS: {error}"
    else:
        results = write_report(analysis, out, truth).results
        if check is not None:
            content = {**asdict(check), "summary": check.line()}
            add_report_section(out, "The spots' own check of their σ", [check.line()], None,
                               SIGMA_CHECK_KEY, content)
            results[SIGMA_CHECK_KEY] = content
    tables.writer.close()
    return RunAnalysis(results, "; ".join(n for n in (regime, note) if n), check)
