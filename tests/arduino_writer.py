"""A stand-in Arduino: writes lines to a pseudo-terminal whose slave is linked at a path.

    python arduino_writer.py LINK LINES_FILE DISCONNECT_AT

Prints READY once the link exists, waits for GO on stdin, writes the lines paced by their
device times (as the Arduino sends them) and, at line DISCONNECT_AT, writes half of that
line, waits, closes the terminal ("unplugged"), opens a new one at the same link ("plugged
in") and goes on; prints DONE and stays plugged in until a line on stdin.
"""

from __future__ import annotations

import os
import sys
import time
import tty
from pathlib import Path

from sds_arduino.replay import paced


def plug(link: Path) -> tuple[int, int]:
    master, slave = os.openpty()
    tty.setraw(slave)
    temporary = link.with_suffix(".new")
    temporary.unlink(missing_ok=True)
    temporary.symlink_to(os.ttyname(slave))
    os.replace(temporary, link)
    return master, slave


def main() -> None:
    link, lines_file, disconnect_at = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
    lines = lines_file.read_bytes().splitlines(keepends=True)
    master, slave = plug(link)
    print("READY", flush=True)
    sys.stdin.readline()
    for index, line in enumerate(paced(lines)):
        if index == disconnect_at:
            os.write(master, line[: len(line) // 2])
            time.sleep(0.5)
            os.close(master)
            os.close(slave)
            time.sleep(0.5)
            master, slave = plug(link)
            print("RECONNECTED", flush=True)
            time.sleep(1.0)
            continue
        os.write(master, line)
    print("DONE", flush=True)
    sys.stdin.readline()   # stay plugged in until told
    os.close(master)
    os.close(slave)


if __name__ == "__main__":
    main()
