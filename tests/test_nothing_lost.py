"""Nothing lost: results are written whole or not at all, whatever stops the run."""

from __future__ import annotations

import hashlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import av
import pytest
from sds_model.staging import STAGING_PREFIX, staged_file, staged_folder
from sds_sim.scenario import load_scenario
from sds_sim.simulate import SimulationOutput, simulate

SDS = str(Path(sys.executable).with_name("sds"))
REPO = Path(__file__).resolve().parents[1]
RIG = str(REPO / "config" / "rigs" / "stelium.yaml")


def folder_bytes(folder: Path) -> dict[str, str]:
    """Every file of a folder (recursively) by its relative path: its SHA-256."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def staging_left(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.startswith(STAGING_PREFIX)]


def test_a_folder_is_replaced_only_when_the_block_completes(tmp_path: Path) -> None:
    target = tmp_path / "out"
    target.mkdir()
    (target / "points.csv").write_text("old")
    (target / "meniscus.png").write_text("old figure")
    (target / "notes.txt").write_text("the user's own")
    with pytest.raises(RuntimeError), staged_folder(target, ["points.csv", "meniscus.png"]) \
            as staging:
        (staging / "points.csv").write_text("half")
        raise RuntimeError("disk full")
    assert (target / "points.csv").read_text() == "old" and not staging_left(tmp_path)
    with staged_folder(target, ["points.csv", "meniscus.png"]) as staging:
        (staging / "points.csv").write_text("new")
    # The earlier run's figure this run did not draw is gone; the user's file stays.
    assert sorted(p.name for p in target.iterdir()) == ["notes.txt", "points.csv"]
    assert (target / "points.csv").read_text() == "new" and not staging_left(tmp_path)
    fresh = tmp_path / "fresh"
    with pytest.raises(KeyboardInterrupt), staged_folder(fresh, []) as staging:
        (staging / "points.csv").write_text("half")
        raise KeyboardInterrupt
    assert not fresh.exists() and not staging_left(tmp_path)


def test_a_file_appears_only_when_complete(tmp_path: Path) -> None:
    target = tmp_path / "rig.mcap"
    target.write_text("earlier")
    with pytest.raises(OSError), staged_file(target) as staging:
        staging.write_text("half")
        raise OSError("no space left on device")
    assert target.read_text() == "earlier" and not staging_left(tmp_path)
    with staged_file(target) as staging:
        staging.write_text("complete")
    assert target.read_text() == "complete" and not staging_left(tmp_path)


@pytest.fixture(scope="module")
def kick(tmp_path_factory) -> SimulationOutput:
    """A 1 s simulated kick (30 frames, 4K)."""
    scenario = load_scenario(REPO / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 1.0})
    return simulate(scenario, tmp_path_factory.mktemp("kick") / "sim", progress=False)


def interruptible(command: list[str], **options) -> subprocess.Popen:
    """`command` with SIGINT's default action, whatever this test runs under: a job started
    in the background of a shell without job control inherits SIGINT ignored, and Python
    then never raises KeyboardInterrupt."""
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            **options)


def process(video: Path, out: Path, *extra: str) -> subprocess.Popen:
    return interruptible([SDS, "process", "--video", str(video), "--rig", RIG, "--out",
                          str(out), "--no-progress", *extra])


def interrupt_when(run: subprocess.Popen, frames: int | None, after_s: float) -> str:
    """SIGINT `after_s` once the progress bar shows `frames` frames tracked (None: from the
    start); what the run printed on stderr."""
    assert run.stderr is not None
    printed: list[str] = []
    seen = threading.Event()

    def read() -> None:
        assert run.stderr is not None
        while text := run.stderr.read(1):
            printed.append(text)
            counts = re.findall(r"frames: +(\d+)", "".join(printed[-200:]))
            if frames is not None and counts and int(counts[-1]) >= frames:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    if frames is not None:
        seen.wait(timeout=120)
    time.sleep(after_s)
    run.send_signal(signal.SIGINT)
    run.wait(timeout=120)
    reader.join(timeout=10)
    return "".join(printed)


def test_process_interrupted_at_any_moment_keeps_the_earlier_results(
        kick: SimulationOutput, tmp_path: Path) -> None:
    out = tmp_path / "results"
    first = process(kick.video, out)
    assert first.wait(timeout=300) == 0, first.stderr.read()
    earlier = folder_bytes(out)
    assert {"points.csv", "analysis.json", "report.html"} <= set(earlier)
    # Start-up, tracking (early and late), the analysis and its figures.
    outcomes = []
    for frames, after_s in ((None, 1.0), (2, 0.0), (15, 0.0), (29, 0.0), (30, 0.5)):
        run = interruptible([SDS, "process", "--video", str(kick.video), "--rig", RIG,
                             "--out", str(out), "--overwrite"])
        stderr = interrupt_when(run, frames, after_s)
        outcomes.append(run.returncode)
        assert run.returncode in (0, 130), stderr
        if run.returncode == 130:
            assert stderr.strip().endswith("sds: interrupted"), stderr
            assert "Traceback" not in stderr, stderr
        assert folder_bytes(out) == earlier, f"interrupted at {frames} frames: {stderr}"
        assert not staging_left(tmp_path)
    assert outcomes[:4] == [130] * 4, outcomes


def test_a_ctrl_c_once_the_command_is_done_changes_nothing(tmp_path: Path) -> None:
    """Ctrl-C while `sds` exits (here in an exit handler, as it may come while threads and
    compiled code close): the command's own exit code and one line, no KeyboardInterrupt (the
    last moment of `sds process`'s run once died of the signal, exit -2)."""
    script = (
        "import atexit, os, signal, sys, time\n"
        "from sds_cli.cli import main\n"
        "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(0.3)))\n"
        "main(sys.argv[1:])\n")
    run = interruptible([sys.executable, "-c", script, "process", "--video",
                         str(tmp_path / "missing.mp4"), "--rig", RIG,
                         "--out", str(tmp_path / "out")])
    _, stderr = run.communicate(timeout=60)
    assert run.returncode == 2, stderr
    assert len(stderr.strip().splitlines()) == 1 and "KeyboardInterrupt" not in stderr, stderr


def test_a_failed_run_leaves_nothing_that_blocks_the_retry(kick: SimulationOutput,
                                                            tmp_path: Path) -> None:
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(b"\x00" * 1000)
    out = tmp_path / "results"
    run = process(broken, out)
    assert run.wait(timeout=120) == 2
    assert not out.exists() and not staging_left(tmp_path)
    run = process(kick.video, out)
    assert run.wait(timeout=300) == 0, run.stderr.read()


def test_a_video_cut_in_half_keeps_the_frames_before_the_cut(kick: SimulationOutput,
                                                              tmp_path: Path) -> None:
    # Matroska, as a camera writes it while it records: readable up to where it stops.
    whole = tmp_path / "whole.mkv"
    with av.open(str(kick.video)) as source, av.open(str(whole), "w") as target:
        stream = target.add_stream_from_template(source.streams.video[0])
        for packet in source.demux(source.streams.video[0]):
            if packet.dts is not None:
                packet.stream = stream
                target.mux(packet)
    data = whole.read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(data[:len(data) // 2])
    out = tmp_path / "results"
    run = process(cut, out)
    code, stderr = run.wait(timeout=300), run.stderr.read()
    assert code == 2 and "INPUT INCOMPLETE" in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1, stderr
    frames = {int(line.split(",")[0]) for line in
              (out / "spots.csv").read_text().splitlines()[1:]}
    assert 3 <= len(frames) < 30 and frames == set(range(len(frames))), sorted(frames)
    assert "INCOMPLETE" in (out / "analysis.json").read_text()


@pytest.mark.ros
def test_ctrl_c_during_the_demos_graph_is_an_interruption_not_a_failure(tmp_path: Path) -> None:
    """Ctrl-C (SIGINT to the terminal's process group) while the graph runs: exit 130, said
    in one line, no export or analysis of a partial run."""
    demo = interruptible([SDS, "demo", "--seconds", "1", "--out", str(tmp_path)],
                         start_new_session=True)
    assert demo.stdout is not None and demo.stderr is not None
    for line in demo.stdout:
        if line.startswith("running the graph"):
            break
    time.sleep(5.0)
    os.killpg(demo.pid, signal.SIGINT)
    code = demo.wait(timeout=120)
    stderr = demo.stderr.read()
    assert code == 130, stderr
    assert "sds demo: interrupted: no results and no analysis written" in stderr, stderr
    assert not (tmp_path / "results").exists() and not (tmp_path / "analysis").exists()
    assert "FRAMES MISSING" not in demo.stdout.read()
