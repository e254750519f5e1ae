"""No tool replaces an existing file unless told to (`--overwrite`, `overwrite`)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from ros_helpers import SdsGraphRun
from sds_recon.results import ResultsWriter
from sds_record.mcap_files import McapRecorder

SDS = str(Path(sys.executable).with_name("sds"))
REPO = Path(__file__).resolve().parents[1]


def sds(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([SDS, *args], capture_output=True, text=True, timeout=120)


def refused(done: subprocess.CompletedProcess, text: str) -> None:
    assert done.returncode == 2, done.stdout + done.stderr
    assert text in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def recording(path: Path) -> bytes:
    """A recording with one message (one without any would not block a retry)."""
    recorder = McapRecorder(path)
    recorder.add_topic("/t", "std_msgs/msg/Header")
    recorder.write("/t", b"\x00\x01\x00\x00" + bytes(12), 1, 1)
    recorder.close()
    return path.read_bytes()


def test_a_recording_is_never_replaced_unless_asked(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    before = recording(path)
    with pytest.raises(ValueError, match="exists"):
        McapRecorder(path)
    assert path.read_bytes() == before
    McapRecorder(path, overwrite=True).close()
    assert path.read_bytes() != before


def test_mcap_repair_refuses_a_source_that_is_not_mcap_and_an_existing_target(
        tmp_path: Path) -> None:
    target = tmp_path / "existing.mcap"
    kept = recording(target)
    refused(sds("mcap-repair", str(REPO / "README.md"), str(tmp_path / "new.mcap")),
            "is not an MCAP file")
    assert not (tmp_path / "new.mcap").exists()
    source = tmp_path / "source.mcap"
    recording(source)
    refused(sds("mcap-repair", str(source), str(target)), "exists")
    assert target.read_bytes() == kept
    done = sds("mcap-repair", str(source), str(target), "--overwrite")
    assert done.returncode == 0, done.stderr


def test_results_folders_simulations_and_imports_are_kept(tmp_path: Path) -> None:
    out = tmp_path / "results"
    ResultsWriter(out).close()
    columns = (out / "columns.json").read_text()
    rig = str(REPO / "config" / "rigs" / "stelium.yaml")
    refused(sds("process", "--video", str(REPO / "README.md"), "--rig", rig, "--out", str(out)),
            "holds results already")
    refused(sds("export", str(tmp_path / "nothing.mcap"), "--out", str(out)), "no such")
    assert (out / "columns.json").read_text() == columns
    log = tmp_path / "SDS_LOG.TXT"
    log.write_text("$SDS1,0,1234049,LAS,1*13\r\n")
    existing = tmp_path / "log.mcap"
    kept = recording(existing)
    refused(sds("import-sd", str(log), "--out", str(existing)), "exists")
    assert existing.read_bytes() == kept
    (tmp_path / "sim" / "truth").mkdir(parents=True)
    (tmp_path / "sim" / "truth" / "run.json").write_text("{}")
    refused(sds("simulate", str(REPO / "config" / "scenarios" / "ground_kick.yaml"), "--out",
                str(tmp_path / "sim")), "holds a simulation already")


@pytest.mark.ros
def test_the_recorder_refuses_an_existing_output_at_start(tmp_path: Path) -> None:
    output = tmp_path / "earlier.mcap"
    kept = recording(output)
    graph = SdsGraphRun("record.yaml", "--set", f"recorder.output={output}")
    assert graph.wait(timeout=60) == 2, graph.output()
    assert "exists" in graph.output() and "Traceback" not in graph.output()
    assert output.read_bytes() == kept


@pytest.mark.ros
def test_a_misspelled_parameter_is_an_error_naming_the_close_match(tmp_path: Path) -> None:
    graph = SdsGraphRun("record.yaml", "--set", f"recorder.outptu={tmp_path / 'x.mcap'}")
    assert graph.wait(timeout=60) == 2, graph.output()
    assert "no parameter 'outptu'; did you mean output" in graph.output(), graph.output()
    assert "Traceback" not in graph.output() and not (tmp_path / "x.mcap").exists()


def test_calibration_and_camera_files_are_kept(tmp_path: Path) -> None:
    existing = tmp_path / "existing.yaml"
    existing.write_text("kept: true\n")
    rig = str(REPO / "config" / "rigs" / "stelium.yaml")
    for args in (["calibrate", "camera", "--model", "pinhole", "--images", rig, "--board", "9x6",
                  "--square", "20"],
                 ["calibrate", "lasers", "--rig", rig, "--spots", rig, "--surfaces", rig],
                 ["camera", "import", "ocamcalib", rig],
                 ["camera", "camera-info", rig]):
        refused(sds(*args, "--out", str(existing)), "exists")
        assert existing.read_text() == "kept: true\n"


def test_reports_rerun_files_and_tables_are_kept(tmp_path: Path) -> None:
    analysis = tmp_path / "analysis"
    analysis.mkdir()
    (analysis / "analysis.json").write_text("{}")
    refused(sds("analyze", str(REPO / "README.md"), "--out", str(analysis)),
            "holds an analysis already")
    rrd = tmp_path / "run.rrd"
    rrd.write_text("kept")
    refused(sds("view", str(REPO / "README.md"), "--out", str(rrd)), "exists")
    table = tmp_path / "resolution"
    table.mkdir()
    (table / "resolution.csv").write_text("kept")
    refused(sds("resolution", "--out", str(table)), "exists")
    assert (analysis / "analysis.json").read_text() == "{}" and rrd.read_text() == "kept"
    assert (table / "resolution.csv").read_text() == "kept"
    done = sds("resolution", "--out", str(table), "--overwrite")
    assert done.returncode == 0 and (table / "resolution.csv").read_text() != "kept"
