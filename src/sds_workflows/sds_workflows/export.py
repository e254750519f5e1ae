"""`sds export`: a recording of the graph as result files and an analysis report."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from sds_model.errors import InputError
from sds_model.rig import Rig
from sds_model.staging import staged_folder
from sds_recon.instant import InstantFits
from sds_recon.reconstruction import LINE_LASER_ID, SurfacePoints
from sds_recon.results import ResultsWriter, refuse_results
from sds_record.mcap_files import decoded_messages
from sds_record.recorded_series import recording_rig
from sds_ros.point_cloud import CloudPoints, read_cloud, stamp_ns
from sds_ros.static_tf import LATERAL_FRAME
from sds_sloshing.analysis import AnalysisOptions
from sds_sloshing.surface_series import RecordingError

from sds_workflows.run_tables import (
    CAMERA_IMU_TOPIC,
    RUN_FILES,
    RunAnalysis,
    RunTables,
    finish_analysis,
)


def export_results(recording: Path, out: Path, rig_file: Path | None = None,
                   gravity_m_s2: float | None = None, overwrite: bool = False
                   ) -> tuple[int, RunAnalysis]:
    """A recording's result files and analysis report in `out` (refused if it holds results,
    unless `overwrite`; written whole or not at all: `staging.staged_folder`); `rig_file`
    default: the rig the recording carries. Returns the number of frames and the analysis."""
    if not recording.is_file():
        raise InputError(f"{recording}: no such recording")
    rig = recording_rig(recording, rig_file)
    if not overwrite:
        refuse_results(out)
    with staged_folder(out, RUN_FILES) as staging:
        tables = RunTables(ResultsWriter(staging), rig)
        frames = export_recording(recording, rig, tables)
        analysis = finish_analysis(tables, str(recording), staging,
                                   AnalysisOptions(gravity_m_s2=gravity_m_s2))
    return frames, analysis


def export_recording(path: Path, rig: Rig, tables: RunTables) -> int:
    """The tables from a recording of the graph (spots, line, points, fits, IMU, ToF)."""
    first: int | None = None   # the first frame's stamp [ns]
    frames = 0
    frame_of: dict[int, int] = {}   # header stamp [ns] -> frame index (clouds carry none)
    clouds: list[tuple[int, float, CloudPoints]] = []
    camera_imu: list[tuple[int, object]] = []
    sensors: list[tuple[int, str, Any]] = []   # the Arduino's IMU and ToF: stamp [ns], topic
    for recorded, msg in decoded_messages(path):
        name = recorded.type_name
        if not hasattr(msg, "header") or msg.header.frame_id == LATERAL_FRAME:
            continue    # the side camera's frames are not the top camera's
        stamp = stamp_ns(msg)   # in ns: differences of float wall-clock seconds lose 0.24 µs
        if first is None and name in ("sensor_msgs/msg/Image", "sds_msgs/msg/LaserSpotArray",
                                      "sds_msgs/msg/LaserLineProfile"):
            first = stamp
        time_s = (stamp - (first if first is not None else stamp)) * 1e-9
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
                clouds.append((stamp, time_s, cloud))
        elif name == "sds_msgs/msg/SurfaceFit":
            _add_fit_message(tables, msg, time_s)
        elif name == "sensor_msgs/msg/Imu" and recorded.topic == CAMERA_IMU_TOPIC:
            camera_imu.append((stamp, msg))   # may come before the first frame: kept for later
        elif name in ("sensor_msgs/msg/Imu", "sensor_msgs/msg/Range"):
            sensors.append((stamp, recorded.topic, msg))   # the same
    if frames == 0:
        raise RecordingError(f"{path}: no laser spots (sds_msgs/LaserSpotArray) recorded")
    analysed = _at_frame_times(rig, clouds)
    for position, (stamp, time_s, cloud) in enumerate(clouds):
        tables.add_points(frame_of.get(stamp, -1), time_s, cloud.points, cloud.rejected,
                          cloud.sample_offsets_s, analysed.get(position))
    origin = first if first is not None else 0
    for stamp, msg in sorted(camera_imu, key=lambda item: item[0]):
        tables.add_camera_imu_message(msg, (stamp - origin) * 1e-9)
    for stamp, topic, msg in sorted(sensors, key=lambda item: item[0]):
        if hasattr(msg, "range"):
            tables.add_tof((stamp - origin) * 1e-9, msg.range * 1e3)
        else:
            a = msg.linear_acceleration
            tables.add_imu(topic, (stamp - origin) * 1e-9, (a.x, a.y, a.z))
    return frames


def _at_frame_times(rig: Rig, clouds: list[tuple[int, float, CloudPoints]]
                    ) -> dict[int, SurfacePoints]:
    """The spot clouds' points carried to their frames' times (`sds_recon.instant`: what the
    reconstruction fitted), by position in `clouds`; a global shutter's as recorded."""
    instant: InstantFits[int] = InstantFits(rig)
    carried: dict[int, SurfacePoints] = {}
    spots = [(time_s, position, cloud) for position, (_, time_s, cloud) in enumerate(clouds)
             if not np.all(cloud.points.laser_ids == LINE_LASER_ID)]
    for time_s, position, cloud in sorted(spots, key=lambda item: item[0]):
        for frame in instant.push(position, time_s, cloud.points, cloud.sample_offsets_s):
            carried[frame.key] = frame.points
    for frame in instant.flush():
        carried[frame.key] = frame.points
    return carried


def _add_fit_message(tables: RunTables, msg, time_s: float) -> None:
    """A recorded SurfaceFit as a fits row."""
    tables.writer.add_fit((msg.frame_index, time_s, msg.p00_mm, msg.p10, msg.p01,
                           np.degrees(msg.tilt_x_rad), np.degrees(msg.tilt_y_rad),
                           msg.r_squared, msg.rmse_mm, msg.sse_mm2, msg.point_count,
                           msg.rejected_count),
                          tuple(msg.mode_names), list(msg.modal_amplitudes_mm))
