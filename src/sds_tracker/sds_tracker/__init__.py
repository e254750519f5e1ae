"""Laser spot and line tracking (seed Sec. 3.4), pure numpy/OpenCV/numba.

`spots` (windowed centroids on each beam's image path, line-light subtraction), `kernels`
(the compiled inner loops), `hampel` (the online Hampel filter), `line` (the line's centre per
row), `tracker` (one frame, all of it), `discovery` (every spot in a region, for calibration),
`plateaus` (still stretches of a tilt-table video). The graph's node is `sds_nodes.tracker`.
"""
