"""The surface cloud's layout on ROS topics: metres (REP-103) out, mm back, old recordings too."""

from __future__ import annotations

import numpy as np
from sds_recon.reconstruction import LINE_LASER_ID, SurfacePoints
from sds_ros.point_cloud import points_to_cloud, read_cloud
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header


def test_points_go_out_in_metres_and_come_back_in_mm() -> None:
    points = SurfacePoints(np.array([0, 7, LINE_LASER_ID]),
                           np.array([[10.0, -20.0, 1.5], [35.5, 4.25, -0.75], [0.0, 50.0, 2.0]]),
                           np.array([0.02, 0.03, 0.05]), np.array([0.001, 0.002, np.nan]))
    msg = points_to_cloud(Header(frame_id="world"), points, np.array([0, 1, 0]))
    names = [f.name for f in msg.fields]
    assert names[:3] == ["x", "y", "z"] and "height_sigma" in names
    raw = np.frombuffer(bytes(msg.data), np.float32, count=3)   # x, y, z of the first point
    np.testing.assert_allclose(raw, [0.010, -0.020, 0.0015], rtol=1e-6)
    back = read_cloud(msg)
    assert back is not None
    np.testing.assert_allclose(back.points.points_mm, points.points_mm, atol=1e-5)
    np.testing.assert_allclose(back.points.height_sigma_mm, points.height_sigma_mm, rtol=1e-6)
    np.testing.assert_allclose(back.points.miss_distance_mm, points.miss_distance_mm,
                               rtol=1e-6, equal_nan=True)
    assert back.points.laser_ids.tolist() == [0, 7, LINE_LASER_ID]
    assert back.rejected.tolist() == [False, True, False]


def test_a_cloud_recorded_in_the_old_mm_layout_reads_the_same() -> None:
    layout = [("x", np.float32), ("y", np.float32), ("z", np.float32), ("laser_id", np.uint16),
              ("height_sigma_mm", np.float32), ("miss_distance_mm", np.float32)]
    rows = np.zeros(1, layout)
    rows["x"], rows["y"], rows["z"], rows["laser_id"] = 12.5, -3.0, 0.75, 4
    rows["height_sigma_mm"], rows["miss_distance_mm"] = 0.04, 0.002
    dtype = rows.dtype
    msg = PointCloud2(height=1, width=1, is_bigendian=False, point_step=dtype.itemsize,
                      row_step=dtype.itemsize, data=rows.tobytes())
    kinds = {np.float32: PointField.FLOAT32, np.uint16: PointField.UINT16}
    msg.fields = [PointField(name=name, offset=dtype.fields[name][1], datatype=kinds[kind],
                             count=1) for name, kind in layout]
    back = read_cloud(msg)
    assert back is not None and back.points.laser_ids.tolist() == [4]
    np.testing.assert_allclose(back.points.points_mm, [[12.5, -3.0, 0.75]], rtol=1e-6)
    np.testing.assert_allclose(back.points.height_sigma_mm, [0.04], rtol=1e-6)
    assert not back.rejected.any()
