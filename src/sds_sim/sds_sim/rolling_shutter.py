"""A rig and a scenario whose camera reads its rows over a given time (tests and benches).

`rolling_rig` copies a rig file and its camera file, the camera file stating `readout_s`: what
the pipeline is told. `rolling_scenario` copies a scenario to render that readout (the true
camera's, `Sensor.readout_s`) on a given rig file.
"""

from __future__ import annotations

from pathlib import Path

import yaml
from sds_model.camera.files import read_yaml
from sds_model.errors import InputError
from sds_model.rig import load_rig


def rolling_rig(rig_file: Path, readout_s: float, folder: Path) -> Path:
    """folder/rig.yaml: the rig of `rig_file` with its camera file (folder/camera.yaml)
    stating `readout_s` [s]."""
    folder.mkdir(parents=True, exist_ok=True)
    camera_file = load_rig(rig_file).camera_file
    if camera_file is None:
        raise InputError(f"{rig_file}: its camera comes inline, not from a camera file")
    camera = read_yaml(camera_file)
    camera["readout_s"] = readout_s
    (folder / "camera.yaml").write_text(yaml.safe_dump(camera))
    rig = read_yaml(rig_file)
    rig["camera"]["model"] = str((folder / "camera.yaml").resolve())
    (folder / "rig.yaml").write_text(yaml.safe_dump(rig))
    return folder / "rig.yaml"


def rolling_scenario(scenario_file: Path, rig_file: Path, readout_s: float, folder: Path
                     ) -> Path:
    """folder/scenario.yaml: the scenario of `scenario_file` on `rig_file`, its camera
    reading the rows over `readout_s` [s]."""
    folder.mkdir(parents=True, exist_ok=True)
    content = read_yaml(scenario_file)
    content["rig"] = str(Path(rig_file).resolve())
    content["sensor"] = {**(content.get("sensor") or {}), "readout_s": readout_s}
    (folder / "scenario.yaml").write_text(yaml.safe_dump(content))
    return folder / "scenario.yaml"
