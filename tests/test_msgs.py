"""sds_msgs is built and installed: its types import, carry their constants, and serialize."""

from __future__ import annotations

import math

from rclpy.serialization import deserialize_message, serialize_message

from sds_msgs.msg import (
    CameraModel,
    LaserLineProfile,
    LaserSpot,
    LaserSpotArray,
    SloshingEstimate,
    SurfaceFit,
    SyncEvent,
)


def test_spot_flags_are_distinct_bits():
    flags = [LaserSpot.FLAG_LOST, LaserSpot.FLAG_SATURATED, LaserSpot.FLAG_REFLECTION_SUSPECTED,
             LaserSpot.FLAG_OFF_PATH, LaserSpot.FLAG_HAMPEL_REPLACED,
             LaserSpot.FLAG_NOT_FILTERED, LaserSpot.FLAG_AMBIGUOUS]
    assert all(f and f & (f - 1) == 0 for f in flags)
    assert len(set(flags)) == len(flags)


def test_every_message_survives_cdr_serialization():
    spots = LaserSpotArray(frame_index=7, spots=[
        LaserSpot(laser_id=3, x_px=1.25, y_px=2.5, sigma_px=0.05, flags=LaserSpot.FLAG_SATURATED),
        LaserSpot(laser_id=4, x_px=math.nan, y_px=math.nan, flags=LaserSpot.FLAG_LOST),
    ])
    line = LaserLineProfile(x_px=[1.0, 2.0], y_px=[3.0, 4.0], sigma_px=[0.1, 0.2],
                            peak_intensity=[100.0, 90.0], flags=[0, 1])
    fit = SurfaceFit(p00_mm=49.9, p10=0.1, p01=-0.2, r_squared=0.99, point_count=20,
                     mode_names=["lateral_1_cos"], modal_amplitudes_mm=[1.5])
    estimate = SloshingEstimate(mode="lateral_1", method="matrix_pencil", frequency_hz=2.78,
                                damping_ratio=0.01)
    sync = SyncEvent(kind=SyncEvent.KIND_LED_ON, source="arduino", device_time_us=123456)
    model = CameraModel(model_type="scaramuzza", full_width=3840, full_height=2160, channel="red")
    model.roi.x_offset, model.roi.width = 1185, 1470
    for msg in (spots, line, fit, estimate, sync, model):
        back = deserialize_message(serialize_message(msg), type(msg))
        if msg is spots:
            assert back.spots[0] == msg.spots[0]
            assert math.isnan(back.spots[1].x_px) and back.spots[1].flags == LaserSpot.FLAG_LOST
        else:
            assert back == msg
