"""A run's results as plain files without a ROS graph (`sds process`, `sds export`).

`process` runs the graph's own code in one process (frame selection, FrameTracker,
reconstruct_spots/line, fit_surface, the analysis) with the parameters of
config/graphs/drop.yaml, so its results equal the graph's on the same input. `export` writes
the same files from a recording of the graph.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sds_camera.camera_imu import CameraImu, imu_samples
from sds_camera.frame_source import (
    FrameSource,
    FrameSourceError,
    Region,
    open_source,
    read_ahead,
)
from sds_model.rig import Rig
from sds_recon.reconstruction import (
    LINE_LASER_ID,
    SurfaceFits,
    SurfacePoints,
    reconstruct_frame,
    reconstruct_line,
)
from sds_recon.results import ResultsWriter
from sds_record.mcap_files import decoded_messages, recorded_topics
from sds_ros.image_msg import msg_to_image
from sds_ros.point_cloud import read_cloud, stamp_s
from sds_sloshing.analysis import AnalysisOptions, analyze, with_gravity_regime
from sds_sloshing.estimators import DecayError
from sds_sloshing.report import Truth, write_report
from sds_sloshing.surface_series import (
    RecordingError,
    SurfaceSeries,
    surface_series_from_rows,
)
from sds_tracker.spots import LOST
from sds_tracker.tracker import FrameTracker, TrackedSpot, parse_seeds, tracker_config
from tqdm import tqdm

from sds_bringup.graph import node_parameters
from sds_bringup.paths import CONFIG
from sds_bringup.rig_calibration import (
    calibrate_images,
    calibration_frames,
    known_surfaces,
    write_calibration,
)

GRAPH = CONFIG / "graphs" / "drop.yaml"
"""The graph whose tracker and reconstruction parameters the offline pipeline uses."""
CAMERA_IMU_TOPIC = "/camera/imu"
LINE_FRAMES_IN_FULL = 1800
LINE_FRAME_STEP = 10
"""The analysis keeps the line's points of the first LINE_FRAMES_IN_FULL frames (a minute at
30 fps), then of every LINE_FRAME_STEP-th: they serve only the meniscus, a mean radial profile,
and all of a 10-minute 4K run's would hold 0.8 GB (the result files keep every one)."""
FRAMES_BEFORE_MODEL = 90
"""Camera frames a recording may hold before its first camera model (3 s at 30 fps; the
recorder logs the latched model once it matches, about 3 frames late in the graph's tests)."""


@dataclass(frozen=True)
class RedFrame:
    """A frame's red channel (the region only), its region offset [px] and time [s]."""

    index: int
    time_s: float
    red: np.ndarray
    offset: tuple[int, int]


def video_frames(path: Path, rig: Rig, fps: float = 0.0) -> Iterator[RedFrame]:
    """A video's frames, the container's region (Rig.container_region_px) in red; the video
    is opened and checked here, before the first frame is asked for."""
    source = open_source(str(path), fps=fps)
    region = Region(*rig.container_region_px(rig.camera))
    try:
        region.check_inside(source.width, source.height)
    except FrameSourceError:
        source.close()
        raise
    return read_ahead(_red_frames(source, region))


def _red_frames(source: FrameSource, region: Region) -> Iterator[RedFrame]:
    """The region's red channel of each frame (a video converts only that region)."""
    try:
        for frame in source.frames(region, "red"):
            yield RedFrame(frame.index, frame.time_ns * 1e-9, frame.image, (region.x, region.y))
    finally:
        source.close()


def mcap_frames(path: Path) -> Iterator[RedFrame]:
    """A recording's camera frames (sensor_msgs/Image) and the region its camera model gives;
    a recording without frames is refused here, before the first frame is asked for."""
    types = {type_name for type_name, _ in recorded_topics(path).values()}
    if "sensor_msgs/msg/Image" not in types:
        raise RecordingError(f"{path}: the recording has no camera frames (sensor_msgs/Image)")
    return read_ahead(_recorded_frames(path))


def _recorded_frames(path: Path) -> Iterator[RedFrame]:
    """The frames in recorded order, each with the latest camera model's region offset; the
    frames before the first model wait for it (a recorder may log the latched model after
    the first frames), at most FRAMES_BEFORE_MODEL of them."""
    offset: tuple[int, int] | None = None
    waiting: list[tuple[float, np.ndarray]] = []   # (stamp [s], red image) before any model
    first: float | None = None
    index = 0
    for recorded, msg in decoded_messages(path):
        name = recorded.type_name
        if name == "sds_msgs/msg/CameraModel":
            offset = (int(msg.roi.x_offset), int(msg.roi.y_offset))
        elif name == "sensor_msgs/msg/Image":
            image = msg_to_image(msg)
            waiting.append((stamp_s(msg), image[..., 2] if image.ndim == 3 else image))
            if offset is None and len(waiting) > FRAMES_BEFORE_MODEL:
                raise RecordingError(f"{path}: {len(waiting)} camera frames before any camera "
                                     "model (the region offset is unknown)")
        if offset is not None:
            for stamp, red in waiting:
                first = stamp if first is None else first
                yield RedFrame(index, stamp - first, red, offset)
                index += 1
            waiting.clear()
    if waiting:
        raise RecordingError(f"{path}: camera frames but no camera model (the region offset "
                             "is unknown)")


def calibrate_from_images(rig: Rig, paths: list[Path], surfaces: Path, out: Path
                          ) -> tuple[Rig, Path]:
    """Self-calibrate the rig from images of known surfaces (image k is frame k of the
    surfaces CSV) or one tilt-table video, as `sds calibrate rig` does; write the rig, its
    report and overlays."""
    known = known_surfaces(surfaces)
    pictures, names = calibration_frames(paths, rig, len(known))
    result, found = calibrate_images(rig, pictures, known)
    out.mkdir(parents=True, exist_ok=True)
    rig_path = out / "rig_calibrated.yaml"
    calibrated = write_calibration(rig, result, found, pictures, names, rig_path,
                                   f"`sds process --calibrate-lasers` from {len(names)} images")
    return calibrated, rig_path


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
        self._kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # time, id, X Y Z
        self._tof: list[tuple[float, float]] = []                         # time [s], [mm]
        self._accelerations: dict[str, list[np.ndarray]] = defaultdict(list)  # t, ax, ay, az
        self._line_frames = 0

    def add_spots(self, frame: int, time_s: float, rows: list[tuple]) -> None:
        """Spot rows (laser_id, x, y, x_raw, y_raw, sigma, intensity, flags) of a frame."""
        self.writer.add("spots", [(frame, time_s, i, x, y, xr, yr, s, p, int(not f & LOST),
                                   f) for i, x, y, xr, yr, s, p, f in rows])

    def add_points(self, frame: int, time_s: float, points: SurfacePoints,
                   rejected: np.ndarray | None = None) -> None:
        """Point rows; `rejected` marks those left out of the frame's fits (and the analysis)."""
        count = len(points.laser_ids)
        flags = np.zeros(count, int) if rejected is None else np.asarray(rejected, dtype=int)
        xyz = np.asarray(points.points_mm, dtype=float).reshape(count, 3)
        self.writer.add_columns("points", [frame, time_s, points.laser_ids, xyz[:, 0],
                                           xyz[:, 1], xyz[:, 2], points.height_sigma_mm,
                                           points.miss_distance_mm, flags])
        kept = flags == 0
        if count and np.all(np.asarray(points.laser_ids) == LINE_LASER_ID):
            self._line_frames += 1
            if (self._line_frames > LINE_FRAMES_IN_FULL
                    and self._line_frames % LINE_FRAME_STEP):
                return
        self._kept.append((np.full(int(kept.sum()), time_s),
                           np.asarray(points.laser_ids)[kept], xyz[kept]))

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
        """The camera's own IMU samples in time order, one row each (the other sensor's cells
        empty)."""
        self.writer.add("camera_imu", [
            _camera_imu_row(t, value if sensor == "accel" else None,
                            value if sensor == "gyro" else None)
            for t, sensor, value in imu_samples(imu)])
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


def process_frames(frames: Iterator[RedFrame], rig: Rig, tables: RunTables,
                   progress: bool = True) -> int:
    """Track, reconstruct and fit every frame, as the tracker and reconstruction nodes do."""
    tracker_values = node_parameters(GRAPH, "tracker")
    recon_values = node_parameters(GRAPH, "recon")
    tracker = FrameTracker(rig, tracker_config(tracker_values),
                           parse_seeds(tracker_values["seeds"]))
    beam_weight = float(recon_values["beam_weight"])
    default_sigma = float(recon_values["default_sigma_px"])
    times: dict[int, float] = {}

    def spots_done(ready: list[tuple[int, list[TrackedSpot]]]) -> None:
        for frame, spots in ready:
            time_s = times.pop(frame)
            tables.add_spots(frame, time_s, [(s.laser_id, s.x_px, s.y_px, s.x_raw_px, s.y_raw_px,
                                              s.sigma_px, s.peak, s.flags) for s in spots])
            points, fits = reconstruct_frame(
                rig, [s.laser_id for s in spots], [[s.x_px, s.y_px] for s in spots],
                [s.sigma_px for s in spots], [bool(s.flags & LOST) for s in spots], beam_weight,
                default_sigma)
            tables.add_points(frame, time_s, points, fits.rejected)
            tables.add_fit(frame, time_s, fits)

    count = 0
    for frame in tqdm(frames, desc="frames", unit="frame", disable=not progress):
        times[frame.index] = frame.time_s
        ready, line = tracker.process(frame.index, frame.red, frame.offset)
        spots_done(ready)
        tables.add_line(frame.index, frame.time_s, line.x_px, line.y_px, line.sigma_px,
                        line.peak, line.flags)
        tables.add_points(frame.index, frame.time_s, reconstruct_line(
            rig, np.column_stack([line.x_px, line.y_px]), line.sigma_px, default_sigma))
        count += 1
    spots_done(tracker.flush())
    return count


def export_recording(path: Path, rig: Rig, tables: RunTables) -> int:
    """The tables from a recording of the graph (spots, line, points, fits, IMU, ToF)."""
    first: float | None = None
    frames = 0
    frame_of: dict[float, int] = {}   # header stamp [s] -> frame index (clouds carry none)
    clouds: list[tuple[float, float, SurfacePoints, np.ndarray]] = []
    camera_imu: list[tuple[float, object]] = []
    sensors: list[tuple[float, str, Any]] = []   # the Arduino's IMU and ToF: stamp, topic
    for recorded, msg in decoded_messages(path):
        name = recorded.type_name
        if not hasattr(msg, "header"):
            continue
        stamp = stamp_s(msg)
        if first is None and name in ("sensor_msgs/msg/Image", "sds_msgs/msg/LaserSpotArray",
                                      "sds_msgs/msg/LaserLineProfile"):
            first = stamp
        time_s = stamp - (first if first is not None else stamp)
        if name in ("sds_msgs/msg/LaserSpotArray", "sds_msgs/msg/LaserLineProfile"):
            frame_of[stamp] = msg.frame_index
        if name == "sds_msgs/msg/LaserSpotArray":
            tables.add_spots(msg.frame_index, time_s, [
                (s.laser_id, s.x_px, s.y_px, s.x_raw_px, s.y_raw_px, s.sigma_px,
                 s.peak_intensity, s.flags) for s in msg.spots])
            frames += 1
        elif name == "sds_msgs/msg/LaserLineProfile":
            tables.add_line(msg.frame_index, time_s, msg.x_px, msg.y_px, msg.sigma_px,
                            msg.peak_intensity, np.asarray(msg.flags, np.uint8))
        elif name == "sensor_msgs/msg/PointCloud2":
            cloud = read_cloud(msg)
            if cloud is not None:   # its frame is known once every spots message is read
                clouds.append((stamp, time_s, cloud.points, cloud.rejected))
        elif name == "sds_msgs/msg/SurfaceFit":
            _add_fit_message(tables, msg, time_s)
        elif name == "sensor_msgs/msg/Imu" and recorded.topic == CAMERA_IMU_TOPIC:
            camera_imu.append((stamp, msg))   # may come before the first frame: kept for later
        elif name in ("sensor_msgs/msg/Imu", "sensor_msgs/msg/Range"):
            sensors.append((stamp, recorded.topic, msg))   # the same
    if frames == 0:
        raise RecordingError(f"{path}: no laser spots (sds_msgs/LaserSpotArray) recorded")
    for stamp, time_s, points, rejected in clouds:
        tables.add_points(frame_of.get(stamp, -1), time_s, points, rejected)
    origin = first if first is not None else 0.0
    for stamp, msg in sorted(camera_imu, key=lambda item: item[0]):
        tables.add_camera_imu_message(msg, stamp - origin)
    for stamp, topic, msg in sensors:
        if hasattr(msg, "range"):
            tables.add_tof(stamp - origin, msg.range * 1e3)
        else:
            a = msg.linear_acceleration
            tables.add_imu(topic, stamp - origin, (a.x, a.y, a.z))
    return frames


def _add_fit_message(tables: RunTables, msg, time_s: float) -> None:
    """A recorded SurfaceFit as a fits row."""
    tables.writer.add_fit((msg.frame_index, time_s, msg.p00_mm, msg.p10, msg.p01,
                           np.degrees(msg.tilt_x_rad), np.degrees(msg.tilt_y_rad),
                           msg.r_squared, msg.rmse_mm, msg.sse_mm2, msg.point_count,
                           msg.rejected_count),
                          tuple(msg.mode_names), list(msg.modal_amplitudes_mm))


@dataclass(frozen=True)
class RunAnalysis:
    """A run's analysis: the report's results (None when there was nothing to analyse) and
    what the console should say about it (the gravity regime, why there is no analysis)."""

    results: dict[str, Any] | None
    note: str


def finish_analysis(tables: RunTables, source: str, out: Path, options: AnalysisOptions,
                    truth: Truth | None = None) -> RunAnalysis:
    """The analysis of the run's points and ToF ranges (report, analysis.json), the tables
    closed. Without a gravity in `options`, a free fall in any accelerometer the run holds
    means microgravity (`sds process`, `sds export`, `sds run` and the demo alike)."""
    options, regime = with_gravity_regime(options, tables.accelerations())
    results, note = None, ""
    try:
        analysis = analyze(tables.surface_series(source), tables.rig, options)
        results = write_report(analysis, out, truth).results
    except (RecordingError, DecayError, ValueError) as error:
        note = f"no analysis: {error}"
    tables.writer.close()
    return RunAnalysis(results, "; ".join(n for n in (regime, note) if n))
