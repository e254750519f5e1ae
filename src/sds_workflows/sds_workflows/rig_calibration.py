"""`sds calibrate rig`: images of known surfaces → identified spots → the self-calibrated rig.

Reads each image, finds every spot-like blob in the container's region (sds_tracker.discovery)
and the line laser's centre per row, identifies and fits the rig (sds_recon.calibration.
rig_calibration), and writes the calibrated rig file, its report (JSON, text, HTML) and one
diagnostic overlay per image in the manner of seed Figs. 5/6.
"""

from __future__ import annotations

import html
import json
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sds_camera.frame_source import Region, VideoFileSource, open_source, select
from sds_model.errors import InputError
from sds_model.rig import Rig, save_rig
from sds_recon.calibration.laser_files import read_surfaces
from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.rig_calibration import (
    CalibrationSettings,
    RigCalibration,
)
from sds_recon.calibration.rig_calibration import calibrate_rig as fit_rig
from sds_recon.calibration.rig_model import LineObservations
from sds_recon.calibration.rig_report import calibrated_rig, report_text, rig_report
from sds_recon.triangulation import beam_image_path
from sds_tracker.discovery import SpotCandidates, averaged, excess_sigma_px, find_spots
from sds_tracker.line import LineSettings, continued_within, seek_line
from sds_tracker.plateaus import Plateau, changed_pixels, find_plateaus
from sds_tracker.sigma_scale import video_sigma_scale
from sds_tracker.tracker import flat_line_px, line_reach_px

REGION_MARGIN_MM = 8.0
"""The search region reaches this far beyond the rim (a turned camera moves the image)."""
LINE_SAMPLES_PER_FRAME = 60
"""Line rows per image that enter the joint fit (evenly spaced; more add time, not accuracy)."""
IMAGE_THREADS = 2
"""Image files read (and `sds demo`'s table images written) at once: OpenCV's PNG codec
releases the GIL, so the 2-core machine reads two at a time."""
OVERLAY_WIDTH_PX = 1200
VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi", ".m4v")
STILL_S = 0.5
"""Shortest still stretch of a calibration video that counts as a plateau [s]."""
STILL_PX = 4
"""Most changed pixels (half resolution) between two frames of a still stretch."""
FRAMES_PER_STILL = 5
"""Frames of each still stretch of a calibration video whose spots are averaged (its middle
frame and those around it): speckle on the liquid is new in every frame, so their mean is
closer by about √5 and their scatter says how close (a still photo keeps one pattern). Five
full 4K frames per surface hold about 1.1 GB for the protocol's eleven."""


@dataclass(frozen=True)
class CalibrationImages:
    """What was found in each calibration image: blobs and line pixels, and what the stills'
    repeated frames showed of a single frame's spot σ: a still's (`excess_sigma_px`) and,
    once the rig is fitted, a video's (`video_sigma_scale`); None without them."""

    spots: list[SpotCandidates]
    line: LineObservations
    region: Region
    spot_excess_sigma_px: float | None = None
    spot_sigma_scale: float | None = None


def read_images(paths: list[Path]) -> list[np.ndarray]:
    """BGR images from files, IMAGE_THREADS at once; a one-line error (InputError) for one
    that cannot be read."""
    with ThreadPoolExecutor(IMAGE_THREADS) as pool:
        read = list(pool.map(lambda path: cv2.imread(str(path), cv2.IMREAD_COLOR), paths))
    images: list[np.ndarray] = []
    for path, image in zip(paths, read, strict=True):
        if image is None:
            raise InputError(f"{path}: not a readable image")
        images.append(image)
    return images


def known_surfaces(path: Path) -> list[KnownSurface]:
    """The surfaces CSV's surfaces in frame order; its frames must run 0, 1, … without gaps."""
    known = read_surfaces(path)
    if sorted(known) != list(range(len(known))):
        raise InputError(f"{path}: frames must run 0, 1, 2, … (got {sorted(known)[:8]})")
    if not known:
        raise InputError(f"{path}: no known surface")
    return [known[k] for k in range(len(known))]


def is_one_video(paths: list[Path]) -> bool:
    """Whether the calibration's input is one video file (VIDEO_SUFFIXES), not images."""
    return len(paths) == 1 and paths[0].suffix.lower() in VIDEO_SUFFIXES


def calibration_frames(paths: list[Path], rig: Rig, count: int
                       ) -> tuple[list[np.ndarray], list[str], list[list[np.ndarray]] | None]:
    """Images of the known surfaces from image files (one per surface, or a burst of the
    same number per surface, in order: the first of each burst is its image, the others its
    repeats), or from the still stretches of one video file (VIDEO_SUFFIXES), with each
    stretch's further frames (`read_video_plateaus`); a name for each image; no repeats
    (None) for one image per surface."""
    if is_one_video(paths):
        return read_video_plateaus(paths[0], rig, count)
    if count == 0 or len(paths) % count:
        raise InputError(f"{len(paths)} images but {count} known surfaces: give one image per "
                         "surface, or a burst of the same number for each, in the surfaces' "
                         "order")
    burst = len(paths) // count
    images = read_images(paths)
    firsts = images[::burst]
    names = [str(p) for p in paths[::burst]]
    if burst == 1:
        return firsts, names, None
    return firsts, names, [images[k * burst + 1:(k + 1) * burst] for k in range(count)]


def read_video_plateaus(path: Path, rig: Rig, count: int, min_still_s: float = STILL_S
                        ) -> tuple[list[np.ndarray], list[str], list[list[np.ndarray]]]:
    """The middle frame (BGR) of each of the `count` still stretches of a tilt-table video,
    a name for each, and the stretch's further frames around it (FRAMES_PER_STILL in all,
    where it is that long); a one-line error (ValueError) when it has another number of
    stretches.

    Two passes: the first measures each frame's change inside the container's region (red
    channel, half resolution), the second keeps only the plateaus' middle frames and those
    around them.
    """
    region = Region(*rig.container_region_px(rig.camera))
    source = open_source(str(path))
    try:
        fps = source.nominal_fps if isinstance(source, VideoFileSource) else 0.0
        if not fps > 0:
            raise InputError(f"{path}: a video file with a frame rate is needed")
        changes, previous = [], None
        region.check_inside(source.width, source.height)
        for frame in source.frames(region, "red"):
            red = cv2.resize(frame.image, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
            changes.append(0 if previous is None else changed_pixels(previous, red))
            previous = red
    finally:
        source.close()
    plateaus = find_plateaus(np.array(changes), max(2, round(min_still_s * fps)),
                             STILL_PX)
    if len(plateaus) != count:
        found = ", ".join(f"{p.first / fps:.1f}–{p.last / fps:.1f} s" for p in plateaus[:12])
        raise InputError(f"{path}: {len(plateaus)} still stretches of {min_still_s:g} s or more "
                         f"({found or 'none'}), but {count} known surfaces")
    wanted = {p.middle: p for p in plateaus}
    around = {index: k for k, p in enumerate(plateaus) for index in _around_middle(p)}
    images, names = [], []
    repeats: list[list[np.ndarray]] = [[] for _ in plateaus]
    source = open_source(str(path))
    try:
        for frame in source.frames():
            if frame.index in wanted:
                images.append(frame.image)
                p = wanted[frame.index]
                names.append(f"{path.name} frame {frame.index} (still {p.first / fps:.2f}–"
                             f"{p.last / fps:.2f} s)")
            elif frame.index in around:
                repeats[around[frame.index]].append(frame.image)
            if frame.index >= max(around, default=-1) and len(images) == len(wanted):
                break
    finally:
        source.close()
    names = [f"{name}, spots averaged over {1 + len(more)} frames"
             for name, more in zip(names, repeats, strict=True)]
    return images, names, repeats


def _around_middle(plateau: Plateau) -> range:
    """The FRAMES_PER_STILL frames of a still stretch centred on its middle (fewer where it
    is shorter)."""
    first = max(plateau.first, plateau.middle - FRAMES_PER_STILL // 2)
    return range(first, min(plateau.last, first + FRAMES_PER_STILL - 1) + 1)


def observe(rig: Rig, images: list[np.ndarray],
            repeats: list[list[np.ndarray]] | None = None) -> CalibrationImages:
    """Blobs and line centres in each image (BGR, full frame), inside the container region;
    with `repeats`, more frames of each image's still (the same surface at rest), whose blobs
    each image's are averaged with (`sds_tracker.discovery.averaged`)."""
    margin = int(np.ceil(REGION_MARGIN_MM * rig.surface_px_per_mm()))
    region = Region(*rig.container_region_px(rig.camera, margin))
    flat_rows, _ = flat_line_px(rig)
    settings = LineSettings()
    rows, low_x, high_x = line_reach_px(rig, settings.band_px)
    spots, line_frame, line_pixels, line_sigma = [], [], [], []
    for index, image in enumerate(images):
        region.check_inside(image.shape[1], image.shape[0])
        red = select(image, region, "red")
        profile = continued_within(seek_line(red, (region.x, region.y), rows, low_x, high_x,
                                          settings), flat_rows[0], flat_rows[-1], settings) \
            if len(rows) else None
        line_px = (profile.y_px, profile.x_px) if profile is not None and \
            len(profile.y_px) > len(flat_rows) // 4 else None
        found = find_spots(red, (region.x, region.y), line=line_px)
        if repeats and repeats[index]:
            found = averaged([found, *(find_spots(select(frame, region, "red"),
                                                  (region.x, region.y), line=line_px)
                                       for frame in repeats[index])])
        spots.append(found)
        if profile is not None:
            keep = np.linspace(0, len(profile.x_px) - 1,
                               min(LINE_SAMPLES_PER_FRAME, len(profile.x_px))).astype(int)
            line_frame += [index] * len(keep)
            line_pixels += list(zip(profile.x_px[keep], profile.y_px[keep], strict=True))
            line_sigma += list(profile.sigma_px[keep])
    line = LineObservations(np.array(line_frame, int), np.array(line_pixels).reshape(-1, 2),
                            np.array(line_sigma, float))
    return CalibrationImages(spots, line, region, excess_sigma_px(spots))


def calibrate_images(rig: Rig, images: list[np.ndarray], surfaces: list[KnownSurface],
                     settings: CalibrationSettings | None = None,
                     repeats: list[list[np.ndarray]] | None = None, from_video: bool = False
                     ) -> tuple[RigCalibration, CalibrationImages]:
    """Self-calibrate the rig from images of the known surfaces (one surface per image; with
    `repeats`, more frames of each, whose spots are averaged with its own). Where they are
    frames of the camera's own video (`from_video`), as the drop's are, the repeats also give
    a video's σ scale (`video_sigma_scale`); image bursts give none: without the video's
    codec, their spots' scatter is not a video's."""
    if len(images) != len(surfaces):
        raise InputError(f"{len(images)} images but {len(surfaces)} known surfaces")
    found = observe(rig, images, repeats)
    line = found.line if len(found.line.frame) else None
    result = fit_rig(rig, surfaces, [s.pixels for s in found.spots],
                     [s.covariance_px2 for s in found.spots], line, settings)
    if repeats and from_video:   # the fitted rig's paths lead a video's tracker to the spots
        region = found.region
        stills = [[select(frame, region, "red") for frame in (image, *more)]
                  for image, more in zip(images, repeats, strict=True)]
        found = replace(found, spot_sigma_scale=video_sigma_scale(
            calibrated_rig(rig, result), stills, (region.x, region.y)))
    return result, found


def calibrate_rig(rig: Rig, paths: list[Path], surfaces_csv: Path, rig_path: Path,
                  source: str, settings: CalibrationSettings | None = None
                  ) -> tuple[Rig, RigCalibration]:
    """Self-calibrate `rig` from images of known surfaces (image k is frame k of the surfaces
    CSV) or one tilt-table video (its still stretches in order); write the calibrated rig to
    `rig_path` with its report and overlays beside it (`source`: the command, for the rig
    file's header)."""
    surfaces = known_surfaces(surfaces_csv)
    images, names, repeats = calibration_frames(paths, rig, len(surfaces))
    result, found = calibrate_images(rig, images, surfaces, settings, repeats,
                                     from_video=is_one_video(paths))
    rig_path.parent.mkdir(parents=True, exist_ok=True)
    return write_calibration(rig, result, found, images, names, rig_path, source), result


def calibrated_rig_file(nominal: Rig, result: RigCalibration, found: CalibrationImages,
                        report: dict[str, Any] | None = None) -> Rig:
    """The calibrated rig as `sds calibrate rig` writes it: `calibrated_rig` (its record from
    `report` where given), and where the stills had repeated frames, what a single frame's
    spot σ leaves out in its record: `spot_excess_sigma_px` (the tracker adds it to the σ of
    every spot whose own light does not measure its speckle: stills', and a video's on the
    laser line) and `spot_sigma_scale` (it scales the σ of a video's spots that do)."""
    rig = calibrated_rig(nominal, result, report)
    measured = {key: value for key, value in (
        ("spot_excess_sigma_px", found.spot_excess_sigma_px),
        ("spot_sigma_scale", found.spot_sigma_scale)) if value is not None}
    if not measured:
        return rig
    return replace(rig, calibration={**(rig.calibration or {}), **measured})


def write_calibration(nominal: Rig, result: RigCalibration, found: CalibrationImages,
                      images: list[np.ndarray], names: list[str], rig_path: Path,
                      source: str) -> Rig:
    """Write the calibrated rig, `<rig>.report.json`/`.txt`/`.html` and overlays beside it."""
    report = rig_report(nominal, result)
    rig = calibrated_rig_file(nominal, result, found, report)
    text = report_text(report)
    if found.spot_excess_sigma_px is not None:
        report["spot_excess_sigma_px"] = found.spot_excess_sigma_px
        text += (f"\nspots' frame-to-frame scatter on the stills beyond their own σ: "
                 f"{found.spot_excess_sigma_px:.3f} px per axis (added to the σ of "
                 "spots whose own light does not measure their speckle)")
    if found.spot_sigma_scale is not None:
        report["spot_sigma_scale"] = found.spot_sigma_scale
        text += (f"\na video's spots' frame-to-frame scatter on the stills against their "
                 f"own σ: × {found.spot_sigma_scale:.2f} (their σ is scaled by it; at least 1)")
    save_rig(rig, rig_path, comment=f"Self-calibrated by {source} ({len(images)} images):\n"
                                    f"{text}")
    stem = rig_path.with_suffix("")
    Path(f"{stem}.report.json").write_text(json.dumps(report, indent=2) + "\n")
    Path(f"{stem}.report.txt").write_text(text + "\n")
    overlays = []
    for index, image in enumerate(images):
        path = Path(f"{stem}.overlay_{index:02d}.png")
        cv2.imwrite(str(path), overlay(nominal, rig, result, found, index, image))
        overlays.append(path)
    figures = "".join(f"<figure><img src='{p.name}' width='900'><figcaption>{html.escape(n)}"
                      "</figcaption></figure>" for p, n in zip(overlays, names, strict=True))
    Path(f"{stem}.report.html").write_text(
        "<html><head><meta charset='utf-8'><title>SDS rig calibration</title></head><body>"
        f"<h1>Rig calibration</h1><pre>{html.escape(text)}</pre>"
        "<p>Overlays: green crosses, the rig file's spot positions; red circles, spots "
        "identified (with ids); red lines, the calibrated beams' image paths (surface heights "
        "−30…40 mm); yellow circles, blobs no diode claimed (wall reflections, noise).</p>"
        f"{figures}</body></html>\n")
    return rig


def overlay(nominal: Rig, calibrated: Rig, result: RigCalibration, found: CalibrationImages,
            index: int, image: np.ndarray) -> np.ndarray:
    """One calibration image's region with what the calibration saw and decided."""
    r = found.region
    crop = image[r.y:r.y + r.height, r.x:r.x + r.width].copy()
    factor = min(1.0, OVERLAY_WIDTH_PX / r.width)
    picture = cv2.resize(crop, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA)

    def point(pixel: np.ndarray) -> tuple[int, int]:
        return round((pixel[0] - r.x) * factor), round((pixel[1] - r.y) * factor)

    surface = result.fit.model.surfaces[index]
    for diode in nominal.diodes:
        hit = surface.intersect(diode.emitter_mm, diode.direction[None])
        pixel = nominal.project(hit)[0]
        if np.isfinite(pixel).all():
            cv2.drawMarker(picture, point(pixel), (0, 255, 0), cv2.MARKER_CROSS, 14, 1)
    heights = np.linspace(-30.0, 40.0, 15)
    for laser_id in result.laser_ids:
        path = beam_image_path(calibrated, laser_id, heights)
        path = path[np.isfinite(path).all(axis=1)]
        if len(path) > 1:
            cv2.polylines(picture, [np.array([point(p) for p in path], np.int32)], False,
                          (0, 0, 200), 1, cv2.LINE_AA)
    blobs = found.spots[index].pixels
    for k in np.flatnonzero(result.frame == index):
        pixel = blobs[result.blob[k]]
        cv2.circle(picture, point(pixel), 9, (0, 0, 255), 2, cv2.LINE_AA)
        cv2.putText(picture, str(result.laser_ids[result.diode[k]]),
                    (point(pixel)[0] + 10, point(pixel)[1] - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)
    used = set(result.blob[result.frame == index].tolist())
    for j, pixel in enumerate(blobs):
        if j not in used:
            cv2.circle(picture, point(pixel), 9, (0, 255, 255), 1, cv2.LINE_AA)
    return picture
