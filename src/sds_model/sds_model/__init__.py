"""The shared model of the SDS rig, which every other package uses (pure numpy/SciPy).

`camera/` (the one camera-model interface, pinhole + Brown-Conrady, Scaramuzza, camera files
and importers), `geometry` (rigid transforms, seed Eq. 1), `rig` (the rig file: camera pose,
beams, line laser, container, calibration record), `mode_theory` (the cylindrical container's
linear sloshing modes: shapes and frequencies), `errors` (`InputError`, what every check of
the user's input raises), `staging` (result files written whole or not at all).
"""
