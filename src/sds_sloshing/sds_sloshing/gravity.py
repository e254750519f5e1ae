"""The gravity regime of a run from an accelerometer: free fall (a drop) or not.

In free fall an accelerometer fixed to the rig feels almost no specific force; at rest on the
ground it feels 1 g. A stretch of at least `FREE_FALL_MIN_S` in which |a| stays below
`FREE_FALL_M_S2` (a tenth of g, far above the sensors' noise, far below 1 g) is a free fall,
and a run with one is analysed as microgravity rather than with the 1 g theory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FREE_FALL_M_S2 = 1.0
"""Specific force below which the rig is falling freely [m/s²]."""
FREE_FALL_MIN_S = 0.2
"""Shortest free fall that counts [s] (a bump's zero crossing does not)."""


@dataclass(frozen=True)
class FreeFall:
    """The longest free fall of a record: start and end [s], mean |a| during it [m/s²]."""

    start_s: float
    end_s: float
    residual_m_s2: float


def free_fall(times_s: np.ndarray, accel_m_s2: np.ndarray) -> FreeFall | None:
    """The longest stretch with |a| < FREE_FALL_M_S2 lasting FREE_FALL_MIN_S or more."""
    times_s = np.asarray(times_s, dtype=float)
    magnitude = np.linalg.norm(np.asarray(accel_m_s2, dtype=float).reshape(len(times_s), -1),
                               axis=1)
    falling = np.concatenate([[False], magnitude < FREE_FALL_M_S2, [False]])
    edges = np.flatnonzero(np.diff(falling.astype(int)))
    best: FreeFall | None = None
    for first, end in zip(edges[::2], edges[1::2], strict=True):
        duration = times_s[end - 1] - times_s[first]
        if duration >= FREE_FALL_MIN_S and (best is None or
                                            duration > best.end_s - best.start_s):
            best = FreeFall(float(times_s[first]), float(times_s[end - 1]),
                            float(np.mean(magnitude[first:end])))
    return best


def gravity_regime(accelerometers: dict[str, tuple[np.ndarray, np.ndarray]]
                   ) -> tuple[float | None, str]:
    """0 (microgravity) and a note naming the stream and the fall if any accelerometer (name →
    times [s], N×3 m/s²) shows a free fall; else None (the rig's gravity) and no note."""
    for name, (times_s, accel) in sorted(accelerometers.items()):
        if len(times_s) < 2:
            continue
        fall = free_fall(times_s, accel)
        if fall is not None:
            return 0.0, (f"{name}: free fall of {fall.end_s - fall.start_s:.2f} s "
                         f"(|a| {fall.residual_m_s2:.2f} m/s²), analysed as microgravity "
                         "(--gravity overrides)")
    return None, ""
