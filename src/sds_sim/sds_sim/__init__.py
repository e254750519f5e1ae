"""The simulator: a rig as built, rendered as its camera and its Arduino would record it.

`surface` (h(x, y, t) of the sloshing modes), `optics` (beam and line-laser hits, wall
reflections), `render` (frames and their truth), `arduino` and `camera_imu` (the sensors),
`scenario` (scenario files), `simulate` (a run's files), `true_rig` (random rigs that differ
from their rig file: layouts, leaning beams, a moved camera) and `tilt_series` (tilt-table
images with their truth).
"""
