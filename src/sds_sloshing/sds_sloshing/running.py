"""Running estimates during a drop: modal amplitudes accumulated frame by frame, re-analysed."""

from __future__ import annotations

import numpy as np

from sds_sloshing.analysis import AnalysisOptions, ModeResult, analyze_series, decay_start
from sds_sloshing.estimators import DecayError
from sds_sloshing.modal import ModalSeries, mode_coordinates


class RunningAnalysis:
    """Per-frame modal amplitudes in; every `period_s` of data, the modes' current estimates
    over the last `window_s` (a drop lasts 4.7 or 9.3 s; the cost grows with the window)."""

    def __init__(self, period_s: float, options: AnalysisOptions | None = None,
                 expected_hz: dict[str, float] | None = None, window_s: float = 20.0) -> None:
        self.period_s = period_s
        self.options = options or AnalysisOptions()
        self.expected_hz = expected_hz or {}
        self.window_s = window_s
        self._names: tuple[str, ...] = ()
        self._times: list[float] = []
        self._rows: list[np.ndarray] = []
        self._last_s = -np.inf

    def add(self, time_s: float, names: tuple[str, ...], amplitudes_mm: np.ndarray) -> None:
        """One frame's modal fit; a change of mode set starts over."""
        if names != self._names:
            self._names, self._times, self._rows = names, [], []
        self._times.append(time_s)
        self._rows.append(np.asarray(amplitudes_mm, dtype=float))
        while self._times[-1] - self._times[0] > self.window_s:
            del self._times[0], self._rows[0]

    def due(self) -> bool:
        """True when `period_s` of data has arrived since the last estimate."""
        return bool(self._times) and self._times[-1] - self._last_s >= self.period_s

    def snapshot(self) -> ModalSeries:
        """A copy of the amplitudes so far, to estimate from (in another thread if need be)."""
        self._last_s = self._times[-1] if self._times else self._last_s
        return ModalSeries(np.array(self._times), self._names,
                           np.array(self._rows).reshape(len(self._times), len(self._names)),
                           np.full(len(self._times), np.nan))

    def estimate(self, series: ModalSeries,
                 modes: tuple[str, ...] = ("lateral_1", "lateral_2")) -> list[ModeResult]:
        """The named modes' estimates on the free decay in `series` (none until one is found)."""
        if len(series.time_s) == 0:
            return []
        results = []
        for coordinate in mode_coordinates(series):
            if coordinate.name not in modes:
                continue
            try:
                start = decay_start(coordinate.time_s, coordinate.values_mm, self.options)
            except DecayError:
                continue
            results.append(analyze_series(coordinate.name, coordinate.time_s,
                                          coordinate.values_mm, "mm", start, None, self.options,
                                          self.expected_hz.get(coordinate.name)))
        return results
