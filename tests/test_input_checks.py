"""Nothing silently wrong: input that cannot be right is refused at once, in one line."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import av
import numpy as np
import pytest
import yaml
from sds_model.rig import RigError, load_rig
from sds_ros.graph_file import GraphFileError, apply_overrides, check_plugins, load_graph
from sds_sim.scenario import ScenarioError, load_scenario

SDS = str(Path(sys.executable).with_name("sds"))
REPO = Path(__file__).resolve().parents[1]
RIG = REPO / "config" / "rigs" / "stelium.yaml"


def sds(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([SDS, *args], capture_output=True, text=True, timeout=120)


def one_line_error(done: subprocess.CompletedProcess, text: str) -> None:
    assert done.returncode == 2, done.stdout + done.stderr
    assert text in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "Traceback" not in done.stderr


def test_process_refuses_a_video_of_another_frame_size(tmp_path: Path) -> None:
    video = tmp_path / "small.mp4"
    with av.open(str(video), "w") as container:
        stream = container.add_stream("libx264", rate=30)
        stream.width, stream.height, stream.pix_fmt = 1280, 720, "yuv420p"
        for _ in range(3):
            frame = av.VideoFrame.from_ndarray(np.zeros((720, 1280, 3), np.uint8), "bgr24")
            container.mux(stream.encode(frame))
        container.mux(stream.encode())
    done = sds("process", "--video", str(video), "--rig", str(RIG), "--out",
               str(tmp_path / "out"))
    one_line_error(done, "frames of 1280x720 px, but the rig's camera")
    assert not (tmp_path / "out").exists()


def test_a_refusal_loads_no_numerical_library() -> None:
    """A command's one-line refusal comes at once: the CLI and the workflows' input errors load
    neither SciPy, Numba nor Matplotlib (they took 3-4 s before every `sds` refusal), while
    every entry point the workflows package names is there when asked for."""
    heavy = ("scipy", "numba", "matplotlib")
    probe = ("import sys, sds_cli.cli, sds_model.errors\n"
             f"print([m for m in {heavy!r} if m in sys.modules])")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          timeout=60, check=True)
    assert done.stdout.strip() == "[]", done.stdout
    import sds_workflows

    assert all(callable(getattr(sds_workflows, name)) for name in sds_workflows.__all__)
    with pytest.raises(AttributeError, match="no attribute 'process_videos'"):
        sds_workflows.process_videos  # noqa: B018


def test_run_refuses_a_missing_video_before_any_process_starts(tmp_path: Path) -> None:
    done = sds("run", "--video", str(tmp_path / "nope.mp4"), "--rig", str(RIG), "--out",
               str(tmp_path / "run"))
    one_line_error(done, f"argument --video: {tmp_path / 'nope.mp4'}: no such file")
    assert not (tmp_path / "run").exists()     # no graph started, no folder made


def test_an_override_of_the_wrong_type_is_refused_not_replaced() -> None:
    entries = load_graph(REPO / "config" / "graphs" / "drop.yaml")
    with pytest.raises(GraphFileError, match=r"is an integer .* not 'abc'"):
        apply_overrides(entries, ["camera.max_in_flight=abc"])
    with pytest.raises(GraphFileError, match="true or false"):
        apply_overrides(entries, ["camera.wait_for_subscribers=3", "recorder.overwrite=5"])
    fixed = apply_overrides(entries, ["camera.max_in_flight=3", "camera.source=0"])
    camera = next(e for e in fixed if e.name == "camera")
    assert camera.parameters["max_in_flight"] == 3 and camera.parameters["source"] == "0"
    one_line_error(sds("graph", str(REPO / "config" / "graphs" / "drop.yaml"), "--set",
                       "camera.max_in_flight=abc"), "is an integer")


def test_an_unknown_plugin_is_named_before_any_process_starts(tmp_path: Path) -> None:
    graph = yaml.safe_load((REPO / "config" / "graphs" / "drop.yaml").read_text())
    for node in graph["nodes"]:
        node["params"] = [str((REPO / "config" / "graphs" / p).resolve())
                          for p in ([node["params"]] if isinstance(node.get("params"), str)
                                    else node.get("params", []))]
    graph["nodes"][1]["plugin"] = graph["nodes"][1]["plugin"] + "X"
    path = tmp_path / "typo.yaml"
    path.write_text(yaml.safe_dump(graph))
    with pytest.raises(GraphFileError, match=r"no class \w+X in .*did you mean"):
        check_plugins(load_graph(path))
    graph["nodes"][1]["plugin"] = "sds_nodes.no_such_module:Node"
    path.write_text(yaml.safe_dump(graph))
    done = sds("graph", str(path))
    one_line_error(done, "no module sds_nodes.no_such_module installed")
    assert "started" not in done.stdout


@pytest.mark.parametrize("command", [
    ("view", "{file}"), ("export", "{file}", "--out", "{out}"),
    ("process", "--mcap", "{file}", "--out", "{out}"), ("analyze", "{file}", "--out", "{out}")])
def test_a_file_that_is_not_mcap_is_named_as_such(command: tuple[str, ...],
                                                  tmp_path: Path) -> None:
    file = tmp_path / "notes.mcap"
    shutil.copy(REPO / "README.md", file)
    done = sds(*(part.format(file=file, out=tmp_path / "out") for part in command))
    one_line_error(done, "is not an MCAP file")
    assert not (tmp_path / "out").exists() and not file.with_suffix(".rrd").exists()


def test_view_refuses_an_image_scale_of_zero_and_leaves_no_file(tmp_path: Path) -> None:
    from sds_record.mcap_files import McapRecorder

    recording = tmp_path / "run.mcap"
    recorder = McapRecorder(recording)
    recorder.add_topic("/t", "std_msgs/msg/Header")
    recorder.close()
    one_line_error(sds("view", str(recording), "--image-scale", "0"),
                   "argument --image-scale: 0 must be above 0")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]


@pytest.mark.parametrize("change, message", [
    (lambda rig: rig["container"].update(radious_mm=50), "unknown key 'radious_mm'"),
    (lambda rig: rig.update(gravity=9.81), "unknown key 'gravity' (did you mean gravity_m_s2"),
    (lambda rig: rig["diodes"][3].update(emiter_mm=[0, 0, 0]), "diodes[3]: unknown key"),
    (lambda rig: rig["container"].update(fill_height_mm=250.0), "would overflow"),
])
def test_a_rig_file_with_a_typo_or_an_impossible_fill_is_refused(change, message: str,
                                                                 tmp_path: Path) -> None:
    content = yaml.safe_load(RIG.read_text())
    content["camera"]["model"] = str((RIG.parent / content["camera"]["model"]).resolve())
    change(content)
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(content))
    with pytest.raises(RigError, match=f"^{re.escape(str(path))}: .*{re.escape(message)}"):
        load_rig(path)


def test_a_scenario_with_a_growing_mode_is_refused(tmp_path: Path) -> None:
    scenario = yaml.safe_load((REPO / "config" / "scenarios" / "ground_kick.yaml").read_text())
    scenario["rig"] = str(RIG)
    scenario["modes"][0]["damping_ratio"] = -0.01
    path = tmp_path / "growing.yaml"
    path.write_text(yaml.safe_dump(scenario))
    with pytest.raises(ScenarioError, match=r"modes\[0\]: damping_ratio -0.01 must be in"):
        load_scenario(path)


def test_resolution_refuses_a_camera_below_the_surface(tmp_path: Path) -> None:
    one_line_error(sds("resolution", "--height-mm", "-170", "--out", str(tmp_path / "r")),
                   "argument --height-mm: -170 must be above 0")
    assert not (tmp_path / "r").exists()


def test_every_argument_of_every_command_says_what_it_is() -> None:
    import argparse

    from sds_cli.cli import build_parser

    silent = []

    def walk(parser: argparse.ArgumentParser, command: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{command} {name}")
            elif not action.help:
                silent.append(f"{command} {'/'.join(action.option_strings) or action.dest}")

    walk(build_parser(), "sds")
    assert not silent, silent
