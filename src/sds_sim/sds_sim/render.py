"""Frames as the rig's camera records them, with the exact truth of what was drawn."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from sds_model.camera.rolling_shutter import RollingShutter
from sds_model.geometry import RigidTransform

from sds_sim.optics import line_laser_rays, ray_surface_points, wall_reflections
from sds_sim.scenario import Disturbances, Scenario
from sds_sim.surface import Surface

PSF_SIGMA_PX = 0.5
"""Lens and sensor blur added to every spot and line width [px at full resolution]."""
NOISE_BANK_MARGIN_PX = 64
ROW_TIME_ITERATIONS = 3
"""Fixed-point steps to the row a moving spot is exposed in (converged to 1e-6 px)."""
SATURATION_BLEED = 0.6
"""Share of the red excess above 255 spilling into green and blue (saturated spots look white)."""


Bounds = tuple[int, int, int, int]
"""A window's rows and columns: y0, y1, x0, x1 (ends excluded)."""
Window = tuple[Bounds, np.ndarray]


@dataclass(frozen=True)
class FrameTruth:
    """What one frame shows, exactly: per diode (N rows) and per image row for the line."""

    index: int
    time_s: float
    spot_px: np.ndarray           # N×2 spot centres at their row's time (mid-exposure)
    spot_exposure_px: np.ndarray  # N×2 intensity centroid over the exposure (motion blur)
    spot_mm: np.ndarray           # N×3 world points where the beams meet the liquid then
    visible: np.ndarray           # N, False while occluded or off the liquid
    reflection_px: np.ndarray     # N×2 wall reflections (NaN: none drawn)
    line_rows: np.ndarray         # image rows the line crosses
    line_x_px: np.ndarray         # line centre per row at that row's time
    line_mm: np.ndarray           # M×3 world points of the line at their rows' times
    led_on: bool
    vibration_rad: np.ndarray     # camera roll-off about its x, y axes
    spot_time_s: np.ndarray       # N: when each spot's centre is exposed (its row's time)
    line_time_s: np.ndarray       # per line row: when that row is exposed
    gain: float = 1.0             # the auto exposure's gain on the whole frame
    glint_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # one-frame glints


def vibration_rad(d: Disturbances, time_s: float) -> np.ndarray:
    """The camera's launch vibration at a time: roll-off about its x and y axes [rad]."""
    if d.vibration_start_s is None or time_s < d.vibration_start_s:
        return np.zeros(2)
    tau = time_s - d.vibration_start_s
    envelope = np.radians(d.vibration_amplitude_deg) * np.exp(-tau / d.vibration_decay_s)
    phase = 2 * np.pi * d.vibration_frequency_hz * tau
    return envelope * np.array([np.sin(phase), 0.6 * np.sin(1.3 * phase)])


class FrameRenderer:
    """Draws scenario frames: background once, then per frame only the lasers' regions."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.camera = scenario.rig.camera.scaled(scenario.scale)
        self.width, self.height = self.camera.width_px, self.camera.height_px
        self.rng = np.random.default_rng(scenario.seed)
        rig = scenario.rig
        self.emitters = np.array([d.emitter_mm for d in rig.diodes])
        self.directions = np.array([d.direction for d in rig.diodes])
        self.line_directions = (line_laser_rays(rig.line_laser, rig.container.radius_mm,
                                                scenario.optics.line_rays)
                                if rig.line_laser is not None else np.zeros((0, 3)))
        sensor = scenario.sensor
        self.shutter = RollingShutter(sensor.readout_s, sensor.readout_direction)
        self.falloff = self._falloff()
        self.background = self._background()
        self.occluded = self._occlusions()
        self.gains = self._gains()
        sigma = scenario.sensor.read_noise
        margin = NOISE_BANK_MARGIN_PX
        bank = self.rng.normal(0.0, sigma, (self.height + margin, self.width + margin, 3))
        bank = bank.astype(np.float32)
        self._noise_up = np.clip(bank, 0, 255).astype(np.uint8)
        self._noise_down = np.clip(-bank, 0, 255).astype(np.uint8)

    def pose_at(self, time_s: float) -> tuple[RigidTransform, np.ndarray]:
        """World → camera at a time, with the launch vibration; and the vibration angles [rad]."""
        angles = vibration_rad(self.scenario.disturbances, time_s)
        base = self.scenario.rig.world_to_camera
        if not angles.any():
            return base, angles
        shake = RigidTransform.from_rotation_vector([angles[0], angles[1], 0.0], np.zeros(3))
        return shake.compose(base), angles

    def _falloff(self) -> np.ndarray | None:
        """Per pixel, the light's share that reaches the sensor (H×W): vignetting (a
        quadratic fall to 1 − `vignetting` at the corners) times the ambient light's linear
        gradient across the frame (± `ambient_gradient` / 2, in a seeded direction); None
        where both are 0. The gradient scales the whole scene: a lamp beside the rig."""
        sensor = self.scenario.sensor
        if not sensor.vignetting and not sensor.ambient_gradient:
            return None
        # A row and a column, broadcast: the same values as full grids, without their memory.
        xs = np.arange(self.width, dtype=np.float32)[np.newaxis, :]
        ys = np.arange(self.height, dtype=np.float32)[:, np.newaxis]
        u = (xs - (self.width - 1) / 2) / (self.width / 2)
        v = (ys - (self.height - 1) / 2) / (self.height / 2)
        falloff = 1.0 - sensor.vignetting * (u**2 + v**2) / 2.0
        if sensor.ambient_gradient:
            angle = self.rng.uniform(0.0, 2 * np.pi)
            along = (np.cos(angle) * u + np.sin(angle) * v) / np.sqrt(2.0)
            falloff *= 1.0 + sensor.ambient_gradient / 2 * along
        return falloff.astype(np.float32)

    def _gains(self) -> np.ndarray:
        """The auto exposure's gain per frame: a log random walk of `gain_step` per frame,
        held within `gain_range` (all 1 without a step)."""
        sensor = self.scenario.sensor
        count = self.scenario.frame_count
        if not sensor.gain_step:
            return np.ones(count)
        low, high = np.log(sensor.gain_range)
        gains = np.zeros(count)
        for index in range(1, count):
            gains[index] = np.clip(gains[index - 1] + self.rng.normal(0.0, sensor.gain_step),
                                   low, high)
        return np.exp(gains)

    def _background(self) -> np.ndarray:
        """Static scene: dim textured surroundings, black liquid, the container's rim."""
        level = self.scenario.sensor.background
        coarse = self.rng.normal(0.0, 1.0, (self.height // 8 + 1, self.width // 8 + 1))
        texture = cv2.resize(coarse.astype(np.float32), (self.width, self.height),
                             interpolation=cv2.INTER_CUBIC)
        image = level * (1.0 + 0.15 * texture)
        rim_px = self.scenario.rig.rim_px(self.camera, samples=721)
        mask = np.zeros((self.height, self.width), np.uint8)
        if np.isfinite(rim_px).all():
            polygon = np.round(rim_px * 16).astype(np.int32)
            cv2.fillPoly(mask, [polygon], 1, lineType=cv2.LINE_AA, shift=4)
            image[mask > 0] *= 0.45
            thickness = max(1, round(3 * self.scale))
            cv2.polylines(image, [polygon], True, 1.8 * level, thickness=thickness,
                          lineType=cv2.LINE_AA, shift=4)
        if self.falloff is not None:
            image *= self.falloff
        gray = np.clip(np.round(image), 0, 255).astype(np.uint8)
        return np.dstack([gray, gray, gray])

    @property
    def scale(self) -> float:
        """Image scale relative to the camera file's sensor."""
        return self.scenario.scale

    def _occlusions(self) -> np.ndarray:
        """frames × diodes: True where a diode's spot is hidden (seeded, reproducible)."""
        s = self.scenario
        hidden = np.zeros((s.frame_count, len(s.rig.diodes)), dtype=bool)
        rate = s.disturbances.occlusion_rate_per_s
        if rate <= 0:
            return hidden
        shortest, longest = s.disturbances.occlusion_frames
        for diode in range(hidden.shape[1]):
            count = self.rng.poisson(rate * s.duration_s)
            for start in self.rng.integers(0, s.frame_count, count):
                hidden[start: start + self.rng.integers(shortest, longest + 1), diode] = True
        return hidden

    def _spots(self, surface: Surface, pose: RigidTransform, time_s: float | np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        points = ray_surface_points(surface, self.emitters, self.directions, time_s)
        return points, self.camera.project(pose.apply(points))

    def _footprint(self, points: np.ndarray, pose: RigidTransform, size_mm: float) -> np.ndarray:
        """Image covariance (N×2×2 px²) of a round footprint of `size_mm` (4σ) on the liquid."""
        sigma_mm = size_mm / 4.0
        centre = self.camera.project(pose.apply(points))
        jx = self.camera.project(pose.apply(points + np.array([sigma_mm, 0, 0]))) - centre
        jy = self.camera.project(pose.apply(points + np.array([0, sigma_mm, 0]))) - centre
        jacobian = np.stack([jx, jy], axis=2)
        psf = (PSF_SIGMA_PX * self.scale) ** 2 * np.eye(2)
        return jacobian @ np.transpose(jacobian, (0, 2, 1)) + psf

    def render(self, index: int) -> tuple[np.ndarray, FrameTruth]:
        """Frame `index` (BGR uint8) and its truth."""
        s = self.scenario
        time_s = index / s.fps
        optics = s.optics
        samples = time_s + optics.exposure_s * ((np.arange(optics.blur_samples) + 0.5)
                                                / optics.blur_samples - 0.5)
        surface = s.surface_at(time_s)
        pose, vibration = self.pose_at(time_s)
        delays = self._spot_delays(surface, pose, time_s)
        spot_mm, spot_px = self._spots(surface, pose, time_s + delays)
        visible = np.isfinite(spot_px).all(axis=1) & ~self.occluded[index]
        red = _Layer(self.height, self.width)
        exposure_px = np.zeros_like(spot_px)
        covariance = self._footprint(spot_mm, pose, optics.spot_diameter_mm)
        reflection_px = np.full_like(spot_px, np.nan)
        line_rows, line_x = np.zeros(0, int), np.zeros(0)
        line_mm = np.zeros((0, 3))
        for t in samples:
            surface_t = s.surface_at(t)
            pose_t, _ = self.pose_at(t)
            points, pixels = self._spots(surface_t, pose_t, t + delays)
            exposure_px += pixels / len(samples)
            for i in np.flatnonzero(visible & np.isfinite(pixels).all(axis=1)):
                red.gaussian(pixels[i], covariance[i], optics.spot_peak / len(samples))
            if s.disturbances.reflection_strength > 0:
                wall = wall_reflections(surface_t, points, self.directions, t + delays,
                                        s.rig.container.height_mm - s.rig.container.fill_height_mm)
                wall_px = self.camera.project(pose_t.apply(wall))
                for i in np.flatnonzero(visible & np.isfinite(wall_px).all(axis=1)):
                    red.gaussian(wall_px[i], covariance[i] * 2.0, optics.spot_peak *
                                 s.disturbances.reflection_strength / len(samples))
                    reflection_px[i] = wall_px[i]
            if len(self.line_directions):
                rows, x_px, width = self._line(self._timed_line_points(surface_t, pose_t, t),
                                               pose_t)
                red.line(rows, x_px, width, optics.line_peak / len(samples))
        if len(self.line_directions):
            line_mm = self._timed_line_points(surface, pose, time_s)
            line_rows, line_x, _ = self._line(line_mm, pose)
        if optics.speckle > 0:
            red.speckle(self.rng, optics.speckle, optics.speckle_grain_px)
        glint_px = self._glints(red, surface, pose, time_s)
        led_y = s.events.led_position_px[1] * self.scale
        led_time_s = time_s + float(self.shutter.row_time_s(led_y, self.height))
        led = s.events.led_on_s <= led_time_s < s.events.led_off_s
        gain = float(self.gains[min(index, len(self.gains) - 1)])
        frame = self._compose(red, vibration, led, gain)
        truth = FrameTruth(index, time_s, spot_px, exposure_px, spot_mm, visible, reflection_px,
                           line_rows, line_x, line_mm, led, vibration, time_s + delays,
                           time_s + self.shutter.row_time_s(line_rows, self.height), gain,
                           glint_px)
        return frame, truth

    def _glints(self, red: _Layer, surface: Surface, pose: RigidTransform, time_s: float
                ) -> np.ndarray:
        """One-frame glints (ambient light off the moving liquid, foam): a Poisson number at
        `glint_rate_per_s`, at uniform points of the liquid, each a point of light blurred by
        the lens, up to `glint_peak`; their pixels (K×2)."""
        d = self.scenario.disturbances
        if d.glint_rate_per_s <= 0:
            return np.zeros((0, 2))
        count = self.rng.poisson(d.glint_rate_per_s / self.scenario.fps)
        radius_mm = surface.radius_mm * np.sqrt(self.rng.uniform(0.0, 1.0, count))
        azimuth = self.rng.uniform(0.0, 2 * np.pi, count)
        x_mm, y_mm = radius_mm * np.cos(azimuth), radius_mm * np.sin(azimuth)
        points = np.column_stack([x_mm, y_mm, surface.height(x_mm, y_mm, time_s)])
        pixels = self.camera.project(pose.apply(points)).reshape(-1, 2)
        sigma_px = max(PSF_SIGMA_PX * self.scale, 0.4) * 1.5
        for pixel in pixels[np.isfinite(pixels).all(axis=1)]:
            red.gaussian(pixel, sigma_px**2 * np.eye(2), d.glint_peak * self.rng.uniform(0.3, 1))
        return pixels

    def _spot_delays(self, surface: Surface, pose: RigidTransform, time_s: float
                     ) -> np.ndarray:
        """How long after the frame's time each spot's row is exposed [s] (zeros for a global
        shutter): the row where the spot is then, found by fixed-point iteration (a spot
        moves a fraction of a pixel during the readout's few ms)."""
        delays = np.zeros(len(self.emitters))
        if not self.shutter.readout_s:
            return delays
        for _ in range(ROW_TIME_ITERATIONS):
            _, pixels = self._spots(surface, pose, time_s + delays)
            delays = np.nan_to_num(self.shutter.row_time_s(pixels[:, 1], self.height))
        return delays

    def _timed_line_points(self, surface: Surface, pose: RigidTransform, time_s: float
                           ) -> np.ndarray:
        """The line's world points, each at the time its row is exposed (see _spot_delays)."""
        times = np.full(len(self.line_directions), time_s)
        points = self._line_points(surface, times)
        if not self.shutter.readout_s:
            return points
        for _ in range(ROW_TIME_ITERATIONS):
            rows = self.camera.project(pose.apply(points))[:, 1]
            times = time_s + np.nan_to_num(self.shutter.row_time_s(rows, self.height))
            points = self._line_points(surface, times)
        return points

    def _line_points(self, surface: Surface, time_s: float | np.ndarray) -> np.ndarray:
        line = self.scenario.rig.line_laser
        if line is None:   # a rig without a line laser: no line points
            return np.zeros((0, 3))
        origins = np.repeat(line.emitter_mm[None, :], len(self.line_directions), axis=0)
        return ray_surface_points(surface, origins, self.line_directions, time_s)

    def _line(self, points: np.ndarray, pose: RigidTransform
              ) -> tuple[np.ndarray, np.ndarray, float]:
        """Rows the line's world points cross, its centre per row [px], its Gaussian σ [px]."""
        pixels = self.camera.project(pose.apply(points))
        pixels = pixels[np.isfinite(pixels).all(axis=1)]
        if len(pixels) < 2:
            return np.zeros(0, int), np.zeros(0), 1.0
        order = np.argsort(pixels[:, 1])
        ys, xs = pixels[order, 1], pixels[order, 0]
        rows = np.arange(int(np.ceil(ys[0])), int(np.floor(ys[-1])) + 1)
        rows = rows[(rows >= 0) & (rows < self.height)]
        centre = points[np.isfinite(points).all(axis=1)][len(pixels) // 2]
        across = self.camera.project(pose.apply(np.array([centre, centre + np.array([1.0, 0, 0])])))
        px_per_mm = float(np.linalg.norm(across[1] - across[0]))
        width = np.hypot(self.scenario.optics.line_width_mm / 4 * px_per_mm,
                         PSF_SIGMA_PX * self.scale)
        return rows, np.interp(rows, ys, xs), width

    def _compose(self, red: _Layer, vibration: np.ndarray, led: bool, gain: float = 1.0
                 ) -> np.ndarray:
        """The frame: the background (shaken, times the gain), the lasers' light (through
        the falloff, times the gain, with shot noise, the halo of what saturates, the excess
        bleeding into green and blue), the LED, read noise."""
        frame = self.background.copy() if gain == 1.0 else \
            cv2.convertScaleAbs(self.background, alpha=gain)
        sensor = self.scenario.sensor
        if vibration.any():
            shift = self._vibration_shift(vibration)
            frame = cv2.warpAffine(frame, np.array([[1, 0, shift[0]], [0, 1, shift[1]]]),
                                   (self.width, self.height), borderMode=cv2.BORDER_REFLECT)
        bloom_px = sensor.bloom_sigma_px * self.scale
        pad = int(np.ceil(3 * bloom_px)) if sensor.bloom_fraction > 0 else 0
        for (y0, y1, x0, x1), values in red.windows():
            if self.falloff is not None:
                values = values * self.falloff[y0:y1, x0:x1]
            values = values * np.float32(gain)
            if sensor.shot_noise:
                values = values + np.sqrt(np.maximum(values, 0)) * \
                    self.rng.standard_normal(values.shape).astype(np.float32)
            if pad:
                (y0, y1, x0, x1), values = self._bloom(frame, (y0, y1, x0, x1), values, pad,
                                                       bloom_px)
            region = frame[y0:y1, x0:x1].astype(np.float32)
            region[..., 2] += values
            excess = np.maximum(region[..., 2] - 255.0, 0.0) * SATURATION_BLEED
            region[..., 0] += excess
            region[..., 1] += excess
            frame[y0:y1, x0:x1] = np.clip(np.round(region), 0, 255).astype(np.uint8)
        if led:
            centre = np.array(self.scenario.events.led_position_px) * self.scale
            cv2.circle(frame, tuple(int(v) for v in centre), max(2, round(8 * self.scale)),
                       (255, 255, 255), -1, lineType=cv2.LINE_AA)
        if self.scenario.sensor.read_noise > 0:
            dy, dx = self.rng.integers(0, NOISE_BANK_MARGIN_PX, 2)
            window = (slice(dy, dy + self.height), slice(dx, dx + self.width))
            cv2.add(frame, self._noise_up[window], dst=frame)
            cv2.subtract(frame, self._noise_down[window], dst=frame)
        return frame

    def _bloom(self, frame: np.ndarray, bounds: Bounds, values: np.ndarray, pad: int,
               sigma_px: float) -> Window:
        """A window's light widened by `pad` px with the halo of its saturated part: the
        red light beyond 255 over the frame, times `bloom_fraction`, spread by a Gaussian
        of `sigma_px`."""
        y0, y1, x0, x1 = bounds
        p0, p1 = max(y0 - pad, 0), min(y1 + pad, self.height)
        q0, q1 = max(x0 - pad, 0), min(x1 + pad, self.width)
        padded = np.zeros((p1 - p0, q1 - q0), np.float32)
        padded[y0 - p0:y1 - p0, x0 - q0:x1 - q0] = values
        excess = np.maximum(frame[p0:p1, q0:q1, 2].astype(np.float32) + padded - 255.0, 0.0)
        halo = cv2.GaussianBlur(excess, (0, 0), sigma_px, borderType=cv2.BORDER_CONSTANT)
        return (p0, p1, q0, q1), padded + self.scenario.sensor.bloom_fraction * halo

    def _vibration_shift(self, vibration: np.ndarray) -> np.ndarray:
        """Image shift [px] of the scene's centre under the vibration (moves the background)."""
        still = self.scenario.rig.world_to_camera
        shaken = RigidTransform.from_rotation_vector([*vibration, 0.0], np.zeros(3)).compose(still)
        point = np.array([[0.0, 0.0, 0.0]])
        moved = self.camera.project(shaken.apply(point)) - self.camera.project(still.apply(point))
        return moved[0]


class _Layer:
    """Sparse float32 light layer: small windows, merged per frame, added to the background."""

    def __init__(self, height: int, width: int) -> None:
        self.height, self.width = height, width
        self._windows: list[Window] = []

    def _window(self, x0: float, x1: float, y0: float, y1: float) -> Bounds | None:
        bounds = (max(0, int(np.floor(y0))), min(self.height, int(np.ceil(y1)) + 1),
                  max(0, int(np.floor(x0))), min(self.width, int(np.ceil(x1)) + 1))
        return bounds if bounds[0] < bounds[1] and bounds[2] < bounds[3] else None

    def gaussian(self, centre: np.ndarray, covariance: np.ndarray, peak: float) -> None:
        """Add an anisotropic Gaussian (covariance in px²) of height `peak`."""
        reach = 4.5 * np.sqrt(np.max(np.linalg.eigvalsh(covariance)))
        bounds = self._window(centre[0] - reach, centre[0] + reach, centre[1] - reach,
                              centre[1] + reach)
        if bounds is None:
            return
        y0, y1, x0, x1 = bounds
        ys, xs = np.mgrid[y0:y1, x0:x1]
        d = np.stack([xs - centre[0], ys - centre[1]], axis=-1)
        inverse = np.linalg.inv(covariance)
        exponent = np.einsum("...i,ij,...j->...", d, inverse, d)
        self._windows.append((bounds, (peak * np.exp(-0.5 * exponent)).astype(np.float32)))

    def line(self, rows: np.ndarray, x_px: np.ndarray, sigma_px: float, peak: float) -> None:
        """Add a line: per row a Gaussian profile across columns centred at x_px."""
        if len(rows) == 0:
            return
        reach = 4.5 * sigma_px
        bounds = self._window(x_px.min() - reach, x_px.max() + reach, rows[0], rows[-1])
        if bounds is None:
            return
        y0, y1, x0, x1 = bounds
        inside = (rows >= y0) & (rows < y1)
        columns = np.arange(x0, x1)
        profile = np.zeros((y1 - y0, x1 - x0), np.float32)
        d = columns[None, :] - x_px[inside][:, None]
        profile[rows[inside] - y0] = peak * np.exp(-0.5 * (d / sigma_px) ** 2)
        self._windows.append((bounds, profile))

    def speckle(self, rng: np.random.Generator, contrast: float, grain_px: float) -> None:
        """Multiply every window by laser speckle: the intensity of a random complex field
        correlated over `grain_px` (the blur's σ), whose statistics are exponential (fully
        developed: contrast 1), mixed with its mean to the given `contrast` (σ / mean)."""
        for index, (bounds, values) in enumerate(self._windows):
            field_re, field_im = (cv2.GaussianBlur(
                rng.standard_normal(values.shape).astype(np.float32), (0, 0), grain_px)
                for _ in range(2))
            intensity = field_re**2 + field_im**2
            intensity /= max(float(intensity.mean()), 1e-12)
            self._windows[index] = (bounds, values * (1 + contrast * (intensity - 1)))

    def windows(self) -> list[Window]:
        """Each window's bounds (y0, y1, x0, x1) and values, overlapping windows merged."""
        merged: dict[Bounds, np.ndarray] = {}
        for bounds, values in self._windows:
            merged[bounds] = merged[bounds] + values if bounds in merged else values
        boxes = list(merged.items())
        if not boxes:
            return []
        y0 = min(b[0] for b, _ in boxes)
        y1 = max(b[1] for b, _ in boxes)
        x0 = min(b[2] for b, _ in boxes)
        x1 = max(b[3] for b, _ in boxes)
        area = sum((b[1] - b[0]) * (b[3] - b[2]) for b, _ in boxes)
        if area * 4 > (y1 - y0) * (x1 - x0):   # dense: one canvas
            canvas = np.zeros((y1 - y0, x1 - x0), np.float32)
            for (a0, a1, b0, b1), values in boxes:
                canvas[a0 - y0:a1 - y0, b0 - x0:b1 - x0] += values
            return [((y0, y1, x0, x1), canvas)]
        return _disjoint(boxes)


def _disjoint(boxes: list[Window]) -> list[Window]:
    """Merge overlapping windows so each pixel is written once."""
    boxes = sorted(boxes, key=lambda item: item[0][0])
    result: list[Window] = []
    while boxes:
        (y0, y1, x0, x1), values = boxes.pop(0)
        merged = True
        while merged:
            merged = False
            for index, ((a0, a1, b0, b1), other) in enumerate(boxes):
                if a0 < y1 and y0 < a1 and b0 < x1 and x0 < b1:
                    n0, n1, m0, m1 = min(y0, a0), max(y1, a1), min(x0, b0), max(x1, b1)
                    canvas = np.zeros((n1 - n0, m1 - m0), np.float32)
                    canvas[y0 - n0:y1 - n0, x0 - m0:x1 - m0] += values
                    canvas[a0 - n0:a1 - n0, b0 - m0:b1 - m0] += other
                    (y0, y1, x0, x1), values = (n0, n1, m0, m1), canvas
                    boxes.pop(index)
                    merged = True
                    break
        result.append(((y0, y1, x0, x1), values))
    return result
