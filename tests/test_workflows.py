"""The workflows as a notebook calls them: the public entry points and the one per-frame
pipeline give what the `sds` command gives."""

from __future__ import annotations

import filecmp
import html
import json
import subprocess
import sys
from pathlib import Path

import pytest
from sds_model.rig import load_rig
from sds_sim.scenario import load_scenario
from sds_sim.simulate import SimulationOutput, simulate
from sds_workflows.demo import HOST_CLOCK, arduino_lines
from sds_workflows.pipeline import PipelineStep, damping_caveat

from sds_workflows import FramePipeline, process_video, video_frames

RESULT_FILES = ("spots.csv", "points.csv", "line.csv", "fits.csv", "analysis.json")


@pytest.fixture(scope="module")
def kick(repo: Path, tmp_path_factory: pytest.TempPathFactory) -> SimulationOutput:
    """Half a second of the 1 g ground kick at 4K (15 frames)."""
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 0.5})
    return simulate(scenario, tmp_path_factory.mktemp("kick") / "sim", progress=False)


def test_process_video_writes_what_sds_process_writes(repo: Path, kick: SimulationOutput,
                                                      tmp_path: Path) -> None:
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    run = process_video(kick.video, load_rig(rig_file), tmp_path / "api", progress=False)
    done = subprocess.run([str(Path(sys.executable).with_name("sds")), "process", "--video",
                           str(kick.video), "--rig", str(rig_file), "--out",
                           str(tmp_path / "cli"), "--no-progress"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert run.frames == 15 and done.stdout.startswith(f"sds process: 15 frames of {kick.video}")
    # The spots' own check of their σ, as the API gives it (sds_tracker.path_scatter).
    check = run.analysis.sigma_check
    assert check is not None and check.spots == 20, check
    assert run.sigma_check_line() == \
        f"sds process: {kick.video}: spots' σ check: {check.line()}"
    assert run.sigma_check_line() in done.stdout.splitlines(), done.stdout
    recorded = json.loads((tmp_path / "cli" / "analysis.json").read_text())["spot_sigma_check"]
    assert recorded["scatter_over_sigma"] == check.scatter_over_sigma
    assert html.escape(check.line()) in (tmp_path / "cli" / "report.html").read_text()
    match, mismatch, errors = filecmp.cmpfiles(tmp_path / "api", tmp_path / "cli",
                                               RESULT_FILES, shallow=False)
    assert sorted(match) == sorted(RESULT_FILES), (mismatch, errors)


def test_a_compressed_video_puts_its_caveat_on_the_damping_ratios(kick: SimulationOutput,
                                                                   tmp_path: Path) -> None:
    """H.264 shrinks sub-pixel motion (bench/README.md): a video's analysis says so; images
    do not."""
    assert damping_caveat(kick.video).startswith("h264 video: compression shrinks sub-pixel")
    assert damping_caveat(tmp_path) == ""


def test_the_pipeline_gives_every_frame_once_in_order(repo: Path, kick: SimulationOutput
                                                      ) -> None:
    rig = load_rig(repo / "config" / "rigs" / "stelium.yaml")
    steps: list[PipelineStep] = list(FramePipeline(rig).run(video_frames(kick.video, rig)))
    lines = [step.line.index for step in steps if step.line is not None]
    spot_frames = [frame for step in steps for frame in step.spot_frames]
    assert lines == list(range(15))
    assert [frame.index for frame in spot_frames] == list(range(15))
    assert steps[-1].line is None   # the flush: what the Hampel window held
    # the window holds back the last frames until the flush, the first until it has filled
    assert steps[0].spot_frames == [] and steps[-1].spot_frames
    for frame in spot_frames:
        assert len(frame.spots) == len(rig.diodes) == len(frame.points.laser_ids)
        assert frame.fits.plane is not None and abs(frame.fits.plane.p00_mm) < 5.0


def test_a_runs_summary_says_which_clock_the_arduinos_stamps_are_on() -> None:
    """From the bridge's lines in the graph's log (as it writes them): its final counts, and
    the camera's clock with the LED's offset, or the host's, flagged, when the LED never
    came; nothing from a log without the bridge."""
    final = ("[arduino] [INFO] [1796614726.14] [arduino]: final: records 470, published 470, "
             "bad lines 0, noise bytes 0, missing records 0, reconnects 0")
    aligned = ("[arduino] [INFO] [1796614720.89] [arduino]: stamps on the camera's clock: "
               "LED offset -1.4539 s")
    unaligned = ("[arduino] [WARN] [1796614726.10] [arduino]: no sync LED seen within 30 s: "
                 "this run's Arduino stamps are on the host clock, not the camera's")
    counts = "Arduino            records 470, published 470, bad lines 0, noise bytes 0, " \
             "missing records 0, reconnects 0"
    assert arduino_lines(f"{aligned}\n{final}\n") == [
        counts, "clocks             camera vs Arduino, from the sync LED: -1.4539 s"]
    said = arduino_lines(f"{unaligned}\n{final}\n")
    assert said[0] == counts and said[1].startswith(HOST_CLOCK) and "host clock" in said[1]
    assert arduino_lines("[camera] [INFO] [1.0] [camera]: reading a file\n") == []
