"""Sloshing: what the measured surface says about the liquid's modes.

`theory` (the container's linear mode frequencies), `modal` (modal coordinates from the
per-frame points), `estimators` (matrix pencil, FFT peak, half-power, log decrement),
`gravity` (free fall from an accelerometer), `analysis` (a recording's modes, tilt table,
meniscus), `running` (the running estimates of the sloshing node), `recording` (what the
analysis reads: surface recordings, points and series tables), `report` (the HTML report).
"""
