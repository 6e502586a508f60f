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
shear_in   y       kappa G A / l     optional slide: shear in the base plane (Timoshenko)
shear_out  z       kappa G A / l     optional slide: shear out of the base plane
=========  ======  ===============  ============================================

Each spring gets damping ``beta * k`` (``Damping.stiffness_proportional_s``). Masses and inertias of
the pieces are computed exactly (boxes) and lumped hardware is added at the link ends; the resulting
inertia is set explicitly on each body.

``rigid``: one rigid body per link (no springs): the kinematic-chain limit, for comparison.

``cable`` and ``flex``: MuJoCo's own deformables (the ``mujoco.elasticity.cable`` plugin on the
segment chain's bodies, and a 1D ``flex`` rod); built by :mod:`fpm_sim.model.deformable_links`, which
states what each can and cannot represent. Their ``segments`` is the number of elastic joints
(``cable``) or flex edges (``flex``). Neither is available in MJX; ``segments`` stays the default.
"""

from __future__ import annotations

from typing import TypedDict

import mujoco
import numpy as np

from fpm_sim.beam_theory import shear_coefficient_rectangle
from fpm_sim.config import LumpedMass, Material, Section
from fpm_sim.model.deformable_links import add_cable_link, add_flex_link
from fpm_sim.model.parts import (
    LinkBuild,
    LinkModelError,
    add_box_geom,
    box_part,
    check_link_model,
    lump_part,
    quat_z,
    set_inertial,
)

__all__ = ["add_link"]


def _add_spring(body: mujoco.MjsBody, name: str, kind: str, stiffness: float, beta: float) -> None:
    axis = {
        "bend_in": [0, 0, 1],
        "bend_out": [0, 1, 0],
        "twist": [1, 0, 0],
        "axial": [1, 0, 0],
        "shear_in": [0, 1, 0],
        "shear_out": [0, 0, 1],
    }[kind]
    slide = kind in ("axial", "shear_in", "shear_out")
    jtype = mujoco.mjtJoint.mjJNT_SLIDE if slide else mujoco.mjtJoint.mjJNT_HINGE
    j = body.add_joint(name=name, type=jtype, axis=axis)
    j.stiffness = [stiffness, 0.0, 0.0]
    j.springref = 0.0
    j.damping = [beta * stiffness, 0.0, 0.0]


class _DeformableLinkArgs(TypedDict):
    """The keywords :func:`add_link` passes on to both ``add_cable_link`` and ``add_flex_link``."""

    name: str
    pos: np.ndarray
    angle_rad: float
    length_m: float
    section: Section
    material: Material
    segments: int
    axial: bool
    damping_beta_s: float
    start_lumps: tuple[LumpedMass, ...]
    end_lumps: tuple[LumpedMass, ...]
    rgba: tuple[float, float, float, float]


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
    shear: bool = False,
    hub_length_m: float = 0.0,
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

    ``shear`` (``segments`` only) adds two slide springs at each spring location, across the link in
    the plane (``shear_in``) and out of it (``shear_out``), of stiffness ``kappa G A / l`` (Cowper's
    ``kappa``, :func:`fpm_sim.beam_theory.shear_coefficient_rectangle`): with ``rotary_inertia`` the
    chain then converges to a Timoshenko beam (tested against :func:`fpm_sim.beam_theory.timoshenko_beam_hz`).

    ``hub_length_m`` (``segments`` and ``rigid`` only): a rigid length at each end; the springs are
    spread over the flexible span ``length_m - 2 hub_length_m`` only (pieces ``hub + l/2, l, ..., l,
    l/2 + hub`` with ``l`` the span over ``segments``); mass stays uniform along the whole link.

    ``spec`` (the spec ``parent`` belongs to) is needed by ``cable`` and ``flex``. ``free_start``
    and ``free_end`` say that nothing holds the link's start (the caller gives the chain models a
    free joint; ``flex`` then starts on a free vertex and ``build.first`` is that vertex's body) or
    attaches to ``build.last`` (``flex`` then ends on a free vertex instead of a hub); the chain
    models ignore both.
    """
    check_link_model(link_model, segments)
    if hub_length_m and link_model in ("cable", "flex"):
        raise LinkModelError(
            f"rigid hubs (geometry.hub_length_m) exist only for link_model 'segments' or 'rigid', not {link_model!r}"
        )
    if not 0.0 <= 2.0 * hub_length_m < length_m:
        raise LinkModelError(f"hub_length_m {hub_length_m} m leaves no flexible span on a {length_m} m link")
    if shear and link_model != "segments":
        raise LinkModelError(f"shear springs exist only for link_model 'segments', not {link_model!r}")
    if link_model in ("cable", "flex"):
        if spec is None:
            raise TypeError(f"add_link(link_model={link_model!r}) needs spec= (the MjSpec of parent)")
        common = _DeformableLinkArgs(
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
        l_seg = (length_m - 2.0 * hub_length_m) / segments
        lengths = [hub_length_m + l_seg / 2.0] + [l_seg] * (segments - 1) + [l_seg / 2.0 + hub_length_m]
    sec, mat = section, material
    k = {
        "bend_in": mat.young_pa * sec.i_inplane_m4,
        "bend_out": mat.young_pa * sec.i_outofplane_m4,
        "twist": mat.shear_pa * sec.torsion_constant_m4,
        "axial": mat.young_pa * sec.area_m2,
        "shear_in": shear_coefficient_rectangle(mat.poisson) * mat.shear_pa * sec.area_m2,
        "shear_out": shear_coefficient_rectangle(mat.poisson) * mat.shear_pa * sec.area_m2,
    }
    build = LinkBuild(name=name, bodies=[], piece_lengths_m=lengths)
    body = parent
    for j, piece in enumerate(lengths):
        if j == 0:
            body = body.add_body(name=f"{name}_b0", pos=list(pos), quat=quat_z(angle_rad))
        else:
            body = body.add_body(name=f"{name}_b{j}", pos=[lengths[j - 1], 0.0, 0.0])
            l_spring = (length_m - 2.0 * hub_length_m) / segments
            kinds = ["bend_in", "bend_out", "twist"] + (["axial"] if axial else [])
            kinds += ["shear_in", "shear_out"] if shear else []
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
