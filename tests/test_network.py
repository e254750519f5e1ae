"""A graph across two machines: `sds graph --network` in two network namespaces joined by a veth
pair, the camera on one, a frame monitor on the other. They meet through ROS_STATIC_PEERS, and
machines that do not name each other do not meet, on the same link."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import NTSC, random_frames, write_lossless_clip

pytestmark = pytest.mark.ros

SDS = str(Path(sys.executable).with_name("sds"))
PARAMS = Path(__file__).resolve().parents[1] / "config" / "params"
ADDRESSES = {"a": "10.77.0.1", "b": "10.77.0.2"}
DOMAIN_ID = "17"


def ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=False)


@pytest.fixture(scope="module")
def namespaces():
    """Two network namespaces joined by a veth pair; skipped where they cannot be made."""
    if shutil.which("ip") is None:
        pytest.skip("no `ip` command: cannot make network namespaces")
    names = {side: f"sds{side}{os.getpid()}" for side in ADDRESSES}
    if ip("netns", "add", names["a"]).returncode:
        pytest.skip("cannot create network namespaces here (needs CAP_SYS_ADMIN)")
    ip("netns", "add", names["b"])
    link = f"sv{os.getpid() % 100000}"
    ip("link", "add", f"{link}a", "type", "veth", "peer", "name", f"{link}b")
    for side, name in names.items():
        ip("link", "set", f"{link}{side}", "netns", name)
        ip("-n", name, "addr", "add", f"{ADDRESSES[side]}/24", "dev", f"{link}{side}")
        ip("-n", name, "link", "set", f"{link}{side}", "up")
        ip("-n", name, "link", "set", "lo", "up")
    yield names
    for name in names.values():
        ip("netns", "del", name)


def graph_file(folder: Path, node: dict) -> Path:
    path = folder / f"{node['name']}.yaml"
    path.write_text(yaml.safe_dump({"nodes": [node]}))
    return path


def start(namespace: str, graph: Path, peers: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items()
           if k not in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS")}
    env["ROS_STATIC_PEERS"] = peers
    return subprocess.Popen(["ip", "netns", "exec", namespace, SDS, "graph", str(graph),
                             "--network", "--domain-id", DOMAIN_ID], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def graphs(folder: Path) -> tuple[Path, Path, Path]:
    clip = write_lossless_clip(folder / "clip.mp4", random_frames(20, 120, 160, seed=5), NTSC)
    summary = folder / "summary.json"
    camera = graph_file(folder, {
        "name": "camera", "plugin": "sds_nodes.frame_source:FrameSourceNode",
        "params": str(PARAMS / "frame_source.yaml"), "required": True,
        "parameters": {"source": str(clip), "pacing": "flood", "ack_consumers": 1,
                       "linger_s": 0.5},
        "remap": {"image": "/camera/image", "frame_ack": "/camera/frame_ack"}})
    monitor = graph_file(folder, {
        "name": "monitor", "plugin": "sds_nodes.frame_monitor:FrameMonitorNode",
        "params": str(PARAMS / "frame_monitor.yaml"),
        "parameters": {"summary_path": str(summary), "report_period_s": 0.5},
        "remap": {"image": "/camera/image", "frame_ack": "/camera/frame_ack"}})
    return camera, monitor, summary


def stop(process: subprocess.Popen) -> str:
    process.terminate()
    output, _ = process.communicate(timeout=30)
    return output


def test_two_machines_that_name_each_other_share_a_graph(namespaces, tmp_path) -> None:
    camera, monitor, summary = graphs(tmp_path)
    receiver = start(namespaces["b"], monitor, ADDRESSES["a"])
    sender = start(namespaces["a"], camera, ADDRESSES["b"])
    try:
        sent, _ = sender.communicate(timeout=90)   # the camera ends once the file is done
    finally:
        received = stop(receiver)
    assert sender.returncode == 0, sent
    assert "published 20 frames" in sent and "+ peers 10.77.0.2" in sent, sent
    assert json.loads(summary.read_text())["frames"] == 20, received


def test_machines_that_do_not_name_each_other_do_not_meet(namespaces, tmp_path) -> None:
    camera, monitor, summary = graphs(tmp_path)
    receiver = start(namespaces["b"], monitor, "10.77.0.9")   # some other machine
    sender = start(namespaces["a"], camera, "10.77.0.8")
    time.sleep(8.0)
    sent, received = stop(sender), stop(receiver)
    assert "waiting for 1 subscriber(s)" in sent, sent
    assert "stopped: published 0 frames and the 0 video packets" in sent, sent
    assert json.loads(summary.read_text())["frames"] == 0, received
