"""Graph files: loading, overrides, errors, and --ros-args that rclpy really accepts."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest
import rclpy
import yaml
from rclpy.node import Node
from sds_bringup.launcher import group_processes
from sds_ros.graph_file import (
    MOVED_PLUGINS,
    GraphFileError,
    apply_overrides,
    composed,
    load_graph,
)
from sds_ros.node_host import load_plugin


def test_shipped_graph_loads_with_existing_parameter_files_and_plugins(repo):
    for graph_file in sorted((repo / "config" / "graphs").glob("*.yaml")):
        entries = load_graph(graph_file)
        assert entries, graph_file
        for entry in entries:
            assert all(path.is_file() for path in entry.params_files)
            assert issubclass(load_plugin(entry.plugin), Node)


@pytest.mark.parametrize("module, params_file", [
    ("frame_source", "frame_source"), ("frame_monitor", "frame_monitor"),
    ("tracker", "tracker"), ("reconstruction", "recon"), ("sloshing", "sloshing"),
    ("recorder", "recorder"), ("player", "player"), ("arduino_bridge", "arduino"),
    ("viewer", "viewer")])
def test_each_node_declares_what_its_parameter_file_documents(repo, module, params_file):
    """A node's PARAMETERS table is the one list of its parameters; its config/params file
    documents each of them and nothing else."""
    declared = importlib.import_module(f"sds_nodes.{module}").PARAMETERS
    document = yaml.safe_load((repo / "config" / "params" / f"{params_file}.yaml").read_text())
    documented = {name for section in document.values()
                  for name in (section or {}).get("ros__parameters", {})}
    assert documented == set(declared)


def test_every_moved_plugin_names_a_node_that_loads():
    """Each old name is a node module of an algorithm package, `package.<name>_node:Class`,
    and its new name loads the same class."""
    for old, moved_to in MOVED_PLUGINS.items():
        assert re.fullmatch(r"sds_[a-z]+\.[a-z_]+_node:\w+", old), old
        assert old.split(":")[1] == moved_to.split(":")[1]
        assert issubclass(load_plugin(moved_to), Node)


def test_ros_args_reach_the_node_as_parameters_and_remaps(tmp_path: Path):
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    rate: 2.5\n    channel: red\n"
                      "    source: ''\n")
    graph = tmp_path / "graph.yaml"
    graph.write_text(
        "nodes:\n  - name: cam\n    plugin: rclpy.node:Node\n    params: params.yaml\n"
        "    parameters: {channel: green, roi: [1, 2, 3, 4]}\n    remap: {image: /x/image}\n"
    )
    (entry,) = apply_overrides(load_graph(graph), ["cam.source=/data/a b.mp4", "cam.rate=0.5"])
    with pytest.raises(GraphFileError, match="no parameter 'rat'; did you mean rate"):
        apply_overrides(load_graph(graph), ["cam.rat=0.5"])
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node(entry.name, context=context, cli_args=entry.ros_args(),
                    automatically_declare_parameters_from_overrides=True)
        values = {p: node.get_parameter(p).value for p in ("rate", "channel", "roi", "source")}
        assert values == {"rate": 0.5, "channel": "green", "roi": [1, 2, 3, 4],
                          "source": "/data/a b.mp4"}
        assert node.resolve_topic_name("image") == "/x/image"
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_processes_group_nodes_and_compose_puts_all_in_one(repo):
    entries = load_graph(repo / "config" / "graphs" / "camera_monitor.yaml")
    assert [p.name for p in group_processes(entries)] == ["camera", "monitor"]
    (single,) = group_processes(composed(entries))
    assert [e.name for e in single.entries] == ["camera", "monitor"]
    assert single.required


def test_compose_keeps_niced_nodes_in_their_own_processes(repo):
    entries = load_graph(repo / "config" / "graphs" / "drop.yaml")
    processes = {p.name: p for p in group_processes(composed(entries))}
    assert set(processes) == {"graph", "sloshing"}
    assert processes["sloshing"].nice == 10 and processes["graph"].nice == 0
    assert "sloshing" not in [e.name for e in processes["graph"].entries]


@pytest.mark.parametrize(
    "text, message",
    [
        ("nodes: 3", "list under 'nodes'"),
        ("nodes:\n  - {name: a}", "'plugin'"),
        ("nodes:\n  - {name: a, plugin: m:C, colour: red}", "unknown keys"),
        ("nodes:\n  - {name: a, plugin: m:C, params: nope.yaml}", "does not exist"),
        ("nodes:\n  - {name: a, plugin: m:C}\n  - {name: a, plugin: m:D}", "used twice"),
        ("nodes: [", "cannot read"),
        ("nodes:\n  - {name: a, plugin: m:C, nice: 20}", "'nice'"),
        ("nodes:\n  - {name: a, plugin: m:C, nice: -5}", "'nice'"),
        ("nodes:\n  - {name: a, plugin: m:C, nice: high}", "'nice'"),
        ("nodes:\n  - {name: t, plugin: 'sds_tracker.tracker_node:TrackerNode'}",
         "is now sds_nodes.tracker:TrackerNode"),
    ],
)
def test_bad_graph_files_are_named_in_the_error(tmp_path, text, message):
    graph = tmp_path / "bad.yaml"
    graph.write_text(text)
    with pytest.raises(GraphFileError, match=message):
        load_graph(graph)


def test_a_whole_number_for_a_float_parameter_is_taken_as_a_float(repo):
    """`--set camera.linger_s=5`: ROS would refuse the integer for a double parameter and the
    node would not start; the override gives 5.0 (an integer parameter keeps its integer)."""
    entries = load_graph(repo / "config" / "graphs" / "camera_monitor.yaml")
    camera = next(e for e in apply_overrides(entries, ["camera.linger_s=5",
                                                       "camera.max_in_flight=3"])
                  if e.name == "camera")
    assert camera.parameters["linger_s"] == 5.0 and isinstance(camera.parameters["linger_s"],
                                                                float)
    assert camera.parameters["max_in_flight"] == 3 and isinstance(
        camera.parameters["max_in_flight"], int)


def test_bad_overrides_are_refused(repo):
    entries = load_graph(repo / "config" / "graphs" / "camera_monitor.yaml")
    for override in ("camera.rate", "nobody.rate=1", "camera=1"):
        with pytest.raises(GraphFileError):
            apply_overrides(entries, [override])


def test_the_graph_environment_keeps_what_the_user_set_about_discovery() -> None:
    from sds_bringup.ros_env import graph_domain_id, graph_environment

    assert graph_environment(5, base={})["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    chosen = graph_environment(5, base={"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
                                        "ROS_STATIC_PEERS": "10.0.0.2"})
    assert chosen["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert chosen["ROS_STATIC_PEERS"] == "10.0.0.2" and chosen["ROS_DOMAIN_ID"] == "5"
    across = graph_environment(5, base={"ROS_STATIC_PEERS": "10.0.0.2"}, network=True)
    assert across["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"   # + the named peers only
    with pytest.raises(ValueError, match="ROS_STATIC_PEERS"):
        graph_environment(5, base={}, network=True)
    assert graph_domain_id(None, base={"ROS_DOMAIN_ID": "33"}) == 33
    assert graph_domain_id(12, base={"ROS_DOMAIN_ID": "33"}) == 12
    assert 1 <= graph_domain_id(None, base={}) <= 101
    with pytest.raises(ValueError, match="--domain-id"):
        graph_domain_id(None, network=True, base={})


def test_graph_processes_run_one_blas_thread_unless_the_user_says() -> None:
    from sds_bringup.ros_env import graph_environment

    assert graph_environment(5, base={})["OPENBLAS_NUM_THREADS"] == "1"
    assert graph_environment(5, base={"OPENBLAS_NUM_THREADS": "4"})["OPENBLAS_NUM_THREADS"] == "4"
