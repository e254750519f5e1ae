"""Every `sds` command line of docs/ runs as written on small simulated inputs (issue 48): the
files a page names (a drop's video, the side camera's video and board images, the SD card's
log, a recording) are made by the simulator under those names, in a folder that sees the
repository's config/ as the page's reader does. Only what depends on the image's size changes:
the inputs are a quarter of 4K, so the rig file is the scaled one and the LED's region scaled.
A new command line on a page runs here without a word of this file changing."""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from sds_model.camera.files import save_camera
from sds_model.rig import load_rig, save_rig
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from test_docs import command_lines
from test_lateral import TOP_SCALE, side_scenario
from test_sloshing import observe, write_points_mcap

REPO = Path(__file__).resolve().parents[1]
SDS = str(Path(sys.executable).with_name("sds"))
STELIUM = "config/rigs/stelium.yaml"
DOCUMENTED = [(page, line) for page in sorted((REPO / "docs").glob("*.md"))
              for line in command_lines(page.read_text())]


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder that sees the repository's config/ as a page's reader does."""
    folder = tmp_path_factory.mktemp("docs")
    (folder / "config").symlink_to(REPO / "config")
    return folder


@pytest.fixture(scope="module")
def inputs(folder: Path) -> Path:
    """`folder` with the pages' input files, by the names the pages give them: a 1.4 s kick
    seen by both cameras (top at TOP_SCALE) with the Arduino's log, a microgravity drop's
    recording (with its rig, as the graph records it), and the rig file at TOP_SCALE."""
    simulation = simulate(replace(side_scenario(1.4), scale=TOP_SCALE), folder / "simulation",
                          progress=False)
    assert simulation.lateral_video is not None
    named = {"top.mp4": simulation.video, "side.mp4": simulation.lateral_video,
             "board_front.png": simulation.lateral_boards[0],
             "board_middle.png": simulation.lateral_boards[1], "SDS_LOG.TXT": simulation.sd_log}
    for name, path in named.items():
        (folder / name).symlink_to(path)
    drop = load_scenario(REPO / "config" / "scenarios" / "drop_4p7s.yaml")
    write_points_mcap(observe(drop), folder / "recording.mcap", rig=drop.rig)
    rig = load_rig(REPO / STELIUM)
    camera_file = save_camera(rig.camera.scaled(TOP_SCALE), folder / "camera_at_scale.yaml")
    save_rig(replace(rig, camera=rig.camera.scaled(TOP_SCALE), camera_file=camera_file),
             folder / "rig_at_scale.yaml")
    return folder


def at_scale(words: list[str], folder: Path) -> list[str]:
    """A page's command for inputs at TOP_SCALE: `sds process`'s rig file scaled with its
    camera, the LED's region [px] scaled; `$PWD` as a shell expands it."""
    words = [word.replace("$PWD", str(folder)) for word in words]
    if words[1] != "process":
        return words
    words = [str(folder / "rig_at_scale.yaml") if word == STELIUM else word for word in words]
    if "--led-roi" in words:
        start = words.index("--led-roi") + 1
        words[start:start + 4] = [str(round(int(v) * TOP_SCALE)) for v in words[start:start + 4]]
    return words


def test_the_pages_show_command_lines() -> None:
    """The pages' `sds` lines are found (the runner below has something to run)."""
    assert {line.split()[1] for _, line in DOCUMENTED} >= {"process", "analyze", "graph"}


@pytest.mark.parametrize("page, line", [
    pytest.param(page, line, id=f"{page.name}:{line.split()[1]}",
                 marks=[pytest.mark.ros] if line.split()[1] in ("graph", "run") else [])
    for page, line in DOCUMENTED])
def test_a_pages_command_line_runs_as_written(request: pytest.FixtureRequest, folder: Path,
                                              page: Path, line: str) -> None:
    """Each line exits 0, and what its --out names is written; `sds graph` (a ROS test, as
    `sds run` would be), which runs until
    stopped, comes up with its nodes and stops on Ctrl-C with every node exiting cleanly."""
    words = at_scale([SDS, *shlex.split(line)[1:]], folder)
    if words[1] == "graph":
        graph = subprocess.Popen(words, cwd=folder, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True)
        started = []
        assert graph.stdout is not None
        for output in graph.stdout:
            started += [output.split("]")[0][1:]] if "] started (pid" in output else []
            if "diodes" in output:    # the reconstruction node has read its rig
                break
        graph.send_signal(signal.SIGINT)
        rest = graph.communicate(timeout=60)[0]
        # 128 + SIGINT, a shell's code for a program stopped by Ctrl-C, once every node exited
        assert graph.returncode == 128 + signal.SIGINT and started, (started, rest)
        assert all(f"[{name}] exited with code 0" in rest for name in started), rest
        return
    request.getfixturevalue("inputs")
    done = subprocess.run(words, cwd=folder, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "MPLBACKEND": "Agg"})
    assert done.returncode == 0, (page.name, words, done.stdout[-2000:], done.stderr[-2000:])
    out = folder / words[words.index("--out") + 1]
    written = {"process": "points.csv", "analyze": "analysis.json"}[words[1]]
    assert (out / written).exists(), sorted(p.name for p in out.iterdir())
    if words[1] == "analyze":
        assert json.loads((out / written).read_text())
