"""Graph files: which nodes run, with which parameter files, in which processes."""

from __future__ import annotations

import ast
import difflib
import importlib.util
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml
from sds_model.errors import InputError


class GraphFileError(InputError):
    """A graph file or override that does not describe a valid graph."""


@dataclass(frozen=True)
class NodeEntry:
    """One node of a graph: its name, class, parameters and the process that hosts it."""

    name: str
    plugin: str
    params_files: tuple[Path, ...] = ()
    parameters: dict[str, Any] = field(default_factory=dict)
    remap: dict[str, str] = field(default_factory=dict)
    process: str = ""
    required: bool = False
    needed: bool = True
    nice: int = 0

    def ros_args(self) -> list[str]:
        """The node's --ros-args: parameter files, then single parameters, then remappings."""
        args = ["--ros-args"]
        for path in self.params_files:
            args += ["--params-file", str(path)]
        for key, value in self.parameters.items():
            text = yaml.safe_dump(value, default_flow_style=True, width=10**6).strip()
            text = text.removesuffix("\n...").strip()
            args += ["-p", f"{key}:={text}"]
        for source, target in self.remap.items():
            args += ["-r", f"{source}:={target}"]
        return args


_NODE_KEYS = {"name", "plugin", "params", "parameters", "remap", "process", "required", "needed",
              "nice"}


def load_graph(path: str | Path) -> list[NodeEntry]:
    """Read a graph file; relative parameter-file paths are taken from the graph file's folder."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise GraphFileError(f"cannot read graph file {path}: {error}") from error
    if not isinstance(document, dict) or not isinstance(document.get("nodes"), list):
        raise GraphFileError(f"{path}: expected a mapping with a list under 'nodes'")
    entries = [_node_entry(path, index, item) for index, item in enumerate(document["nodes"])]
    names = [entry.name for entry in entries]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise GraphFileError(f"{path}: node names used twice: {', '.join(duplicates)}")
    return entries


MOVED_PLUGINS = {
    "sds_camera.frame_source_node:FrameSourceNode": "sds_nodes.frame_source:FrameSourceNode",
    "sds_camera.frame_monitor_node:FrameMonitorNode": "sds_nodes.frame_monitor:FrameMonitorNode",
    "sds_tracker.tracker_node:TrackerNode": "sds_nodes.tracker:TrackerNode",
    "sds_recon.recon_node:ReconstructionNode": "sds_nodes.reconstruction:ReconstructionNode",
    "sds_recon.sloshing_node:SloshingNode": "sds_nodes.sloshing:SloshingNode",
    "sds_record.recorder_node:RecorderNode": "sds_nodes.recorder:RecorderNode",
    "sds_record.player_node:PlayerNode": "sds_nodes.player:PlayerNode",
    "sds_arduino.bridge_node:ArduinoBridgeNode": "sds_nodes.arduino_bridge:ArduinoBridgeNode",
    "sds_viz.viewer_node:ViewerNode": "sds_nodes.viewer:ViewerNode",
}
"""Plugins of graph files written before the nodes moved into `sds_nodes` (2026-12)."""


def check_plugins(entries: list[NodeEntry]) -> None:
    """GraphFileError naming the first node whose plugin names no node class, or whose string
    parameter is not one of the values its module's `PARAMETER_CHOICES` literal allows; found
    without importing a module: a launcher calls this before it starts any process (reading a
    graph for its parameters does not need it)."""
    for entry in entries:
        missing = _missing_plugin(entry.plugin)
        if missing:
            raise GraphFileError(f"node {entry.name!r}: plugin {entry.plugin!r}: {missing}")
        values = entry_parameters(entry)
        for name, allowed in _parameter_choices(entry.plugin).items():
            if name in values and values[name] not in allowed:
                raise GraphFileError(f"node {entry.name!r}: parameter {name}={values[name]!r} "
                                     f"is not one of {', '.join(allowed)}")


def _parameter_choices(plugin: str) -> dict[str, tuple[str, ...]]:
    """The plugin module's `PARAMETER_CHOICES` (a dict literal at its top level), read from
    its source; empty when it has none."""
    spec = importlib.util.find_spec(plugin.partition(":")[0])
    assert spec is not None and spec.origin is not None   # `_missing_plugin` found it
    tree = ast.parse(Path(spec.origin).read_text(), spec.origin)
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "PARAMETER_CHOICES" for t in node.targets):
            return dict(ast.literal_eval(node.value))
    return {}


def _missing_plugin(plugin: str) -> str:
    """Why 'package.module:Class' names no node class ('' when it does), from the module's
    source."""
    module_name, _, class_name = plugin.partition(":")
    if not module_name or not class_name:
        return "must look like 'package.module:Class'"
    try:
        spec = importlib.util.find_spec(module_name)
    except (ImportError, ValueError):
        spec = None
    if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
        return f"no module {module_name} installed"
    tree = ast.parse(Path(spec.origin).read_text(), spec.origin)
    classes = [node.name for node in tree.body if isinstance(node, ast.ClassDef)]
    if class_name not in classes:
        close = difflib.get_close_matches(class_name, classes, n=1)
        return f"no class {class_name} in {module_name}" + (
            f" (did you mean {close[0]}?)" if close else "")
    return ""


def _node_entry(path: Path, index: int, item: Any) -> NodeEntry:
    where = f"{path}: nodes[{index}]"
    if not isinstance(item, dict):
        raise GraphFileError(f"{where} must be a mapping")
    unknown = set(item) - _NODE_KEYS
    if unknown:
        raise GraphFileError(
            f"{where}: unknown keys {sorted(unknown)}; allowed {sorted(_NODE_KEYS)}"
        )
    for key in ("name", "plugin"):
        if not isinstance(item.get(key), str) or not item[key]:
            raise GraphFileError(f"{where}: '{key}' must be a non-empty string")
    moved_to = MOVED_PLUGINS.get(item["plugin"])
    if moved_to:
        raise GraphFileError(f"{where}: plugin {item['plugin']} is now {moved_to}")
    params = item.get("params", [])
    params = [params] if isinstance(params, str) else params
    files = tuple((path.parent / p).resolve() for p in params)
    for file in files:
        if not file.is_file():
            raise GraphFileError(f"{where}: parameter file {file} does not exist")
    for key in ("parameters", "remap"):
        if not isinstance(item.get(key, {}), dict):
            raise GraphFileError(f"{where}: '{key}' must be a mapping")
    for key in ("required", "needed"):
        if not isinstance(item.get(key, False), bool):
            raise GraphFileError(f"{where}: '{key}' must be true or false")
    nice = item.get("nice", 0)
    if not isinstance(nice, int) or isinstance(nice, bool) or not 0 <= nice <= 19:
        raise GraphFileError(f"{where}: 'nice' must be an integer from 0 to 19, got {nice!r}")
    return NodeEntry(
        name=item["name"],
        plugin=item["plugin"],
        params_files=files,
        parameters=dict(item.get("parameters", {})),
        remap={str(k): str(v) for k, v in item.get("remap", {}).items()},
        process=str(item.get("process", item["name"])),
        required=item.get("required", False),
        needed=item.get("needed", True),
        nice=nice,
    )


def apply_overrides(entries: list[NodeEntry], overrides: list[str]) -> list[NodeEntry]:
    """Apply 'node.parameter=value' overrides (value in YAML syntax) to the named nodes."""
    by_name = {entry.name: entry for entry in entries}
    for override in overrides:
        target, equals, value = override.partition("=")
        node, dot, parameter = target.partition(".")
        if not equals or not dot or not parameter:
            raise GraphFileError(f"override {override!r} must look like node.parameter=value")
        if node not in by_name:
            close = difflib.get_close_matches(node, list(by_name), n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else \
                f" (it has {', '.join(by_name)})"
            raise GraphFileError(f"override {override!r}: no node {node!r} in the graph{hint}")
        entry = by_name[node]
        documented = documented_parameters(entry)
        if documented and parameter not in documented:
            close = difflib.get_close_matches(parameter, sorted(documented), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise GraphFileError(f"override {override!r}: node {node!r} has no parameter "
                                 f"{parameter!r}{hint}")
        try:
            parsed = yaml.safe_load(value)
        except yaml.YAMLError as error:
            raise GraphFileError(f"override {override!r}: not a YAML value ({error})") from None
        if parameter in documented:
            parsed = _as_documented(override, parsed, documented[parameter])
        by_name[node] = replace(entry, parameters={**entry.parameters, parameter: parsed})
    return [by_name[entry.name] for entry in entries]


def _as_documented(override: str, value: Any, documented: Any) -> Any:
    """`value` in the type of the parameter file's value: an integer for a double becomes a
    float (ROS refuses it: the node would not start), a number for a string its text; any
    other mismatch is an error (ROS would silently keep the file's value)."""
    kind = type(documented)
    if isinstance(value, kind) and not (isinstance(value, bool) and kind is not bool):
        return value
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is str and isinstance(value, int | float) and not isinstance(value, bool):
        return str(value)
    names = {bool: "true or false", int: "an integer", float: "a number", str: "a string",
             list: "a list, e.g. [1, 2]"}
    raise GraphFileError(f"override {override!r}: the parameter is {names.get(kind, kind.__name__)}"
                         f" (its parameter file has {documented!r}), not {value!r}")


def documented_parameters(entry: NodeEntry) -> dict[str, Any]:
    """The parameters a node's parameter files document, with their values there (empty
    without a file): every parameter a node declares is in its config/params file, with what
    it means."""
    values: dict[str, Any] = {}
    for file in entry.params_files:
        document = yaml.safe_load(file.read_text()) or {}
        for section in document.values():
            values.update((section or {}).get("ros__parameters", {}))
    return values


def composed(entries: list[NodeEntry]) -> list[NodeEntry]:
    """The same graph with every node hosted in one process, but for niced nodes: a priority
    is a process's, so each of them keeps its own."""
    return [entry if entry.nice else replace(entry, process="graph") for entry in entries]


def node_parameters(graph_file: str | Path, node_name: str) -> dict[str, Any]:
    """The parameters a graph gives one node (`entry_parameters`)."""
    entry = next((e for e in load_graph(graph_file) if e.name == node_name), None)
    if entry is None:
        raise GraphFileError(f"{graph_file}: no node named {node_name!r}")
    return entry_parameters(entry)


def entry_parameters(entry: NodeEntry) -> dict[str, Any]:
    """The parameters a node gets: its parameter files ('/**' and its own name's section, in
    order), then the graph's `parameters` (overrides included)."""
    values: dict[str, Any] = {}
    for file in entry.params_files:
        document = yaml.safe_load(file.read_text()) or {}
        for section in ("/**", entry.name, f"/{entry.name}"):
            values.update((document.get(section) or {}).get("ros__parameters", {}))
    values.update(entry.parameters)
    return values
