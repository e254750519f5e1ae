"""The Arduino's byte stream, clock mapping and protocol: fault injection and fuzzing."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap_ros2.reader import read_ros2_messages
from sds_arduino.clock import DeviceClock
from sds_arduino.protocol import FIELDS, WRAP, ProtocolError, Record, format_record, parse_line
from sds_arduino.stamps import RecordStamper, StampClock
from sds_arduino.stream import RecordStream
from sds_sim.arduino import arduino_records
from sds_sim.scenario import load_scenario

NOISE = bytes(b for b in range(256) if b not in b"$\r\n")
PRINTABLE = bytes(b for b in range(0x20, 0x7F) if b != ord("$"))


def valid_records(count: int, rng: np.random.Generator) -> list[Record]:
    kinds = list(FIELDS)
    records = []
    for seq in range(count):
        kind = kinds[rng.integers(len(kinds))]
        values = tuple(int(v) for v in rng.integers(-16000, 16000, len(FIELDS[kind])))
        records.append(Record(seq, (seq * 5000 + 7) % WRAP, kind, values))
    return records


def corrupted_stream(records: list[Record], rng: np.random.Generator
                     ) -> tuple[bytes, list[Record], int, int]:
    """Lines with random corruption, truncation and noise between them: the bytes, the
    records that must come out, the bad lines and the noise bytes that must be counted."""
    out, intact, bad, noise = bytearray(), [], 0, 0
    for index, record in enumerate(records):
        cut = False
        line = bytearray(format_record(record).encode())
        fault = rng.random()
        last = index == len(records) - 1
        if fault < 0.1:                                  # one byte replaced
            position = int(rng.integers(1, len(line) - 2))
            line[position] = PRINTABLE[(PRINTABLE.index(line[position]) + 1
                                        + int(rng.integers(len(PRINTABLE) - 1)))
                                       % len(PRINTABLE)] if line[position] in PRINTABLE \
                else PRINTABLE[0]
            bad += 1
        elif fault < 0.2 and not last:                   # cut short: the next '$' ends it
            line = line[: int(rng.integers(1, len(line) - 2))]
            bad += 1
            cut = True
        else:
            intact.append(record)
        out += line
        if rng.random() < 0.1:                           # noise between records
            junk = bytes(NOISE[i] for i in rng.integers(len(NOISE), size=rng.integers(1, 20)))
            out += junk
            noise += 0 if cut else len(junk)   # after a cut line it joins that line's frame
    return bytes(out), intact, bad, noise


def test_100k_corrupted_lines_give_every_valid_record_and_count_the_rest() -> None:
    rng = np.random.default_rng(7)
    records = valid_records(100_000, rng)
    data, intact, bad, noise = corrupted_stream(records, rng)
    stream, out, position = RecordStream(), [], 0
    while position < len(data):                          # arbitrary read sizes
        size = int(rng.integers(1, 300))
        out += stream.feed(data[position:position + size])
        position += size
    assert out == intact
    assert stream.stats.bad_lines == bad
    assert stream.stats.noise_bytes == noise
    assert stream.stats.records == len(intact)
    assert stream.stats.missing_records == len(records) - len(intact) - \
        (records[-1] not in intact)


def test_a_disconnect_mid_line_drops_that_line_only() -> None:
    records = valid_records(3, np.random.default_rng(0))
    lines = [format_record(r).encode() for r in records]
    stream = RecordStream()
    out = list(stream.feed(lines[0] + lines[1][:10]))
    stream.reset()
    out += stream.feed(lines[2])
    assert out == [records[0], records[2]]
    assert stream.stats.reasons == {"cut by a disconnect": 1}
    assert stream.stats.missing_records == 1


@settings(max_examples=2000, deadline=None)
@given(st.binary(max_size=200))
def test_fuzzed_bytes_never_crash_the_parser(data: bytes) -> None:
    try:
        record = parse_line(data)
    except ProtocolError:
        return
    assert format_record(record).rstrip("\r\n") == data.decode().rstrip("\r\n")


@settings(max_examples=1000, deadline=None)
@given(st.lists(st.binary(max_size=120), max_size=20))
def test_fuzzed_chunks_never_crash_the_stream(chunks: list[bytes]) -> None:
    """Any bytes in any chunking: no exception, and every record or rejection had its '$'."""
    stream = RecordStream()
    records = [record for chunk in chunks for record in stream.feed(chunk)]
    stream.reset()
    assert len(records) + stream.stats.bad_lines <= b"".join(chunks).count(b"$")
    assert all(isinstance(r, Record) for r in records)


def test_clock_mapping_recovers_offset_and_drift() -> None:
    """Device micros() with a 1.234 s offset, 40 ppm drift and wraps; host delays 0.1–5 ms."""
    rng = np.random.default_rng(3)
    clock = DeviceClock()
    true_s = np.arange(0, 120, 0.005)
    ticks = np.round((true_s + 4294.0) * (1 + 40e-6) * 1e6).astype(np.int64) % WRAP
    host = 1000.0 + true_s + rng.exponential(1e-3, len(true_s)) + 1e-4
    errors = []
    for tick, truth, arrival in zip(ticks, true_s, host, strict=True):
        device = clock.device_seconds(int(tick))
        clock.observe(device, arrival)
        errors.append(clock.to_host(device) - (1000.0 + truth))
    errors = np.abs(np.array(errors)[len(errors) // 4:])   # after the first 30 s
    assert errors.max() < 0.5e-3, errors.max()
    assert abs(clock.rate - 1 / (1 + 40e-6)) < 2e-6


def arriving_in_batches(seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Device times of 200 Hz records (40 ppm drift), from the first, and the host times they
    arrive at: each is ready 0.1-5 ms after it was taken, and read with the others ready at
    the next read (every 5-60 ms)."""
    rng = np.random.default_rng(seed)
    true_s = np.arange(0, seconds, 0.005)
    ready_s = 1000.0 + true_s + 1e-4 + rng.exponential(1e-3, len(true_s))
    reads_s = 1000.0 + np.cumsum(rng.uniform(0.005, 0.06, int(seconds / 0.005)))
    return true_s * (1 + 40e-6), reads_s[np.searchsorted(reads_s, ready_s)]


@pytest.mark.parametrize("led_at_s, camera_sees_s", [(1.3, 1.45), (0.3, 0.45), (40.0, 40.2)])
def test_stamps_are_on_one_clock_and_never_go_back(led_at_s: float,
                                                   camera_sees_s: float) -> None:
    """Records arrive in batches; the sync LED at `led_at_s` (device), seen by the camera at
    `camera_sees_s` (host time) on a clock 0.67 s ahead: every stamp on the camera's clock
    from the first record on, or, when the LED comes after the hold, every one on the
    host's."""
    device_s, arrival_s = arriving_in_batches(45.0, seed=5)
    stamper: RecordStamper[int] = RecordStamper(align_to_camera=True, hold_s=30.0)
    released = []
    led_index = int(np.searchsorted(device_s, led_at_s))
    camera_offset_s = 0.67
    seen = False
    for index, (device, arrival) in enumerate(zip(device_s, arrival_s, strict=True)):
        if not seen and arrival >= 1000.0 + camera_sees_s:
            released += stamper.camera_led_on(1000.0 + led_at_s + camera_offset_s)
            seen = True
        released += stamper.add(index, device, arrival, led_on=index == led_index)
    released += stamper.flush()
    assert [r.item for r in released] == list(range(len(device_s)))   # all, in order
    stamps = np.array([r.stamp_s for r in released])
    assert np.all(np.diff(stamps) > 0)                                  # none shared, none back
    true_host_s = 1000.0 + np.arange(len(device_s)) * 0.005
    on_camera = led_at_s < 30.0
    expected = true_host_s + (camera_offset_s if on_camera else 0.0)
    assert stamper.clock is (StampClock.CAMERA if on_camera else StampClock.HOST)
    if on_camera:   # the LED's switch-on is the camera's, even when it came before settling
        camera_led_s = 1000.0 + led_at_s + camera_offset_s
        assert abs(stamps[led_index] - camera_led_s) < 1e-6
    # Late by the lowest delay seen (0.1 ms and the wait for a read): a bias, no scatter.
    errors_s = stamps - expected
    assert np.abs(errors_s).max() < 1.5e-3 and np.ptp(errors_s[len(errors_s) // 4:]) < 1e-3


def test_sds_import_sd_writes_every_valid_record_to_mcap(repo: Path, tmp_path: Path) -> None:
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 2.0})
    records = arduino_records(scenario)
    lines = [format_record(r) for r in records]
    lines.insert(10, "$SDS1,garbage*00\r\n")
    del lines[20]                                   # a lost record: a sequence gap
    log = tmp_path / "SDS_LOG.TXT"
    log.write_text("".join(lines))
    done = subprocess.run([str(Path(sys.executable).with_name("sds")), "import-sd", str(log)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "1 lines rejected, 1 records missing" in done.stdout
    kept = [r for r in records if r is not records[19]]
    by_topic: dict[str, list] = {}
    for message in read_ros2_messages(str(log.with_suffix(".mcap"))):
        by_topic.setdefault(message.channel.topic, []).append(message.ros_msg)
    imu = [r for r in kept if r.kind == "IMU"]
    assert len(by_topic["/arduino/imu"]) == len(imu)
    assert len(by_topic["/arduino/tof"]) == sum(r.kind == "TOF" for r in kept)
    assert len(by_topic["/arduino/events"]) == sum(r.kind in ("TRG", "LED", "LAS") for r in kept)
    first = by_topic["/arduino/imu"][5]
    assert first.linear_acceleration.z == pytest.approx(imu[5].values[2] * 9.80665e-3)
    stamp = first.header.stamp.sec + first.header.stamp.nanosec * 1e-9
    assert stamp == pytest.approx((imu[5].t_us - records[0].t_us) * 1e-6, abs=1e-9)
