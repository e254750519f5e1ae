"""`sds process`: videos and recordings measured in one process, no ROS graph.

`process_video` and `process_recording` run the one per-frame pipeline (`pipeline.FramePipeline`,
the graph's own code and parameters) over a video's or a recording's frames and write the result
files and the analysis report; `process_inputs` does so for several inputs in parallel, one
result folder each; `calibrate_from_images` self-calibrates the rig first (`--calibrate-lasers`).
"""

from __future__ import annotations

import multiprocessing
import sys
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from sds_camera.camera_imu import read_camera_imu
from sds_camera.frame_source import FrameSourceError
from sds_model.errors import InputError
from sds_model.rig import Rig, load_rig
from sds_model.staging import staged_folder
from sds_recon.calibration.rig_calibration import RigCalibration
from sds_recon.results import ResultsWriter, refuse_results
from sds_record.recorded_series import read_accelerations, recording_rig
from sds_sloshing.analysis import AnalysisOptions
from sds_sloshing.report import summary_lines
from tqdm import tqdm

from sds_workflows.lateral import (
    LateralInput,
    LateralRun,
    place_lateral,
    process_lateral,
)
from sds_workflows.pipeline import (
    FramePipeline,
    RedFrame,
    damping_caveat,
    mcap_frames,
    video_frames,
)
from sds_workflows.rig_calibration import calibrate_rig
from sds_workflows.run_tables import RUN_FILES, RunAnalysis, RunTables, finish_analysis


@dataclass
class FramesRead:
    """How the input's frames ended: `broken` is the reader's error when it failed after
    some frames (a truncated or corrupt video), the frames before it being processed."""

    broken: str = ""


def _until_broken(frames: Iterable[RedFrame], ending: FramesRead) -> Iterator[RedFrame]:
    """The frames up to a reader failure, which is noted in `ending` instead of raised once a
    frame has come (none at all: the failure is raised)."""
    count = 0
    try:
        for frame in frames:
            count += 1
            yield frame
    except FrameSourceError as error:
        if count == 0:
            raise
        ending.broken = str(error)


def process_frames(frames: Iterable[RedFrame], rig: Rig, tables: RunTables,
                   progress: bool = True, stills: bool = False) -> tuple[int, FramesRead]:
    """Every frame through the pipeline into `tables` (`stills`: each frame on its own, no
    temporal filter); the number of frames and how the input ended (a video that breaks
    after some frames keeps their results)."""
    pipeline = FramePipeline(rig, stills=stills)
    ending = FramesRead()
    count = 0
    frames = tqdm(_until_broken(frames, ending), desc="frames", unit="frame",
                  disable=not progress)
    for step in pipeline.run(frames):
        tables.add_step(step)
        count += step.line is not None
    return count, ending


@dataclass(frozen=True)
class ProcessedRun:
    """What processing one input gave: its frames, the result folder and the analysis."""

    source: Path
    out: Path
    frames: int
    analysis: RunAnalysis
    broken: str = ""   # the reader's error when the input broke off after `frames` frames
    lateral: LateralRun | None = None   # the side camera, where one was given
    lateral_failure: str = ""   # why the side camera gave nothing (the top's results stand)

    @property
    def incomplete(self) -> bool:
        """Whether part of the input gave no results (a broken video, no analysis, a side
        camera that failed)."""
        return bool(self.broken or self.lateral_failure or self.analysis.results is None)

    def summary(self) -> str:
        """The console's lines: the run, then the side camera's."""
        note = self.analysis.note
        return (f"sds process: {self.frames} frames of {self.source} -> {self.out}"
                + (f" ({note})" if note else "")
                + (f"; INPUT INCOMPLETE, results cover the frames read: {self.broken}"
                   if self.broken else "")
                + (f"; SIDE CAMERA NOT COMPARED: {self.lateral_failure}"
                   if self.lateral_failure else "")
                + "".join(f"\nsds process: {line}" for line in
                          (self.lateral.lines() if self.lateral else [])))

    def sigma_check_line(self) -> str:
        """The spots' own check of their σ as the console says it, a result like the
        frequencies, also for an incomplete run ("" without one)."""
        check = self.analysis.sigma_check
        return f"sds process: {self.source}: spots' σ check: {check.line()}" if check else ""

    def result_lines(self) -> list[str]:
        """The analysis's frequencies and damping ratios, as `sds run` and `sds analyze` print
        them (none without an analysis)."""
        return [f"    {line}" for line in summary_lines(self.analysis.results)] \
            if self.analysis.results else []


def process_video(video: Path, rig: Rig, out: Path, fps: float = 0.0,
                  gravity_m_s2: float | None = None, overwrite: bool = False,
                  progress: bool = True, stills: bool | None = None,
                  lateral: LateralInput | None = None) -> ProcessedRun:
    """A video (or an image folder at `fps`) taken with `rig`: result files, the camera's own
    IMU where the video has one, the analysis report, all in `out` (refused if it holds
    results, unless `overwrite`). `stills` (default: for an image folder) tracks each image on
    its own: images of different surfaces are no video, and a temporal filter across them
    would replace right spots. With `lateral`, the side camera's wall profile and its check
    of the top surface (`lateral.process_lateral`) join them."""
    stills = video.is_dir() if stills is None else stills
    if not overwrite:
        refuse_results(out)
    side_setup = None
    if lateral is not None:
        if not lateral.video.is_file():
            raise InputError(f"{lateral.video}: no such video (the side camera's, --lateral)")
        side_setup = place_lateral(lateral, rig)
    caveat = damping_caveat(video)
    with staged_folder(out, RUN_FILES) as staging:
        tables = RunTables(ResultsWriter(staging), rig)
        count, ending = process_frames(video_frames(video, rig, fps), rig, tables, progress,
                                       stills)
        imu = read_camera_imu(video)
        if imu is not None:
            tables.add_camera_imu(imu)
        analysis = finish_analysis(tables, _source_name(video, ending), staging,
                                   AnalysisOptions(gravity_m_s2=gravity_m_s2,
                                                   damping_caveat=caveat))
        side, side_failure = None, ""
        if side_setup is not None:
            try:   # a side camera that fails costs the top camera's results nothing
                side = process_lateral(side_setup, rig, video, staging, progress)
            except InputError as error:
                side_failure = str(error)
    return ProcessedRun(video, out, count, analysis, ending.broken, side, side_failure)


def _source_name(source: Path, ending: FramesRead) -> str:
    """The source as the report names it, flagged when it broke off."""
    return f"{source} (INCOMPLETE: {ending.broken})" if ending.broken else str(source)


def process_recording(recording: Path, out: Path, rig: Rig | None = None,
                      gravity_m_s2: float | None = None, overwrite: bool = False,
                      progress: bool = True) -> ProcessedRun:
    """A recording's camera frames tracked again (`rig` default: the one it carries), its
    accelerometers for the gravity regime: result files and the analysis report in `out`."""
    rig = rig if rig is not None else recording_rig(recording, None)
    if not overwrite:
        refuse_results(out)
    with staged_folder(out, RUN_FILES) as staging:
        tables = RunTables(ResultsWriter(staging), rig)
        count, ending = process_frames(mcap_frames(recording), rig, tables, progress)
        for topic, (time_s, accel_m_s2) in read_accelerations(recording).items():
            tables.add_accelerations(topic, time_s, accel_m_s2)
        analysis = finish_analysis(tables, _source_name(recording, ending), staging,
                                   AnalysisOptions(gravity_m_s2=gravity_m_s2))
    return ProcessedRun(recording, out, count, analysis, ending.broken)


def process_input(source: Path, is_video: bool, rig_file: Path | None, out: Path,
                  fps: float = 0.0, gravity_m_s2: float | None = None,
                  overwrite: bool = False, progress: bool = True, sequence: bool = False,
                  lateral: LateralInput | None = None) -> ProcessedRun:
    """One video (needs `rig_file`; `lateral`: its side camera) or recording (`rig_file`
    default: the one it carries); an image folder is stills unless `sequence` (a video's
    frames)."""
    if is_video:
        if rig_file is None:
            raise InputError(f"{source}: a video needs a rig file (the rig it was taken with)")
        return process_video(source, load_rig(rig_file), out, fps, gravity_m_s2, overwrite,
                             progress, stills=source.is_dir() and not sequence,
                             lateral=lateral)
    if lateral is not None:
        raise InputError(f"{source}: the side camera is processed with a top video "
                         "(--video), not a recording")
    return process_recording(source, out, recording_rig(source, rig_file), gravity_m_s2,
                             overwrite, progress)


def _process_in_worker(source: Path, is_video: bool, rig_file: Path | None, out: Path,
                       fps: float, gravity_m_s2: float | None, overwrite: bool,
                       sequence: bool) -> tuple[bool, str, str]:
    """One input in a worker process: (done, summary line or the failure's one line, the
    spots' σ check line or ""); an input that broke off is not done, though its frames'
    results are written."""
    try:
        processed = process_input(source, is_video, rig_file, out, fps, gravity_m_s2,
                                  overwrite, False, sequence)
        return not processed.incomplete, processed.summary(), processed.sigma_check_line()
    except InputError as error:
        return False, f"sds process: {source}: {error}", ""


def process_inputs(inputs: list[Path], is_video: bool, rig_file: Path | None, out: Path,
                   jobs: int, fps: float = 0.0, gravity_m_s2: float | None = None,
                   overwrite: bool = False, progress: bool = True, sequence: bool = False
                   ) -> int:
    """The inputs in parallel (`jobs` worker processes), one result folder each under `out`
    (out/<name>), one progress bar; every failure is reported, the others finish. Returns how
    many failed; a fault of the program (not of an input) is raised once all are done."""
    jobs = max(1, min(jobs, len(inputs)))
    failed, faults = 0, []
    # spawn: a fresh interpreter per worker (no forked threads of this one)
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(_process_in_worker, source, is_video, rig_file,
                               out / source.stem, fps, gravity_m_s2, overwrite, sequence): source
                   for source in inputs}
        with tqdm(total=len(inputs), desc="inputs", unit="file", disable=not progress) as bar:
            for future in as_completed(futures):
                try:
                    done, line, check = future.result()
                except Exception as error:   # the program's own fault: raised at the end
                    faults.append(error)
                    done, check = False, ""
                    line = (f"sds process: {futures[future]}: internal error "
                            f"({type(error).__name__}: {error})")
                failed += not done
                bar.write(line, file=sys.stdout if done else sys.stderr)
                if check:
                    bar.write(check, file=sys.stdout)
                bar.update()
    print(f"sds process: {len(inputs) - failed} of {len(inputs)} inputs processed into "
          f"{out}" + (f", {failed} failed (above)" if failed else ""))
    if faults:
        raise faults[0]
    return failed


def calibrate_from_images(rig: Rig, paths: list[Path], surfaces: Path, out: Path
                          ) -> tuple[Rig, Path, RigCalibration]:
    """Self-calibrate the rig from images of known surfaces or one tilt-table video, as `sds
    calibrate rig` does, into out/rig_calibrated.yaml (with its report and overlays)."""
    rig_path = out / "rig_calibrated.yaml"
    calibrated, result = calibrate_rig(rig, paths, surfaces, rig_path,
                                       "`sds process --calibrate-lasers`")
    return calibrated, rig_path, result
