"""Building blocks shared by every link model: the model registry and resolution limits, rigid box
pieces with exact inertia, lumped hardware, and the handles of a built link."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import cast

import mujoco
import numpy as np

from fpm_sim.architecture.description import AnySection
from fpm_sim.config import LumpedMass, Material, Section
from fpm_sim.errors import FpmSimError

__all__ = [
    "DEFAULT_RESOLUTION",
    "LINK_MODELS",
    "MAX_SEGMENTS",
    "MIN_FLEX_EDGES",
    "LinkBuild",
    "LinkModelError",
    "LinkSpec",
    "add_box_geom",
    "add_compliance_springs",
    "add_hinge",
    "box_part",
    "check_link_model",
    "half_lump",
    "lump_part",
    "quat_z",
    "set_inertial",
]

LINK_MODELS = ("segments", "rigid", "cable", "flex")
"""Link models available (see the module docstring)."""

DEFAULT_RESOLUTION = {"segments": 12, "rigid": 1, "cable": 12, "flex": 16}
"""Default ``segments`` per link model, chosen from ``docs/link_models.md`` (228 mm steel bar):
``segments`` and ``cable`` (one linear model) at 12 put the cantilever's first three frequencies
+0.16 / +0.56 / +0.91 % from Euler-Bernoulli; ``flex`` at 16 puts them -0.07 / -0.79 / -2.12 % (its
lumped free-free modes are -1.6 / -3.4 / -5.7 % there, -0.4 / -0.9 / -1.5 % at 32)."""

MAX_SEGMENTS = 200
MIN_FLEX_EDGES = 4  # two constrained ends own two vertices each and need a free vertex between them


class LinkModelError(FpmSimError):
    """Unknown link model, or a resolution the model cannot take."""


def check_link_model(link_model: str, segments: int | None) -> None:
    """Raise :class:`LinkModelError` for an unknown model or an impossible resolution."""
    if link_model not in LINK_MODELS:
        raise LinkModelError(
            "unknown link model",
            parameter="link_model",
            value=link_model,
            hint=f"choose one of {', '.join(LINK_MODELS)}",
        )
    if link_model == "rigid":
        return
    low = MIN_FLEX_EDGES if link_model == "flex" else 1
    if not (isinstance(segments, int) and not isinstance(segments, bool) and low <= segments <= MAX_SEGMENTS):
        what = {"flex": "flex edges", "segments": "spring locations", "cable": "elastic joints"}[link_model]
        raise LinkModelError(
            f"link model {link_model!r} needs {low} <= segments <= {MAX_SEGMENTS} ({what} per link)",
            parameter="segments",
            value=segments,
        )


@dataclass(frozen=True)
class LinkSpec:
    """One straight link: where it starts, what it is made of and how it is discretised.

    Built by :func:`fpm_sim.model.links.add_link`, which dispatches on ``link_model`` to the builder of that link
    model (:data:`fpm_sim.model.links.LINK_BUILDERS`).

    Attributes
    ----------
    name
        Prefix of every body, joint, geom and site of the link.
    pos_m
        Link start in the parent body's frame (m).
    angle_rad
        Direction of the link about the parent's z axis (rad); the link's x axis points along it.
    length_m
        Length from start to end (m).
    section, material
        Cross-section and material of the link.
    link_model
        ``"segments"``, ``"rigid"``, ``"cable"`` or ``"flex"`` (:class:`fpm_sim.model.options.ModelOptions`).
    segments
        Spring locations (``segments``), elastic joints (``cable``) or flex edges (``flex``) per link.
    axial, rotary_inertia, shear
        As :class:`fpm_sim.model.options.ModelOptions`: axial springs, the sections' rotary inertia, shear springs
        (``segments`` only).
    hub_length_m
        Rigid length at each end (m; ``segments`` and ``rigid`` only): the springs are spread over the flexible span
        ``length_m - 2 hub_length_m`` only (pieces ``hub + l/2, l, ..., l, l/2 + hub``); mass stays uniform.
    damping_beta_s
        Stiffness-proportional damping ``beta`` (s): each spring of stiffness ``k`` gets damping ``beta k``.
    start_lumps, end_lumps
        Lumped hardware at the link's start and end.
    rgba
        Colour of the link's geoms.
    free_start, free_end
        Nothing holds the link's start (the caller gives the chain models a free joint; ``flex`` then starts on a
        free vertex and ``build.first`` is that vertex's body) or its end (``flex`` then ends on a free vertex
        instead of a hub); the chain models ignore both.
    """

    name: str
    pos_m: tuple[float, float, float]
    angle_rad: float
    length_m: float
    section: AnySection
    material: Material
    link_model: str = "segments"
    segments: int = 12
    axial: bool = True
    rotary_inertia: bool = False
    shear: bool = False
    hub_length_m: float = 0.0
    damping_beta_s: float = 0.0
    start_lumps: tuple[LumpedMass, ...] = ()
    end_lumps: tuple[LumpedMass, ...] = ()
    rgba: tuple[float, float, float, float] = (0.3, 0.5, 0.8, 1.0)
    free_start: bool = False
    free_end: bool = False
    spin_inertia: bool = True
    """False: the pieces' inertia about the link's own axis is dropped (to 1e-6 of the others: MuJoCo needs it
    positive): a link whose spin is free between two ball joints carries none of it into the other modes, and no
    torque along itself, so it gets no twist springs either (``segments`` and ``rigid`` only)."""
    lump_bodies: bool = False
    """``rigid`` only: each lump its own jointless child body at its place rather than folded into the link's
    inertial (the same dynamics): an exported flexible link built rigid keeps where its masses sit, so that it can
    be imported back flexible (``fpm-sim import``)."""
    quat: tuple[float, float, float, float] | None = None
    """Orientation of the link frame in the parent's (w, x, y, z), for links out of the base plane (``segments``
    and ``rigid`` only); None: ``angle_rad`` about z."""

    @property
    def start_quat(self) -> list[float]:
        """The link frame's orientation in the parent frame (w, x, y, z)."""
        return list(self.quat) if self.quat is not None else quat_z(self.angle_rad)

    @property
    def pos(self) -> np.ndarray:
        """``pos_m`` as an array (m)."""
        return np.array(self.pos_m, dtype=float)


@dataclass
class LinkBuild:
    """Handles of one link in the spec, filled by :func:`~fpm_sim.model.links.add_link`."""

    name: str
    bodies: list[mujoco.MjsBody]
    piece_lengths_m: list[float]
    joints: list[tuple[str, str]] = field(default_factory=list)  # (joint name, kind)
    sites: list[str] = field(default_factory=list)  # along the link, start to end
    end_offset_m: float | None = None  # where the link ends on ``last`` (default: its piece length)

    @property
    def first(self) -> mujoco.MjsBody:
        return self.bodies[0]

    @property
    def last(self) -> mujoco.MjsBody:
        return self.bodies[-1]

    @property
    def last_length_m(self) -> float:
        """Distance along ``last``'s x axis from its origin to the link's end."""
        return self.piece_lengths_m[-1] if self.end_offset_m is None else self.end_offset_m


def quat_z(angle_rad: float) -> list[float]:
    """Quaternion (w, x, y, z) of a rotation about z."""
    return [math.cos(angle_rad / 2.0), 0.0, 0.0, math.sin(angle_rad / 2.0)]


def _combined_inertia(
    parts: list[tuple[float, np.ndarray, np.ndarray]],
) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre and 3x3 inertia about the centre of point-bodies ``(mass, pos, inertia_about_own_com)``."""
    mass = sum((p[0] for p in parts), 0.0)
    com = sum((p[0] * p[1] for p in parts), np.zeros(3)) / mass
    inertia = np.zeros((3, 3))
    for m, pos, i_own in parts:
        r = pos - com
        inertia += i_own + m * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    return mass, com, inertia


def set_inertial(body: mujoco.MjsBody, parts: list[tuple[float, np.ndarray, np.ndarray]]) -> None:
    """Set a body's explicit inertial from lumped parts (see :func:`_combined_inertia`)."""
    mass, com, inertia = _combined_inertia(parts)
    body.mass = mass
    body.ipos = com
    body.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    body.explicitinertial = True


def lump_part(lump: LumpedMass, pos: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    return (lump.mass_kg, np.asarray(pos, float), np.diag(lump.inertia_kg_m2))


def box_part(
    length: float,
    section: AnySection,
    material: Material,
    x0: float,
    *,
    rotary_inertia: bool = False,
    spin_inertia: bool = True,
) -> tuple[float, np.ndarray, np.ndarray]:
    """A box piece along x from ``x0`` to ``x0 + length``.

    ``rotary_inertia=False`` drops the section's own rotary inertia about the bending axes (the
    ``t^2/12`` and ``h^2/12`` terms), keeping the ``l^2/12`` term of the piece's distributed mass:
    the chain then converges to an Euler-Bernoulli beam instead of a Rayleigh beam.
    """
    r = 1.0 if rotary_inertia else 0.0
    if isinstance(section, Section):
        t, h = section.thickness_m, section.height_m
        m = material.density_kg_m3 * length * t * h
        iyy, izz = m * (length**2 + r * h**2) / 12.0, m * (length**2 + r * t**2) / 12.0
        polar = m * (t**2 + h**2) / 12.0
    else:  # any other section (tube, general): the same terms from its constants (radii of gyration I / A)
        m = material.density_kg_m3 * length * section.area_m2
        gz, gy = section.gyration_sq_m2  # about the link's z (in-plane bending) and y axes
        iyy, izz = m * (length**2 / 12.0 + r * gy), m * (length**2 / 12.0 + r * gz)
        polar = m * (gy + gz)
    # Without rotary inertia the twist inertia is capped at iyy + izz (MuJoCo's triangle inequality),
    # 1e-5 below it so that the inequality survives the rounding of the written MJCF.
    ixx = min(polar, (iyy + izz) * (1.0 - 1e-5)) if spin_inertia else 1e-6 * (iyy + izz)
    i = np.diag([ixx, iyy, izz])
    return (m, np.array([x0 + length / 2.0, 0.0, 0.0]), i)


def add_box_geom(
    body: mujoco.MjsBody,
    name: str,
    length: float,
    section: AnySection,
    x0: float,
    rgba: tuple[float, float, float, float],
) -> None:
    """A contact-free box geom of the link section from ``x0`` to ``x0 + length`` along x (the cable
    plugin also reads its section from it)."""
    body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[length / 2.0, section.thickness_m / 2.0, section.height_m / 2.0],
        pos=[x0 + length / 2.0, 0.0, 0.0],
        rgba=list(rgba),
        contype=0,
        conaffinity=0,
    )


def half_lump(lump: LumpedMass) -> LumpedMass:
    """Half of a lumped mass (a joint's hardware shared by the two links it connects)."""
    half = cast("tuple[float, float, float]", tuple(v / 2.0 for v in lump.inertia_kg_m2))
    return LumpedMass(lump.mass_kg / 2.0, half)


def add_hinge(
    body: mujoco.MjsBody, name: str, axis: Sequence[float], stiffness: float = 0.0, damping: float = 0.0
) -> None:
    """A hinge about ``axis`` with stiffness (N m/rad) and damping (N m s/rad)."""
    j = body.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=axis)
    j.stiffness = [stiffness, 0.0, 0.0]
    j.damping = [damping, 0.0, 0.0]


_AXES = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}


def add_compliance_springs(
    body: mujoco.MjsBody, prefix: str, axes: str, k: float, beta: float, kind: str, kinds: dict[str, str]
) -> None:
    """Rotational springs ``{prefix}{axis}`` of stiffness ``k`` (damping ``beta k``) about each of
    ``axes`` (e.g. ``"xy"``); nothing when ``k`` is infinite (rigid)."""
    if math.isfinite(k):
        for ax in axes:
            add_hinge(body, f"{prefix}{ax}", _AXES[ax], k, beta * k)
            kinds[f"{prefix}{ax}"] = kind
