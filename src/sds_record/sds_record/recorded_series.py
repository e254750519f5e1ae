"""What the tools read from a recording: its rig, the surface points, every accelerometer.

Both come through the one reader (`mcap_files.decoded_messages`), so an unfinished recording
is read up to its last complete chunk with a warning. Times are in seconds from the first
frame (the first spot cloud's stamp), the one time convention of every input (`sds export`'s
and the CSVs' `t_s`).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from sds_model.rig import Rig, load_rig, rig_from_document
from sds_recon.reconstruction import LINE_LASER_ID
from sds_ros.point_cloud import read_cloud, stamp_ns, stamp_s
from sds_sloshing.surface_series import RecordingError, SurfaceSeries, surface_series_from_rows

from sds_record.mcap_files import decoded_messages

RIG_TOPIC = "/recon/rig"
CLOUD_TYPE = "sensor_msgs/msg/PointCloud2"
RANGE_TYPE = "sensor_msgs/msg/Range"
IMU_TYPE = "sensor_msgs/msg/Imu"


def read_surface_series(path: str | Path) -> SurfaceSeries:
    """Every surface cloud (PointCloud2 with laser_id; rejected points left out) and ToF
    range (sensor_msgs/Range [m] → mm)."""
    path = Path(path)
    rows: dict[str, list[np.ndarray]] = defaultdict(list)
    tof_time, tof_range = [], []
    try:
        for recorded, msg in decoded_messages(path, types=(CLOUD_TYPE, RANGE_TYPE)):
            cloud = read_cloud(msg) if recorded.type_name == CLOUD_TYPE else None
            if cloud is not None and (~cloud.rejected).any():
                kept = ~cloud.rejected
                rows["time"].append(np.full(int(kept.sum()), stamp_ns(msg)))
                rows["id"].append(cloud.points.laser_ids[kept])
                rows["xyz"].append(cloud.points.points_mm[kept])
            elif recorded.type_name == RANGE_TYPE and np.isfinite(msg.range):
                tof_time.append(stamp_ns(msg))
                tof_range.append(msg.range * 1e3)
    except (McapError, OSError, ValueError) as error:
        raise RecordingError(f"{path}: {error}") from None
    if not rows:
        raise RecordingError(f"{path}: no PointCloud2 with a laser_id field (a recording of the "
                             "reconstruction node's points topic is needed)")
    times_ns, ids = np.concatenate(rows["time"]), np.concatenate(rows["id"])
    spots = ids != LINE_LASER_ID
    origin_ns = times_ns[spots].min() if spots.any() else times_ns.min()
    return surface_series_from_rows(
        (times_ns - origin_ns) * 1e-9, ids, np.concatenate(rows["xyz"]), str(path),
        ((np.array(tof_time, dtype=np.int64) - origin_ns) * 1e-9, np.array(tof_range)))


def read_accelerations(path: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every accelerometer stream (sensor_msgs/Imu messages with a measured linear
    acceleration), by topic: stamps [s] and specific force (N×3 m/s²)."""
    path = Path(path)
    streams: dict[str, tuple[list[float], list[tuple[float, float, float]]]] = defaultdict(
        lambda: ([], []))
    try:
        for recorded, msg in decoded_messages(path, types=(IMU_TYPE,)):
            if msg.linear_acceleration_covariance[0] == -1:
                continue
            a = msg.linear_acceleration
            times, values = streams[recorded.topic]
            times.append(stamp_s(msg))
            values.append((a.x, a.y, a.z))
    except (McapError, OSError, ValueError) as error:
        raise RecordingError(f"{path}: {error}") from None
    return {topic: (np.array(t), np.array(v)) for topic, (t, v) in streams.items()}


def recorded_rig(path: str | Path) -> Rig | None:
    """The rig a recording carries (the reconstruction node's latched `/recon/rig`, camera
    inline); None for a recording made without it."""
    document = None
    for _, msg in decoded_messages(path, [RIG_TOPIC]):
        document = msg.data
    return None if document is None else rig_from_document(document, f"{path} {RIG_TOPIC}")


def recording_rig(path: str | Path, rig_file: str | Path | None) -> Rig:
    """The rig file given, else the one the recording carries; an error saying so if none."""
    if rig_file is not None:
        return load_rig(rig_file)
    rig = recorded_rig(path)
    if rig is None:
        raise RecordingError(f"{path} carries no rig ({RIG_TOPIC}: recorded without the "
                             "reconstruction node, or before recordings carried it): give --rig")
    return rig
