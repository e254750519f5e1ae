"""SDS reconstruction: camera models, calibration and geometry (pure numpy/scipy/OpenCV)."""
