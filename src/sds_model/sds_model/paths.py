"""Where the repository's configuration lives (config/ beside src/): the one place every layer
finds the shipped graphs, node parameters, camera and rig files and scenarios."""

from pathlib import Path

CONFIG = Path(__file__).resolve().parents[3] / "config"
"""config/: graphs, node parameters, camera files, rig files, scenarios."""
