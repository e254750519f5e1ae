"""`sds simulate`: render a scenario to video, Arduino streams and ground truth files.

Output folder (format version 1; units: px, mm, s; pixels x = column, y = row, the centre of
the top-left pixel at (0, 0); world frame of the rig file):
- video.mp4 (H.264, or lossless), or frames/NNNNNN.png: what the camera records.
- video.imu.csv (or frames.imu.csv): the camera's own accelerometer and gyroscope, as a
  GoPro's GPMF track would hold them (sds_camera.camera_imu's sidecar format).
- arduino/serial.txt: the serial line as the bridge reads it; arduino/SDS_LOG.TXT: the SD card
  (the same records; protocol in sds_arduino.protocol).
- truth/run.json: the resolved scenario (modes with frequency, damping, amplitude), camera and
  rig files, image size, fps, frame count, Arduino clock offset and drift, this list.
- truth/spots.csv: per frame and diode: x_px, y_px (mid-exposure), x_exposure_px,
  y_exposure_px (centroid over the exposure), X_mm, Y_mm, Z_mm, visible, reflection x/y.
- truth/frames.csv: per frame: time, LED, tilt, every modal coordinate [mm], vibration [rad].
- truth/line.npz: line_x_px (frames × image rows, NaN off the line), line_mm (frames × rays × 3).
With a side camera (the scenario's `lateral:` section, sds_sim.lateral):
- lateral/video.mp4 (H.264 at the view file's rate): what the side camera records;
  lateral/board_N.png: its image of the checkerboard at the view file's N-th placement.
- truth/lateral.csv: per side frame: its time on its own clock and on the top camera's, LED;
  truth/lateral_edges.npz: edge_row_px (side frames × image columns, NaN outside the
  container): the contact line's row as drawn.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np
from sds_arduino.protocol import format_record
from sds_camera.camera_imu import sidecar_path, write_sidecar
from sds_camera.video_writer import VideoWriter
from sds_model.errors import InputError
from tqdm import tqdm

from sds_sim.arduino import arduino_records
from sds_sim.camera_imu import camera_imu
from sds_sim.lateral import LateralRenderer, LateralTruth
from sds_sim.render import FrameRenderer, FrameTruth
from sds_sim.scenario import Scenario

T = TypeVar("T")
FORMAT_VERSION = 1
CODECS = ("h264", "lossless", "png")


@dataclass(frozen=True)
class SimulationOutput:
    """Paths of everything a simulation wrote."""

    directory: Path
    video: Path
    serial: Path
    sd_log: Path
    run: Path
    spots: Path
    frames: Path
    line: Path
    lateral_video: Path | None = None
    lateral_boards: tuple[Path, ...] = ()
    camera_imu: Path | None = None   # the camera's own IMU (a sidecar CSV beside the video)
    surfaces: Path | None = None   # a tilt-table series: its surfaces CSV, one still each


class _FrameSink:
    """Video file or PNG sequence."""

    def __init__(self, directory: Path, codec: str, width: int, height: int, fps: float,
                 bitrate_bit_s: float | None = None) -> None:
        self.codec = codec
        if codec == "png":
            self.path = directory / "frames"
            self.path.mkdir(parents=True, exist_ok=True)
            self._writer = None
        else:
            self.path = directory / "video.mp4"
            self._writer = VideoWriter(self.path, width, height, fps, codec=codec,
                                       bitrate_bit_s=bitrate_bit_s)
        self._count = 0

    def write(self, frame: np.ndarray) -> None:
        if self._writer is None:
            cv2.imwrite(str(self.path / f"{self._count:06d}.png"), frame)
        else:
            self._writer.write(frame)
        self._count += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


def _render_into(sink: _FrameSink, render: Callable[[int], tuple[np.ndarray, T]], count: int,
                 description: str, progress: bool) -> list[T]:
    """Render frames 0 … count − 1 into `sink` (closed at the end, also on failure); their
    truths in order."""
    truths: list[T] = []
    try:
        for index in tqdm(range(count), desc=description, unit="frame", disable=not progress):
            frame, truth = render(index)
            sink.write(frame)
            truths.append(truth)
    finally:
        sink.close()
    return truths


def simulate(scenario: Scenario, directory: Path, codec: str = "h264",
             progress: bool = True) -> SimulationOutput:
    """Render every frame, write the streams and the truth; return where they are."""
    if codec not in CODECS:
        raise InputError(f"codec must be one of {CODECS}, got {codec!r}")
    directory = Path(directory)
    (directory / "truth").mkdir(parents=True, exist_ok=True)
    (directory / "arduino").mkdir(parents=True, exist_ok=True)
    renderer = FrameRenderer(scenario)
    # The camera's rate at full resolution, the same bits per pixel at a smaller scale. A
    # constant quality wrote these dark frames far below a camera's rate, which shrinks
    # sub-pixel spot motion and biased the damping ratios high (bench/README.md, "Damping
    # ratios and the video's rate").
    bitrate_bit_s = scenario.sensor.bitrate_mbit_s * 1e6 * scenario.scale**2
    sink = _FrameSink(directory, codec, renderer.width, renderer.height, scenario.fps,
                      bitrate_bit_s)
    truths: list[FrameTruth] = _render_into(sink, renderer.render, scenario.frame_count,
                                            "rendering", progress)
    arduino, truth = directory / "arduino", directory / "truth"
    output = SimulationOutput(directory, sink.path, arduino / "serial.txt", arduino / "SDS_LOG.TXT",
                              truth / "run.json", truth / "spots.csv", truth / "frames.csv",
                              truth / "line.npz")
    lateral: dict[str, Any] | None = None
    if scenario.lateral is not None:
        output, lateral = _simulate_lateral(scenario, output, codec, progress)
    lines = "".join(format_record(r) for r in arduino_records(scenario))
    output.serial.write_text(lines, newline="")
    output.sd_log.write_text(lines, newline="")
    _write_spots(scenario, truths, output.spots)
    _write_frames(scenario, truths, output.frames)
    _write_line(renderer, truths, output.line)
    imu = camera_imu(scenario)
    if imu is not None:
        sidecar = sidecar_path(output.video)
        write_sidecar(imu, sidecar)
        output = replace(output, camera_imu=sidecar)
    if scenario.tilt_series_deg:
        surfaces = directory / "surfaces.csv"
        _write_surfaces(scenario, surfaces)
        output = replace(output, surfaces=surfaces)
    description = _run_description(scenario, renderer, output)
    if lateral is not None:
        description["lateral"] = lateral
    output.run.write_text(json.dumps(description, indent=2) + "\n")
    return output


def _simulate_lateral(scenario: Scenario, output: SimulationOutput, codec: str, progress: bool
                      ) -> tuple[SimulationOutput, dict[str, Any]]:
    """The side camera's video, board image and truth; run.json's `lateral` entry."""
    renderer = LateralRenderer(scenario)
    folder = output.directory / "lateral"
    folder.mkdir(parents=True, exist_ok=True)
    boards = tuple(folder / f"board_{index}.png" for index in range(len(renderer.boards)))
    for path, image in zip(boards, renderer.board_images(), strict=True):
        cv2.imwrite(str(path), image)
    sink = _FrameSink(folder, "h264" if codec == "png" else codec, renderer.width,
                      renderer.height, renderer.fps)
    truths: list[LateralTruth] = _render_into(sink, renderer.render, renderer.frame_count,
                                              "side view", progress)
    truth_folder = output.directory / "truth"
    with (truth_folder / "lateral.csv").open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "lateral_time_s", "time_s", "led_on"])
        for truth in truths:
            writer.writerow([truth.index, f"{truth.lateral_time_s:.9f}", f"{truth.time_s:.9f}",
                             int(truth.led_on)])
    np.savez_compressed(truth_folder / "lateral_edges.npz",
                        edge_row_px=np.array([t.edge_row_px for t in truths]))
    spec = scenario.lateral
    assert spec is not None
    description = {
        "view_file": spec.view_file, "fps": renderer.fps, "frame_count": renderer.frame_count,
        "image_size": [renderer.width, renderer.height],
        "camera": renderer.camera.to_dict(),
        "position_mm": list(spec.position_mm), "look_at_mm": list(spec.look_at_mm),
        "roll_deg": spec.roll_deg,
        "world_to_camera": {"rotation": renderer.pose.rotation.tolist(),
                            "translation_mm": renderer.pose.translation_mm.tolist()},
        "clock_offset_s": spec.clock_offset_s, "clock_drift_ppm": spec.clock_drift_ppm,
        "board_offset_mm": list(spec.board_offset_mm),
        "files": {"video": str(sink.path.relative_to(output.directory)),
                  "boards": [str(b.relative_to(output.directory)) for b in boards],
                  "truth": "truth/lateral.csv", "edges": "truth/lateral_edges.npz"},
    }
    return replace(output, lateral_video=sink.path, lateral_boards=boards), description


def _write_surfaces(scenario: Scenario, path: Path) -> None:
    """The tilt table's known surfaces as `sds calibrate rig --video` reads them: frame k is
    the video's k-th still stretch, its tilts [deg] as the table's scale reads them (the
    scenario's angles) and the level offset 0 mm."""
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "tilt_x_deg", "tilt_y_deg", "offset_mm"])
        for index, angle_deg in enumerate(scenario.tilt_series_deg):
            tilt_x, tilt_y = (angle_deg, 0.0) if scenario.tilt_series_axis == "x" else \
                (0.0, angle_deg)
            writer.writerow([index, f"{tilt_x:g}", f"{tilt_y:g}", "0"])


def _write_spots(scenario: Scenario, truths: list[FrameTruth], path: Path) -> None:
    """One row per frame and diode; under a rolling shutter a last column `t_sample_s`: when
    the spot's row was exposed (its position and X, Y, Z are the truth then)."""
    timed = scenario.sensor.readout_s > 0
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "time_s", "laser_id", "ring", "x_px", "y_px", "x_exposure_px",
                         "y_exposure_px", "X_mm", "Y_mm", "Z_mm", "visible", "reflection_x_px",
                         "reflection_y_px", *(["t_sample_s"] if timed else [])])
        for truth in truths:
            for i, diode in enumerate(scenario.rig.diodes):
                writer.writerow([truth.index, f"{truth.time_s:.6f}", diode.laser_id, diode.ring,
                                 *(f"{v:.6f}" for v in (*truth.spot_px[i],
                                                        *truth.spot_exposure_px[i],
                                                        *truth.spot_mm[i])),
                                 int(truth.visible[i]),
                                 *(f"{v:.6f}" for v in truth.reflection_px[i]),
                                 *([f"{truth.spot_time_s[i]:.9f}"] if timed else [])])


def _write_frames(scenario: Scenario, truths: list[FrameTruth], path: Path) -> None:
    modes = scenario.mode_motions()
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "time_s", "led_on", "tilt_x_deg", "tilt_y_deg",
                         *(f"q_m{m.shape.order}n{m.shape.index}_mm" for m in modes),
                         "vibration_x_rad", "vibration_y_rad"])
        for truth in truths:
            tilt = np.degrees(scenario.tilt_at(truth.time_s))
            writer.writerow([truth.index, f"{truth.time_s:.6f}", int(truth.led_on),
                             *(f"{v:.6f}" for v in tilt),
                             *(f"{float(m.coordinate(truth.time_s)):.9f}" for m in modes),
                             *(f"{v:.9f}" for v in truth.vibration_rad)])


def _write_line(renderer: FrameRenderer, truths: list[FrameTruth], path: Path) -> None:
    line_x = np.full((len(truths), renderer.height), np.nan, np.float64)
    rays = max((len(t.line_mm) for t in truths), default=0)
    line_mm = np.full((len(truths), rays, 3), np.nan)
    for truth in truths:
        line_x[truth.index, truth.line_rows] = truth.line_x_px
        line_mm[truth.index, : len(truth.line_mm)] = truth.line_mm
    np.savez_compressed(path, line_x_px=line_x, line_mm=line_mm)


def _run_description(scenario: Scenario, renderer: FrameRenderer,
                     output: SimulationOutput) -> dict[str, Any]:
    modes = [{"order": m.shape.order, "index": m.shape.index, "xi": m.shape.xi,
              "frequency_hz": m.frequency_hz, "damped_frequency_hz": m.damped_frequency_hz,
              "damping_ratio": m.damping_ratio, "amplitude_mm": m.amplitude_mm,
              "azimuth_deg": float(np.degrees(m.shape.azimuth_rad)),
              "phase_deg": float(np.degrees(m.phase_rad)), "start_s": m.start_s}
             for m in scenario.mode_motions()]
    return {
        "format_version": FORMAT_VERSION,
        "scenario": scenario.name, "seed": scenario.seed,
        "rig_file": str(scenario.rig_file), "camera_file": str(scenario.rig.camera_file),
        "image_scale": scenario.scale, "image_size": [renderer.width, renderer.height],
        "fps": scenario.fps, "frame_count": scenario.frame_count,
        "duration_s": scenario.duration_s, "gravity_m_s2": scenario.gravity,
        "kick_s": scenario.kick_s, "modes": modes,
        "events": asdict(scenario.events), "optics": asdict(scenario.optics),
        "sensor": asdict(scenario.sensor), "disturbances": asdict(scenario.disturbances),
        "arduino": asdict(scenario.arduino), "camera_imu": asdict(scenario.camera_imu),
        "conventions": {"pixels": "x = column, y = row, centre of the top-left pixel at (0, 0), "
                                  "full frame at image_size",
                        "world": "rig file's world frame, mm", "time": "s from the first frame"},
        "files": {key: str(getattr(output, key).relative_to(output.directory))
                  for key in ("video", "serial", "sd_log", "run", "spots", "frames", "line")},
    }
