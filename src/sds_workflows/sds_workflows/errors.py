"""What bad input raises in a workflow: a caller reports these in one line, anything else is a
bug and keeps its traceback."""

from __future__ import annotations


def input_errors() -> tuple[type[BaseException], ...]:
    """The errors of bad input (a missing or corrupt file, a wrong rig or camera field, an
    unreadable video or recording); imported only when asked, so that a caller that never
    fails loads no reader."""
    from mcap.exceptions import McapError
    from sds_camera.frame_source import FrameSourceError

    return OSError, ValueError, LookupError, FrameSourceError, McapError
