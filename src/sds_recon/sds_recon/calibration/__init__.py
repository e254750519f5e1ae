"""Calibration: the camera's intrinsics, the beams, and the whole rig from known surfaces.

Intrinsics: `board` (checkerboards), `intrinsics` and `camera_calibration` (pinhole and
Scaramuzza fits), `report`. Beams and planes: `lasers` (beams and the line laser's plane from
points on known surfaces, the seed's method), `laser_files`. The rig's self-calibration:
`identification` (which spot is which diode, over a whole tilt series), `rig_model` (camera
pose and beams as one model), `self_calibration` (the joint least squares, with σ and what the
data cannot determine), `rig_calibration` (the whole run), `rig_report`.
"""
