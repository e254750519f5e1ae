"""Intrinsic calibration: checkerboard detection, pinhole and Scaramuzza fits, reports."""
