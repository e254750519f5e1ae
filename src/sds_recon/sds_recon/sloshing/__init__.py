"""Sloshing: the container's modal theory and (later) the analysis of measured series."""
