"""The side camera's frames (seed Sec. 3): the container from the side, back-lit, at its own
rate and clock, the liquid's contact line on the wall from the same surface as the top view.

Each pixel's ray comes from the true side camera (its view file's intrinsics off by
`intrinsics_off_sigmas` of their σ, its true pose). A ray sees the liquid when, anywhere
along its path through the container, it runs below the surface: at the front wall below the
contact line, or further in where the surface rises above it. In every column the boundary
row between the two is found by bisection (exact to 1e-3 px) and drawn as a step blurred by
the lens (a Gaussian of `psf_sigma_px`) and integrated over the pixel; read noise and H.264
follow. The sync LED is on in a frame whose time (on the top camera's clock) falls within the
blink. The container's bottom and the wall's edges seen edge-on are darker; the LED sits in
a dark mount.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.special import ndtr
from sds_lateral.view import BoardPlacement, LateralView, load_lateral_view
from sds_model.camera.model import CameraModel
from sds_model.errors import InputError
from sds_model.geometry import RigidTransform

from sds_sim.scenario import LateralSpec, Scenario

BISECTION_STEPS = 18
"""Halvings of each column's band (a 120 px band: 5e-4 px)."""
CHORD_SAMPLES = 33
"""Points along a ray's path through the container where it is tested against the surface."""
BOARD_SUPERSAMPLING = 3
"""Samples per pixel side when the checkerboard is drawn."""
EDGE_ON_DEG = 80.0
"""The wall is seen as its dark edge where the ray meets it this obliquely."""
LED_RADIUS_PX = 6.0
LED_HOUSING_PX = 40
"""Side of the dark square the LED sits in (its mount), so that it switches against black."""


def look_at(position_mm: np.ndarray, target_mm: np.ndarray, roll_deg: float) -> RigidTransform:
    """World → camera for a camera at `position_mm` looking at `target_mm`, image x level
    (along the horizontal to the right of the view), turned by `roll_deg` about its axis."""
    forward = np.asarray(target_mm, float) - np.asarray(position_mm, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    roll = np.radians(roll_deg)
    right, down = (np.cos(roll) * right + np.sin(roll) * down,
                   -np.sin(roll) * right + np.cos(roll) * down)
    rotation = np.vstack([right, down, forward])
    return RigidTransform(rotation, -rotation @ np.asarray(position_mm, float))


@dataclass(frozen=True)
class LateralTruth:
    """What one side frame shows: its index, its time on its own clock and on the top camera's
    [s], the contact line's row per column (NaN outside the container) and the LED."""

    index: int
    lateral_time_s: float
    time_s: float
    edge_row_px: np.ndarray
    led_on: bool


def true_camera(view: LateralView, spec: LateralSpec, seed: int) -> CameraModel:
    """The side camera as it is: each intrinsic with a σ in its file off by
    `spec.intrinsics_off_sigmas` of it, with a seeded random sign."""
    rng = np.random.default_rng(seed)
    changes = {name: spec.intrinsics_off_sigmas * sigma * rng.choice([-1.0, 1.0])
               for name, sigma in sorted(view.camera_sigma.items())}
    return view.camera.with_intrinsics(changes)


class LateralRenderer:
    """Draws a scenario's side frames and the checkerboard image (static scene drawn once)."""

    def __init__(self, scenario: Scenario) -> None:
        if scenario.lateral is None:
            raise InputError("the scenario has no side camera (its `lateral:` section)")
        self.scenario, self.spec = scenario, scenario.lateral
        self.view = load_lateral_view(self.spec.view_file)
        self.camera = true_camera(self.view, self.spec, scenario.seed + 7919)
        self.pose = look_at(np.array(self.spec.position_mm), np.array(self.spec.look_at_mm),
                            self.spec.roll_deg)
        offset = np.asarray(self.spec.board_offset_mm, float)
        self.boards = tuple(replace(board, first_corner_mm=board.first_corner_mm + offset)
                            for board in self.view.boards)
        self.width, self.height = self.camera.width_px, self.camera.height_px
        self.radius_mm = scenario.rig.container.radius_mm
        self.centre_mm = self.pose.inverse().translation_mm
        self.rng = np.random.default_rng(scenario.seed + 104729)
        self.fps = self.view.fps
        duration = scenario.duration_s - self.spec.clock_offset_s
        self.frame_count = max(0, int(np.floor(duration * self.fps / self._rate())) + 1)
        self.empty, self.background = self._background()
        self._columns_and_band()

    def _rate(self) -> float:
        """Top-clock seconds per side-clock second (the side clock's drift)."""
        return 1.0 + self.spec.clock_drift_ppm * 1e-6

    def time_s(self, index: int) -> float:
        """Frame `index`'s time on the top camera's clock [s]."""
        return self.spec.clock_offset_s + index / self.fps * self._rate()

    def _rays(self, pixels: np.ndarray) -> np.ndarray:
        """World directions of the true camera's pixel rays (N×3)."""
        return self.camera.pixel_to_ray(pixels) @ self.pose.rotation

    def _chord(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each ray's entry and exit distance through the container's cylinder (NaN: misses)."""
        a = rays[:, 0] ** 2 + rays[:, 1] ** 2
        b = 2 * (self.centre_mm[0] * rays[:, 0] + self.centre_mm[1] * rays[:, 1])
        c = self.centre_mm[0] ** 2 + self.centre_mm[1] ** 2 - self.radius_mm**2
        with np.errstate(invalid="ignore", divide="ignore"):
            root = np.sqrt(b**2 - 4 * a * c)
            return (-b - root) / (2 * a), (-b + root) / (2 * a)

    def _background(self) -> tuple[np.ndarray, np.ndarray]:
        """The scene without the liquid (back-light, the container's bottom, the wall's edges),
        and with the liquid below the flat level (the frames' band is drawn over it)."""
        rows, columns = np.mgrid[0:self.height, 0:self.width]
        pixels = np.column_stack([columns.ravel(), rows.ravel()]).astype(float)
        rays = self._rays(pixels)
        entry, _ = self._chord(rays)
        front = self.centre_mm + entry[:, None] * rays
        light = self.spec.background * (1.0 - 0.12 * ((pixels[:, 0] / self.width - 0.5) ** 2
                                                       + (pixels[:, 1] / self.height - 0.5) ** 2))
        image = light.copy()
        inside = np.isfinite(entry)
        normal = np.column_stack([front[:, 0], front[:, 1]]) / self.radius_mm
        cosine = -np.sum(normal * rays[:, :2], axis=1) / np.linalg.norm(rays, axis=1)
        edge_on = inside & (cosine < np.cos(np.radians(EDGE_ON_DEG)))
        image[edge_on] *= 0.45
        bottom = -self.scenario.rig.container.fill_height_mm
        image[inside & (front[:, 2] < bottom)] = 0.35 * self.spec.background   # the base
        image = image.reshape(self.height, self.width)
        x, y = (round(v - LED_HOUSING_PX / 2) for v in self.spec.led_position_px)
        image[max(y, 0):y + LED_HOUSING_PX, max(x, 0):x + LED_HOUSING_PX] = self.spec.liquid
        empty = image.copy()
        image = image.ravel()
        image[inside & (front[:, 2] < 0.0) & (front[:, 2] >= bottom) & ~edge_on] = \
            self.spec.liquid
        return empty, image.reshape(self.height, self.width)

    def _columns_and_band(self) -> None:
        """The columns that see the container, and each one's band of rows around the flat
        level that holds the contact line at any time."""
        bound = 2.0 + max(self.scenario.surface_at(t).bound_mm()
                          for t in np.linspace(0.0, self.scenario.duration_s, 25))
        columns = np.arange(self.width, dtype=float)
        middle = np.full(self.width, self.height / 2.0)
        rays = self._rays(np.column_stack([columns, middle]))
        entry, _ = self._chord(rays)
        seen = np.isfinite(entry)
        self.columns = columns[seen].astype(int)
        rows = []
        for height in (bound, -bound):
            point = self.centre_mm + entry[seen, None] * rays[seen]
            point[:, 2] = height
            rows.append(self.camera.project(self.pose.apply(point))[:, 1])
        self.band_top = np.clip(np.floor(np.minimum(*rows)) - 3, 0, self.height - 1)
        self.band_bottom = np.clip(np.ceil(np.maximum(*rows)) + 3, 0, self.height - 1)

    def _liquid(self, column: np.ndarray, row: np.ndarray, time_s: float) -> np.ndarray:
        """Whether each pixel's ray runs below the surface anywhere in the container."""
        rays = self._rays(np.column_stack([column, row]))
        entry, exit_ = self._chord(rays)
        fraction = np.linspace(0.0, 1.0, CHORD_SAMPLES)
        distance = entry[:, None] + (exit_ - entry)[:, None] * fraction[None, :]
        points = self.centre_mm + distance[..., None] * rays[:, None, :]
        surface = self.scenario.surface_at(time_s)
        height = surface.height(points[..., 0], points[..., 1], time_s)
        return np.any(points[..., 2] < height, axis=1)

    def edge_rows(self, time_s: float) -> np.ndarray:
        """The contact line's row in each of `self.columns` at a time (bisection)."""
        low = self.band_top.copy()        # above the line: no liquid
        high = self.band_bottom.copy()    # below it: liquid
        columns = self.columns.astype(float)
        for _ in range(BISECTION_STEPS):
            middle = (low + high) / 2
            liquid = self._liquid(columns, middle, time_s)
            high = np.where(liquid, middle, high)
            low = np.where(liquid, low, middle)
        return (low + high) / 2

    def render(self, index: int) -> tuple[np.ndarray, LateralTruth]:
        """Side frame `index` (BGR, grey) and its truth."""
        time_s = self.time_s(index)
        edge = self.edge_rows(time_s)
        image = self.background.copy()
        top, bottom = int(self.band_top.min()), int(self.band_bottom.max()) + 1
        rows = np.arange(top, bottom, dtype=float)[:, None]
        spread = np.hypot(self.spec.psf_sigma_px, np.sqrt(1 / 12))
        lit = ndtr((edge[None, :] - rows) / spread)           # 1 above the line, 0 below
        band = self.empty[top:bottom, self.columns]
        image[top:bottom, self.columns] = self.spec.liquid + (band - self.spec.liquid) * lit
        events = self.scenario.events
        led_on = events.led_on_s <= time_s < events.led_off_s
        if led_on:
            x, y = self.spec.led_position_px
            cv2.circle(image, (round(x), round(y)), round(LED_RADIUS_PX), 255.0, -1,
                       lineType=cv2.LINE_AA)
        if self.spec.read_noise > 0:
            image = image + self.rng.normal(0.0, self.spec.read_noise, image.shape)
        grey = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        edge_rows = np.full(self.width, np.nan)
        edge_rows[self.columns] = edge
        return (np.dstack([grey, grey, grey]),
                LateralTruth(index, index / self.fps, time_s, edge_rows, led_on))

    def board_images(self) -> list[np.ndarray]:
        """The checkerboard at each of its true places in the empty container, as the camera
        sees it (BGR): white squares and margin, lit from behind like the rest of the scene."""
        return [render_board(self.camera, self.pose, board, self.empty, self.rng,
                             self.spec.read_noise) for board in self.boards]


def render_board(camera: CameraModel, pose: RigidTransform, placement: BoardPlacement,
                 background: np.ndarray, rng: np.random.Generator, read_noise: float
                 ) -> np.ndarray:
    """A checkerboard with (columns + 1) × (rows + 1) squares and a one-square white margin,
    drawn over `background` (supersampled, then the noise): BGR."""
    height, width = background.shape
    step = 1.0 / BOARD_SUPERSAMPLING
    offsets = (np.arange(BOARD_SUPERSAMPLING) + 0.5) * step - 0.5
    columns, rows = placement.board.columns, placement.board.rows
    square_mm = placement.board.square_mm
    total = np.zeros((height, width))
    centre = pose.inverse().translation_mm
    for dy in offsets:
        for dx in offsets:
            grid_y, grid_x = np.mgrid[0:height, 0:width]
            pixels = np.column_stack([grid_x.ravel() + dx, grid_y.ravel() + dy]).astype(float)
            rays = camera.pixel_to_ray(pixels) @ pose.rotation
            normal = placement.normal
            with np.errstate(invalid="ignore", divide="ignore"):
                distance = ((placement.first_corner_mm - centre) @ normal) / (rays @ normal)
            points = centre + distance[:, None] * rays - placement.first_corner_mm
            along = points @ placement.row_direction / square_mm
            down = points @ placement.column_direction / square_mm
            i, j = np.floor(along), np.floor(down)
            on_squares = (i >= -1) & (i < columns) & (j >= -1) & (j < rows)
            on_margin = (i >= -2) & (i < columns + 1) & (j >= -2) & (j < rows + 1)
            value = background.ravel().copy()
            value[on_margin] = 235.0
            value[on_squares & ((i + j) % 2 == 0)] = 25.0
            total += value.reshape(height, width)
    image = total / BOARD_SUPERSAMPLING**2 + rng.normal(0.0, read_noise, (height, width))
    grey = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return np.dstack([grey, grey, grey])
