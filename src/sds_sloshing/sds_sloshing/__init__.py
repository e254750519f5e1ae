"""Sloshing: what the measured surface says about the liquid's modes.

`modal` (modal coordinates from the per-frame points, on the modes of
`sds_model.mode_theory`), `estimators` (matrix pencil, FFT peak, half-power, log decrement),
`gravity` (free fall from an accelerometer), `analysis` (a recording's modes, tilt table,
meniscus), `running` (the running estimates of the sloshing node), `surface_series` (what the
analysis reads: surface points per frame from a recording or a points table, series tables),
`report` (the HTML report).
"""
