"""`sds process`: the graph's tracker, reconstruction and analysis in one process, no graph.

Several videos or recordings (or a folder of them) are processed in parallel, one process per
core, one result folder each under --out, with one progress bar; a file that fails is named with
its reason and the others go on (exit code 2 if any failed).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from sds_cli.commands import (
    CommandError,
    add_lateral_options,
    add_overwrite,
    existing_file,
    existing_path,
    lateral_input,
    non_negative_float,
    output_folder,
    positive_float,
    positive_int,
)

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".m4v")


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds process`."""
    parser = commands.add_parser(
        "process", help="track, reconstruct and analyse videos or recordings, no ROS graph",
        description="Run the graph's tracker, reconstruction and analysis in one process (the "
                    "parameters of config/graphs/drop.yaml) and write the result files. "
                    "Several inputs (or a folder of them) run in parallel, one result folder "
                    "each (--out/<name>).")
    inputs = parser.add_mutually_exclusive_group(required=True)
    inputs.add_argument("--video", type=existing_path, nargs="+",
                        help="video files, a folder of videos, or one image folder (with --fps)")
    inputs.add_argument("--mcap", type=existing_path, nargs="+",
                        help="recordings with camera frames, or a folder of them")
    parser.add_argument("--rig", type=existing_file,
                        help="the rig file (needed with --video; with --mcap, default: the one "
                             "each recording carries)")
    parser.add_argument("--out", type=output_folder, required=True,
                        help="folder for the result files (refused if it holds results); with "
                             "several inputs, one subfolder each")
    add_overwrite(parser, "replace the results of an earlier run in --out")
    parser.add_argument("--fps", type=positive_float, default=0.0,
                        help="frame rate of an image folder [1/s]")
    parser.add_argument("--sequence", action="store_true",
                        help="an image folder is a video's frames (motion prior and Hampel "
                             "filter across them); default: still images, each on its own")
    parser.add_argument("--gravity", type=non_negative_float, help="gravity for the theory [m/s²]")
    parser.add_argument("--calibrate-lasers", type=existing_file, nargs="+", metavar="IMAGE",
                        help="images of known surfaces, or one video of the tilt table (its "
                             "still stretches in order): self-calibrate the rig first (needs "
                             "--surfaces) and process with the calibrated rig")
    parser.add_argument("--surfaces", type=existing_file,
                        help="known surface per image: frame, tilt_x_deg, tilt_y_deg"
                             "[, offset_mm] (frame k = k-th image)")
    add_lateral_options(parser, "a second, lateral camera of the same drop (one --video): its "
                        "wall profile and the top surface checked against it (lateral.csv, "
                        "the report)")
    parser.add_argument("--jobs", type=positive_int, default=os.cpu_count() or 1,
                        help="inputs processed at once (default: one per core)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(run=run, command="process")


def expand_inputs(paths: list[Path], suffixes: tuple[str, ...]) -> list[Path]:
    """The inputs: files as given, folders replaced by the files of `suffixes` in them (a
    folder without such files stays one input: an image folder)."""
    inputs: list[Path] = []
    for path in paths:
        if not path.exists():
            raise CommandError(f"{path}: no such file")
        found = sorted(p for p in path.iterdir() if p.suffix.lower() in suffixes) \
            if path.is_dir() else []
        inputs += found or [path]
    stems = [p.stem for p in inputs]
    if len(inputs) > 1 and len(set(stems)) < len(stems):
        raise CommandError("two inputs have the same name: their result folders would clash")
    return inputs


def run(args: argparse.Namespace) -> int:
    """Result files and the analysis report of each video or recording."""
    from sds_recon.results import refuse_results

    is_video = args.video is not None
    lateral = lateral_input(args)
    inputs = expand_inputs(args.video or args.mcap, VIDEO_SUFFIXES if is_video else (".mcap",))
    if is_video and args.rig is None:
        raise CommandError("--video needs --rig (the rig the video was taken with)")
    outs = [args.out] if len(inputs) == 1 else [args.out / source.stem for source in inputs]
    if not args.overwrite:   # before any work: a refused folder is named at once
        for out in outs:
            refuse_results(out)
    # Only now the numerical libraries (seconds): a missing input is told at once.
    from sds_model.rig import load_rig
    from sds_record.recorded_series import recording_rig
    from sds_workflows.process import calibrate_from_images, process_input, process_inputs

    rig_file = args.rig
    if args.calibrate_lasers:
        if args.surfaces is None:
            raise CommandError("--calibrate-lasers needs --surfaces")
        designed = load_rig(args.rig) if args.rig else recording_rig(inputs[0], None)
        calibration_out = args.out if len(inputs) == 1 else args.out / "calibration"
        _, rig_file, calibration = calibrate_from_images(designed, args.calibrate_lasers,
                                                         args.surfaces, calibration_out)
        print(f"sds process: calibrated rig written to {rig_file}; "
              f"{calibration.check.summary()}")
    if lateral is not None and (len(inputs) != 1 or not is_video):
        raise CommandError("--lateral goes with one --video (the same drop's top view)")
    if len(inputs) == 1:
        processed = process_input(inputs[0], is_video, rig_file, args.out, args.fps,
                                  args.gravity, args.overwrite, not args.no_progress,
                                  args.sequence, lateral)
        print(processed.summary(), file=sys.stderr if processed.incomplete else sys.stdout)
        for line in filter(None, [processed.sigma_check_line(), *processed.result_lines()]):
            print(line)
        return 2 if processed.incomplete else 0
    failed = process_inputs(inputs, is_video, rig_file, args.out, args.jobs, args.fps,
                            args.gravity, args.overwrite, not args.no_progress, args.sequence)
    return 2 if failed else 0
