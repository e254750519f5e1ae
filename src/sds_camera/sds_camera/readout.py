"""The rolling shutter's readout time, measured from a video of a flickering light.

A lamp on AC mains (100 or 120 Hz) or an LED driven at a known frequency `f` lights the scene;
a rolling shutter exposes row y at `readout_s · y / H` after the first (`RollingShutter`), so
each frame shows horizontal bands: the light's phase advances by 2π f readout_s / H per row.
Each frame's row means, divided by their mean over the clip (the scene's own brightness per
row), are a periodic function of the row with spatial frequency k = f · readout_s / H cycles
per row, and an unknown phase per frame (the frames' times need not be known). k is the one
nonlinear parameter: for each k the bands' amplitude and phase in every frame are linear least
squares, and k minimises the total squared residual (a grid over readouts, then Brent's
method). Only the fundamental is fitted: with harmonics, half the true k would fit as well (its
second harmonic is the true fundamental); an LED's square wave leaves its harmonics in the
residual, whatever k. σ comes from the cost's curvature and the residual's scatter, widened for
neighbouring rows that err alike. The exposure must be shorter than the flicker period (whole
periods average the bands away), and the flicker no multiple of the frame rate (the bands
would stand still, indistinguishable from the scene).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar
from sds_model.errors import InputError

from sds_camera.frame_source import VideoFileSource

GRID_STEP_S = 0.2e-3
"""Readout step of the coarse search [s]."""
LEAST_CONTRAST = 0.01
"""Smallest band amplitude (a share of the mean) that counts as flicker seen."""
STANDING_CYCLES = 0.05
"""Flicker cycles per frame this close to a whole number make the bands stand (nearly) still."""


@dataclass(frozen=True)
class ReadoutEstimate:
    """The measured readout [s] and its one-sigma error, the bands' contrast (amplitude of
    the fundamental over the mean) and the frames used."""

    readout_s: float
    sigma_s: float
    contrast: float
    frames: int


def row_means(frames: Iterable[np.ndarray]) -> np.ndarray:
    """Each frame's mean brightness per row (frames × rows), colour channels averaged."""
    return np.array([np.asarray(frame, dtype=np.float32).reshape(frame.shape[0], -1)
                     .mean(axis=1) for frame in frames])


def _design(rows: np.ndarray, cycles_per_row: float) -> np.ndarray:
    """Cosine and sine of the bands' phase at each row (rows × 2)."""
    phase = 2 * np.pi * cycles_per_row * rows
    return np.column_stack([np.cos(phase), np.sin(phase)])


def _cost(bands: np.ndarray, cycles_per_row: float) -> float:
    """Total squared residual of every frame's best sinusoid at this spatial frequency."""
    design = _design(np.arange(bands.shape[1], dtype=float), cycles_per_row)
    coefficients, *_ = np.linalg.lstsq(design, bands.T, rcond=None)
    return float(np.sum((bands.T - design @ coefficients) ** 2))


def standing_bands(flicker_hz: float, fps: float) -> bool:
    """Whether the bands stand still from frame to frame (the flicker a multiple of the frame
    rate, e.g. 120 Hz at 30 fps): they then cannot be told from the scene's own rows."""
    cycles_per_frame = flicker_hz / fps
    return abs(cycles_per_frame - round(cycles_per_frame)) < STANDING_CYCLES


def measure_readout(means: np.ndarray, flicker_hz: float, max_readout_s: float
                    ) -> ReadoutEstimate:
    """The readout [s] from the row means of a flicker clip (`row_means`), the flicker's
    frequency [Hz] and the longest readout to consider [s] (the frame period; the bands must
    move from frame to frame: `standing_bands`). ValueError when the clip shows no bands (a
    global shutter, an exposure of whole flicker periods, a light that does not flicker)."""
    if means.ndim != 2 or len(means) < 3:
        raise InputError("a flicker clip of 3 frames or more is needed")
    if not flicker_hz > 0 or not max_readout_s > 0:
        raise InputError("the flicker frequency and the longest readout must be positive")
    height = means.shape[1]
    bands = means / np.maximum(means.mean(axis=0), 1e-6) - 1.0
    per_second = flicker_hz / height          # cycles per row for each second of readout
    grid = np.arange(GRID_STEP_S, max_readout_s + GRID_STEP_S / 2, GRID_STEP_S)
    costs = np.array([_cost(bands, per_second * readout) for readout in grid])
    best = int(np.argmin(costs))
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
    readout = float(minimize_scalar(lambda r: _cost(bands, per_second * r), bounds=(low, high),
                                    method="bounded", options={"xatol": 1e-8}).x)
    design = _design(np.arange(height, dtype=float), per_second * readout)
    coefficients, *_ = np.linalg.lstsq(design, bands.T, rcond=None)
    contrast = float(np.median(np.hypot(coefficients[0], coefficients[1])))
    if contrast < LEAST_CONTRAST:
        raise InputError(f"no flicker bands (contrast {contrast:.3f}): is the light flickering "
                         f"at {flicker_hz:g} Hz, and the exposure shorter than its period?")
    residual = bands.T - design @ coefficients             # rows × frames
    dof = bands.size - coefficients.size - 1
    scatter = float(np.sum(residual**2)) / max(dof, 1)
    step = 1e-3 * readout
    curvature = (_cost(bands, per_second * (readout + step)) - 2 * _cost(
        bands, per_second * readout) + _cost(bands, per_second * (readout - step))) / step**2
    # Neighbouring rows' residuals are alike (the compression's blocks, a square wave's
    # harmonics): fewer independent rows than rows, by (1 + ρ) / (1 − ρ).
    rho = float(np.sum(residual[1:] * residual[:-1]) / np.sum(residual**2))
    widening = (1 + rho) / (1 - rho) if 0 < rho < 1 else 1.0
    sigma = float(np.sqrt(2 * scatter * widening / curvature)) if curvature > 0 else float("inf")
    return ReadoutEstimate(readout, sigma, contrast, len(means))


def video_readout(path: Path, flicker_hz: float) -> ReadoutEstimate:
    """`measure_readout` on a video file's frames (the longest readout: its frame period)."""
    source = VideoFileSource(path)
    try:
        if not source.nominal_fps > 0:
            raise InputError(f"{path}: no frame rate (the longest readout is one frame period)")
        if standing_bands(flicker_hz, source.nominal_fps):
            raise InputError(f"{path}: a {flicker_hz:g} Hz flicker at {source.nominal_fps:g} fps "
                             "makes bands that stand still, which cannot be told from the "
                             "scene: film at another frame rate (or an LED at another rate)")
        means = row_means(frame.image for frame in source.frames())
    finally:
        source.close()
    return measure_readout(means, flicker_hz, 1.0 / source.nominal_fps)
