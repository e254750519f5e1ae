"""Records out of a raw serial byte stream: partial lines, garbage, gaps, all counted."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

from sds_arduino.protocol import WRAP, ProtocolError, Record, parse_line

MAX_LINE_BYTES = 96
"""Longer than any valid record: such a 'line' is noise and is dropped."""


@dataclass
class StreamStats:
    """Counts of what came over the line."""

    records: int = 0
    bad_lines: int = 0          # framed by '$' … newline but not a valid record
    noise_bytes: int = 0        # bytes outside any '$' … newline frame
    overlong_lines: int = 0
    missing_records: int = 0    # sequence gaps
    reasons: dict[str, int] = field(default_factory=dict)

    def reject(self, reason: str) -> None:
        self.bad_lines += 1
        self.reasons[reason] = self.reasons.get(reason, 0) + 1


class RecordStream:
    """Feed bytes as they arrive; get every valid record, in order, exactly once.

    A record starts at '$' and ends at a newline; bytes before a '$' are noise, a '$' inside a
    frame restarts it (the earlier part was a truncated line), a frame longer than
    MAX_LINE_BYTES is dropped. Sequence numbers reveal lost records.
    """

    def __init__(self) -> None:
        self.stats = StreamStats()
        self._frame = bytearray()
        self._in_frame = False
        self._last_seq: int | None = None

    def feed(self, data: bytes) -> Iterator[Record]:
        """The records completed by `data`."""
        for byte in data:
            if byte == 0x24:   # '$'
                if self._in_frame:
                    self.stats.reject("truncated")
                self._frame = bytearray(b"$")
                self._in_frame = True
            elif not self._in_frame:
                if byte not in (0x0A, 0x0D):
                    self.stats.noise_bytes += 1
            elif byte == 0x0A:
                self._in_frame = False
                record = self._parse(bytes(self._frame))
                if record is not None:
                    yield record
            else:
                self._frame.append(byte)
                if len(self._frame) > MAX_LINE_BYTES:
                    self.stats.overlong_lines += 1
                    self.stats.reject("longer than any record")
                    self._in_frame = False

    def reset(self) -> None:
        """The port was reopened: a half-received line is dropped (and counted)."""
        if self._in_frame:
            self.stats.reject("cut by a disconnect")
        self._in_frame = False
        self._frame = bytearray()

    def _parse(self, line: bytes) -> Record | None:
        try:
            record = parse_line(line)
        except ProtocolError as error:
            self.stats.reject(error.reason)
            return None
        if self._last_seq is not None:
            self.stats.missing_records += (record.seq - self._last_seq - 1) % WRAP
        self._last_seq = record.seq
        self.stats.records += 1
        return record
