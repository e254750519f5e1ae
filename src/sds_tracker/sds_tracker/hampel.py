"""Online Hampel filter in time (seed Sec. 3.4): replaces short outliers such as reflections."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from sds_model.errors import InputError

MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class BankOutput:
    """One frame of a HampelBank: raw and filtered positions (N×2) and replacements (N)."""

    frame: int
    raw: np.ndarray
    filtered: np.ndarray
    replaced: np.ndarray


class HampelBank:
    """Hampel filter for N tracks (N×2 positions per frame, vectorised) over a window of
    2·half + 1 frames, with a latency of `half` frames.

    A spot moves during the window, so the test runs on residuals from the motion rather than
    on raw positions (whose median lags a fast spot and would replace good samples): the centre
    sample is predicted by a quadratic in time through the others, and it is an outlier when
    its residual exceeds `k` scaled MADs of the residuals the same model leaves on the other
    samples, each predicted without itself and without the centre (with a floor, `floor_px`,
    as quantised or very smooth tracks give a MAD of 0). An outlier is replaced by its
    prediction. The one motion this model misses is a kink (a hard kick from rest): there a
    good sample can be replaced, flagged as such, with its raw position kept. A sample is never
    replaced while its residual is within `k` of its own measurement σ (the σ each push may
    give per track, propagated through the prediction): a spot measured poorly moves within
    its σ. Missing samples (NaN) stay missing; a sample without `half` valid samples on each
    side (stream ends, next to an occlusion) is passed on unchanged.
    """

    def __init__(self, window: int = 5, k: float = 3.0, floor_px: float = 0.5) -> None:
        if window < 5 or window % 2 == 0:
            raise InputError(f"the Hampel window must be odd and at least 5, got {window}")
        self.half, self.k, self.floor_px = window // 2, k, floor_px
        self._frames: deque[int] = deque(maxlen=window)
        self._values: deque[np.ndarray] = deque(maxlen=window)
        self._sigmas: deque[np.ndarray] = deque(maxlen=window)

    def push(self, frame: int, positions: np.ndarray, sigma_px: np.ndarray | None = None
             ) -> BankOutput | None:
        """Add this frame's N×2 positions (and their N measurement σ [px], default 0); return
        the frame `half` back, once known."""
        self._frames.append(frame)
        values = np.asarray(positions, dtype=float)
        self._values.append(values)
        self._sigmas.append(np.zeros(len(values)) if sigma_px is None
                            else np.nan_to_num(np.asarray(sigma_px, dtype=float)))
        if len(self._frames) <= self.half:
            return None
        return self._filter(len(self._frames) - 1 - self.half)

    def flush(self) -> list[BankOutput]:
        """The last `half` frames at the end of a stream, passed on unchanged (one-sided)."""
        start = max(len(self._frames) - self.half, 0)
        outputs = [self._filter(i) for i in range(start, len(self._frames))]
        self._frames.clear()
        self._values.clear()
        self._sigmas.clear()
        return outputs

    def _filter(self, index: int) -> BankOutput:
        times = np.array(self._frames, dtype=float)
        values = np.stack(self._values)                       # window × N × 2
        raw = values[index]
        filtered = raw.copy()
        replaced = np.zeros(len(raw), dtype=bool)
        if index < self.half or len(times) - 1 - index < self.half:
            return BankOutput(self._frames[index], raw, filtered, replaced)
        finite = np.isfinite(values).all(axis=2)               # window × N
        complete = finite.all(axis=0)
        if complete.any():
            centre, scale, weights = _residuals(times, values[:, complete], index)
            # the centre's residual σ from the samples' own: its own and the prediction's
            sigmas = np.stack(self._sigmas)[:, complete]               # window × N
            weights[index] = 1.0
            measured = np.sqrt(np.tensordot(weights**2, sigmas**2, axes=1))[:, None]
            outlier = np.any(np.abs(centre) > self.k * np.maximum(
                np.maximum(scale, self.floor_px), measured), axis=1)
            rows = np.flatnonzero(complete)[outlier]
            filtered[rows] = raw[rows] - centre[outlier]
            replaced[rows] = True
        return BankOutput(self._frames[index], raw, filtered, replaced)


def _residuals(times: np.ndarray, values: np.ndarray, index: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every track (values: samples × N × 2): the centre's residual from the quadratic
    through the others, the scaled MAD of the others' residuals without the centre, and the
    weights of the centre's prediction (a copy, one per sample)."""
    centre_weights, rest_weights = _window_weights(tuple(times - times[index]), index)
    centre = values[index] - np.tensordot(centre_weights, values, axes=1)
    rest = values[np.arange(len(times)) != index] - np.tensordot(rest_weights, values, axes=1)
    return centre, MAD_TO_SIGMA * np.median(np.abs(rest), axis=0), centre_weights.copy()


@lru_cache(maxsize=64)
def _window_weights(offsets: tuple[float, ...], index: int) -> tuple[np.ndarray, np.ndarray]:
    """Weights over the whole window: the centre's prediction from the others (a row), and
    each other sample's prediction from the rest without the centre (a matrix)."""
    times = np.array(offsets)
    count = len(times)
    others = np.flatnonzero(np.arange(count) != index)
    centre = np.zeros(count)
    centre[others] = _prediction_weights(tuple(times[others]))
    rest = np.zeros((len(others), count))
    for row, j in enumerate(others):
        subset = others[others != j]
        rest[row, subset] = _prediction_weights(tuple(times[subset] - times[j]))
    return centre, rest


@lru_cache(maxsize=256)
def _prediction_weights(offsets: tuple[float, ...]) -> np.ndarray:
    """Weights w with w · values = the fitted polynomial at offset 0 (depends on timing only)."""
    degree = min(2, len(offsets) - 1)
    design = np.vander(np.array(offsets), degree + 1)
    return np.linalg.pinv(design)[-1]
