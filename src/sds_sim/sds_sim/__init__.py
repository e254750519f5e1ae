"""Synthetic SDS rig: surfaces, laser optics, rendered frames, Arduino streams, ground truth."""
