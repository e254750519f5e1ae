"""The one recording reader's decoded messages against rclpy's own, and its bad-input errors."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from mcap.writer import Writer
from rclpy.serialization import serialize_message
from sds_record.mcap_files import (
    McapRecorder,
    decoded_messages,
    message_counts,
    not_recorded,
)
from sds_ros.image_msg import image_to_msg
from sensor_msgs.msg import Imu
from std_msgs.msg import Header, String

from sds_msgs.msg import LaserLineProfile, LaserSpot, LaserSpotArray, SurfaceFit


def _is_message(value: Any) -> bool:
    return hasattr(value, "get_fields_and_field_types")


def _assert_same(decoded: Any, original: Any, where: str) -> None:
    """Field by field, by rclpy's field list: nested messages, sequences, numbers, strings."""
    if _is_message(original):
        for field in original.get_fields_and_field_types():
            _assert_same(getattr(decoded, field), getattr(original, field), f"{where}.{field}")
    elif isinstance(original, list) and original and _is_message(original[0]):
        assert len(decoded) == len(original), where
        for index, (item, expected) in enumerate(zip(decoded, original, strict=True)):
            _assert_same(item, expected, f"{where}[{index}]")
    elif isinstance(original, list | tuple | np.ndarray | bytes) or hasattr(original, "typecode"):
        expected = np.frombuffer(original, np.uint8) if isinstance(original, bytes) else \
            np.asarray(original)
        if expected.dtype.kind in "iuf":
            np.testing.assert_array_equal(np.asarray(decoded), expected, err_msg=where)
        else:
            assert list(decoded) == list(expected), where
    else:
        assert decoded == original, where


def _messages() -> list[tuple[str, str, Any]]:
    header = Header(stamp=Time(sec=12, nanosec=345_678_901), frame_id="camera_optical")
    spots = LaserSpotArray(header=header, frame_index=7, spots=[
        LaserSpot(laser_id=i, x_px=100.25 + i, y_px=-3.5 * i, sigma_px=0.07, flags=i % 3)
        for i in range(4)])
    line = LaserLineProfile(header=header, frame_index=7, x_px=[1.5, 2.5, np.nan],
                            y_px=[10.0, 11.0, 12.0], sigma_px=[0.1, 0.2, 0.3],
                            peak_intensity=[250.0, 251.0, 1.0], flags=[0, 1, 6])
    fit = SurfaceFit(header=header, frame_index=7, p00_mm=-0.25, tilt_x_rad=1e-3,
                     rejected_laser_ids=[3, 19], mode_names=["mean", "lateral_1_cos"],
                     modal_amplitudes_mm=[0.01, 2.5])
    imu = Imu(header=header)
    imu.linear_acceleration.z = 9.81
    imu.orientation_covariance[0] = -1.0
    image = image_to_msg(np.arange(6 * 5 * 3, dtype=np.uint8).reshape(6, 5, 3),
                         header.stamp, "camera_optical")
    return [("/tracker/spots", "sds_msgs/msg/LaserSpotArray", spots),
            ("/tracker/line", "sds_msgs/msg/LaserLineProfile", line),
            ("/recon/fit", "sds_msgs/msg/SurfaceFit", fit),
            ("/camera/imu", "sensor_msgs/msg/Imu", imu),
            ("/camera/image", "sensor_msgs/msg/Image", image),
            ("/recon/rig", "std_msgs/msg/String", String(data="rig: ünïcode")),
            ("/test/header", "std_msgs/msg/Header", header)]


def _record(path: Path, messages: list[tuple[str, str, Any]]) -> None:
    recorder = McapRecorder(path)
    for topic, type_name, _ in messages:
        recorder.add_topic(topic, type_name)
    for index, (topic, _, msg) in enumerate(messages):
        recorder.write(topic, serialize_message(msg), index + 1, index + 1)
    recorder.close()


def test_decoded_messages_equal_rclpys_originals(tmp_path: Path) -> None:
    messages = _messages()
    _record(tmp_path / "all.mcap", messages)
    decoded = list(decoded_messages(tmp_path / "all.mcap"))
    assert [r.topic for r, _ in decoded] == [topic for topic, _, _ in messages]
    for (recorded, msg), (topic, type_name, original) in zip(decoded, messages, strict=True):
        assert recorded.type_name == type_name
        _assert_same(msg, original, topic)
    only = list(decoded_messages(tmp_path / "all.mcap", types=["sensor_msgs/msg/Imu"]))
    assert [r.topic for r, _ in only] == ["/camera/imu"]


def test_a_message_that_does_not_decode_is_a_one_line_error(tmp_path: Path) -> None:
    recorder = McapRecorder(tmp_path / "bad.mcap")
    recorder.add_topic("/tracker/spots", "sds_msgs/msg/LaserSpotArray")
    good = serialize_message(_messages()[0][2])
    recorder.write("/tracker/spots", good, 1, 1)
    recorder.write("/tracker/spots", good[:30], 2, 2)   # cut inside the spots
    recorder.close()
    read = decoded_messages(tmp_path / "bad.mcap")
    assert next(read)[1].frame_index == 7
    with pytest.raises(ValueError, match=r"^/tracker/spots: the message logged at 2 ns does "
                                         r"not decode \(.*\)$"):
        next(read)


def _foreign_file(path: Path, schema_encoding: str, schema_text: str, data: bytes) -> None:
    """One std_msgs/String written by the mcap library itself with the given schema."""
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="another recorder")
        schema = writer.register_schema("std_msgs/msg/String", schema_encoding,
                                        schema_text.encode())
        channel = writer.register_channel("/chatter", "cdr", schema)
        writer.add_message(channel, log_time=5, publish_time=5, data=data)
        writer.finish()


def test_an_idl_schema_decodes_and_an_unknown_encoding_is_named(tmp_path: Path) -> None:
    data = serialize_message(String(data="from IDL"))
    idl = "module std_msgs { module msg { struct String { string data; }; }; };"
    _foreign_file(tmp_path / "idl.mcap", "ros2idl", idl, data)
    assert [m.data for _, m in decoded_messages(tmp_path / "idl.mcap")] == ["from IDL"]
    _foreign_file(tmp_path / "json.mcap", "jsonschema", "{}", data)
    with pytest.raises(ValueError, match=r"^/chatter: its schema std_msgs/msg/String does not "
                                         r"parse \(.*'jsonschema'.*\)$"):
        list(decoded_messages(tmp_path / "json.mcap"))


def test_message_counts_come_from_the_statistics_or_an_unfinished_files_chunks(
        tmp_path: Path) -> None:
    """A finished file's counts (its statistics), an unfinished one's (its complete chunks,
    as a killed recorder leaves them), and 0 for a topic the file does not have."""
    header = Header(stamp=Time(sec=1), frame_id="lateral_optical")
    recorder = McapRecorder(tmp_path / "run.mcap", flush_period_s=0.0)   # a chunk per message
    recorder.add_topic("/lateral/image", "std_msgs/msg/Header")
    recorder.add_topic("/tracker/spots", "std_msgs/msg/Header")
    for index in range(7):
        recorder.write("/lateral/image" if index % 3 else "/tracker/spots",
                       serialize_message(header), index + 1, index + 1)
    unfinished = tmp_path / "unfinished.mcap"
    unfinished.write_bytes((tmp_path / "run.mcap").read_bytes())
    recorder.close()
    wanted = ["/lateral/image", "/tracker/spots", "/camera/video"]
    expected = {"/lateral/image": 4, "/tracker/spots": 3, "/camera/video": 0}
    assert message_counts(tmp_path / "run.mcap", wanted) == expected
    assert message_counts(unfinished, wanted) == expected


def test_what_the_recorder_never_got_reads_back_from_its_file(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """The counts a recorder closes its file with come back by topic, and reading the file
    says them once; a file closed without them, and an unfinished one (a killed recorder's:
    its complete chunks), have none."""
    header = serialize_message(Header(stamp=Time(sec=1)))
    for name, counts in (("counted", {"/arduino/imu": 120, "/arduino/tof": 4}),
                         ("clean", None)):
        recorder = McapRecorder(tmp_path / f"{name}.mcap", flush_period_s=0.0)
        recorder.add_topic("/arduino/imu", "std_msgs/msg/Header")
        recorder.write("/arduino/imu", header, 1, 1)
        if name == "counted":
            (tmp_path / "unfinished.mcap").write_bytes((tmp_path / "counted.mcap").read_bytes())
        recorder.close(counts)
    assert not_recorded(tmp_path / "counted.mcap") == {"/arduino/imu": 120, "/arduino/tof": 4}
    assert not_recorded(tmp_path / "clean.mcap") == {}
    assert not_recorded(tmp_path / "unfinished.mcap") == {}
    with caplog.at_level(logging.WARNING, logger="sds_record.mcap_files"):
        for _ in range(2):
            assert len(list(decoded_messages(tmp_path / "counted.mcap"))) == 1
            assert len(list(decoded_messages(tmp_path / "clean.mcap"))) == 1
    assert [record.getMessage() for record in caplog.records] == [
        f"{tmp_path / 'counted.mcap'} lacks messages its recorder never got: "
        "120 of /arduino/imu, 4 of /arduino/tof"]
