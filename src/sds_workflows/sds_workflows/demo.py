"""`sds demo` and `sds run`: the whole measuring chain on a simulated drop or a real video, then
the result files, the Rerun file and the analysis.

The chain itself runs as node processes through a `ChainRunner` the caller gives
(`sds_bringup.chain.run_chain`: the workflows start no graph of their own). The Rerun file is
written from the recording once the graph is done: complete, where the live viewer's
best-effort subscriptions may skip frames. The demo simulates a drop, has the runner feed the
simulator's Arduino stream through a pseudo-terminal, and compares the analysis with the
simulator's truth.
"""

from __future__ import annotations

import csv
import multiprocessing
import shutil
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from sds_lateral.clock import LateralClock
from sds_model.errors import InputError
from sds_model.paths import CONFIG
from sds_model.rig import Rig, load_rig
from sds_model.staging import staged_folder
from sds_recon.results import ResultsWriter, load_results, refuse_results
from sds_record.mcap_files import holds_messages, message_counts, not_recorded
from sds_sim.imaging import merged
from sds_sim.scenario import Scenario, load_scenario
from sds_sim.simulate import SimulationOutput, simulate
from sds_sloshing.analysis import AnalysisOptions
from sds_sloshing.report import summary_lines, truth_from_run
from sds_sloshing.surface_series import RecordingError
from sds_tracker.path_scatter import SigmaCheck
from sds_viz.from_mcap import mcap_to_rrd

from sds_workflows.demo_rig import DemoRig, calibrate_demo_rig, draw_demo_rig
from sds_workflows.export import export_recording
from sds_workflows.lateral import (
    LateralInput,
    LateralRun,
    LateralSetup,
    link_side_clock,
    place_lateral,
    process_lateral,
)
from sds_workflows.pipeline import damping_caveat
from sds_workflows.rig_calibration import FRAMES_PER_STILL
from sds_workflows.run_tables import RunTables, finish_analysis

VIDEO_TOPIC = "/camera/video"
"""The camera's packets in a recording of the drop graph (config/graphs/drop.yaml)."""
SPOTS_TOPIC = "/tracker/spots"
SIDE_IMAGE_TOPIC = "/lateral/image"
"""The side camera's frames (config/graphs/lateral.yaml)."""

DEMO_SCENARIO = CONFIG / "scenarios" / "drop_4p7s.yaml"
LED_ROI_HALF_PX = 12


class ChainOutputs(Protocol):
    """Where a chain's run put its files, and how its graph ended."""

    @property
    def recording(self) -> Path: ...
    @property
    def rerun(self) -> Path: ...
    @property
    def log(self) -> Path: ...
    @property
    def failure(self) -> str | None:
        """The needed node that failed and why (None if none did)."""
    @property
    def interrupted(self) -> bool:
        """Whether Ctrl-C (or SIGTERM) stopped the graph."""


class ChainRunner(Protocol):
    """Runs the measuring chain with graph overrides until `expected_frames` were tracked
    (None: until Ctrl-C), feeding `serial_lines` to a stand-in Arduino at `port` if given,
    with the nodes of the extra graph files `graphs` (config/graphs/, e.g. lateral.yaml),
    and until the recorder has written the `side_frames` of lateral.yaml's file if given."""

    def __call__(self, overrides: list[str], out: Path, expected_frames: int | None,
                 serial_lines: list[bytes] | None = None, port: Path | None = None,
                 graphs: tuple[str, ...] = (), side_frames: int | None = None
                 ) -> ChainOutputs: ...


def height_errors(truth_spots: Path, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Measured minus true height [mm] of every spot point with a truth, and each one's own
    σ (sigma_Z_mm)."""
    truth = {}
    with truth_spots.open() as file:
        for row in csv.DictReader(file):
            if row["visible"] == "1":
                truth[(int(row["frame"]), int(row["laser_id"]))] = float(row["Z_mm"])
    kept = [p for p in points if (int(p["frame"]), int(p["laser_id"])) in truth]
    return (np.array([p["Z_mm"] - truth[(int(p["frame"]), int(p["laser_id"]))] for p in kept]),
            np.array([p["sigma_Z_mm"] for p in kept]))


def hidden_points(truth_spots: Path, points: np.ndarray) -> int:
    """How many spot points were measured where the truth says their spot was hidden (a
    drop-out, outside the image): each one is made of something else's light."""
    with truth_spots.open() as file:
        hidden = {(int(row["frame"]), int(row["laser_id"])) for row in csv.DictReader(file)
                  if row["visible"] != "1"}
    return sum((int(p["frame"]), int(p["laser_id"])) in hidden for p in points)


@dataclass(frozen=True)
class SideCheck:
    """The side camera's check of a run's top surface (`sds run --lateral`): its placed view,
    the top video and the clock link measured before the run."""

    setup: LateralSetup
    top_video: Path
    clock: LateralClock | None


@dataclass(frozen=True)
class AnalysedRun:
    """What `analyse_run` gave: the analysis's results, and the side camera's check (None
    without one) or why it failed."""

    results: dict[str, Any]
    side: LateralRun | None = None
    side_failure: str = ""
    sigma_check: SigmaCheck | None = None   # the spots' own check of their σ


def analyse_run(recording: Path, rig: Rig, out: Path, options: AnalysisOptions,
                truth_run: Path | None = None, overwrite: bool = True,
                side: SideCheck | None = None) -> AnalysedRun:
    """Result files (out/results), the analysis report (out/analysis) and, with `side`, the
    side camera's check of the top surface, from the recording (`sds export`'s, in two reads);
    the Rerun file beside the recording (every frame). The run's own folder `out` gets them in
    one commit (`staging.staged_folder`): a kill leaves the earlier run's whole, never a mix
    (an earlier run's results are replaced: the caller checked `overwrite`)."""
    mcap_to_rrd(recording, recording.with_suffix(".rrd"), rig)
    if not overwrite:
        refuse_results(out / "results")
    side_run, side_failure = None, ""
    with staged_folder(out, ("results", "analysis")) as staging:
        results, report = staging / "results", staging / "analysis"
        results.mkdir()
        report.mkdir()
        tables = RunTables(ResultsWriter(results), rig)
        export_recording(recording, rig, tables)
        truth = truth_from_run(truth_run) if truth_run else None
        analysis = finish_analysis(tables, str(recording), report, options, truth)
        if analysis.results is None:
            raise RecordingError(analysis.note)
        if side is not None:
            try:   # a side camera that fails costs the top camera's results nothing
                side_run = process_lateral(side.setup, rig, side.top_video, results,
                                           progress=False, report=report, clock=side.clock)
            except InputError as error:
                side_failure = str(error)
    if analysis.note:
        print(f"sds: {analysis.note}")
    return AnalysedRun(analysis.results, side_run, side_failure, analysis.sigma_check)


def interrupted(command: str, outputs: ChainOutputs) -> int:
    """Say that the run was interrupted (no results, no analysis) and what it kept; the exit
    code of an interruption."""
    kept = (f"the recording so far is in {outputs.recording}" if outputs.recording.is_file()
            else "nothing was recorded")
    print(f"{command}: interrupted: no results and no analysis written; {kept}",
          file=sys.stderr)
    return 130


def simulate_drop(scenario: Scenario, out: Path, as_built: bool, progress: bool = True
                  ) -> SimulationOutput:
    """Simulate the demo's drop into `out`/simulation, saying what it renders."""
    print(f"simulating '{scenario.name}': {scenario.duration_s:g} s, {scenario.frame_count} "
          f"frames at {scenario.rig.camera.width_px}x{scenario.rig.camera.height_px}"
          + (", the rig as built with a real camera's imaging" if as_built else ""), flush=True)
    return simulate(scenario, out / "simulation", progress=progress)


def run_demo(out: Path, seconds: float | None, run_chain: ChainRunner,
             exact_rig: bool = False) -> int:
    """Simulate a drop, run the whole chain on it, analyse, print the summary. The drop is
    rendered with a rig as built (while its table's images are) and measured with the rig
    file the calibration protocol gave (`demo_rig`); with `exact_rig`, rendered and measured
    with the scenario's own rig file."""
    out.mkdir(parents=True, exist_ok=True)
    overrides = {} if seconds is None else {"duration_s": seconds}
    scenario = load_scenario(DEMO_SCENARIO, overrides)
    built = None
    if exact_rig:
        simulation = simulate_drop(scenario, out, as_built=False)
    else:
        folder = out / "calibration"
        if folder.exists():   # the demo's own folder: its earlier calibration is replaced
            shutil.rmtree(folder)
        folder.mkdir()
        print(f"calibrating a rig as built ({folder}): sds calibrate plan, the tilt table's "
              "images, sds calibrate rig", flush=True)
        drawn = draw_demo_rig(scenario, folder)
        scenario = replace(load_scenario(DEMO_SCENARIO, merged(overrides,
                                                               drawn.scenario_overrides)),
                           rig=drawn.true)
        # The drop needs only the true rig: it is rendered in a second process while the
        # table's images are, so that the two share the machine's cores.
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            drop = pool.submit(simulate_drop, scenario, out, as_built=True, progress=False)
            built = calibrate_demo_rig(drawn, folder)
            simulation = drop.result()
    rig_file = built.calibrated_file if built else scenario.rig_file.resolve()
    rig = load_rig(rig_file)
    led_x, led_y = (int(v) for v in scenario.events.led_position_px)
    half = LED_ROI_HALF_PX
    port = (out / "ttyARDUINO").resolve()
    serial_lines = simulation.serial.read_bytes().splitlines(keepends=True)
    camera_model = [] if rig.camera_file is None else [f"camera.camera_model={rig.camera_file}"]
    # The watcher ends the demo's graph once every frame and the Arduino's last line are in.
    outputs = run_chain(["recorder.overwrite=true", "camera.linger_s=60.0",
                         f"camera.source={simulation.video.resolve()}",
                         f"camera.roi={list(rig.container_region_px(rig.camera))}",
                         *camera_model,
                         f"camera.led_roi={[led_x - half, led_y - half, 2 * half, 2 * half]}",
                         f"tracker.rig={rig_file}", f"recon.rig={rig_file}",
                         f"viewer.rig={rig_file}", f"arduino.port={port}"],
                        out, scenario.frame_count, serial_lines, port, graphs=("arduino.yaml",))
    if outputs.interrupted:
        return interrupted("sds demo", outputs)
    if outputs.failure or not outputs.recording.is_file():
        print(f"demo failed: {outputs.failure or 'no recording'} (see {outputs.log})",
              file=sys.stderr)
        return 1
    analysed = analyse_run(outputs.recording, rig, out, AnalysisOptions(
        gravity_m_s2=scenario.gravity, damping_caveat=damping_caveat(simulation.video)),
        simulation.run)
    return print_summary(out, scenario, simulation, outputs, analysed, built)


def print_summary(out: Path, scenario, simulation, outputs: ChainOutputs,
                  analysed: AnalysedRun, built: DemoRig | None = None) -> int:
    """The demo's summary: the rig's calibration (with `built`), files, modes against the
    truth, heights, spots and their own check of their σ, the Arduino."""
    results = load_results(out / "results")
    spots, points = results.spots, results.points
    if spots is None or points is None:
        print(f"demo failed: no spots or points in {out / 'results'}", file=sys.stderr)
        return 1
    frames = len(set(spots["frame"].tolist()))
    errors, sigmas = height_errors(simulation.spots, points[points["laser_id"] != 65535])
    print(f"\nSDS demo: '{scenario.name}', {scenario.frame_count} frames "
          f"({scenario.duration_s:g} s at {scenario.fps:g} fps, "
          f"{scenario.rig.camera.width_px}x{scenario.rig.camera.height_px})")
    if built is not None:
        record = built.calibrated.calibration or {}
        check, unseen = record["model_check"], record["unseen_surfaces"]
        print(f"  rig as built       calibrated by the protocol: {len(built.images)} table "
              f"images, {len(built.images) // FRAMES_PER_STILL} positions "
              f"({built.surfaces_csv.name} from sds calibrate plan), {built.calibrated_file}")
        print(f"    chi2/dof         {check['chi2_per_dof']:.2f} (expected "
              f"{check['expected'][0]:.2f}–{check['expected'][1]:.2f}: "
              + ("the model explains the images)" if check["explained"]
                 else "THE MODEL DOES NOT EXPLAIN THE IMAGES; see the rig report)"))
        print(f"    unseen surfaces  the rig report states tilt ± {unseen['tilt_sigma_deg']:.3f} "
              f"deg, heights ± {unseen['height_sigma_mm']:.3f} mm (the plan predicted tilt ± "
              f"{built.planned_tilt_sigma_deg:.3f} deg)")
        print("\n".join(f"    {line}" for line in built.against_truth()))
    print(f"  recording (MCAP)   {outputs.recording}")
    print(f"  Rerun              {outputs.rerun}   (open: rerun {outputs.rerun.name})")
    print(f"  report             {out / 'analysis' / 'report.html'}")
    print(f"  result files       {out / 'results'}/ (spots, points, line, fits, imu, tof .csv)")
    print(f"  frames processed   {frames} of {scenario.frame_count}; "
          f"{live_coverage(outputs.recording)}")
    lost = not_recorded_line(outputs.recording)
    if lost is not None:
        print(f"  NOT RECORDED       {lost}")
    print(f"  heights            RMSE {np.sqrt(np.mean(errors**2)):.3f} mm against the truth "
          f"({len(errors)} points; their own σ RMS {np.sqrt(np.mean(sigmas**2)):.3f} mm, "
          f"error/σ RMS {np.sqrt(np.mean((errors / sigmas) ** 2)):.2f})")
    flags = {name: int(np.sum(spots["flags"] & bit != 0)) for name, bit in (
        ("lost", 1), ("saturated", 2), ("reflection suspected", 4), ("off path", 8),
        ("Hampel-replaced", 16))}
    print(f"  spots              {len(spots)} ({len(spots) // max(frames, 1)} per frame): "
          + ", ".join(f"{count} {name}" for name, count in flags.items()))
    if analysed.sigma_check is not None:
        print(f"    σ check          {analysed.sigma_check.line()}")
    for line in arduino_lines(outputs.log.read_text()):
        print(f"  {line}")
    print("  sloshing (the report has every method; errors against the simulator's truth):")
    for line in summary_lines(analysed.results):
        if any(key in line for key in ("matrix_pencil", " tof ", "no oscillation", "note:")):
            print(f"    {line}")
    complete = frames == scenario.frame_count
    print("  result             " + ("FRAMES MISSING" if not complete else
                                     "MESSAGES NOT RECORDED" if lost is not None else
                                     "every frame measured"))
    return 0 if complete and lost is None else 1


def run_live(source: str, rig_file: Path, out: Path, port: str | None,
             gravity: float | None, run_chain: ChainRunner, overwrite: bool = False,
             lateral: LateralInput | None = None) -> int:
    """`sds run`: a video file or a camera through the whole chain (with the Arduino's bridge
    at `port`, None: without it), then the analysis (the caller checked `overwrite` against
    an earlier run in `out`). With `lateral`, the side camera's video runs beside it
    (config/graphs/lateral.yaml: recorded, shown), and after the run its wall profile checks
    the top surface (`sds process --lateral`'s files). Exit code 2 (INCOMPLETE) when a source
    it was asked for gave nothing: the Arduino, the side camera's check."""
    rig = load_rig(rig_file)
    is_file = Path(source).is_file()
    frames = _video_frames(Path(source), rig) if is_file else None
    side = place_lateral(lateral, rig) if lateral is not None else None
    out.mkdir(parents=True, exist_ok=True)
    overrides = [f"recorder.overwrite={str(overwrite).lower()}", f"camera.source={source}",
                 f"camera.roi={list(rig.container_region_px(rig.camera))}",
                 f"tracker.rig={rig_file.resolve()}", f"recon.rig={rig_file.resolve()}",
                 f"viewer.rig={rig_file.resolve()}"]
    if rig.camera_file is not None:   # the recorded camera_model then carries the intrinsics
        overrides.append(f"camera.camera_model={rig.camera_file}")
    graphs: tuple[str, ...] = ()
    if port is not None:
        graphs += ("arduino.yaml",)
        overrides.append(f"arduino.port={port}")
    clock, side_frames = None, None
    if side is not None:
        graphs += ("lateral.yaml",)
        side_source = side.inputs.video
        overrides += [f"lateral.source={side_source.resolve()}",
                      f"lateral.camera_model={side.view.camera_file}",
                      f"lateral.led_roi={list(side.view.led_roi_px)}"]
        if side.inputs.top_led_roi is not None:
            overrides.append(f"camera.led_roi={list(side.inputs.top_led_roi)}")
        if is_file:   # the side file plays on the top camera's clock
            clock = link_side_clock(side, rig, Path(source))
            print(f"sds run: {clock.summary()}")
            overrides.append(f"lateral.stamp_offset_s={clock.offset_s}")
            side_frames = _announced_frames(side_source)
    outputs = run_chain(overrides, out, frames, graphs=graphs, side_frames=side_frames)
    if outputs.interrupted and is_file:   # a live camera's run ends with Ctrl-C
        return interrupted("sds run", outputs)
    if outputs.failure or not outputs.recording.is_file():
        kept = f"; the recording keeps what came before: sds process --mcap " \
            f"{outputs.recording} --rig {rig_file} --out DIR" \
            if outputs.recording.is_file() and holds_messages(outputs.recording) else ""
        print(f"sds run: {outputs.failure or 'no recording'} (see {outputs.log}){kept}",
              file=sys.stderr)
        return 1   # the graph failed: its cause is said (a process the stop then killed is not)
    check = SideCheck(side, Path(source), clock) if side is not None and is_file else None
    analysed = analyse_run(outputs.recording, rig, out, AnalysisOptions(
        gravity_m_s2=gravity, damping_caveat=damping_caveat(Path(source)) if is_file else ""),
        side=check)
    print(f"\nSDS run: {source}\n  recording {outputs.recording}\n  Rerun {outputs.rerun}\n"
          f"  report {out / 'analysis' / 'report.html'}\n  results {out / 'results'}/\n"
          f"  frames {live_coverage(outputs.recording)}")
    if analysed.sigma_check is not None:
        print(f"  spots' σ check: {analysed.sigma_check.line()}")
    for line in summary_lines(analysed.results):
        print(f"    {line}")
    missing = []
    if port is not None and not _rows(out / "results" / "imu.csv"):
        missing.append(f"the Arduino at {port} sent no record (no imu.csv, no ToF; see "
                       f"{outputs.log})")
    if side_frames is not None:
        recorded = message_counts(outputs.recording, [SIDE_IMAGE_TOPIC])[SIDE_IMAGE_TOPIC]
        print(f"  side camera: {recorded} of its {side_frames} frames recorded")
        if recorded < side_frames:
            missing.append(f"{side_frames - recorded} side frames are not in the recording "
                           f"(see {outputs.log})")
    if analysed.side is not None:
        print("\n".join(f"  {line}" for line in analysed.side.lines()))
    elif analysed.side_failure:
        missing.append(f"side camera not compared: {analysed.side_failure}")
    elif side is not None:
        print(f"  side camera: recorded ({SIDE_IMAGE_TOPIC}); its check of the top surface "
              "needs the two videos: sds process --video TOP --lateral SIDE ...")
    if port is not None:
        for line in arduino_lines(outputs.log.read_text()):
            print(f"  {line}")
            if line.startswith(HOST_CLOCK):
                print(f"sds run: note: {line.removeprefix(HOST_CLOCK).strip()}",
                      file=sys.stderr)
    lost = not_recorded_line(outputs.recording)
    if lost is not None:
        missing.append(f"not recorded: {lost} (see {outputs.log})")
    for line in missing:
        print(f"sds run: INCOMPLETE: {line}", file=sys.stderr)
    return 2 if missing else 0


def live_coverage(recording: Path) -> str:
    """How many of the frames the camera sent were measured live and whether the recording
    holds them all (its packets): one line for a run's summary."""
    counts = message_counts(recording, (VIDEO_TOPIC, SPOTS_TOPIC))
    measured, sent = counts[SPOTS_TOPIC], counts[VIDEO_TOPIC]
    if not sent:
        return f"{measured} measured live (the recording holds the frames it measured)"
    if measured >= sent:
        return f"all {sent} measured live; the recording holds every one (its packets)"
    return (f"{measured} of {sent} measured live (the others were shed: the machine could not "
            f"decode and measure them in time); the recording holds all {sent}: "
            f"`sds process --mcap {recording} --rig RIG --out DIR` measures them all")


HOST_CLOCK = "clocks             NOT ALIGNED:"
"""How a summary's clock line starts when the Arduino's stamps stayed on the host clock."""


def arduino_lines(log_text: str) -> list[str]:
    """What the Arduino's bridge said of a run in the graph's log, as summary lines: its
    final counts, and the clock its stamps are on (the camera's, from the sync LED; or the
    host's, when the LED was not seen in time: then its times are not the video's)."""
    lines = log_text.splitlines()
    final = [line.split("final: ")[1] for line in lines if "final: records" in line]
    offset = [line.split("LED offset ")[1] for line in lines if "LED offset" in line]
    said = [f"Arduino            {final[-1]}"] if final else []
    if offset:
        said.append(f"clocks             camera vs Arduino, from the sync LED: {offset[-1]}")
    elif any("no sync LED seen" in line for line in lines):
        said.append(f"{HOST_CLOCK} no sync LED seen: the Arduino's stamps are on the host "
                    "clock, not the camera's (its records are not on the frames' times)")
    return said


def not_recorded_line(recording: Path) -> str | None:
    """The messages the graph published that its recorder never got (`not_recorded`), one
    line for a run's summary; None when it got every one."""
    counts = not_recorded(recording)
    if not counts:
        return None
    return (", ".join(f"{count} of {topic}" for topic, count in sorted(counts.items()))
            + " (published before the recorder subscribed, or lost on the way)")


def _announced_frames(video: Path) -> int:
    """The frames a video file announces (the side camera's)."""
    from contextlib import closing

    from sds_camera.frame_source import VideoFileSource

    with closing(VideoFileSource(video)) as source:
        return source.announced_frames


def _video_frames(video: Path, rig: Rig) -> int:
    """The frames a video announces, once its frame size is known to be the rig camera's
    (before the graph: its processes take seconds to start and then fail on the same)."""
    from contextlib import closing

    from sds_camera.frame_source import VideoFileSource

    with closing(VideoFileSource(video)) as source:
        camera = rig.camera
        if (source.width, source.height) != (camera.width_px, camera.height_px):
            raise InputError(f"{video} is {source.width}x{source.height} px, the rig's camera "
                             f"{camera.width_px}x{camera.height_px}: another rig file (--rig), "
                             "or the video of this rig")
        return source.announced_frames


def _rows(table: Path) -> int:
    """How many data rows a result table holds (0 when it is absent)."""
    if not table.is_file():
        return 0
    with table.open() as file:
        return max(sum(1 for _ in file) - 1, 0)
