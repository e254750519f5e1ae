"""Launcher, node host, command line and demo of the SDS graph."""
