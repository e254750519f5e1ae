"""`sds resolution`: ideal vertical resolution [mm/px] against the spot's radius (seed Fig. 7)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_model.paths import CONFIG

from sds_cli.commands import (
    add_overwrite,
    existing_file,
    output_folder,
    positive_float,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds resolution`."""
    parser = commands.add_parser(
        "resolution", help="ideal vertical resolution [mm/px] against laser radius (seed Fig. 7)",
        description="Camera looking straight down at a flat surface: how many mm of surface "
                    "height one pixel of spot motion means, for each radial spot position.",
    )
    parser.add_argument("--camera", type=existing_file, help="camera file (default: the GoPro's)",
                        default=CONFIG / "cameras" / "gopro_hero5_session.yaml")
    parser.add_argument("--height-mm", type=positive_float, default=170.0,
                        help="camera above the flat surface [mm] (default 170)")
    parser.add_argument("--beam-tilt-deg", type=float, default=0.0,
                        help="beam tilt from the vertical, outwards [deg] (default 0)")
    parser.add_argument("--radii-mm", type=float, nargs=3, default=[0.0, 60.0, 1.0],
                        metavar=("START", "STOP", "STEP"), help="radii of the table [mm]")
    parser.add_argument("--rings-mm", type=float, nargs="*", default=[],
                        help="radii of the diode rings, drawn dashed")
    parser.add_argument("--out", type=output_folder, default=Path("resolution"),
                        help="directory for resolution.csv and resolution.png")
    add_overwrite(parser, "replace an earlier table and plot in --out")
    parser.set_defaults(run=run, command="resolution")


def run(args: argparse.Namespace) -> int:
    """The table (CSV, printed) and its plot."""
    import numpy as np
    from sds_model.camera import load_camera
    from sds_recon.resolution import plot_resolution, table_text, vertical_resolution

    refuse_existing(args.out / "resolution.csv", args.overwrite)
    camera = load_camera(args.camera)
    start, stop, step = args.radii_mm
    radii = np.arange(start, stop + step / 2, step)
    table = vertical_resolution(camera, radii, args.height_mm, np.radians(args.beam_tilt_deg))
    args.out.mkdir(parents=True, exist_ok=True)
    text = table_text(table)
    (args.out / "resolution.csv").write_text(text + "\n")
    plot_resolution(table, args.out / "resolution.png", args.rings_mm)
    print(text)
    print(f"wrote {args.out / 'resolution.csv'} and {args.out / 'resolution.png'}")
    return 0
