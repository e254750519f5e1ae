"""The import picture: algorithm packages → ROS layer → nodes → launcher | workflows → CLI, no
arrow up, and none between the launcher and the workflows.

Every `import` in every module counts, also those inside functions (lazy imports).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
LAYERS = {
    "sds_arduino": 0, "sds_camera": 0, "sds_model": 0, "sds_recon": 0, "sds_sim": 0,
    "sds_sloshing": 0, "sds_tracker": 0, "sds_lateral": 0,
    "sds_ros": 1, "sds_record": 1, "sds_viz": 1,
    "sds_nodes": 2,
    "sds_bringup": 3, "sds_workflows": 3,
    "sds_cli": 4,
}
"""0: pure algorithms (numpy, SciPy, OpenCV); 1: the ROS layer (node host, QoS, message codecs,
graph files, recordings, the Rerun scene of messages); 2: the graph's nodes; 3: the launcher
(`sds_bringup`) and the workflows (`sds_workflows`, what the commands do), side by side; 4: the
`sds` command (`sds_cli`)."""
APART = ("sds_bringup", "sds_workflows")
"""Neither imports the other: the launcher runs graphs, the workflows run jobs; the CLI (or a
notebook) joins them."""
ROS_MODULES = ("rclpy", "sds_msgs", "sensor_msgs", "std_msgs", "builtin_interfaces",
               "geometry_msgs", "tf2_msgs", "foxglove_msgs", "rosgraph_msgs", "rosidl_runtime_py",
               "mcap_ros2", "rosbags")


def imported_modules(path: Path) -> set[str]:
    """Top-level names of every module that `path` imports (absolute imports)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_every_python_package_has_a_layer() -> None:
    packages = {p.name for p in SRC.iterdir() if (p / p.name / "__init__.py").is_file()}
    assert packages == set(LAYERS)


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_no_import_runs_up_and_no_algorithm_package_imports_ros(package: str) -> None:
    layer = LAYERS[package]
    wrong = []
    for module in sorted((SRC / package / package).rglob("*.py")):
        for name in imported_modules(module):
            if LAYERS.get(name, -1) > layer:
                wrong.append(f"{module.relative_to(SRC)} imports {name} (layer {LAYERS[name]})")
            if layer == 0 and name in ROS_MODULES:
                wrong.append(f"{module.relative_to(SRC)} imports {name}")
    assert not wrong, "\n".join(wrong)


def test_launcher_and_workflows_import_each_other_nowhere() -> None:
    wrong = [f"{module.relative_to(SRC)} imports {other}"
             for package in APART for other in APART if other != package
             for module in sorted((SRC / package / package).rglob("*.py"))
             if other in imported_modules(module)]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_package_xml_declares_every_sds_package_imported(package: str) -> None:
    """colcon builds `src/` in a ROS 2 workspace from these declarations."""
    declared = set(re.findall(r"<exec_depend>(sds_\w+)</exec_depend>",
                              (SRC / package / "package.xml").read_text()))
    imported = {name for module in (SRC / package / package).rglob("*.py")
                for name in imported_modules(module) if name.startswith("sds_")}
    assert imported - {package} <= declared
