"""The environment every SDS graph process runs in: domain, discovery and large-image transport."""

from __future__ import annotations

import os
import random
from collections.abc import Mapping
from pathlib import Path

from sds_model.errors import InputError

# Measured in ../shared/docs/ros2-from-pypi.md: without these, 4K images between processes
# fall to 0-8 fps; with them 4K mono8 and bgr8 run at 30 fps.
LARGE_IMAGE_TRANSPORT = {
    "FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA?max_msg_size=1MB&sockets_size=64MB",
    "MALLOC_MMAP_THRESHOLD_": "268435456",
    "MALLOC_TRIM_THRESHOLD_": "536870912",
}
FASTDDS_PROFILES = Path(__file__).with_name("fastdds_profiles.xml")
"""Reliable writers' heartbeat every 100 ms (Fast DDS: 3 s), for quick repair of a lost sample;
histories that free each message's buffer once it is gone (the file says why)."""
MAX_DOMAIN_ID = 101


def pick_domain_id() -> int:
    """A random ROS domain id in 1..101, so concurrent runs on one machine do not meet."""
    return random.SystemRandom().randint(1, MAX_DOMAIN_ID)


def graph_domain_id(requested: int | None, network: bool = False,
                    base: Mapping[str, str] | None = None) -> int:
    """The graph's domain: `requested` (--domain-id), else the user's ROS_DOMAIN_ID, else (one
    machine) a random one; a graph across machines needs one both sides name."""
    env = os.environ if base is None else base
    if requested is not None:
        return requested
    if env.get("ROS_DOMAIN_ID"):
        return int(env["ROS_DOMAIN_ID"])
    if network:
        raise InputError("a graph across machines needs one domain on every machine: give "
                         "--domain-id N (or set ROS_DOMAIN_ID) on each")
    return pick_domain_id()


def graph_environment(domain_id: int, base: Mapping[str, str] | None = None,
                      network: bool = False) -> dict[str, str]:
    """Environment for a graph process: its domain, discovery, fast transport, one BLAS thread.

    Discovery: what the user set (ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_STATIC_PEERS) is kept.
    Otherwise one machine: LOCALHOST; across machines (`network`): LOCALHOST plus the peers
    named in ROS_STATIC_PEERS only, so that no other machine of the network joins the graph.
    """
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise InputError(f"ROS domain id {domain_id} is outside 0..{MAX_DOMAIN_ID}")
    env = dict(os.environ if base is None else base)
    if network and not env.get("ROS_STATIC_PEERS") and \
            not env.get("ROS_AUTOMATIC_DISCOVERY_RANGE"):
        raise InputError("--network meets only the machines named in ROS_STATIC_PEERS (their "
                         "addresses, ';'-separated); set it, or ROS_AUTOMATIC_DISCOVERY_RANGE="
                         "SUBNET to meet every machine of the subnet")
    env.update(LARGE_IMAGE_TRANSPORT)
    env["FASTDDS_DEFAULT_PROFILES_FILE"] = str(FASTDDS_PROFILES)
    # Without it rmw_fastrtps replaces the profile's history memory policy with its own, whose
    # pools grow for as long as a video repeats (fastdds_profiles.xml).
    env["RMW_FASTRTPS_USE_QOS_FROM_XML"] = "1"
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONUNBUFFERED"] = "1"
    # A process that dies of a fatal signal (SIGSEGV in a C extension) prints every thread's
    # Python stack to its log first: the one clue such a rare crash leaves.
    env["PYTHONFAULTHANDLER"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    # The graph's parallelism is its processes. OpenBLAS's own threads spin while they wait:
    # the sloshing node's small fits took 9.6 ms of CPU per frame with them and 3.0 without,
    # and the live latency's p95 fell from 46 to 33 ms (bench/README.md). A user's setting wins.
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    # Two malloc arenas: each new decoder thread (a video played again opens a new decoder)
    # otherwise took an arena of its own, and with MALLOC_TRIM_THRESHOLD_ none was given
    # back: the frame source grew from 36 MB to 1 GB in ten minutes of a repeated clip; with
    # two it stayed at 352-386 MB (bench/README.md, "Live preview latency").
    env.setdefault("MALLOC_ARENA_MAX", "2")
    return env
