"""Reading .rrd files back with Rerun's own CLI."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

RERUN = str(Path(sys.executable).with_name("rerun"))


def rrd_entities(path: Path) -> dict[str, set[str]]:
    """Entity path → archetypes, from `rerun rrd print`."""
    done = subprocess.run([RERUN, "rrd", "print", str(path)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    entities: dict[str, set[str]] = {}
    for entity, columns in re.findall(r" - (/\S+) - data columns: \[(.*)\]", done.stdout):
        entities.setdefault(entity, set()).update(c.split(":")[0] for c in columns.split())
    return entities
