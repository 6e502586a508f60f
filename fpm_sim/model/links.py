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

from collections.abc import Callable

import mujoco
import numpy as np

from fpm_sim.architecture.description import AnySection
from fpm_sim.beam_theory import shear_coefficient_rectangle
from fpm_sim.config import Material
from fpm_sim.model.deformable_links import add_cable_link, add_flex_link
from fpm_sim.model.parts import (
    LinkBuild,
    LinkModelError,
    LinkSpec,
    add_box_geom,
    box_part,
    check_link_model,
    lump_part,
    set_inertial,
)

__all__ = ["LINK_BUILDERS", "LinkBuilder", "LinkSpec", "add_link", "add_segment_link", "check_link_spec"]


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


def check_link_spec(link: LinkSpec) -> None:
    """Refuse what the link model cannot build: hubs on deformables, no flexible span, shear off ``segments``.

    Raises
    ------
    LinkModelError
        Naming what the link model cannot represent.
    """
    check_link_model(link.link_model, link.segments)
    if link.hub_length_m and link.link_model in ("cable", "flex"):
        raise LinkModelError(
            "rigid hubs (geometry.hub_length_m) exist only for link_model 'segments' or 'rigid', "
            f"not {link.link_model!r}"
        )
    if not 0.0 <= 2.0 * link.hub_length_m < link.length_m:
        raise LinkModelError(f"hub_length_m {link.hub_length_m} m leaves no flexible span on a {link.length_m} m link")
    if link.shear and link.link_model != "segments":
        raise LinkModelError(f"shear springs exist only for link_model 'segments', not {link.link_model!r}")


def add_link(spec: mujoco.MjSpec, parent: mujoco.MjsBody, link: LinkSpec) -> LinkBuild:
    """Add the straight link ``link`` to ``parent`` (a body of ``spec``), built by its link model's builder.

    The first body's frame sits at the link start (``link.pos_m`` in the parent frame, turned by
    ``link.angle_rad`` about z) with x along the link; the caller adds the joint connecting it to ``parent``
    (none = clamped). Lumped masses are placed at the link's start and end.

    ``shear`` (``segments`` only) adds two slide springs at each spring location, across the link in
    the plane (``shear_in``) and out of it (``shear_out``), of stiffness ``kappa G A / l`` (Cowper's
    ``kappa``, :func:`fpm_sim.beam_theory.shear_coefficient_rectangle`): with ``rotary_inertia`` the
    chain then converges to a Timoshenko beam (tested against :func:`fpm_sim.beam_theory.timoshenko_beam_hz`).

    Raises
    ------
    LinkModelError
        What the link model cannot build (:func:`check_link_spec`).
    """
    check_link_spec(link)
    return LINK_BUILDERS[link.link_model](spec, parent, link)


def _segment_stiffness(section: AnySection, material: Material) -> dict[str, float]:
    """Stiffness times length of each spring kind (N m^2 for rotations, N for slides; divide by the spacing)."""
    shear_ga = shear_coefficient_rectangle(material.poisson) * material.shear_pa * section.area_m2
    return {
        "bend_in": material.young_pa * section.i_inplane_m4,
        "bend_out": material.young_pa * section.i_outofplane_m4,
        "twist": material.shear_pa * section.torsion_constant_m4,
        "axial": material.young_pa * section.area_m2,
        "shear_in": shear_ga,
        "shear_out": shear_ga,
    }


def add_segment_link(spec: mujoco.MjSpec, parent: mujoco.MjsBody, link: LinkSpec) -> LinkBuild:
    """Add a ``segments`` link (rigid pieces joined by spring locations; see module docstring), or a ``rigid``
    one (one piece). ``spec`` is unused: the builders of :data:`LINK_BUILDERS` share one signature."""
    name, length_m, hub_m, sec, mat = link.name, link.length_m, link.hub_length_m, link.section, link.material
    if link.link_model == "rigid":
        lengths = [length_m]
    else:
        l_seg = (length_m - 2.0 * hub_m) / link.segments
        lengths = [hub_m + l_seg / 2.0] + [l_seg] * (link.segments - 1) + [l_seg / 2.0 + hub_m]
    k = _segment_stiffness(sec, mat)
    # a link without spin inertia (free to spin between two ball joints) carries no torque along itself: no twist
    kinds = ["bend_in", "bend_out"] + (["twist"] if link.spin_inertia else []) + (["axial"] if link.axial else [])
    kinds += ["shear_in", "shear_out"] if link.shear else []
    build = LinkBuild(name=name, bodies=[], piece_lengths_m=lengths)
    body = parent
    for j, piece in enumerate(lengths):
        if j == 0:
            body = body.add_body(name=f"{name}_b0", pos=list(link.pos), quat=link.start_quat)
        else:
            body = body.add_body(name=f"{name}_b{j}", pos=[lengths[j - 1], 0.0, 0.0])
            l_spring = (length_m - 2.0 * hub_m) / link.segments
            for kind in kinds:
                jn = f"{name}_s{j}_{kind}"
                _add_spring(body, jn, kind, k[kind] / l_spring, link.damping_beta_s)
                build.joints.append((jn, kind))
        parts = [box_part(piece, sec, mat, 0.0, rotary_inertia=link.rotary_inertia, spin_inertia=link.spin_inertia)]
        if j == 0:
            parts += [lump_part(lump, np.zeros(3)) for lump in link.start_lumps if lump.mass_kg > 0]
        if j == len(lengths) - 1:
            parts += [lump_part(lump, np.array([piece, 0.0, 0.0])) for lump in link.end_lumps if lump.mass_kg > 0]
        if link.link_model == "rigid" and link.lump_bodies:  # LinkSpec.lump_bodies
            parts = parts[:1] + _lump_bodies(body, name, parts[1:])
        set_inertial(body, parts)
        add_box_geom(body, f"{name}_g{j}", piece, sec, 0.0, link.rgba)
        site = f"{name}_p{j}"
        body.add_site(name=site, pos=[0.0, 0.0, 0.0], size=[0.002, 0, 0])
        build.sites.append(site)
        build.bodies.append(body)
    end_site = f"{name}_p{len(lengths)}"
    body.add_site(name=end_site, pos=[lengths[-1], 0.0, 0.0], size=[0.002, 0, 0])
    build.sites.append(end_site)
    return build


def _lump_bodies(
    body: mujoco.MjsBody, name: str, lumps: list[tuple[float, np.ndarray, np.ndarray]]
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """Each lump of a rigid link as a jointless child body at its place (MuJoCo welds it to ``body``: the same
    dynamics as the lump in ``body``'s inertial); what is left for ``body``'s own inertial (nothing)."""
    for k, lump in enumerate(lumps):
        child = body.add_body(name=f"{name}_lump{k}", pos=[float(v) for v in lump[1]])
        set_inertial(child, [(lump[0], np.zeros(3), lump[2])])
    return []


LinkBuilder = Callable[[mujoco.MjSpec, mujoco.MjsBody, LinkSpec], LinkBuild]

LINK_BUILDERS: dict[str, LinkBuilder] = {
    "segments": add_segment_link,
    "rigid": add_segment_link,
    "cable": add_cable_link,
    "flex": add_flex_link,
}
"""The builder of each link model (``rigid`` is the segment chain's one-piece case)."""
