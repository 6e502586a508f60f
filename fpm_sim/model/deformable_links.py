"""Links as MuJoCo's own deformables: the ``cable`` plugin and the 1D ``flex`` rod.

Both builders take a :class:`~fpm_sim.model.parts.LinkSpec`, as :func:`fpm_sim.model.links.add_link` (which
dispatches to them by link model) does, and fill the same :class:`fpm_sim.model.parts.LinkBuild`: the caller
adds the joint of the link's start to ``build.first`` (none = clamped), and attaches whatever follows the link
(next link, pin, far clamp) to ``build.last`` at ``build.last_length_m`` along its x axis.

``cable`` (``mujoco.elasticity.cable`` plugin)
    The segment chain's layout: ``n`` elastic joints at the centres of ``n`` equal parts of length
    ``l = L / n``, ``n + 1`` rigid box pieces ``l/2, l, ..., l, l/2``. Each elastic joint is a
    **ball** joint (the plugin requires one as the last joint of each plugin body); with ``axial`` an
    axial slide spring ``E A / l`` precedes it. The plugin applies ``-[G J, E I_out, E I_in] *
    rotvec / d`` (twist, bend out of plane, bend in plane) with ``d`` the distance between the body
    origins of consecutive plugin bodies and ``I``, ``J`` read from the **first geom** of each body
    (box half sizes ``(., t/2, h/2)``; ``J`` by Roark's rectangle formula, as the segment chain). Its
    attributes: ``bend`` = E, ``twist`` = G. The first plugin body gets no stiffness towards its
    parent, so a massless, jointless *anchor* body sits at ``-l/2`` on the first piece: it is the
    first plugin body, and every elastic joint then has ``d = l`` exactly (the stock
    ``<composite type="cable">`` instead welds its first segment rigidly to the parent, which makes a
    cantilever stiff by about ``1/n``). Masses and inertias are set exactly as for ``segments``. In
    the linear range the cable equals the segment chain (same joint locations, same ``k = E I / l``);
    anisotropic sections (``t != h``) and torsion are represented. It cannot represent shear, and
    it has no stiffness-proportional damping per axis: the ball joint takes one damping value,
    ``beta * E * min(I_in, I_out) / l`` (the softer bending axis).

``flex`` (1D ``flex``, ``dim = 1``)
    ``n`` edges between vertex bodies (three slide joints each, lumped mass ``rho A l``, ``rho A l/2``
    at a free end, hardware lumps at the ends), bending from ``young``/``poisson`` with
    ``section = box`` and ``sectionsize = (t/2, h/2)``; damping ``beta`` on the bending forces (the
    flex's stiffness-proportional ``damping``, which in 3.17 acts only along the rod's current
    curvature, so a gravity sag out of plane leaves the in-plane modes undamped:
    :class:`DampingWarning`). Axial: with ``axial`` each edge is an undamped
    spring ``E A / l`` (``edgestiffness``; see the comment in :func:`add_flex_link`), otherwise an
    inextensible edge equality. A constrained end (the
    start, unless ``free_start``; the end, unless ``free_end``) owns the two vertices at ``-l/2`` and
    ``+l/2`` around the end point (this placement makes the clamp second-order accurate; placing the
    clamp at a vertex is first-order wrong by about ``1/n``), and ``l`` is chosen so that the span
    between the end points is ``L``. The start's two vertices belong to ``build.first`` (a body in
    the parent's frame, so no joint = clamped); the end's two vertices belong to a *hub*, a child of
    the world with three slides and three hinges, which is ``build.last``. Degrees of freedom are
    of kind ``flex_in`` (motion in the base plane: x, y slides, z hinge) or ``flex_out`` (z slide,
    x and y hinges), so a mode's ``character`` tells in-plane from out-of-plane.

    What the 1D flex of MuJoCo 3.17 cannot represent: it has **one** bending stiffness per vertex
    triple, computed with the second moment of the **weaker** axis, so a section with ``t != h``
    bends in both planes with ``min(I_in, I_out)`` (:class:`SectionWarning`); its vertices are points,
    so it has **no torsion** stiffness or twist inertia (modes that twist a link come out too low),
    and no rotary inertia of the section; its damping leaves in-plane bending undamped once the rod
    sags out of plane.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from fpm_sim.config import LumpedMass, Material, Section
from fpm_sim.errors import FpmSimWarning
from fpm_sim.model.parts import (
    LinkBuild,
    LinkModelError,
    LinkSpec,
    add_box_geom,
    box_part,
    lump_part,
    quat_z,
    set_inertial,
)

__all__ = [
    "CABLE_PLUGIN",
    "DampingWarning",
    "SectionWarning",
    "add_cable_link",
    "add_flex_link",
    "flex_spacing_m",
]

CABLE_PLUGIN = "mujoco.elasticity.cable"


_HUB_INERTIA_KG_M2 = 1e-9
"""Rotary inertia added to a flex end body (MuJoCo needs a positive inertia on every moving body)."""


_VERTEX_INERTIA_KG_M2 = 1e-12
"""Inertia of a vertex body (slides only: it never rotates; MuJoCo wants a positive value)."""


class SectionWarning(FpmSimWarning):
    """The link model cannot represent the requested cross-section; it computes an approximation."""


class DampingWarning(FpmSimWarning):
    """The link model cannot apply the requested damping everywhere."""


def _check_engine(link_model: str) -> None:
    """Refuse engines on which the model is missing or its linearisation is known to be wrong.

    MuJoCo 4.0 removed the cable plugin, and keeps 1D-flex rod frames in ``mjData.plastic``, which
    ``mjd_transitionFD`` does not restore (noted before the project began, on older MuJoCo); 3.17 has neither issue
    (tests/test_deformable_links.py checks ``mjd_transitionFD`` against a full-state difference).
    """
    major = int(mujoco.__version__.split(".")[0])
    if major >= 4 and link_model == "cable":
        raise LinkModelError(
            f"link model 'cable' needs the mujoco.elasticity.cable plugin, removed in MuJoCo {mujoco.__version__}; "
            "install mujoco==3.17.0 (the pinned version) or use link_model='segments'"
        )
    if major >= 4 and link_model == "flex":
        raise LinkModelError(
            f"link model 'flex' is not linearised correctly on MuJoCo {mujoco.__version__} (mjd_transitionFD "
            "misses the rod frames in mjData.plastic); install mujoco==3.17.0 or use link_model='segments'"
        )


def add_cable_link(spec: mujoco.MjSpec, parent: mujoco.MjsBody, link: LinkSpec) -> LinkBuild:
    """Add a cable-plugin link (see module docstring) to ``parent``, a body of ``spec``."""
    _check_engine("cable")
    name, length_m, section, material = link.name, link.length_m, link.section, link.material
    damping_beta_s, n = link.damping_beta_s, link.segments
    l_seg = length_m / n
    lengths = [l_seg / 2.0] + [l_seg] * (n - 1) + [l_seg / 2.0]
    plugin = _cable_plugin(spec, name, material)
    build = LinkBuild(name=name, bodies=[], piece_lengths_m=lengths)
    k_axial = material.young_pa * section.area_m2 / l_seg
    k_min_bend = material.young_pa * min(section.i_inplane_m4, section.i_outofplane_m4) / l_seg
    body = parent
    for j, piece in enumerate(lengths):
        if j == 0:
            body = parent.add_body(name=f"{name}_b0", pos=list(link.pos), quat=quat_z(link.angle_rad))
            anchor = body.add_body(name=f"{name}_anchor", pos=[-l_seg / 2.0, 0.0, 0.0])
            # the plugin reads the section from the first geom of each plugin body
            add_box_geom(anchor, f"{name}_ganchor", l_seg / 2.0, section, l_seg / 2.0, (0, 0, 0, 0))
            anchor.plugin = plugin
        else:
            # piece 1 hangs from the anchor (so the plugin bodies are consecutive and the first
            # joint's origin distance is l); every body origin sits at its proximal joint
            chain_parent = anchor if j == 1 else body
            body = chain_parent.add_body(name=f"{name}_b{j}", pos=[l_seg, 0.0, 0.0])
            if link.axial:
                jn = f"{name}_s{j}_axial"
                ja = body.add_joint(name=jn, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
                ja.stiffness = [k_axial, 0.0, 0.0]
                ja.springref = 0.0
                ja.damping = [damping_beta_s * k_axial, 0.0, 0.0]
                build.joints.append((jn, "axial"))
            jn = f"{name}_s{j}_ball"
            jb = body.add_joint(name=jn, type=mujoco.mjtJoint.mjJNT_BALL)
            jb.damping = [damping_beta_s * k_min_bend, 0.0, 0.0]
            build.joints.append((jn, "ball"))
            body.plugin = plugin
        # the first piece's frame is at the link start; every later piece's at its proximal joint
        add_box_geom(body, f"{name}_g{j}", piece, section, 0.0, link.rgba)
        parts = [box_part(piece, section, material, 0.0, rotary_inertia=link.rotary_inertia)]
        if j == 0:
            parts += [lump_part(lump, np.zeros(3)) for lump in link.start_lumps if lump.mass_kg > 0]
        if j == len(lengths) - 1:
            parts += [lump_part(lump, np.array([piece, 0.0, 0.0])) for lump in link.end_lumps if lump.mass_kg > 0]
        set_inertial(body, parts)
        site = f"{name}_p{j}"
        body.add_site(name=site, pos=[0.0, 0.0, 0.0], size=[0.002, 0, 0])
        build.sites.append(site)
        build.bodies.append(body)
    end_site = f"{name}_p{len(lengths)}"
    body.add_site(name=end_site, pos=[lengths[-1], 0.0, 0.0], size=[0.002, 0, 0])
    build.sites.append(end_site)
    return build


def _cable_plugin(spec: mujoco.MjSpec, name: str, material: Material) -> mujoco.MjsPlugin:
    spec.activate_plugin(CABLE_PLUGIN)
    plugin = spec.add_plugin(name=f"{name}_cable", plugin_name=CABLE_PLUGIN, active=True)
    # bend = Young's modulus E, twist = shear modulus G (the plugin's only material attributes)
    plugin.config = {
        "twist": repr(float(material.shear_pa)),
        "bend": repr(float(material.young_pa)),
        "flat": "false",
        "vmax": "0",
    }
    return plugin


def flex_spacing_m(length_m: float, segments: int, *, free_start: bool, free_end: bool) -> float:
    """Vertex spacing ``l`` of a flex link of ``segments`` edges whose span between end points is ``length_m``.

    A constrained end owns the vertices at ``-l/2`` and ``+l/2`` around its end point, so each one
    removes half an edge from the span.
    """
    return length_m / (segments - (0.0 if free_start else 0.5) - (0.0 if free_end else 0.5))


@dataclass
class _FlexVertices:
    """The flex's vertices as they are added: the body of each and its position in that body (m, x y z)."""

    bodies: list[str] = field(default_factory=list)
    pos_m: list[float] = field(default_factory=list)


def add_flex_link(spec: mujoco.MjSpec, parent: mujoco.MjsBody, link: LinkSpec) -> LinkBuild:
    """Add a 1D-flex link (see module docstring) to ``parent``, a body of ``spec``.

    A constrained start is a host body on ``parent`` carrying the first two vertices, the free vertices are
    bodies on the world with three slides each, and a constrained end is a hub body (three slides and three
    hinges) carrying the last two; ``link.free_start`` / ``link.free_end`` replace host or hub by a free vertex.

    Warns
    -----
    SectionWarning
        If ``thickness_m != height_m``: the flex bends in both planes with the weaker axis.
    DampingWarning
        If ``damping_beta_s > 0``: bending is damped only along the current curvature.
    """
    _check_engine("flex")
    if not isinstance(link.section, Section):
        raise LinkModelError("a flex link takes a rectangular section", parameter="section", value=link.section)
    _warn_if_not_square(link.section)
    n = link.segments
    l_v = flex_spacing_m(link.length_m, n, free_start=link.free_start, free_end=link.free_end)
    s0 = 0.0 if link.free_start else -l_v / 2.0
    s = s0 + l_v * np.arange(n + 1)  # arc length of each vertex from the link start
    m_l = link.material.density_kg_m3 * link.section.area_m2 * l_v
    t, h = link.section.thickness_m, link.section.height_m
    # an end body carries its vertex cell (length l, mass rho A l) with the cell's own inertia about
    # its centre: free vertices are points, but without it a hub's twist would have no inertia and
    # a weld on it would be soft (MuJoCo scales constraint stiffness with the effective mass)
    cell = m_l * np.array([min(t**2 + h**2, 2 * l_v**2), l_v**2, l_v**2]) / 12.0
    build = LinkBuild(name=link.name, bodies=[], piece_lengths_m=[])
    verts = _FlexVertices()
    # world position of the link start (the parent frame may be moving but is at its qpos0 pose)
    start_w, rot_w = _world_pose(parent, link.pos, link.angle_rad)
    first_free = 0
    if not link.free_start:
        _add_flex_host(parent, link, (m_l, np.array([s[1], 0.0, 0.0]), np.diag(cell)), build)
        verts.bodies += [build.last.name, build.last.name]
        verts.pos_m += [s[0], 0.0, 0.0, s[1], 0.0, 0.0]
        first_free = 2
    last_free = n if link.free_end else n - 2
    for k in range(first_free, last_free + 1):
        _add_flex_vertex(spec.worldbody, link, k, start_w + s[k] * rot_w[:, 0], m_l, build)
        verts.bodies.append(build.last.name)
        verts.pos_m += [0.0, 0.0, 0.0]
    if not link.free_end:
        cell_end = (m_l, np.array([s[n - 1] - link.length_m, 0.0, 0.0]), np.diag(cell))
        _add_flex_hub(spec.worldbody, link, start_w + link.length_m * rot_w[:, 0], rot_w, cell_end, build)
        verts.bodies += [build.last.name, build.last.name]
        verts.pos_m += [s[n - 1] - link.length_m, 0.0, 0.0, s[n] - link.length_m, 0.0, 0.0]
    _add_flex(spec, link, l_v, verts)
    build.piece_lengths_m = [l_v] * n  # the edges
    # a hub's origin is the link's end; a free end vertex is the end itself
    build.end_offset_m = 0.0
    return build


def _warn_if_not_square(section: Section) -> None:
    """:class:`SectionWarning` when ``thickness_m != height_m`` (the flex bends with the weaker axis in both planes)."""
    t, h = section.thickness_m, section.height_m
    i_in, i_out = section.i_inplane_m4, section.i_outofplane_m4
    if not math.isclose(t, h, rel_tol=1e-9):
        weak = "in-plane" if t < h else "out-of-plane"
        warnings.warn(
            f"link model 'flex' cannot represent the {t * 1e3:g} x {h * 1e3:g} mm section "
            f"(thickness_m != height_m): MuJoCo's 1D flex has one bending stiffness, that of the weaker "
            f"({weak}) axis, so the other plane is too soft by I_max/I_min = "
            f"{max(i_in, i_out) / min(i_in, i_out):.2f}x; "
            "use link_model 'segments' or 'cable' for such sections",
            SectionWarning,
            stacklevel=4,
        )


def _add_flex_host(
    parent: mujoco.MjsBody, link: LinkSpec, cell: tuple[float, np.ndarray, np.ndarray], build: LinkBuild
) -> None:
    """The body on ``parent`` that holds a constrained start (vertices 0 and 1)."""
    host = parent.add_body(name=f"{link.name}_b0", pos=list(link.pos), quat=quat_z(link.angle_rad))
    # the rod between the start point and the first free vertex's cell: vertex v1 (at +l/2)
    # carries rho A l, as every interior vertex; hardware lumps sit at the start point
    _finish_end_body(host, cell, link.start_lumps, f"{link.name}_p0", build)


def _finish_end_body(
    body: mujoco.MjsBody,
    cell: tuple[float, np.ndarray, np.ndarray],
    lumps: Sequence[LumpedMass],
    site: str,
    build: LinkBuild,
) -> None:
    """An end body of a flex link: its rod cell, the hardware lumps at the end, a small hub inertia, and the
    end's site; recorded in ``build``."""
    parts = [cell]
    parts += [lump_part(lump, np.zeros(3)) for lump in lumps if lump.mass_kg > 0]
    parts.append((0.0, np.zeros(3), np.eye(3) * _HUB_INERTIA_KG_M2))
    _set_parts(body, parts)
    body.add_site(name=site, pos=[0.0, 0.0, 0.0], size=[0.002, 0, 0])
    build.sites.append(site)
    build.bodies.append(body)


def _add_flex_vertex(
    world: mujoco.MjsBody, link: LinkSpec, k: int, pos_w: np.ndarray, m_l: float, build: LinkBuild
) -> None:
    """Free vertex ``k``: a point mass on three slides at ``pos_w`` (world, m)."""
    name, n = link.name, link.segments
    vb = world.add_body(name=f"{name}_v{k}", pos=list(pos_w))
    for ax_name, axis in zip("xyz", np.eye(3)):
        jn = f"{name}_v{k}_{ax_name}"
        vb.add_joint(name=jn, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=list(axis))
        build.joints.append((jn, "flex_out" if ax_name == "z" else "flex_in"))
    mass = m_l
    lumps: tuple[LumpedMass, ...] = ()
    if k == 0:
        mass, lumps = m_l / 2.0, link.start_lumps
    elif k == n:
        mass, lumps = m_l / 2.0, link.end_lumps
    # a vertex is a point: hardware inertia cannot be carried, only its mass
    point = mass + sum(lump.mass_kg for lump in lumps)
    set_inertial(vb, [(point, np.zeros(3), np.eye(3) * _VERTEX_INERTIA_KG_M2)])
    vb.add_site(name=f"{name}_p{k}", pos=[0.0, 0.0, 0.0], size=[0.002, 0, 0])
    build.sites.append(f"{name}_p{k}")
    build.bodies.append(vb)


def _add_flex_hub(
    world: mujoco.MjsBody,
    link: LinkSpec,
    end_w: np.ndarray,
    rot_w: np.ndarray,
    cell: tuple[float, np.ndarray, np.ndarray],
    build: LinkBuild,
) -> None:
    """The body at the link's end ``end_w`` (world, m) that holds a constrained end (the last two vertices)."""
    name, n = link.name, link.segments
    hub = world.add_body(name=f"{name}_hub", pos=list(end_w), quat=_quat_of(rot_w))
    for ax_name, axis in zip("xyz", np.eye(3)):
        jn = f"{name}_hub_t{ax_name}"
        hub.add_joint(name=jn, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=list(axis))
        build.joints.append((jn, "flex_out" if ax_name == "z" else "flex_in"))
    for ax_name, axis in zip("xyz", np.eye(3)):
        jn = f"{name}_hub_r{ax_name}"
        hub.add_joint(name=jn, type=mujoco.mjtJoint.mjJNT_HINGE, axis=list(axis))
        build.joints.append((jn, "flex_in" if ax_name == "z" else "flex_out"))
    _finish_end_body(hub, cell, link.end_lumps, f"{name}_p{n}", build)


def _add_flex(spec: mujoco.MjSpec, link: LinkSpec, l_v: float, verts: _FlexVertices) -> None:
    """The 1D flex through ``verts``: bending from the section, edges as axial springs (or held rigid without
    ``axial``), the flex's own damping (with its :class:`DampingWarning`)."""
    section, material = link.section, link.material
    t, h = section.thickness_m, section.height_m
    nvert = len(verts.bodies)
    flex = spec.add_flex(
        name=f"{link.name}_flex",
        dim=1,
        radius=min(t, h) / 2.0,
        young=material.young_pa,
        poisson=material.poisson,
        section=int(mujoco.mjtFlexSection.mjFLEXSECTION_BOX),
        sectionsize=[t / 2.0, h / 2.0],
        vertbody=verts.bodies,
        vert=verts.pos_m,
        elem=[int(v) for i in range(nvert - 1) for v in (i, i + 1)],
        contype=0,
        conaffinity=0,
        rgba=list(link.rgba),
    )
    if link.axial:
        # the edges are axial springs E A / l, left undamped: MuJoCo 3.17 applies flex edge damping
        # explicitly, and beta * E A / l on the light vertices (c h / m ~ 2.3 at the automatic
        # timestep) made the discrete map unstable and gave the manipulator spurious undamped modes
        # (32.8 / 34.4 / 38.8 Hz against 46.3 / 49.0 / 49.0 Hz without it, segments = 8)
        flex.edgestiffness = material.young_pa * section.area_m2 / l_v
    else:
        eq = spec.add_equality(name=f"{link.name}_edges", type=mujoco.mjtEq.mjEQ_FLEX, objtype=mujoco.mjtObj.mjOBJ_FLEX)
        eq.name1 = flex.name
    # the flex's own damping is stiffness-proportional on its bending forces, but in 3.17, linearised
    # about a bent rod, it acts only along the existing curvature (measured on the cantilever:
    # straight, zeta = beta omega / 2 in both planes; sagged by gravity out of plane, by micrometres,
    # zeta = 0 in plane)
    flex.damping = link.damping_beta_s
    if link.damping_beta_s > 0:
        warnings.warn(
            "link model 'flex' damps bending only along the rod's current curvature (MuJoCo 3.17's 1D flex "
            "damping): at an equilibrium sagged out of plane by gravity its in-plane modes come out undamped; "
            "use link_model 'segments' or 'cable' for modal damping ratios",
            DampingWarning,
            stacklevel=4,
        )


def _set_parts(body: mujoco.MjsBody, parts: list[tuple[float, np.ndarray, np.ndarray]]) -> None:
    mass = sum(p[0] for p in parts)
    if mass <= 0.0:
        raise ValueError(f"body {body.name!r} has no mass")
    set_inertial(body, parts)


def _world_pose(parent: mujoco.MjsBody, pos: np.ndarray, angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """World position of ``pos`` (parent frame) and the world rotation of a child frame turned by ``angle_rad``.

    Composes the spec's ``pos``/``quat`` up the tree: valid at ``qpos0`` (all joints at zero), which is
    how every model of this project is assembled.
    """
    p_w, r_w = np.zeros(3), np.eye(3)
    chain = []
    b = parent
    while b is not None and b.name != "world":
        chain.append(b)
        b = b.parent
    for body in reversed(chain):
        r_b = np.zeros(9)
        q = np.asarray(body.quat, float)
        mujoco.mju_quat2Mat(r_b, q / np.linalg.norm(q))
        p_w = p_w + r_w @ np.asarray(body.pos, float)
        r_w = r_w @ r_b.reshape(3, 3)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    r_z = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return p_w + r_w @ pos, r_w @ r_z


def _quat_of(rot: np.ndarray) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, rot.reshape(9))
    return q.tolist()
