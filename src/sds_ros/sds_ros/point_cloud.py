"""The surface point cloud on /recon/points and /recon/line_points (sensor_msgs/PointCloud2).

One unordered row (height 1) per reconstructed point, little-endian, in the rig's world frame
(`frame_id` world), in SI units as ROS tools expect (REP-103):

    x, y, z          float32  surface point [m]
    laser_id         uint16   diode id; 65535 for the line laser
    height_sigma     float32  one-sigma height uncertainty [m]
    miss_distance    float32  distance between camera ray and beam, Eq. 9 [m]; NaN for the line
    rejected         uint8    1: left out of the frame's fits as not on the surface
    t                float32  when the point's image row was exposed, after the header stamp [s]
                              (only under a rolling shutter: the camera file's readout_s; the
                              per-point time field of lidar drivers)

Recordings made before this layout carry x, y, z in mm and the fields `height_sigma_mm` and
`miss_distance_mm`; `read_cloud` reads both layouts and gives mm, the unit of the algorithms
and the result files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from sds_recon.reconstruction import SurfacePoints
from sensor_msgs.msg import PointCloud2, PointField

CLOUD_FIELDS = (("x", np.float32), ("y", np.float32), ("z", np.float32),
                ("laser_id", np.uint16), ("height_sigma", np.float32),
                ("miss_distance", np.float32), ("rejected", np.uint8))
POINT_FIELD_TYPES = {PointField.INT8: "i1", PointField.UINT8: "u1", PointField.INT16: "<i2",
                     PointField.UINT16: "<u2", PointField.INT32: "<i4", PointField.UINT32: "<u4",
                     PointField.FLOAT32: "<f4", PointField.FLOAT64: "<f8"}
"""sensor_msgs/PointField datatype → numpy type (little-endian clouds)."""
_DATATYPES: dict[type, int] = {np.float32: PointField.FLOAT32, np.uint16: PointField.UINT16,
                               np.uint8: PointField.UINT8}
MM_PER_M = 1000.0


SAMPLE_TIME_FIELD = ("t", np.float32)
"""The per-point time field, after the header stamp [s] (a rolling shutter's clouds only)."""


def cloud_fields(timed: bool = False) -> tuple[tuple[str, type], ...]:
    """The fields of one cloud point, with the sample time's if `timed`."""
    return (*CLOUD_FIELDS, SAMPLE_TIME_FIELD) if timed else CLOUD_FIELDS


def cloud_dtype(timed: bool = False) -> np.dtype:
    """Packed layout of one cloud point."""
    return np.dtype([(name, kind) for name, kind in cloud_fields(timed)])


def points_to_cloud(header, points: SurfacePoints, rejected: ArrayLike | None = None,
                    sample_offsets_s: ArrayLike | None = None) -> PointCloud2:
    """The PointCloud2 of reconstructed points [mm in, m out]; `rejected` marks the points
    left out of the frame's fits; `sample_offsets_s` (a rolling shutter's) is when each
    point's row was exposed after the header stamp [s]."""
    timed = sample_offsets_s is not None
    dtype = cloud_dtype(timed)
    ids = np.asarray(points.laser_ids)
    rows = np.zeros(len(ids), dtype)
    xyz = np.asarray(points.points_mm, dtype=float).reshape(len(ids), 3)
    for axis, name in enumerate("xyz"):
        rows[name] = xyz[:, axis] / MM_PER_M
    rows["laser_id"] = ids
    rows["height_sigma"] = np.asarray(points.height_sigma_mm, dtype=float) / MM_PER_M
    rows["miss_distance"] = np.asarray(points.miss_distance_mm, dtype=float) / MM_PER_M
    if rejected is not None:
        rows["rejected"] = rejected
    if sample_offsets_s is not None:
        rows["t"] = sample_offsets_s
    msg = PointCloud2(header=header, height=1, width=len(rows), is_bigendian=False,
                      point_step=dtype.itemsize, row_step=dtype.itemsize * len(rows),
                      is_dense=True)
    offsets = {name: dtype.fields[name][1] for name in dtype.names or ()} if dtype.fields else {}
    msg.fields = [PointField(name=name, offset=offsets[name], datatype=_DATATYPES[kind],
                             count=1) for name, kind in cloud_fields(timed)]
    msg.data = rows.tobytes()
    return msg


@dataclass(frozen=True)
class CloudPoints:
    """A surface cloud read back, in mm: the points and which were left out of the fits."""

    points: SurfacePoints
    rejected: np.ndarray           # (N,) bool
    sample_offsets_s: np.ndarray | None = None   # (N,) after the stamp [s]; None: untimed


def read_cloud(msg) -> CloudPoints | None:
    """The points of a PointCloud2 (rclpy's or decoded from MCAP) with a laser_id field, in
    mm, whichever layout it has; None for a cloud without laser ids or big-endian."""
    names = [f.name for f in msg.fields]
    if "laser_id" not in names or msg.is_bigendian:
        return None
    dtype = np.dtype({"names": names, "offsets": [f.offset for f in msg.fields],
                      "formats": [POINT_FIELD_TYPES[f.datatype] for f in msg.fields],
                      "itemsize": msg.point_step})
    rows = np.frombuffer(bytes(msg.data), dtype, count=msg.width * msg.height)
    metres = "height_sigma_mm" not in names   # the layout before SI units was in mm
    scale = MM_PER_M if metres else 1.0
    suffix = "" if metres else "_mm"

    def optional(name: str) -> np.ndarray:   # a cloud of another writer may lack it: NaN
        return rows[name].astype(float) * scale if name in names else np.full(len(rows), np.nan)

    rejected = rows["rejected"].astype(bool) if "rejected" in names else \
        np.zeros(len(rows), dtype=bool)   # clouds recorded before the field existed
    return CloudPoints(SurfacePoints(
        rows["laser_id"].astype(int),
        np.column_stack([rows["x"], rows["y"], rows["z"]]).astype(float) * scale,
        optional(f"height_sigma{suffix}"), optional(f"miss_distance{suffix}")), rejected,
        rows["t"].astype(float) if "t" in names else None)


def stamp_s(msg) -> float:
    """A message's header stamp [s] (rclpy's messages or decoded from MCAP: the same fields)."""
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def stamp_ns(msg) -> int:
    """A message's header stamp [ns], exact: for differences between wall-clock stamps, which
    `stamp_s` resolves only to 0.24 µs (a float's 53 bits over 1.8e9 s)."""
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
