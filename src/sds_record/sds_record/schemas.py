"""ROS 2 message definitions (rosbag2's concatenated `ros2msg` text) for MCAP schemas.

The definitions come from the `.msg` files installed with each interface package
(`share/<package>/msg/<Type>.msg` under AMENT_PREFIX_PATH, or this Python's prefix), so custom
`sds_msgs` are embedded like the standard ones and readers need no ROS installation.
"""

from __future__ import annotations

import os
import sys
from functools import cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg
from rosbags.typesys.store import Typestore
from sds_model.errors import InputError

SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


class SchemaError(InputError, LookupError):
    """A message type whose definition is not installed; the message names it."""


def interface_prefixes() -> list[Path]:
    """Install prefixes to search: AMENT_PREFIX_PATH, then this Python's prefix (the venv)."""
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [*prefixes, Path(sys.prefix)]


def msg_file(type_name: str) -> Path:
    """The installed .msg file of 'package/msg/Type'."""
    package, _, name = type_name.split("/")
    for prefix in interface_prefixes():
        path = prefix / "share" / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path
    raise SchemaError(f"no installed definition of {type_name} (share/{package}/msg/{name}.msg "
                      f"under {', '.join(map(str, interface_prefixes()))})")


@cache
def _typestore() -> Typestore:
    from rosbags.typesys import get_typestore

    return get_typestore(Stores.EMPTY)


def _register(type_name: str) -> None:
    """Register a type and, recursively, every type its fields use."""
    store = _typestore()
    if type_name in store.fielddefs:
        return
    store.register(get_types_from_msg(msg_file(type_name).read_text(), type_name))
    for dependency in _nested_types(type_name):
        _register(dependency)


def _nested_types(type_name: str) -> list[str]:
    """Message types named by a registered type's fields (rosbags' field descriptions)."""
    _, fields = _typestore().fielddefs[type_name]
    nested: list[str] = []
    for _, (kind, detail) in fields:
        if kind.name == "NAME":
            nested.append(str(detail))
        elif kind.name in ("ARRAY", "SEQUENCE") and isinstance(detail, tuple):
            element = detail[0]   # detail: ((element kind, element type), size)
            if isinstance(element, tuple) and getattr(element[0], "name", "") == "NAME":
                nested.append(str(element[1]))
    return nested


@cache
def message_definition(type_name: str) -> str:
    """The concatenated definition rosbag2 writes into MCAP schemas for 'package/msg/Type',
    from the installed .msg files (tf2_msgs and sds_msgs too: built at setup)."""
    _register(type_name)
    text, _ = _typestore().generate_msgdef(type_name, ros_version=2)
    return text
