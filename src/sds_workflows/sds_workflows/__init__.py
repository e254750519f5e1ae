"""The jobs of SDS, for the `sds` command and for a script or notebook alike.

    from pathlib import Path
    from sds_model.rig import load_rig
    from sds_workflows import process_video

    run = process_video(Path("drop.mp4"), load_rig(Path("config/rigs/stelium.yaml")),
                        Path("drop_results"))
    print(run.summary(), run.analysis.results["modes"])

The main entry points:
- `process_video`, `process_recording`, `process_inputs` (`process.py`): result files and the
  analysis report from videos or recordings, no ROS graph;
- `FramePipeline`, `video_frames`, `mcap_frames` (`pipeline.py`): the one per-frame pipeline
  (tracker → triangulation → fits) over an iterator of frames;
- `export_results` (`export.py`): a recording of the graph as result files and a report;
- `calibrate_rig` (`rig_calibration.py`): a rig self-calibrated from images of known surfaces;
  `calibrate_line_plane` (`line_plane_calibration.py`): the line laser's plane from a checkerboard;
- `analyse_recording` (`analyze.py`): frequencies and damping of a recording or a table;
- `link_clocks` (`clock_link.py`): a camera's clock against the Arduino's;
- `LateralInput` (`lateral.py`): a side camera's video, view file and board image, given to
  `process_video(..., lateral=...)`: its wall profile and the top surface checked against it;
- `run_demo`, `run_live` (`demo.py`): the whole graph on a simulated drop or a video, given the
  launcher's `sds_bringup.chain.run_chain` (the workflows start no graph themselves).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

if TYPE_CHECKING:   # what a type checker sees: every entry point, re-exported
    from sds_workflows.analyze import analyse_recording as analyse_recording
    from sds_workflows.clock_link import link_clocks as link_clocks
    from sds_workflows.export import export_results as export_results
    from sds_workflows.lateral import LateralInput as LateralInput
    from sds_workflows.line_plane_calibration import calibrate_line_plane as calibrate_line_plane
    from sds_workflows.pipeline import FramePipeline as FramePipeline
    from sds_workflows.pipeline import mcap_frames as mcap_frames
    from sds_workflows.pipeline import video_frames as video_frames
    from sds_workflows.process import process_inputs as process_inputs
    from sds_workflows.process import process_recording as process_recording
    from sds_workflows.process import process_video as process_video
    from sds_workflows.rig_calibration import calibrate_rig as calibrate_rig

_MODULE_OF = {
    "FramePipeline": "pipeline", "LateralInput": "lateral", "analyse_recording": "analyze",
    "calibrate_line_plane": "line_plane_calibration", "calibrate_rig": "rig_calibration",
    "export_results": "export", "link_clocks": "clock_link", "mcap_frames": "pipeline",
    "process_inputs": "process", "process_recording": "process", "process_video": "process",
    "video_frames": "pipeline",
}
"""Where each entry point lives (the package's one list of them)."""
__all__ = sorted(_MODULE_OF)


def __getattr__(name: str) -> object:
    """An entry point, imported when first asked for (PEP 562): importing one light module of
    the package, such as `clock_link`, then loads none of the others (seconds of SciPy, Numba and
    Matplotlib for every `sds` command)."""
    if name not in _MODULE_OF:
        raise AttributeError(f"module 'sds_workflows' has no attribute {name!r}")
    return getattr(import_module(f"sds_workflows.{_MODULE_OF[name]}"), name)
