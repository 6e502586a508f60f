"""Flexible link discretisations added to a :class:`mujoco.MjSpec`.

``segments`` (default): the rigid-finite-element layout. A link of length L is cut into ``n`` equal
parts of length ``l = L / n``; a spring-damper element sits at the centre of each part, so the rigid
pieces are ``l/2, l, ..., l, l/2`` long (``n + 1`` bodies, ``n`` spring locations). Each spring
location carries three hinges of the link frame (x along the link, z along the motor axes):

=========  ======  ===============  ============================================
kind       axis    stiffness        what it is
=========  ======  ===============  ============================================
bend_in    z       E * I_in / l      bending in the base plane (I_in = h t^3 / 12)
bend_out   y       E * I_out / l     bending out of the base plane (I_out = t h^3 / 12)
twist      x       G * J / l         torsion (Saint-Venant J of the rectangle)
axial      x       E * A / l         optional slide: axial stretch
=========  ======  ===============  ============================================

Each spring gets damping ``beta * k`` (``Damping.stiffness_proportional_s``). Masses and inertias of
the pieces are computed exactly (boxes) and lumped hardware is added at the link ends; the resulting
inertia is set explicitly on each body.

``rigid``: one rigid body per link (no springs): the kinematic-chain limit, for comparison.

``cable`` and ``flex``: MuJoCo's own deformables (the ``mujoco.elasticity.cable`` plugin on the
segment chain's bodies, and a 1D ``flex`` rod); built by :mod:`fpm_sim.deformable_links`, which
states what each can and cannot represent. Their ``segments`` is the number of elastic joints
(``cable``) or flex edges (``flex``). Neither is available in MJX; ``segments`` stays the default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from .config import LumpedMass, Material, Section

__all__ = [
    "DEFAULT_RESOLUTION",
    "LINK_MODELS",
    "LinkBuild",
    "LinkModelError",
    "add_link",
    "check_link_model",
    "SPRING_KINDS",
]

LINK_MODELS = ("segments", "rigid", "cable", "flex")
"""Link models available (see the module docstring)."""

SPRING_KINDS = ("bend_in", "bend_out", "twist", "axial")

DEFAULT_RESOLUTION = {"segments": 12, "rigid": 1, "cable": 12, "flex": 16}
"""Default ``segments`` per link model, chosen from ``docs/link_models.md`` (228 mm steel bar):
``segments`` and ``cable`` (one linear model) at 12 put the cantilever's first three frequencies
+0.16 / +0.56 / +0.91 % from Euler-Bernoulli; ``flex`` at 16 puts them -0.07 / -0.79 / -2.12 % (its
lumped free-free modes are -1.6 / -3.4 / -5.7 % there, -0.4 / -0.9 / -1.5 % at 32)."""

_MAX_SEGMENTS = 200
_MIN_FLEX_EDGES = 4  # two constrained ends own two vertices each and need a free vertex between them


class LinkModelError(ValueError):
    """Unknown link model, or a resolution the model cannot take."""


def check_link_model(link_model: str, segments: int) -> None:
    """Raise :class:`LinkModelError` for an unknown model or an impossible resolution."""
    if link_model not in LINK_MODELS:
        raise LinkModelError(
            f"unknown link model {link_model!r} (--link-model); choose one of {', '.join(LINK_MODELS)}"
        )
    if link_model == "rigid":
        return
    low = _MIN_FLEX_EDGES if link_model == "flex" else 1
    if not (isinstance(segments, int) and not isinstance(segments, bool) and low <= segments <= _MAX_SEGMENTS):
        what = {"flex": "flex edges", "segments": "spring locations", "cable": "elastic joints"}[link_model]
        raise LinkModelError(
            f"link model {link_model!r} needs {low} <= segments <= {_MAX_SEGMENTS} ({what} per link; --segments), "
            f"got {segments!r}"
        )


@dataclass
class LinkBuild:
    """Handles of one link in the spec, filled by :func:`add_link`."""

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
    mass = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / mass
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
    length: float, section: Section, material: Material, x0: float, *, rotary_inertia: bool = False
) -> tuple[float, np.ndarray, np.ndarray]:
    """A box piece along x from ``x0`` to ``x0 + length``.

    ``rotary_inertia=False`` drops the section's own rotary inertia about the bending axes (the
    ``t^2/12`` and ``h^2/12`` terms), keeping the ``l^2/12`` term of the piece's distributed mass:
    the chain then converges to an Euler-Bernoulli beam instead of a Rayleigh beam.
    """
    t, h = section.thickness_m, section.height_m
    m = material.density_kg_m3 * length * t * h
    r = 1.0 if rotary_inertia else 0.0
    iyy, izz = m * (length**2 + r * h**2) / 12.0, m * (length**2 + r * t**2) / 12.0
    # Without rotary inertia the twist inertia is capped at iyy + izz (MuJoCo's triangle inequality),
    # 1e-5 below it so that the inequality survives the rounding of the written MJCF.
    ixx = min(m * (t**2 + h**2) / 12.0, (iyy + izz) * (1.0 - 1e-5))
    i = np.diag([ixx, iyy, izz])
    return (m, np.array([x0 + length / 2.0, 0.0, 0.0]), i)


def add_box_geom(
    body: mujoco.MjsBody,
    name: str,
    length: float,
    section: Section,
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


def _add_spring(body: mujoco.MjsBody, name: str, kind: str, stiffness: float, beta: float) -> None:
    axis = {"bend_in": [0, 0, 1], "bend_out": [0, 1, 0], "twist": [1, 0, 0], "axial": [1, 0, 0]}[kind]
    jtype = mujoco.mjtJoint.mjJNT_SLIDE if kind == "axial" else mujoco.mjtJoint.mjJNT_HINGE
    j = body.add_joint(name=name, type=jtype, axis=axis)
    j.stiffness = [stiffness, 0.0, 0.0]
    j.springref = 0.0
    j.damping = [beta * stiffness, 0.0, 0.0]


def add_link(
    parent: mujoco.MjsBody,
    *,
    name: str,
    pos: np.ndarray,
    angle_rad: float,
    length_m: float,
    section: Section,
    material: Material,
    link_model: str = "segments",
    segments: int = 12,
    axial: bool = True,
    rotary_inertia: bool = False,
    damping_beta_s: float = 0.0,
    start_lumps: tuple[LumpedMass, ...] = (),
    end_lumps: tuple[LumpedMass, ...] = (),
    rgba: tuple[float, float, float, float] = (0.3, 0.5, 0.8, 1.0),
    spec: mujoco.MjSpec | None = None,
    free_start: bool = False,
    free_end: bool = False,
) -> LinkBuild:
    """Add a straight link starting at ``pos`` (parent frame), pointing at ``angle_rad`` about z.

    The first body's frame sits at the link start with x along the link; the caller adds the joint
    connecting it to ``parent`` (none = clamped). Lumped masses are placed at the link's start and end.

    ``spec`` (the spec ``parent`` belongs to) is needed by ``cable`` and ``flex``. ``free_start``
    and ``free_end`` say that nothing holds the link's start (the caller gives the chain models a
    free joint; ``flex`` then starts on a free vertex and ``build.first`` is that vertex's body) or
    attaches to ``build.last`` (``flex`` then ends on a free vertex instead of a hub); the chain
    models ignore both.
    """
    check_link_model(link_model, segments)
    if link_model in ("cable", "flex"):
        from .deformable_links import add_cable_link, add_flex_link

        if spec is None:
            raise TypeError(f"add_link(link_model={link_model!r}) needs spec= (the MjSpec of parent)")
        common = dict(
            name=name,
            pos=pos,
            angle_rad=angle_rad,
            length_m=length_m,
            section=section,
            material=material,
            segments=segments,
            axial=axial,
            damping_beta_s=damping_beta_s,
            start_lumps=start_lumps,
            end_lumps=end_lumps,
            rgba=rgba,
        )
        if link_model == "flex":
            return add_flex_link(spec, parent, free_start=free_start, free_end=free_end, **common)
        return add_cable_link(spec, parent, rotary_inertia=rotary_inertia, **common)
    if link_model == "rigid":
        lengths = [length_m]
    else:
        l_seg = length_m / segments
        lengths = [l_seg / 2.0] + [l_seg] * (segments - 1) + [l_seg / 2.0]
    sec, mat = section, material
    k = {
        "bend_in": mat.young_pa * sec.i_inplane_m4,
        "bend_out": mat.young_pa * sec.i_outofplane_m4,
        "twist": mat.shear_pa * sec.torsion_constant_m4,
        "axial": mat.young_pa * sec.area_m2,
    }
    build = LinkBuild(name=name, bodies=[], piece_lengths_m=lengths)
    body = parent
    for j, piece in enumerate(lengths):
        if j == 0:
            body = body.add_body(name=f"{name}_b0", pos=list(pos), quat=quat_z(angle_rad))
        else:
            body = body.add_body(name=f"{name}_b{j}", pos=[lengths[j - 1], 0.0, 0.0])
            l_spring = length_m / segments
            kinds = ["bend_in", "bend_out", "twist"] + (["axial"] if axial else [])
            for kind in kinds:
                jn = f"{name}_s{j}_{kind}"
                _add_spring(body, jn, kind, k[kind] / l_spring, damping_beta_s)
                build.joints.append((jn, kind))
        parts = [box_part(piece, sec, mat, 0.0, rotary_inertia=rotary_inertia)]
        if j == 0:
            parts += [lump_part(lump, np.zeros(3)) for lump in start_lumps if lump.mass_kg > 0]
        if j == len(lengths) - 1:
            parts += [lump_part(lump, np.array([piece, 0.0, 0.0])) for lump in end_lumps if lump.mass_kg > 0]
        set_inertial(body, parts)
        add_box_geom(body, f"{name}_g{j}", piece, sec, 0.0, rgba)
        site = f"{name}_p{j}"
        body.add_site(name=site, pos=[0.0, 0.0, 0.0], size=[0.002, 0, 0])
        build.sites.append(site)
        build.bodies.append(body)
    end_site = f"{name}_p{len(lengths)}"
    body.add_site(name=end_site, pos=[lengths[-1], 0.0, 0.0], size=[0.002, 0, 0])
    build.sites.append(end_site)
    return build
