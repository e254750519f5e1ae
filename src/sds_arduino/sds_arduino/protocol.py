"""The Arduino's line protocol, version 1: one record per line, on the serial port and SD card.

    $SDS1,<seq>,<t_us>,<kind>,<value>,...*<checksum>\\r\\n

- `seq`: record counter, 0..2^32-1, wrapping; a gap means lost records.
- `t_us`: device clock (Arduino micros()), 0..2^32-1 µs, wrapping after 71.6 minutes.
- `kind` and its integer values:
  IMU ax_mg, ay_mg, az_mg   accelerometer (MPU6050, ±16 g range), x along the excitation [mg]
  TOF range_mm, status      time of flight (VL53L0X) to the liquid [mm]; status 0 = valid
  TRG level                 capsule trigger line (1 = drop started)
  LED state                 sync LED seen by the cameras (1 = on)
  LAS state                 laser diodes and line laser power (1 = on)
- `checksum`: XOR of every byte between '$' and '*', two upper-case hex digits (as NMEA).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sds_model.errors import InputError

HEADER = "$SDS1"
FIELDS = {"IMU": ("ax_mg", "ay_mg", "az_mg"), "TOF": ("range_mm", "status"), "TRG": ("level",),
          "LED": ("state",), "LAS": ("state",)}
WRAP = 2**32


class ProtocolError(InputError):
    """A line that is not a valid version-1 record; the message says what is wrong, `reason`
    names the kind of fault (for counting)."""

    def __init__(self, message: str, reason: str = "invalid record") -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class Record:
    """One record: sequence number, device time [µs], kind and its integer values."""

    seq: int
    t_us: int
    kind: str
    values: tuple[int, ...]

    def __post_init__(self) -> None:
        if self.kind not in FIELDS:
            raise ProtocolError(f"unknown record kind {self.kind!r}", "unknown kind")
        if len(self.values) != len(FIELDS[self.kind]):
            raise ProtocolError(f"{self.kind} has {len(FIELDS[self.kind])} values, "
                                f"got {len(self.values)}", "wrong value count")
        if not (0 <= self.seq < WRAP and 0 <= self.t_us < WRAP):
            raise ProtocolError(f"seq and t_us must lie in 0..2^32-1, got {self.seq}, "
                                f"{self.t_us}", "out of range")


def checksum(body: str) -> str:
    """XOR of the body's bytes as two upper-case hex digits."""
    value = 0
    for byte in body.encode("ascii"):
        value ^= byte
    return f"{value:02X}"


def format_record(record: Record) -> str:
    """The record's line, with checksum and CR LF."""
    body = ",".join([HEADER[1:], str(record.seq), str(record.t_us), record.kind,
                     *map(str, record.values)])
    return f"${body}*{checksum(body)}\r\n"


def parse_line(line: str | bytes) -> Record:
    """The record of one line (line ending optional); ProtocolError for anything else."""
    if isinstance(line, bytes):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError as error:
            raise ProtocolError("non-ASCII bytes in the line", "non-ASCII") from error
    line = line.rstrip("\r\n")
    if not line.startswith("$") or "*" not in line:
        raise ProtocolError("a record starts with '$' and has '*' before its checksum",
                            "no frame")
    body, _, given = line[1:].rpartition("*")
    if given != checksum(body):
        raise ProtocolError(f"checksum {given!r} does not match {checksum(body)!r}",
                            "bad checksum")
    parts = body.split(",")
    if parts[0] != HEADER[1:]:
        raise ProtocolError(f"unknown protocol header {parts[0]!r} (expected {HEADER[1:]})",
                            "unknown header")
    if len(parts) < 4:
        raise ProtocolError("a record needs seq, t_us and kind", "too few fields")
    try:
        numbers = [int(p) for p in (parts[1], parts[2], *parts[4:])]
    except ValueError as error:
        raise ProtocolError(f"non-integer field in {body!r}", "non-integer field") from error
    return Record(numbers[0], numbers[1], parts[3], tuple(numbers[2:]))


def read_log(path: str | Path) -> tuple[list[Record], int]:
    """Every valid record of a serial capture or SD-card log, and how many lines were rejected."""
    records, rejected = [], 0
    with Path(path).open("rb") as stream:
        for line in stream:
            if not line.strip():
                continue
            try:
                records.append(parse_line(line))
            except ProtocolError:
                rejected += 1
    return records, rejected


def unwrap_time_s(t_us: Sequence[int]) -> np.ndarray:
    """Device times [s] from `t_us` values, undoing the 2³² µs wrap of micros()."""
    ticks = np.asarray(t_us, dtype=np.int64)
    if len(ticks) == 0:
        return np.empty(0)
    elapsed_us = np.concatenate([[0], np.cumsum(np.diff(ticks) % WRAP)])
    return (ticks[0] + elapsed_us) * 1e-6
