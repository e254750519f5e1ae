"""Test-run environment: own ROS domain, localhost discovery, large-image transport, ROS_HOME."""

from __future__ import annotations

import os
import signal
import tempfile
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from sds_bringup.ros_env import MAX_DOMAIN_ID, graph_environment, pick_domain_id


def domain_id_of_this_process() -> int:
    """This process's ROS domain: the run's (SDS_TEST_DOMAIN_ID if set, else a random one,
    drawn once per run and handed on to pytest-xdist's workers), and for worker gwN the N+1-th
    after it, so that two workers' graphs never meet (two random draws would meet in one run
    of about 100)."""
    run_domain_id = int(os.environ.setdefault("SDS_TEST_DOMAIN_ID", str(pick_domain_id())))
    worker = os.environ.get("PYTEST_XDIST_WORKER")   # "gw0", "gw1", ... (set before conftest)
    if worker is None:
        return run_domain_id
    return 1 + (run_domain_id + int(worker.removeprefix("gw"))) % MAX_DOMAIN_ID


# Set before anything imports rclpy: every node of this run, in this process or started by it,
# meets only the others of this run (of its worker, with pytest-xdist).
DOMAIN_ID = domain_id_of_this_process()
os.environ.update(graph_environment(DOMAIN_ID))
os.environ.setdefault("ROS_HOME", tempfile.mkdtemp(prefix="sds-test-ros-home-"))
# A test run started in the background (a shell's `make test &`) ignores SIGINT, and every
# `sds` a test starts then inherits that: a test's Ctrl-C before the launcher's own handler
# was lost (the graph ran to its end). Ctrl-C's own action, as in a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def repo() -> Path:
    """The repository root."""
    return REPO


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data, or a skip saying it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"public data sets not found at {SHARED_DATA} (they sit beside the repo in CI)")
    return SHARED_DATA


def random_frames(count: int, height: int, width: int, seed: int = 0) -> np.ndarray:
    """Frames of random BGR pixels (every pixel differs, so any crop or channel error shows)."""
    return np.random.default_rng(seed).integers(0, 256, (count, height, width, 3), dtype=np.uint8)


def write_lossless_clip(path: Path, frames: np.ndarray, fps: Fraction) -> Path:
    """A lossless clip of the given BGR frames at a rational frame rate."""
    from sds_camera.video_writer import VideoWriter

    height, width = frames.shape[1:3]
    with VideoWriter(path, width, height, fps, codec="lossless") as writer:
        for frame in frames:
            writer.write(frame)
    return path


NTSC = Fraction(30000, 1001)


def ntsc_time_ns(index: int) -> int:
    """Presentation time of frame `index` at 29.97 fps [ns], from the frame rate alone."""
    return round(Fraction(index * 10**9) / NTSC)
