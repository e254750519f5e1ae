"""SDS reconstruction: from spot pixels to the free surface (pure numpy/SciPy/OpenCV).

`camera/` (the camera-model interface, pinhole + Brown-Conrady, Scaramuzza, camera files),
`rig` (the rig file: camera pose, beams, line laser, container), `geometry` and
`triangulation` (seed Eqs. 1, 9–11), `reconstruction` (one frame's points and fits),
`surface_fit` (Eq. 12, modes, outliers, meniscus), `calibration/` (camera, beams, the rig's
self-calibration), `sloshing/` (mode theory, estimators, analysis, report), `results` (the
result files), `resolution` (Fig. 7). The graph's reconstruction and sloshing nodes are in
`sds_nodes`.
"""
