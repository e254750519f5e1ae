"""Conversion between numpy frames and sensor_msgs/Image, and of a video's packets to
foxglove_msgs/CompressedVideo, without per-element copies."""

from __future__ import annotations

import array
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import CompressedImage, Image

from foxglove_msgs.msg import CompressedVideo

_ENCODING_CHANNELS = {"mono8": 1, "bgr8": 3, "rgb8": 3}


def encoding_for(image: np.ndarray) -> str:
    """ROS encoding of an 8-bit mono (H x W) or BGR (H x W x 3) array."""
    if image.dtype != np.uint8:
        raise ValueError(f"only 8-bit images are published, got {image.dtype}")
    if image.ndim == 2:
        return "mono8"
    if image.ndim == 3 and image.shape[2] == 3:
        return "bgr8"
    raise ValueError(f"cannot publish an image of shape {image.shape}")


def image_to_msg(image: np.ndarray, stamp: Time, frame_id: str) -> Image:
    """Image message holding one copy of a C-contiguous mono8 or bgr8 array."""
    if not image.flags.c_contiguous:
        raise ValueError("image_to_msg needs a C-contiguous array")
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = image.shape[:2]
    msg.encoding = encoding_for(image)
    msg.is_bigendian = 0
    msg.step = image.strides[0]
    data = array.array("B")
    data.frombytes(image.data.cast("B"))
    msg.data = data
    return msg


def msg_to_image(msg: Image) -> np.ndarray:
    """Read-only numpy view of an Image message's pixels (H x W or H x W x 3)."""
    channels = _ENCODING_CHANNELS.get(msg.encoding)
    if channels is None:
        raise ValueError(f"unsupported image encoding {msg.encoding!r}")
    flat = np.frombuffer(msg.data, dtype=np.uint8)
    row_bytes = msg.width * channels
    if msg.step < row_bytes or flat.size < msg.step * msg.height:
        raise ValueError(f"image message too short for {msg.width}x{msg.height} {msg.encoding}")
    rows = flat[: msg.step * msg.height].reshape(msg.height, msg.step)[:, :row_bytes]
    if channels == 1:
        return rows
    return rows.reshape(msg.height, msg.width, channels)


def packet_msg(data: bytes, stamp: Time, frame_id: str, packet_format: str
               ) -> CompressedVideo | CompressedImage:
    """A camera's packet as it is published: a JPEG as sensor_msgs/CompressedImage, a video
    stream's packet as foxglove_msgs/CompressedVideo; one copy of its bytes."""
    packet = array.array("B")
    packet.frombytes(data)
    if packet_format == "jpeg":
        image = CompressedImage()
        image.header.stamp, image.header.frame_id = stamp, frame_id
        image.format, image.data = "jpeg", packet
        return image
    msg = CompressedVideo()
    msg.timestamp, msg.frame_id = stamp, frame_id
    msg.format, msg.data = packet_format, packet
    return msg


PACKET_TYPES = ("foxglove_msgs/msg/CompressedVideo", "sensor_msgs/msg/CompressedImage")
"""The messages that carry a camera's packets: a video stream's, a JPEG camera's."""


def packet_fields(msg: Any) -> tuple[str, int, str, bytes]:
    """(frame_id, stamp [ns], format, bytes) of a CompressedVideo or CompressedImage message
    (rclpy's objects or rosbags')."""
    if hasattr(msg, "timestamp"):
        frame_id, stamp = msg.frame_id, msg.timestamp
    else:
        frame_id, stamp = msg.header.frame_id, msg.header.stamp
    return (frame_id, int(stamp.sec) * 10**9 + int(stamp.nanosec), msg.format,
            msg.data.tobytes())
