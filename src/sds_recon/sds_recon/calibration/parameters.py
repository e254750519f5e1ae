"""The joint fit's parameters as one table: what each is, its unit and scale, the prior the
user declared, and what calibration data determine it.

The fit (`self_calibration.py`), its report (`rig_report.py`) and the planner (`plan.py`) read
this one description. A parameter is a small change from the rig file's value (a rotation or
tilt [rad], a shift [mm]); its prior, where the user declared a tolerance (rig file
`tolerances:`, the surfaces CSV's σ columns), is a residual value / σ_prior in the fit, so
that it moves only as far as the data require.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Kind:
    """What the parameters of one kind share."""

    name: str
    unit: str              # "rad" or "mm" (the report shows rad as degrees)
    scale: float           # a typical change: the solver's scale, 1e-6 of it the derivative step
    limit: float           # largest σ at which a parameter without a prior counts as determined
    goal: float            # σ above which a fitted parameter is reported as weakly determined
    determined_by: str     # the calibration data that determine a parameter of this kind


DEGREE = float(np.radians(1.0))
CAMERA_ROTATION_KIND = Kind("camera rotation", "rad", DEGREE, np.radians(0.2),
                            np.radians(0.033), "tilts about the second axis")
CAMERA_POSITION_KIND = Kind("camera position", "mm", 1.0, 1.0, 0.1,
                            "tilts about the second axis (or known emitters)")
BEAM_KIND = Kind("beam", "rad", DEGREE, np.radians(0.2), np.radians(0.017),
                 "tilts about the second axis, or a second fill level (its spot hardly moves "
                 "on these surfaces: it sits near the tilt axis)")
EMITTER_KIND = Kind("emitter", "mm", 1.0, 1.0, 0.1,
                    "a second fill level and tilts about the second axis")
SURFACE_TILT_KIND = Kind("surface tilt", "rad", DEGREE, np.radians(0.2), np.radians(0.033),
                         "a more accurate reading of the tilt table")
SURFACE_OFFSET_KIND = Kind("surface offset", "mm", 1.0, 1.0, 0.1,
                           "a more accurate fill level")
LINE_PLANE_KIND = Kind("line plane", "rad", DEGREE, np.radians(0.2), np.radians(0.033),
                       "tilts about the second axis (a line that runs along the tilt axis lies "
                       "in nearly every plane through it)")
LINE_OFFSET_KIND = Kind("line plane offset", "mm", 1.0, 1.0, 0.1, LINE_PLANE_KIND.determined_by)



def intrinsic_kind(name: str, sigma: float) -> Kind:
    """The kind of one camera intrinsic (a camera file's `sigma:` entry): its own scale, always
    determined (its prior bounds it)."""
    unit = "px" if name.endswith("_px") or name.startswith("a") else "-"
    return Kind(f"camera {name}", unit, sigma, np.inf, np.inf,
                "a camera calibration from more images (sds calibrate camera)")


CAMERA_ROTATION = ("camera rotation about X", "camera rotation about Y",
                   "camera rotation about Z")
CAMERA_SHIFT = ("camera X", "camera Y", "camera Z")
LINE_PLANE = ("line plane tilt a", "line plane tilt b", "line plane offset")
CAMERA_Z_DETERMINED_BY = "a level surface at a second known fill level"


@dataclass(frozen=True)
class Parameter:
    """One parameter of the joint fit: a change from the rig file's (or the CSV's) value."""

    name: str
    kind: Kind
    prior_sigma: float = np.inf     # one σ of the declared tolerance [rad or mm]; inf: none
    determined_by: str = ""         # "" : the kind's

    @property
    def has_prior(self) -> bool:
        """Whether the user declared a tolerance for it (it is then always determined)."""
        return bool(np.isfinite(self.prior_sigma))

    @property
    def advice(self) -> str:
        """The calibration data that determine it."""
        return self.determined_by or self.kind.determined_by


@dataclass(frozen=True)
class ParameterTable:
    """The fit's parameters in the order of its vector."""

    parameters: tuple[Parameter, ...]

    def __len__(self) -> int:
        return len(self.parameters)

    @property
    def names(self) -> list[str]:
        """Every parameter's name, in order."""
        return [p.name for p in self.parameters]

    @property
    def scales(self) -> np.ndarray:
        """Every parameter's typical change [rad or mm]."""
        return np.array([p.kind.scale for p in self.parameters])

    @property
    def prior_sigmas(self) -> np.ndarray:
        """Every parameter's prior σ (inf where none was declared)."""
        return np.array([p.prior_sigma for p in self.parameters])

    @property
    def limits(self) -> np.ndarray:
        """Every parameter's largest σ to count as determined."""
        return np.array([p.kind.limit for p in self.parameters])

    @property
    def goals(self) -> np.ndarray:
        """Every parameter's goal σ."""
        return np.array([p.kind.goal for p in self.parameters])

    def index(self, name: str) -> int:
        """The position of a parameter by name."""
        return self.names.index(name)
