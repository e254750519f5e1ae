"""numpy <-> sensor_msgs/Image conversion keeps every pixel, through real serialization."""

from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sds_ros.image_msg import image_to_msg, msg_to_image
from sensor_msgs.msg import Image


@pytest.mark.parametrize("shape, encoding", [((37, 53), "mono8"), ((37, 53, 3), "bgr8")])
def test_round_trip_through_cdr_serialization(shape, encoding):
    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    msg = image_to_msg(image, Time(sec=12, nanosec=345), "camera_optical")
    assert (msg.encoding, msg.height, msg.width) == (encoding, 37, 53)
    assert msg.step == 53 * (3 if encoding == "bgr8" else 1)
    received = deserialize_message(serialize_message(msg), Image)
    np.testing.assert_array_equal(msg_to_image(received), image)
    assert received.header.stamp == Time(sec=12, nanosec=345)


def test_padded_rows_are_read_without_the_padding():
    image = np.arange(6 * 10, dtype=np.uint8).reshape(6, 10)
    msg = Image(height=6, width=7, encoding="mono8", step=10)
    msg.data = image.tobytes()
    np.testing.assert_array_equal(msg_to_image(msg), image[:, :7])


def test_refuses_what_it_cannot_publish_or_read():
    with pytest.raises(ValueError, match="contiguous"):
        image_to_msg(np.zeros((4, 6), np.uint8)[:, ::2], Time(), "c")
    with pytest.raises(ValueError, match="8-bit"):
        image_to_msg(np.zeros((4, 4), np.uint16), Time(), "c")
    with pytest.raises(ValueError, match="encoding"):
        msg_to_image(Image(height=1, width=1, encoding="16UC1", step=2, data=b"\0\0"))
    with pytest.raises(ValueError, match="too short"):
        msg_to_image(Image(height=2, width=2, encoding="mono8", step=2, data=b"\0\0"))
