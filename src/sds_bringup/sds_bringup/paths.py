"""Where the repository's configuration lives (config/ beside src/)."""

from pathlib import Path

CONFIG = Path(__file__).resolve().parents[3] / "config"
"""config/: graphs, node parameters, camera files."""
