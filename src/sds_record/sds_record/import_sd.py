"""`sds import-sd`: an SD-card log as an MCAP recording (drops where only the card was read)."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

from builtin_interfaces.msg import Time
from rclpy.serialization import serialize_message
from sds_arduino.protocol import WRAP, read_log, unwrap_time_s
from sds_model.errors import InputError
from sds_model.staging import staged_file
from sds_ros.arduino_msg import TOPICS, SensorSpec, record_message

from sds_record.mcap_files import McapRecorder

TYPE_NAMES = {"imu": "sensor_msgs/msg/Imu", "tof": "sensor_msgs/msg/Range",
              "events": "sds_msgs/msg/SyncEvent"}


@dataclass(frozen=True)
class Import:
    """How many records went in, how many lines were rejected, how many records are missing."""

    records: int
    rejected_lines: int
    missing_records: int


def import_sd(log: str | Path, output: str | Path, namespace: str = "/arduino",
              start_s: float = 0.0, spec: SensorSpec | None = None,
              overwrite: bool = False) -> Import:
    """Every valid record as /arduino/imu, /arduino/tof, /arduino/events messages stamped with
    the device clock (seconds since the log's first record, plus `start_s`); the file appears
    only when complete."""
    records, rejected = read_log(log)
    if not records:
        raise InputError(f"{log}: no valid protocol-v1 record ({rejected} lines rejected)")
    spec = spec or SensorSpec()
    device_times = unwrap_time_s([r.t_us for r in records])
    device_times -= device_times[0]
    missing = sum((b.seq - a.seq - 1) % WRAP for a, b in pairwise(records))
    output = Path(output)
    if output.exists() and not overwrite:
        raise InputError(f"{output} exists (not replaced: another name, or --overwrite)")
    with staged_file(output) as staging:
        recorder = McapRecorder(staging)
        try:
            for record, device_s in zip(records, device_times, strict=True):
                stamp_ns = round((start_s + device_s) * 1e9)
                topic = f"{namespace}/{TOPICS[record.kind]}"
                recorder.add_topic(topic, TYPE_NAMES[TOPICS[record.kind]])
                msg = record_message(record, Time(sec=stamp_ns // 10**9,
                                                  nanosec=stamp_ns % 10**9),
                                     round(device_s * 1e6), spec)
                recorder.write(topic, serialize_message(msg), stamp_ns, stamp_ns)
        finally:
            recorder.close()
    return Import(len(records), rejected, missing)
