"""Online Hampel filter in time (seed Sec. 3.4): replaces short outliers such as reflections."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class HampelOutput:
    """The sample from `half` frames ago: raw and filtered position, and whether it was replaced."""

    frame: int
    raw: np.ndarray
    filtered: np.ndarray
    replaced: bool


class OnlineHampel:
    """Hampel filter over a window of 2·half + 1 frames, with a latency of `half` frames.

    A spot moves during the window, so the test runs on residuals from the motion rather than
    on raw positions (whose median lags a fast spot and would replace good samples): the centre
    sample is predicted by a quadratic in time through the others, and it is an outlier when
    its residual exceeds `k` scaled MADs of the residuals the same model leaves on the other
    samples, each predicted without itself and without the centre (with a floor, `floor_px`,
    as quantised or very smooth tracks give a MAD of 0). An outlier is replaced by its
    prediction. The one motion this model misses is a kink (a hard kick from rest): there a
    good sample can be replaced, flagged as such, with its raw position kept. Missing samples
    (NaN) stay missing; a sample without `half` valid samples on each side (stream ends, next
    to an occlusion) is passed on unchanged.
    """

    def __init__(self, window: int = 5, k: float = 3.0, floor_px: float = 0.5) -> None:
        if window < 5 or window % 2 == 0:
            raise ValueError(f"the Hampel window must be odd and at least 5, got {window}")
        self.half, self.k, self.floor_px = window // 2, k, floor_px
        self._samples: deque[tuple[int, np.ndarray]] = deque(maxlen=window)

    def push(self, frame: int, position: np.ndarray) -> HampelOutput | None:
        """Add this frame's position; return the filtered sample `half` frames back, once known."""
        self._samples.append((frame, np.asarray(position, dtype=float)))
        if len(self._samples) <= self.half:
            return None
        return self._filter(len(self._samples) - 1 - self.half)

    def flush(self) -> list[HampelOutput]:
        """The last `half` samples at the end of a stream (with the window they have)."""
        start = max(len(self._samples) - self.half, 0)
        outputs = [self._filter(i) for i in range(start, len(self._samples))]
        self._samples.clear()
        return outputs

    def _filter(self, index: int) -> HampelOutput:
        frame, raw = self._samples[index]
        times = np.array([f for f, _ in self._samples], dtype=float)
        values = np.array([p for _, p in self._samples])
        finite = np.isfinite(values).all(axis=1)
        before, after = finite[:index].sum(), finite[index + 1:].sum()
        if not np.isfinite(raw).all() or before < self.half or after < self.half:
            return HampelOutput(frame, raw, raw.copy(), False)   # no two-sided window
        others = finite.copy()
        others[index] = False
        centre = raw - _quadratic_prediction(times[others], values[others], times[index])
        rest = []
        for j in np.flatnonzero(others):   # the motion model's own error, without the centre
            rest_of = others.copy()
            rest_of[j] = False
            rest.append(values[j] - _quadratic_prediction(times[rest_of], values[rest_of],
                                                           times[j]))
        scale = np.maximum(MAD_TO_SIGMA * np.median(np.abs(np.array(rest)), axis=0),
                           self.floor_px)

        outlier = bool(np.any(np.abs(centre) > self.k * scale))
        return HampelOutput(frame, raw, raw - centre if outlier else raw.copy(), outlier)


def _quadratic_prediction(times: np.ndarray, values: np.ndarray, at: float) -> np.ndarray:
    """Value at `at` of the least-squares quadratic (linear with 2 points) through the samples."""
    return _prediction_weights(tuple(times - at)) @ values


@lru_cache(maxsize=256)
def _prediction_weights(offsets: tuple[float, ...]) -> np.ndarray:
    """Weights w with w · values = the fitted polynomial at offset 0 (depends on timing only)."""
    degree = min(2, len(offsets) - 1)
    design = np.vander(np.array(offsets), degree + 1)
    return np.linalg.pinv(design)[-1]
