"""SDS reconstruction: from spot pixels to the free surface (pure numpy/SciPy/OpenCV).

`triangulation` (seed Eqs. 9–11: a spot's ray with its beam, a line pixel's ray with the laser
plane), `reconstruction` (one frame's points and fits, the per-frame code of the node and of
`sds process`), `surface_fit` (Eq. 12, modes, outliers, meniscus), `calibration/` (camera,
beams, the rig's self-calibration), `results` (the result files), `resolution` (Fig. 7). The
rig, camera models and geometry it works on are in `sds_model`; the sloshing analysis of its
results in `sds_sloshing`; its node in `sds_nodes`.
"""
