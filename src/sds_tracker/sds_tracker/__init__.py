"""Laser spot and line tracking (seed Sec. 3.4): pure trackers and their node."""
