"""The rig description: camera and its pose, laser diodes, line laser, container and fluid."""

from __future__ import annotations

import difflib
import os
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from sds_model.camera.files import camera_from_dict, camera_sigma, read_yaml
from sds_model.camera.model import CameraModel, CameraModelError
from sds_model.camera.rolling_shutter import RollingShutter, rolling_shutter
from sds_model.errors import InputError
from sds_model.geometry import RigidTransform

WORLD_FRAME = ("origin on the container axis at the flat liquid surface (fill level), Z up "
               "against gravity, mm")


class RigError(InputError):
    """A rig file that does not describe a usable rig; the message names the bad field."""


@dataclass(frozen=True)
class LaserDiode:
    """One laser diode: emitter position [mm, world], unit beam direction (to the liquid),
    the direction's one-sigma uncertainty [deg] once calibrated, whether it is tracked
    (a diode that calibration could not identify is kept in the file but not tracked), and
    its emitter's own position tolerance [mm, σ per axis] where it differs from the rig's."""

    laser_id: int
    ring: int
    emitter_mm: np.ndarray
    direction: np.ndarray
    direction_sigma_deg: float | None = None
    tracked: bool = True
    emitter_sigma_mm: float | None = None

    def point_at(self, distance_mm: ArrayLike) -> np.ndarray:
        """Points on the beam `distance_mm` from the emitter (N×3, mm)."""
        return self.emitter_mm + np.asarray(distance_mm, dtype=float)[..., None] * self.direction


@dataclass(frozen=True)
class LineLaser:
    """The line laser: emitter position [mm, world] and the unit normal of its light plane."""

    emitter_mm: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class Container:
    """Cylindrical container: inner radius, liquid fill height and wall height [mm]."""

    radius_mm: float
    fill_height_mm: float
    height_mm: float


@dataclass(frozen=True)
class Fluid:
    """Liquid properties used by the sloshing theory."""

    density_kg_m3: float
    surface_tension_n_m: float


@dataclass(frozen=True)
class Tolerances:
    """How far the rig as built may depart from its file: one σ per axis of each quantity
    (None: exact as drawn, or, for the camera pose and the beams' directions, unknown and
    fitted freely where the calibration's data determine it)."""

    emitter_mm: float | None = None           # each emitter's position (a 3D-printed holder)
    camera_position_mm: float | None = None   # the camera centre
    camera_angle_deg: float | None = None     # the camera's rotation about each world axis
    beam_lean_deg: float | None = None        # each beam's direction, about each axis across it
    line_plane_deg: float | None = None       # the line laser plane's normal
    line_plane_mm: float | None = None        # the line laser plane along its normal


TOLERANCE_KEYS = tuple(f.name for f in fields(Tolerances))


@dataclass(frozen=True)
class Rig:
    """Everything geometric about one rig, in the world frame (WORLD_FRAME)."""

    camera: CameraModel
    world_to_camera: RigidTransform
    diodes: tuple[LaserDiode, ...]
    line_laser: LineLaser | None
    container: Container
    fluid: Fluid
    gravity_m_s2: float
    camera_file: Path | None   # None: the camera model came inline (a recording's rig)
    calibration: dict[str, Any] | None = None   # what `sds calibrate rig` found (uncertainties)
    tolerances: Tolerances = field(default_factory=Tolerances)
    camera_sigma: dict[str, float] = field(default_factory=dict)   # the camera file's `sigma:`
    camera_shutter: RollingShutter = field(default_factory=RollingShutter)   # its readout

    @property
    def tracked_diodes(self) -> tuple[LaserDiode, ...]:
        """The diodes the tracker follows (calibration may leave unidentified ones out)."""
        return tuple(d for d in self.diodes if d.tracked)

    @cached_property
    def camera_position_mm(self) -> np.ndarray:
        """Camera centre in the world frame [mm] (computed once: every triangulation uses it)."""
        position = self.world_to_camera.inverse().translation_mm.copy()
        position.flags.writeable = False
        return position

    def project(self, points_mm: ArrayLike) -> np.ndarray:
        """World points (N×3 mm) → image pixels (N×2); NaN where the camera does not see them."""
        return self.camera.project(self.world_to_camera.apply(points_mm))

    def surface_px_per_mm(self) -> float:
        """Image scale [px per mm along X] at the centre of the flat surface."""
        pixels = self.project(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
        return float(np.linalg.norm(pixels[1] - pixels[0]))

    def pixel_rays(self, pixels: ArrayLike) -> np.ndarray:
        """Unit rays (N×3) in the world frame from the camera centre through the pixels."""
        return self.camera.pixel_to_ray(pixels) @ self.world_to_camera.rotation

    def rim_px(self, camera: CameraModel, samples: int = 361) -> np.ndarray:
        """The liquid's rim at rest (the wall at Z = 0) in the image (samples×2 px).

        `camera` is this rig's camera or a scaled copy of it.
        """
        angle = np.linspace(0.0, 2 * np.pi, samples)
        radius = self.container.radius_mm
        rim = radius * np.column_stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)])
        return camera.project(self.world_to_camera.apply(rim))

    def container_region_px(self, camera: CameraModel, margin_px: int = 16) -> tuple[int, ...]:
        """(x, y, width, height) [px] of the image region that holds the liquid's rim.

        `camera` is this rig's camera or a scaled copy of it; the region is clipped to the image.
        """
        pixels = self.rim_px(camera)
        low = np.maximum(np.floor(np.nanmin(pixels, axis=0)) - margin_px, 0).astype(int)
        high = np.minimum(np.ceil(np.nanmax(pixels, axis=0)) + margin_px + 1,
                          [camera.width_px, camera.height_px]).astype(int)
        return int(low[0]), int(low[1]), int(high[0] - low[0]), int(high[1] - low[1])

    @cached_property
    def _diodes_by_id(self) -> dict[int, LaserDiode]:
        """Laser id → diode (built once: every triangulated spot looks its diode up)."""
        return {diode.laser_id: diode for diode in self.diodes}

    def emitter_sigma_mm(self, laser_id: int) -> float:
        """The σ per axis of a diode's emitter position [mm]: its own, else the rig's, else 0
        (exact as drawn)."""
        own = self.diode(laser_id).emitter_sigma_mm
        if own is not None:
            return own
        return self.tolerances.emitter_mm or 0.0

    def diode(self, laser_id: int) -> LaserDiode:
        """The diode with this id."""
        try:
            return self._diodes_by_id[laser_id]
        except KeyError:
            raise KeyError(f"no laser diode with id {laser_id}") from None


def _vector(content: dict[str, Any], key: str, where: str, unit: bool = False) -> np.ndarray:
    try:
        vector = np.asarray(content[key], dtype=float).reshape(3)
    except KeyError as error:
        raise RigError(f"{where}.{key} is missing") from error
    except (TypeError, ValueError) as error:
        raise RigError(f"{where}.{key} must be three numbers, got {content[key]!r}") from error
    if not np.isfinite(vector).all():
        raise RigError(f"{where}.{key} must be finite, got {vector.tolist()}")
    if unit:
        norm = np.linalg.norm(vector)
        if norm < 1e-9:
            raise RigError(f"{where}.{key} must not be zero")
        vector = vector / norm
    return vector


def _number(content: dict[str, Any], key: str, where: str, positive: bool = True) -> float:
    try:
        value = float(content[key])
    except KeyError as error:
        raise RigError(f"{where}.{key} is missing") from error
    except (TypeError, ValueError) as error:
        raise RigError(f"{where}.{key} must be a number, got {content[key]!r}") from error
    if positive and not value > 0:
        raise RigError(f"{where}.{key} must be positive, got {value}")
    return value


RIG_KEYS = {
    "": ("camera", "diodes", "line_laser", "container", "fluid", "gravity_m_s2", "tolerances",
         "calibration"),
    "camera": ("model", "position_mm", "orientation_xyz_deg"),
    "diodes[]": ("id", "ring", "emitter_mm", "direction", "direction_sigma_deg", "tracked",
                 "emitter_sigma_mm"),
    "line_laser": ("emitter_mm", "normal"),
    "container": ("radius_mm", "fill_height_mm", "height_mm"),
    "fluid": ("density_kg_m3", "surface_tension_n_m"),
}
"""The keys of each section of a rig file (`rig_to_dict` writes no other)."""


def _known_keys(content: dict[str, Any], section: str, where: str) -> None:
    """RigError naming a key the section does not have (a typo would silently be ignored)."""
    allowed = RIG_KEYS[section]
    for key in content:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f"did you mean {close[0]}?" if close else f"known: {', '.join(allowed)}"
            raise RigError(f"{where or 'the rig'}: unknown key {key!r} ({hint})")


def _section(content: dict[str, Any], key: str) -> dict[str, Any]:
    section = content.get(key)
    if not isinstance(section, dict):
        raise RigError(f"{key} is missing or not a mapping")
    return section


def camera_pose(position_mm: ArrayLike, orientation_xyz_deg: ArrayLike) -> RigidTransform:
    """World → camera transform (Eq. 1) from the camera centre and its orientation.

    `orientation_xyz_deg`: the camera-to-world rotation as extrinsic x-y-z angles [deg];
    [180, 0, 0] looks straight down with image x along world X and image y along world −Y.
    """
    camera_to_world = Rotation.from_euler("xyz", np.asarray(orientation_xyz_deg, dtype=float),
                                          degrees=True).as_matrix()
    rotation = camera_to_world.T
    return RigidTransform(rotation, -rotation @ np.asarray(position_mm, dtype=float))


def rig_from_dict(content: Any, base: Path) -> Rig:
    """Build a rig from a rig file's mapping; relative paths are taken from `base`."""
    if not isinstance(content, dict):
        raise RigError("a rig file must be a YAML mapping")
    _known_keys(content, "", "")
    camera_section = _section(content, "camera")
    _known_keys(camera_section, "camera", "camera")
    if "model" not in camera_section:
        raise RigError("camera.model is missing (a camera file, config/cameras/*.yaml)")
    model = camera_section["model"]
    camera_file = None if isinstance(model, dict) else (base / str(model)).resolve()
    try:   # a mapping: the camera file's content inline (a recording's rig, `rig_document`)
        content_of_camera = model if camera_file is None else read_yaml(camera_file)
        camera = camera_from_dict(content_of_camera)
        intrinsics_sigma = camera_sigma(content_of_camera, camera)
        shutter = rolling_shutter(content_of_camera)
    except CameraModelError as error:
        where = "camera.model" if camera_file is None else f"camera.model {camera_file}"
        raise RigError(f"{where}: {error}") from error
    pose = camera_pose(_vector(camera_section, "position_mm", "camera"),
                       _vector(camera_section, "orientation_xyz_deg", "camera"))
    diodes = []
    entries = content.get("diodes", [])
    if not isinstance(entries, list):
        raise RigError("diodes must be a list")
    for index, entry in enumerate(entries):
        where = f"diodes[{index}]"
        if not isinstance(entry, dict) or "id" not in entry:
            raise RigError(f"{where} must be a mapping with an id")
        _known_keys(entry, "diodes[]", where)
        sigma = entry.get("direction_sigma_deg")
        emitter_sigma = entry.get("emitter_sigma_mm")
        diodes.append(LaserDiode(int(entry["id"]), int(entry.get("ring", 0)),
                                 _vector(entry, "emitter_mm", where),
                                 _vector(entry, "direction", where, unit=True),
                                 None if sigma is None else _number(entry, "direction_sigma_deg",
                                                                    where, positive=False),
                                 bool(entry.get("tracked", True)),
                                 None if emitter_sigma is None else _number(
                                     entry, "emitter_sigma_mm", where, positive=False)))
    ids = [d.laser_id for d in diodes]
    if len(set(ids)) != len(ids):
        raise RigError(f"diode ids must be unique, got {ids}")
    line = content.get("line_laser")
    line_laser = None
    if line is not None:
        if not isinstance(line, dict):
            raise RigError("line_laser must be a mapping")
        _known_keys(line, "line_laser", "line_laser")
        line_laser = LineLaser(_vector(line, "emitter_mm", "line_laser"),
                               _vector(line, "normal", "line_laser", unit=True))
    container = _section(content, "container")
    _known_keys(container, "container", "container")
    fluid = _section(content, "fluid")
    _known_keys(fluid, "fluid", "fluid")
    vessel = Container(_number(container, "radius_mm", "container"),
                       _number(container, "fill_height_mm", "container"),
                       _number(container, "height_mm", "container"))
    if vessel.fill_height_mm > vessel.height_mm:
        raise RigError(f"container.fill_height_mm {vessel.fill_height_mm:g} is above its "
                       f"height_mm {vessel.height_mm:g}: the liquid would overflow")
    return Rig(
        camera=camera, world_to_camera=pose, diodes=tuple(diodes), line_laser=line_laser,
        container=vessel,
        fluid=Fluid(_number(fluid, "density_kg_m3", "fluid"),
                    _number(fluid, "surface_tension_n_m", "fluid", positive=False)),
        gravity_m_s2=_number(content, "gravity_m_s2", "rig", positive=False),
        camera_file=camera_file,
        calibration=_calibration(content),
        tolerances=_tolerances(content),
        camera_sigma=intrinsics_sigma,
        camera_shutter=shutter,
    )


def _tolerances(content: dict[str, Any]) -> Tolerances:
    """The `tolerances:` section (absent: every quantity as drawn or freely fitted)."""
    section = content.get("tolerances")
    if section is None:
        return Tolerances()
    if not isinstance(section, dict):
        raise RigError("tolerances must be a mapping")
    unknown = sorted(set(section) - set(TOLERANCE_KEYS))
    if unknown:
        raise RigError(f"tolerances: unknown keys {unknown} (known: {list(TOLERANCE_KEYS)})")
    return Tolerances(**{key: _number(section, key, "tolerances", positive=False)
                         for key in section if section[key] is not None})


def _calibration(content: dict[str, Any]) -> dict[str, Any] | None:
    calibration = content.get("calibration")
    if calibration is not None and not isinstance(calibration, dict):
        raise RigError("calibration must be a mapping")
    return calibration


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig file (config/rigs/*.yaml)."""
    path = Path(path)
    try:
        content = read_yaml(path)
    except CameraModelError as error:
        raise RigError(str(error)) from error
    try:
        return rig_from_dict(content, path.parent)
    except RigError as error:
        raise RigError(f"{path}: {error}") from error


def _numbers(values: ArrayLike) -> list[float]:
    """Plain floats rounded to 12 significant digits (no 1e-31 noise in the file)."""
    return [float(f"{v:.12g}") + 0.0 for v in np.asarray(values, dtype=float)]


def _camera_reference(rig: Rig, directory: Path | None) -> str | dict[str, Any]:
    """camera.model: the camera file relative to `directory`, or (no directory, or a rig
    whose camera came inline) the camera model's mapping itself."""
    if directory is None or rig.camera_file is None:
        inline = rig.camera.to_dict()
        if rig.camera_sigma:
            inline["sigma"] = dict(rig.camera_sigma)
        if rig.camera_shutter.readout_s:
            inline["readout_s"] = rig.camera_shutter.readout_s
            inline["readout_direction"] = rig.camera_shutter.direction
        return inline
    try:
        return str(rig.camera_file.relative_to(directory.resolve()))
    except ValueError:
        return os.path.relpath(rig.camera_file, directory.resolve())


def rig_to_dict(rig: Rig, directory: Path | None) -> dict[str, Any]:
    """The rig file's mapping, with the camera file path relative to `directory` (None: the
    camera model inline, a self-contained rig)."""
    camera_to_world = Rotation.from_matrix(rig.world_to_camera.rotation.T)
    content: dict[str, Any] = {
        "camera": {"model": _camera_reference(rig, directory),
                   "position_mm": _numbers(rig.camera_position_mm),
                   "orientation_xyz_deg": _numbers(camera_to_world.as_euler("xyz",
                                                                            degrees=True))},
        "container": {"radius_mm": rig.container.radius_mm,
                      "fill_height_mm": rig.container.fill_height_mm,
                      "height_mm": rig.container.height_mm},
        "fluid": {"density_kg_m3": rig.fluid.density_kg_m3,
                  "surface_tension_n_m": rig.fluid.surface_tension_n_m},
        "gravity_m_s2": rig.gravity_m_s2,
    }
    if rig.line_laser is not None:
        content["line_laser"] = {"emitter_mm": _numbers(rig.line_laser.emitter_mm),
                                 "normal": _numbers(rig.line_laser.normal)}
    content["diodes"] = [_diode_entry(d) for d in rig.diodes]
    declared = {key: getattr(rig.tolerances, key) for key in TOLERANCE_KEYS
                if getattr(rig.tolerances, key) is not None}
    if declared:
        content["tolerances"] = declared
    if rig.calibration is not None:
        content["calibration"] = rig.calibration
    return content


def _diode_entry(diode: LaserDiode) -> dict[str, Any]:
    entry: dict[str, Any] = {"id": diode.laser_id, "ring": diode.ring,
                             "emitter_mm": _numbers(diode.emitter_mm),
                             "direction": _numbers(diode.direction)}
    if diode.direction_sigma_deg is not None:
        entry["direction_sigma_deg"] = float(f"{diode.direction_sigma_deg:.3g}")
    if not diode.tracked:
        entry["tracked"] = False
    if diode.emitter_sigma_mm is not None:
        entry["emitter_sigma_mm"] = diode.emitter_sigma_mm
    return entry


def rig_document(rig: Rig) -> str:
    """The rig as one self-contained YAML document, its camera model inline: what a recording
    carries (`/recon/rig`), readable on a machine without the rig's files."""
    return yaml.safe_dump(rig_to_dict(rig, None), sort_keys=False, default_flow_style=None,
                          width=100)


def rig_from_document(text: str, source: str) -> Rig:
    """The rig of `rig_document`'s text; `source` names it in errors."""
    try:
        content = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise RigError(f"{source}: not YAML: {error}") from error
    try:
        return rig_from_dict(content, Path.cwd())
    except RigError as error:
        raise RigError(f"{source}: {error}") from error


def save_rig(rig: Rig, path: str | Path, comment: str = "") -> Path:
    """Write a rig file that load_rig reads back to the same rig."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = f"# SDS rig file (load with sds_model.rig.load_rig).\n# World frame: {WORLD_FRAME}.\n"
    header += "".join(f"# {line}\n" for line in comment.splitlines())
    body = yaml.safe_dump(rig_to_dict(rig, path.parent), sort_keys=False,
                          default_flow_style=None, width=100)
    path.write_text(header + body)
    return path
