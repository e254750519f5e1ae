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
from sds_model.errors import InputError
from sds_model.staging import STAGING_PREFIX, recover, staged_file, staged_folder
from sds_record.mcap_files import McapRecorder, holds_messages
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


def dead_pid() -> int:
    """The id of a process that has ended."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_kill_at_any_point_of_the_commit_leaves_one_whole_run(tmp_path: Path) -> None:
    """The commit is one swap of folders: killed after the new folder was made ready, the next
    run completes it; killed after the old was moved aside, it is restored (or the ready one
    put in its place). Either way one run, whole, and the leftovers named and removed."""
    pid = dead_pid()
    target = tmp_path / "out"
    # Killed between "move the old aside" and "the new into place": both exist beside it.
    (tmp_path / f".sds-old-{pid}-out").mkdir()
    (tmp_path / f".sds-old-{pid}-out" / "points.csv").write_text("old")
    (tmp_path / f".sds-ready-{pid}-out").mkdir()
    (tmp_path / f".sds-ready-{pid}-out" / "points.csv").write_text("new")
    (tmp_path / f"{STAGING_PREFIX}{pid}-other").mkdir()   # a dead run's unfinished output
    done = recover(tmp_path)
    assert (target / "points.csv").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert len(done) == 3 and any("completed the commit" in line for line in done)
    # Killed before the ready folder existed: the old one comes back.
    target.rename(tmp_path / f".sds-old-{pid}-out")
    (tmp_path / f"{STAGING_PREFIX}{pid}-out").mkdir()
    done = recover(tmp_path)
    assert (target / "points.csv").read_text() == "new" and len(done) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    # A live process's staging (this one's) is left alone.
    (tmp_path / f"{STAGING_PREFIX}{os.getpid()}-busy").mkdir()
    assert recover(tmp_path) == [] and (tmp_path / f"{STAGING_PREFIX}{os.getpid()}-busy").exists()


def test_the_next_run_names_and_removes_a_dead_runs_staging(tmp_path: Path) -> None:
    """`sds process` into a folder beside a killed run's staging folder: the staging is named
    on the console and removed."""
    stale = tmp_path / f"{STAGING_PREFIX}{dead_pid()}-out"
    stale.mkdir()
    (stale / "points.csv").write_text("half")
    done = subprocess.run([SDS, "process", "--video", str(tmp_path / "nope"), "--rig", RIG,
                           "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2   # refused before any work: nothing is touched
    assert stale.exists()
    with staged_folder(tmp_path / "out", []) as staging:
        (staging / "points.csv").write_text("whole")
    assert not stale.exists() and (tmp_path / "out" / "points.csv").read_text() == "whole"


def test_files_beside_the_results_are_kept_by_links_not_copies(tmp_path: Path) -> None:
    """A run's folder with its recording: the commit keeps it (the same file, not a copy of
    gigabytes) and replaces only the results."""
    target = tmp_path / "run"
    (target / "results").mkdir(parents=True)
    (target / "results" / "points.csv").write_text("old")
    (target / "recording.mcap").write_bytes(b"recording")
    inode = (target / "recording.mcap").stat().st_ino
    with staged_folder(target, ["results", "analysis"]) as staging:
        (staging / "results").mkdir()
        (staging / "results" / "points.csv").write_text("new")
    assert (target / "results" / "points.csv").read_text() == "new"
    assert (target / "recording.mcap").stat().st_ino == inode
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_recording_without_messages_does_not_block_the_retry(tmp_path: Path) -> None:
    """What a graph that never started leaves (an MCAP without a message) is replaced without
    --overwrite; a recording with messages, or a file that is no recording, is not."""
    path = tmp_path / "recording.mcap"
    McapRecorder(path).close()
    assert not holds_messages(path)
    recorder = McapRecorder(path)
    recorder.add_topic("/t", "std_msgs/msg/Header")
    recorder.write("/t", b"\x00\x01\x00\x00" + bytes(12), 1, 1)
    recorder.close()
    assert holds_messages(path)
    with pytest.raises(InputError, match="overwrite"):
        McapRecorder(path)
    other = tmp_path / "notes.mcap"
    other.write_text("someone's data")
    assert holds_messages(other)
    with pytest.raises(InputError):
        McapRecorder(other)


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
    demo = interruptible([SDS, "demo", "--exact-rig", "--seconds", "1", "--out", str(tmp_path)],
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


def test_ctrl_c_while_the_demo_calibrates_and_renders_leaves_no_process(tmp_path: Path) -> None:
    """Ctrl-C while the demo renders and calibrates the table's images, its drop rendered in
    a second process meanwhile: exit 130, said in one line, and no process of the demo's
    (the drop's renderer, its encoder) is left running."""
    demo = interruptible([SDS, "demo", "--seconds", "1", "--out", str(tmp_path)],
                         start_new_session=True)
    assert demo.stdout is not None and demo.stderr is not None
    for line in demo.stdout:
        if line.startswith("simulating"):   # the drop's process has started
            break
    time.sleep(2.0)
    os.killpg(demo.pid, signal.SIGINT)
    code = demo.wait(timeout=60)
    stderr = demo.stderr.read()
    assert code == 130 and stderr == "sds: interrupted\n", stderr
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            os.killpg(demo.pid, 0)   # a process of the demo's group is still there
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.killpg(demo.pid, signal.SIGKILL)
        pytest.fail("a process of the demo outlived it")
    assert not (tmp_path / "results").exists()


def test_a_report_that_fails_half_way_leaves_no_result(kick: SimulationOutput, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A fault while the report is written (after analysis.json, before report.html) is the
    program's: it is raised, and no folder claims a result (the analysis once caught every
    ValueError as "no analysis" and left analysis.json and modes.png, exit 0)."""
    import sds_workflows.run_tables as run_tables
    from sds_model.rig import load_rig
    from sds_workflows.process import process_video

    def half_a_report(analysis, out: Path, truth=None):
        (out / "analysis.json").write_text("{}")
        raise ValueError("a figure failed")

    monkeypatch.setattr(run_tables, "write_report", half_a_report)
    out = tmp_path / "results"
    with pytest.raises(ValueError, match="a figure failed"):
        process_video(kick.video, load_rig(RIG), out, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_ctrl_c_that_compiled_code_turns_into_another_error_is_an_interruption(
        tmp_path: Path) -> None:
    """matplotlib's Agg renderer, drawing a report's figure when Ctrl-C came, caught the
    KeyboardInterrupt and raised `ValueError: Invalid bounding box` with no cause: `sds
    process` said "internal error" and exited 1 (the test above, once). A command's error
    after a Ctrl-C is the interruption: one line, exit code 130, no crash log."""
    script = (
        "import argparse, os, signal\n"
        "from sds_cli import cli\n"
        "def draw(args):\n"
        "    try:\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "        signal.pause()\n"
        "    except KeyboardInterrupt:\n"
        "        pass\n"
        "    raise ValueError('Invalid bounding box')\n"
        "class Parser:\n"
        "    def parse_args(self, argv):\n"
        "        return argparse.Namespace(command='process', run=draw)\n"
        "cli.build_parser = Parser\n"
        "cli.main([])\n")
    state = tmp_path / "state"
    run = interruptible([sys.executable, "-c", script],
                        env={**os.environ, "XDG_STATE_HOME": str(state)})
    _, stderr = run.communicate(timeout=60)
    assert run.returncode == 130, stderr
    assert stderr.strip() == "sds: interrupted", stderr
    assert not (state / "sds").exists()
