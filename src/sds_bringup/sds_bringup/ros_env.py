"""The environment every SDS graph process runs in: domain, discovery and large-image transport."""

from __future__ import annotations

import os
import random
from collections.abc import Mapping
from pathlib import Path

# Measured in ../shared/docs/ros2-from-pypi.md: without these, 4K images between processes
# fall to 0-8 fps; with them 4K mono8 and bgr8 run at 30 fps.
LARGE_IMAGE_TRANSPORT = {
    "FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA?max_msg_size=1MB&sockets_size=64MB",
    "MALLOC_MMAP_THRESHOLD_": "268435456",
    "MALLOC_TRIM_THRESHOLD_": "536870912",
}
FASTDDS_PROFILES = Path(__file__).with_name("fastdds_profiles.xml")
"""Reliable writers' heartbeat every 100 ms (Fast DDS: 3 s), for quick repair of a lost sample."""
MAX_DOMAIN_ID = 101


def pick_domain_id() -> int:
    """A random ROS domain id in 1..101, so concurrent runs on one machine do not meet."""
    return random.SystemRandom().randint(1, MAX_DOMAIN_ID)


def graph_environment(domain_id: int, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for a graph process: its domain, localhost-only discovery, fast transport."""
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS domain id {domain_id} is outside 0..{MAX_DOMAIN_ID}")
    env = dict(os.environ if base is None else base)
    env.update(LARGE_IMAGE_TRANSPORT)
    env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(FASTDDS_PROFILES)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    return env
