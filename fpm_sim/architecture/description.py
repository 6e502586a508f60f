"""The description of any flexible manipulator: chains of joints and straight links, an end effector, a task.

A manipulator is a set of **chains**. Each chain starts at a base frame (on the ground, or on the end of another
chain: ``parent``) and follows a **path** of joints and links in order. A chain either ends on an attachment point
of the **end effector** through an end joint (``at = "<point>"``: a closed loop) or ends open (a serial arm's last
link, or an arm whose end carries other chains).

Frames: a chain's frame starts at its base frame and moves along its path. A joint moves the frame by its
coordinate (revolute: rotation about ``axis`` by ``q`` rad; prismatic: translation along ``axis`` by ``q`` m;
universal: ``axis`` then ``axis2``; spherical: any rotation), its axes given in the frame before it. A link runs
along the frame's x axis for ``length_m``; its cross-section's ``thickness_m`` lies along the frame's y axis and
``height_m`` along its z axis (for a planar machine whose joint axes are z: in the plane and out of it). So a
chain's joint coordinates are zero when every link continues along its predecessor's x axis.

A **working mode** is an interval of one joint coordinate per chain (``branch_deg`` or ``branch_m``): of the
inverse kinematics' solutions, the one whose coordinates lie inside every interval is taken.

The **task coordinates** (``task``) are those of the end effector's frame the user sets: ``x``, ``y`` (``z``) in
metres and ``phi`` (rotation about z) in radians for a planar machine; a spatial one may set ``x``, ``y``, ``z``.
The end effector's other coordinates follow from the closures.

Every number may carry its provenance as ``{ value = ..., source = "..." }``; a bare number takes the file's
``default_source`` (or ``user: <file>``). The TOML reader is :func:`parse_description`; every error names the path
in the file (``chains[1].path[2].type``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NoReturn

from fpm_sim.config import LumpedMass, Material, Section
from fpm_sim.config.schema import ConfigError

__all__ = [
    "JOINT_TYPES",
    "PLANAR_TASK",
    "SPATIAL_TASK",
    "ChainDesc",
    "Description",
    "EndEffectorDesc",
    "GeneralSection",
    "JointDesc",
    "LinkDesc",
    "PlacedLump",
    "ServoGains",
    "TubeSection",
]

JOINT_TYPES = ("revolute", "prismatic", "universal", "spherical", "fixed")
"""Joint types. ``fixed`` joins rigidly (an end effector carried by a chain's last link)."""
JOINT_DOF = {"revolute": 1, "prismatic": 1, "universal": 2, "spherical": 3, "fixed": 0}
PLANAR_TASK = ("x", "y", "phi")
SPATIAL_TASK = ("x", "y", "z")


@dataclass(frozen=True)
class TubeSection:
    """Round tube: outer and inner diameter (m); inner 0 is a solid rod. ``J = 2 I`` (thin or thick wall)."""

    outer_diameter_m: float
    inner_diameter_m: float = 0.0

    @property
    def area_m2(self) -> float:
        return math.pi * (self.outer_diameter_m**2 - self.inner_diameter_m**2) / 4.0

    @property
    def i_inplane_m4(self) -> float:
        return math.pi * (self.outer_diameter_m**4 - self.inner_diameter_m**4) / 64.0

    @property
    def i_outofplane_m4(self) -> float:
        return self.i_inplane_m4

    @property
    def torsion_constant_m4(self) -> float:
        return 2.0 * self.i_inplane_m4

    @property
    def thickness_m(self) -> float:
        """Width of the drawn box along the link's y axis (m): the outer diameter."""
        return self.outer_diameter_m

    @property
    def height_m(self) -> float:
        """Height of the drawn box along the link's z axis (m): the outer diameter."""
        return self.outer_diameter_m

    @property
    def gyration_sq_m2(self) -> tuple[float, float]:
        """Squared radii of gyration of the section about the link's z and y axes (m^2): ``I / A``."""
        r2 = self.i_inplane_m4 / self.area_m2
        return (r2, r2)


@dataclass(frozen=True)
class GeneralSection:
    """Any section by its constants: area (m^2), second moments for bending in and out of the plane (m^4; the
    deflection along the link's y and z axes), and the torsion constant (m^4). Drawn as a square of equal area."""

    area_m2: float
    i_inplane_m4: float
    i_outofplane_m4: float
    torsion_constant_m4: float

    @property
    def thickness_m(self) -> float:
        return math.sqrt(self.area_m2)

    @property
    def height_m(self) -> float:
        return math.sqrt(self.area_m2)

    @property
    def gyration_sq_m2(self) -> tuple[float, float]:
        return (self.i_inplane_m4 / self.area_m2, self.i_outofplane_m4 / self.area_m2)


AnySection = Section | TubeSection | GeneralSection


@dataclass(frozen=True)
class PlacedLump:
    """A rigid lump at ``position_m`` in the frame of the body it sits on (principal axes along that frame's)."""

    lump: LumpedMass
    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class JointDesc:
    """One joint of a chain's path (see the module docstring for frames and coordinates).

    ``lump`` sits rigidly on the body *before* the joint, at the joint's centre (a chain's first joint: on the
    ground); ``lump_after`` on the body after it. ``branch`` is the working mode's interval of the coordinate (rad
    or m; a revolute interval is read modulo 2 pi). ``at`` names the end effector's attachment point of an end
    joint.
    """

    name: str
    type: str
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    axis2: tuple[float, float, float] = (0.0, 1.0, 0.0)
    actuated: bool = False
    lump: LumpedMass = field(default_factory=LumpedMass)
    lump_after: LumpedMass = field(default_factory=LumpedMass)
    """A lump on the body *after* the joint, at its centre (e.g. the half of a joint's hardware that turns with the
    next link, or the pin of an end joint)."""
    branch: tuple[float, float] | None = None
    at: str | None = None

    @property
    def dof(self) -> int:
        return JOINT_DOF[self.type]


@dataclass(frozen=True)
class LinkDesc:
    """A straight beam along the frame's x axis: length (m), section, material, flexible or rigid, and a lump
    rigid on its end (``end_lump``; e.g. a serial arm's tip)."""

    name: str
    length_m: float
    section: AnySection
    material: Material
    flexible: bool = True
    end_lump: LumpedMass = field(default_factory=LumpedMass)


@dataclass(frozen=True)
class ChainDesc:
    """A chain: its base frame and its path of joints and links.

    ``base_position_m`` and ``base_rotation`` (a 3x3 rotation matrix, row-major) are in the world frame, or in the
    end frame of chain ``parent``.
    """

    name: str
    path: tuple[JointDesc | LinkDesc, ...]
    base_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    parent: str | None = None

    @property
    def joints(self) -> tuple[JointDesc, ...]:
        return tuple(e for e in self.path if isinstance(e, JointDesc))

    @property
    def links(self) -> tuple[LinkDesc, ...]:
        return tuple(e for e in self.path if isinstance(e, LinkDesc))

    @property
    def end_joint(self) -> JointDesc | None:
        """The joint onto the end effector, or None for an open chain."""
        last = self.path[-1]
        return last if isinstance(last, JointDesc) and last.at is not None else None

    @property
    def moving_joints(self) -> tuple[JointDesc, ...]:
        """The joints whose coordinates the kinematics solves for (all but the end joint)."""
        end = self.end_joint
        return tuple(j for j in self.joints if j is not end)


@dataclass(frozen=True)
class EndEffectorDesc:
    """The rigid end effector: its attachment points (m, in its own frame) and its lumps."""

    attachments_m: dict[str, tuple[float, float, float]]
    lumps: tuple[PlacedLump, ...] = ()


SERVO_SOURCE = (
    "assumed default: the 3RRR's stated servo (fpm_sim.sim.trajectory.DEFAULT_SERVO_*: 500 N m/rad, 1 N m s/rad); "
    "a prismatic axis through a 10 mm-lead ball screw of it (x (2 pi / 0.01 m)^2)"
)
"""The provenance of :class:`ServoGains`' defaults (a description's ``[servos]`` table replaces them)."""
_SCREW = (2.0 * math.pi / 0.01) ** 2  # (rad/m)^2: a rotary servo seen through a 10 mm-lead ball screw


@dataclass(frozen=True)
class ServoGains:
    """The position servo of every actuated joint when the machine moves (rollouts with motor torques, moves):
    a spring-damper about the assembled coordinate, its set point moved by the command. Revolute: N m/rad and
    N m s/rad; prismatic: N/m and N s/m. Defaults: :data:`SERVO_SOURCE` (assumed; no machine's gains are known)."""

    stiffness_nm_per_rad: float = 500.0
    damping_nms_per_rad: float = 1.0
    stiffness_n_per_m: float = 500.0 * _SCREW
    damping_ns_per_m: float = 1.0 * _SCREW

    def gains(self, joint_type: str) -> tuple[float, float]:
        """``(stiffness, damping)`` of an actuated joint of ``joint_type`` (revolute or prismatic)."""
        if joint_type == "prismatic":
            return self.stiffness_n_per_m, self.damping_ns_per_m
        return self.stiffness_nm_per_rad, self.damping_nms_per_rad

    def to_dict(self, provenance: dict[str, str]) -> dict[str, Any]:
        """The gains and each one's source (the file's ``servos.<name>`` provenance, else :data:`SERVO_SOURCE`)."""
        return {
            k: {"value": float(getattr(self, k)), "source": provenance.get(f"servos.{k}", SERVO_SOURCE)}
            for k in ("stiffness_nm_per_rad", "damping_nms_per_rad", "stiffness_n_per_m", "damping_ns_per_m")
        }


@dataclass(frozen=True)
class Description:
    """A whole manipulator (module docstring). ``provenance`` maps each value's path in the file to its source."""

    name: str
    planar: bool
    task: tuple[str, ...]
    chains: tuple[ChainDesc, ...]
    end_effector: EndEffectorDesc
    damping_beta_s: float = 0.0
    check_poses: tuple[dict[str, float], ...] = ()
    """Poses the description is checked at (task coordinate -> value, m and rad); the first is the default pose."""
    servos: ServoGains = field(default_factory=ServoGains)
    """The actuated joints' servos when they move (``[servos]`` in the file; :class:`ServoGains`)."""
    provenance: dict[str, str] = field(default_factory=dict, compare=False)
    source_file: str | None = field(default=None, compare=False)
    data: dict[str, Any] | None = field(default=None, compare=False, repr=False)
    """The parsed TOML mapping it was read from (``None``: built in code): what a dotted-path edit
    (:mod:`fpm_sim.architecture.edit`) changes and reads again, so that an edited value is validated as the file's."""
    source: str = field(default="user", compare=False, repr=False)
    """The provenance of the file's bare numbers when it has no ``default_source`` (``user: <file>``)."""

    def chain(self, name: str) -> ChainDesc:
        for c in self.chains:
            if c.name == name:
                return c
        raise ConfigError(f"no chain named {name!r}", parameter="chains", value=name)

    @property
    def all_task_coordinates(self) -> tuple[str, ...]:
        """The coordinates of the end effector's frame that can be task coordinates."""
        return PLANAR_TASK if self.planar else SPATIAL_TASK

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready): name, kind, task coordinates and the chains' paths."""
        return {
            "name": self.name,
            "planar": self.planar,
            "task": list(self.task),
            "chains": [
                {
                    "name": c.name,
                    "parent": c.parent,
                    "path": [
                        {"joint": e.name, "type": e.type, "actuated": e.actuated}
                        if isinstance(e, JointDesc)
                        else {"link": e.name, "length_m": e.length_m, "flexible": e.flexible}
                        for e in c.path
                    ],
                }
                for c in self.chains
            ],
        }


def raise_at(path: str, message: str, value: Any = None, hint: str | None = None) -> NoReturn:
    """Raise the description's error naming ``path`` in the file."""
    if value is None:
        raise ConfigError(message, parameter=path, hint=hint)
    raise ConfigError(message, parameter=path, value=value, hint=hint)
