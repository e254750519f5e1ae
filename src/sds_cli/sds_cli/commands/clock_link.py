"""`sds clock-link`: the camera's clock against the Arduino's, by acceleration and sync LED."""

from __future__ import annotations

import argparse

from sds_cli.commands import CommandError, existing_file


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds clock-link`."""
    parser = commands.add_parser(
        "clock-link", help="the camera's clock against the Arduino's (acceleration, LED)",
        description="Link a video's clock to an Arduino log's: by the excitation both "
                    "accelerometers feel (the camera's own IMU, turned into the rig's frame), "
                    "and by the sync LED where --led-roi is given; print both with their σ, "
                    "their disagreement, and the --start-s that puts the log on the video's "
                    "clock in `sds import-sd`.")
    parser.add_argument("--video", type=existing_file, required=True,
                        help="the video (its own IMU: GoPro GPMF or a sidecar CSV)")
    parser.add_argument("--arduino", type=existing_file, required=True,
                        help="the SD-card log or a serial capture (protocol v1)")
    parser.add_argument("--rig", type=existing_file, required=True,
                        help="rig file: the camera's pose turns its IMU into the rig's frame")
    parser.add_argument("--led-roi", type=int, nargs=4, metavar=("X", "Y", "W", "H"),
                        help="the sync LED's region in the full frame [px]")
    parser.set_defaults(run=run, command="clock-link")


def run(args: argparse.Namespace) -> int:
    """Link the clocks and print both links, their disagreement and the import's --start-s."""
    from sds_model.rig import load_rig
    from sds_workflows.clock_link import link_clocks, read_arduino_log

    log = read_arduino_log(args.arduino)
    links = link_clocks(args.video, log, load_rig(args.rig),
                        tuple(args.led_roi) if args.led_roi else None)
    best = links.acceleration.offset_s if links.acceleration is not None else \
        links.led_offset_s
    if best is None:
        raise CommandError("no link: the video has no camera IMU (or no excitation in both "
                           "records) and no --led-roi with an LED switch")
    a = links.acceleration
    print("acceleration: " + (f"camera − device = {a.offset_s:+.5f} s ± {a.sigma_s * 1e3:.2f} ms"
                              f" (device time {a.window_s[0]:.2f}–{a.window_s[1]:.2f} s)"
                              if a is not None else "none (no camera IMU or no excitation)"))
    print("LED:          " + (f"camera − device = {links.led_offset_s:+.5f} s ± "
                              f"{links.led_sigma_s * 1e3:.2f} ms" if links.led_offset_s is not None
                              and links.led_sigma_s is not None else "none"))
    if links.disagreement_s is not None:
        difference, sigma = links.disagreement_s
        print(f"disagreement: {difference * 1e3:+.2f} ms ± {sigma * 1e3:.2f} ms "
              f"({abs(difference) / sigma:.1f} σ)")
    print(f"sds import-sd {args.arduino} --start-s {log.first_record_s + best:.6f}  "
          "# puts the log on the video's clock")
    return 0
