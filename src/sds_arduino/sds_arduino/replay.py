"""Protocol lines replayed in their own time: a stand-in Arduino for demos and tests."""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator

from sds_arduino.protocol import ProtocolError, parse_line


def paced(lines: Iterable[bytes]) -> Iterator[bytes]:
    """Each line when its device time (t_us, from the first record) has come; a line that is
    not a record (noise, a corrupted copy) goes out at once. Bytes before a '$' are ignored
    for the timing."""
    start, first_us = time.monotonic(), None
    for line in lines:
        frame_start = line.find(b"$")
        try:
            t_us = parse_line(line[frame_start:]).t_us if frame_start >= 0 else None
        except ProtocolError:
            t_us = None
        if t_us is not None:
            first_us = t_us if first_us is None else first_us
            delay = start + (t_us - first_us) * 1e-6 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        yield line
