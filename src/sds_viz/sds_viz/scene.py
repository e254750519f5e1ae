"""What the SDS shows in Rerun, on one timeline "time": image, overlays, 3D surface, series.

Entity paths:
- camera/image (downscaled), camera/image/spots, camera/image/beam_paths (static),
  camera/image/line — pixels of the full frame scaled to the logged image;
- lateral/image — the side camera's frames (frame_id lateral_optical) as they are, on the
  same timeline;
- world/container (static: rim at the fill level, bottom, wall), world/beams (static),
  world/points, world/line_points, world/fitted_plane — mm in the rig's world frame;
- series/height/<laser_id>, series/plane/<tilt_x_deg|tilt_y_deg|p00_mm|rmse_mm>,
  series/modal/<mode name>, series/sloshing/<mode>/<method>,
  series/imu/<frame_id>/<ax_m_s2|ay_m_s2|az_m_s2|gx_rad_s|gy_rad_s|gz_rad_s> (one series per
  source: the Arduino's frame "arduino", the camera's "camera_optical"), series/tof/range_mm.
"""

from __future__ import annotations

import cv2
import numpy as np
import rerun as rr
from sds_model.rig import Rig
from sds_recon.triangulation import beam_image_path

TIMELINE = "time"
RIM_SEGMENTS = 96
PLANE_SEGMENTS = 48
RING_COLOURS = {1: (230, 60, 60), 2: (60, 160, 230), 3: (90, 200, 90)}
LOST_COLOUR = (128, 128, 128)
IMU_AXES = {"accel": ("ax_m_s2", "ay_m_s2", "az_m_s2"),
            "gyro": ("gx_rad_s", "gy_rad_s", "gz_rad_s")}
"""An IMU sensor's series names (results/camera_imu.csv's columns)."""


class RerunScene:
    """Logs SDS data (numpy arrays, world mm, full-frame px) to a Rerun recording stream."""

    def __init__(self, stream: rr.RecordingStream, rig: Rig | None = None,
                 image_scale: float = 0.25) -> None:
        self.stream = stream
        self.rig = rig
        self.image_scale = image_scale
        self.roi_offset = np.zeros(2)
        self.roi_size = (0, 0)   # the region's width and height [px]; (0, 0): not known
        self._ring = {d.laser_id: d.ring for d in rig.diodes} if rig else {}
        if rig is not None:
            self._log_rig(rig)

    def set_time(self, time_s: float) -> None:
        """Move the timeline to `time_s` (seconds since the epoch, or since the start)."""
        self.stream.set_time(TIMELINE, timestamp=time_s)

    def _colours(self, ids: np.ndarray) -> np.ndarray:
        return np.array([RING_COLOURS.get(self._ring.get(int(i), 0), (255, 200, 0))
                         for i in ids], dtype=np.uint8).reshape(-1, 3)

    def _to_image(self, pixels: np.ndarray) -> np.ndarray:
        """Full-frame pixels → the logged image's pixels (region offset, downscale)."""
        return (np.asarray(pixels, dtype=float).reshape(-1, 2) - self.roi_offset) * \
            self.image_scale

    def _log_rig(self, rig: Rig) -> None:
        """Container outline, beams and the beams' image paths (static)."""
        radius, depth = rig.container.radius_mm, rig.container.fill_height_mm
        angle = np.linspace(0, 2 * np.pi, RIM_SEGMENTS + 1)
        circle = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
        rim = np.column_stack([circle, np.zeros(len(circle))])
        bottom = np.column_stack([circle, np.full(len(circle), -depth)])
        walls = [np.array([[x, y, 0.0], [x, y, -depth]]) for x, y in circle[:-1:12]]
        self.stream.log("world/container", rr.LineStrips3D([rim, bottom, *walls],
                                                           colors=(180, 180, 180)), static=True)
        starts = np.array([d.emitter_mm for d in rig.diodes])
        directions = np.array([d.direction for d in rig.diodes])
        reach = (starts[:, 2] + depth) / np.abs(directions[:, 2])   # down to the bottom
        ends = starts + directions * reach[:, None]
        ids = np.array([d.laser_id for d in rig.diodes])
        self.stream.log("world/beams", rr.LineStrips3D(np.stack([starts, ends], axis=1),
                                                       colors=self._colours(ids)), static=True)

    def log_beam_paths(self, heights_mm: tuple[float, float] = (-30.0, 40.0)) -> None:
        """Each beam's image path for the given surface heights (static)."""
        if self.rig is None:
            return
        heights = np.linspace(*heights_mm, 30)
        paths = [self._to_image(beam_image_path(self.rig, d.laser_id, heights))
                 for d in self.rig.diodes]
        ids = np.array([d.laser_id for d in self.rig.diodes])
        self.stream.log("camera/image/beam_paths",
                        rr.LineStrips2D(paths, colors=self._colours(ids), radii=0.5), static=True)

    def log_image(self, image: np.ndarray, roi_offset: tuple[int, int] = (0, 0)) -> None:
        """The camera frame (mono or BGR), downscaled by `image_scale` (area average)."""
        self.roi_offset = np.asarray(roi_offset, dtype=float)
        if self.image_scale != 1.0:
            image = cv2.resize(image, None, fx=self.image_scale, fy=self.image_scale,
                               interpolation=cv2.INTER_AREA)
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
        self.stream.log("camera/image", rr.Image(image))

    def log_side_image(self, entity: str, image: np.ndarray) -> None:
        """A second camera's frame (mono or BGR) at `entity`, as it is (a side view is small)."""
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
        self.stream.log(entity, rr.Image(image))

    def log_spots(self, ids: np.ndarray, pixels: np.ndarray, lost: np.ndarray) -> None:
        """Tracked spots (full-frame px); lost ones grey."""
        colours = self._colours(ids)
        colours[np.asarray(lost, dtype=bool)] = LOST_COLOUR
        self.stream.log("camera/image/spots", rr.Points2D(
            self._to_image(pixels), colors=colours, radii=2.0,
            labels=[str(int(i)) for i in ids]))

    def log_line(self, pixels: np.ndarray) -> None:
        """The line laser's centre per row (full-frame px)."""
        self.stream.log("camera/image/line", rr.Points2D(self._to_image(pixels),
                                                         colors=(255, 255, 0), radii=0.5))

    def log_points(self, ids: np.ndarray, points_mm: np.ndarray) -> None:
        """Triangulated spots [mm] and one height series per diode."""
        self.stream.log("world/points", rr.Points3D(points_mm, colors=self._colours(ids),
                                                    radii=1.0))
        for laser_id, z in zip(ids, np.asarray(points_mm)[:, 2], strict=True):
            self.stream.log(f"series/height/{int(laser_id)}", rr.Scalars(float(z)))

    def log_line_points(self, points_mm: np.ndarray) -> None:
        """Triangulated line samples [mm]."""
        self.stream.log("world/line_points", rr.Points3D(points_mm, colors=(255, 255, 0),
                                                         radii=0.4))

    def log_surface_fit(self, p00_mm: float, p10: float, p01: float, tilt_x_rad: float,
                        tilt_y_rad: float, rmse_mm: float, names: list[str],
                        amplitudes_mm: list[float]) -> None:
        """The fitted plane (Eq. 12) as a disc over the container, its tilts, modal amplitudes."""
        for name, value in (("p00_mm", p00_mm), ("tilt_x_deg", np.degrees(tilt_x_rad)),
                            ("tilt_y_deg", np.degrees(tilt_y_rad)), ("rmse_mm", rmse_mm)):
            if np.isfinite(value):
                self.stream.log(f"series/plane/{name}", rr.Scalars(float(value)))
        for name, value in zip(names, amplitudes_mm, strict=True):
            self.stream.log(f"series/modal/{name}", rr.Scalars(float(value)))
        if self.rig is None or not np.isfinite([p00_mm, p10, p01]).all():
            return
        radius = self.rig.container.radius_mm
        angle = np.linspace(0, 2 * np.pi, PLANE_SEGMENTS, endpoint=False)
        x, y = np.concatenate([[0.0], radius * np.cos(angle)]), \
            np.concatenate([[0.0], radius * np.sin(angle)])
        vertices = np.column_stack([x, y, p00_mm + p10 * x + p01 * y])
        rim = np.arange(1, PLANE_SEGMENTS + 1)
        triangles = np.column_stack([np.zeros(PLANE_SEGMENTS, int), rim, np.roll(rim, -1)])
        self.stream.log("world/fitted_plane", rr.Mesh3D(
            vertex_positions=vertices, triangle_indices=triangles,
            vertex_colors=np.tile([80, 140, 255], (len(vertices), 1)).astype(np.uint8)))

    def log_estimate(self, mode: str, method: str, frequency_hz: float,
                     damping_ratio: float) -> None:
        """A running sloshing estimate."""
        self.stream.log(f"series/sloshing/{mode}/{method}/frequency_hz",
                        rr.Scalars(float(frequency_hz)))
        if np.isfinite(damping_ratio):
            self.stream.log(f"series/sloshing/{mode}/{method}/damping_ratio",
                            rr.Scalars(float(damping_ratio)))

    def log_imu(self, frame_id: str, sensor: str, values: tuple[float, float, float]) -> None:
        """One IMU sensor's sample in its frame: "accel" [m/s²] or "gyro" [rad/s]."""
        axes = IMU_AXES[sensor]
        for axis, value in zip(axes, values, strict=True):
            self.stream.log(f"series/imu/{frame_id}/{axis}", rr.Scalars(float(value)))

    def log_tof(self, range_mm: float) -> None:
        """Time-of-flight range [mm]."""
        self.stream.log("series/tof/range_mm", rr.Scalars(float(range_mm)))
