"""The flexible model of an imported MuJoCo model (:mod:`fpm_sim.architecture.imported`), posed in joint space.

What the builder does (``docs/import.md``):

- the model is read with :meth:`mujoco.MjSpec.from_file` (MJCF, or URDF as MuJoCo compiles it); a free joint is
  refused (fpm-sim analyses a machine on its base);
- the pose ``q = {joint: value}`` (MuJoCo's joint coordinates: rad for hinges, m for slides) is set, the kinematics
  run, and each posed body placed at its posed frame, its joint's coordinate shifted so that zero is the posed
  frame (``ref`` 0; ``springref`` and ``range`` shifted alike, so springs and limits keep their places): ``qpos0``
  is the posed machine at rest, what the linear analysis assumes. (A nonzero ``ref`` gives the same constrained
  eigen-solve, but the finite-difference step map of an undamped model then shows spurious growth of ~1e-6 at
  kHz: measured on the five-bar re-posed from its export);
- actuated joints (those an ``<actuator>`` drives), ``servo_joints`` and ``locked_joints`` are locked: removed, the
  body rigid on its parent, as :func:`fpm_sim.model.general.build_general` locks motors for modal analysis; with
  ``motors="servo"`` the motors (the actuated joints but for ``locked_joints``, and ``servo_joints``) stay as
  position servos instead: the description's ``[servos]`` stiffness and damping about the posed coordinate, the
  model's own actuators on them removed, as a described architecture's servos;
- each flexible body keeps its joint, and a chain of segments (:func:`fpm_sim.model.links.add_link`) hangs on it
  along the beam; the body's child bodies hang on the chain's last piece at their own positions;
- mass: every body's inertial is made explicit as the model states it. A flexible body's geoms that the beam
  replaces (``replace_geoms``; by default the capsules, cylinders and boxes lying along the beam) are taken out;
  when the body states an explicit ``<inertial>`` (or the compiler takes no inertia from geoms), the beam's own
  mass and inertia are subtracted from it instead. What is left stays on the body as a rigid lump;
- ``<equality connect|weld>`` loop closures are kept; gravity is the model's (off with ``gravity=False``); contacts
  are off, constraints on, the integrator and timestep fpm-sim's (:func:`fpm_sim.model.spec.compile_model`).
"""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from fpm_sim.architecture.imported import FlexibleBody, ImportedDescription
from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.model.links import add_link
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.parts import LinkSpec, box_part, set_inertial
from fpm_sim.model.spec import BuiltModel, compile_model
from fpm_sim.model.xml_precision import full_precision_xml

__all__ = [
    "ImportReport",
    "MissingMeshWarning",
    "ModelImportError",
    "build_imported",
    "check_loops_closed",
    "constrained_model",
    "end_sites",
    "import_report",
    "load_spec",
    "locked_joint_names",
    "mechanism_joints",
    "motor_joints",
    "posable_joints",
]

LOOP_TOL = 1e-6
"""Largest loop-closure residual (m for a connect's points, m or rad for a weld's) accepted at a requested pose: a
loop closed by the user's kinematics to solver precision is far below it, one left open by a joint not given far
above."""

_JOINTISH = (mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_TENDON)
_ALONG_TYPES = {int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_BOX)}


class ModelImportError(FpmSimError):
    """What cannot be imported: a body, joint or file the description names, or a model fpm-sim cannot analyse."""


@dataclass
class ImportReport:
    """What the import kept and replaced, per flexible body."""

    locked: list[str] = field(default_factory=list)
    replaced: dict[str, list[str]] = field(default_factory=dict)
    kept: dict[str, list[str]] = field(default_factory=dict)
    lump_kg: dict[str, float] = field(default_factory=dict)
    beam: dict[str, dict[str, Any]] = field(default_factory=dict)
    mass_rule: dict[str, str] = field(default_factory=dict)
    loops: int = 0
    dropped: list[str] = field(default_factory=list)

    def table(self) -> str:
        lines = [f"locked joints: {', '.join(self.locked) or 'none'}; loop closures kept: {self.loops}"]
        if self.dropped:
            lines.append(f"dropped with the locked joints: {', '.join(self.dropped)}")
        for b, beam in self.beam.items():
            lines.append(
                f"{b}: beam {beam['length_m'] * 1e3:.1f} mm ({beam['from']} -> {beam['to']}), "
                f"replaced geoms [{', '.join(self.replaced[b])}], kept geoms [{', '.join(self.kept[b])}], "
                f"rigid lump {self.lump_kg[b]:.4g} kg ({self.mass_rule[b]})"
            )
        return "\n".join(lines)


def _fail(message: str, parameter: str, value: Any = None, hint: str | None = None) -> ModelImportError:
    """The import's error naming ``parameter``; ``value`` (when not ``None``) is the offending value."""
    if value is None:
        return ModelImportError(message, parameter=parameter, hint=hint)
    return ModelImportError(message, parameter=parameter, value=value, hint=hint)


class MissingMeshWarning(FpmSimWarning):
    """A mesh file of the model is missing: its geoms were dropped (their bodies state their inertia)."""


def _drop_missing_meshes(spec: mujoco.MjSpec, model_path: Path) -> None:
    """Drop the geoms of mesh files that cannot be found, with a warning naming each, when every body they belong to
    states its ``<inertial>`` (the mesh then carries no mass the analysis needs: fpm-sim has no contacts and draws no
    meshes); refuse naming the mesh, its file and the body when a body takes its mass from it."""
    base = model_path.parent / (spec.meshdir or "")
    from_geoms = spec.compiler.inertiafromgeom == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
    for mesh in list(spec.meshes):
        if not mesh.file or (base / mesh.file).is_file() or Path(mesh.file).is_file():
            continue
        users = [g for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH and g.meshname == mesh.name]
        bodies = sorted({g.parent.name for g in users})
        massless = [g.parent.name for g in users if g.parent.explicitinertial and not from_geoms]
        if len(massless) != len(users):
            body = next(b for b in bodies if b not in massless)
            raise _fail(
                f"mesh {mesh.name!r} of body {body!r}: file not found: {base / mesh.file}",
                "model",
                hint="the body takes its mass from the mesh: give the mesh file, or the body an <inertial>",
            )
        for g in users:
            spec.delete(g)
        spec.delete(mesh)
        warnings.warn(
            f"mesh {mesh.name!r} ({base / mesh.file}) not found: its geoms on {', '.join(bodies)} dropped (their "
            "bodies state their inertia, so the modes do not depend on it)",
            MissingMeshWarning,
            stacklevel=4,
        )


def _drop_textures(spec: mujoco.MjSpec) -> None:
    """Remove the textures (materials keep their colours): fpm-sim renders nothing, and MuJoCo builds every texture
    at each compile (dm_control's skybox and grid: 70 ms of a 70.3 ms compile, and a build compiles about ten times)."""
    for texture in list(spec.textures):
        spec.delete(texture)
    for material in spec.materials:
        material.textures = [""] * len(material.textures)


def load_spec(desc: ImportedDescription) -> mujoco.MjSpec:
    """The model file of ``desc`` as a spec, textures and missing meshes dropped, its flexible bodies checked."""
    try:
        spec = mujoco.MjSpec.from_file(str(desc.model_path))
        spec.compiler.fusestatic = False  # a URDF's default: a body left without joints by locking keeps its name
        _drop_textures(spec)
        _drop_missing_meshes(spec, desc.model_path)
        spec.compile()
    except ValueError as e:
        raise _fail(f"MuJoCo cannot read {desc.model_path}: {str(e).splitlines()[0]}", "model") from e
    for j in spec.joints:
        if j.type == mujoco.mjtJoint.mjJNT_FREE:
            raise _fail(
                f"joint {j.name or '(unnamed)'} of body {j.parent.name} is a free joint",
                "model",
                hint="fpm-sim analyses a machine on its base: fix the base (remove the free joint)",
            )
    for k, f in enumerate(desc.flexible):
        if spec.body(f.body) is None:
            names = ", ".join(b.name for b in spec.bodies if b.name and b.name != "world")
            raise _fail(f"no body {f.body!r} in {desc.model_path.name}", f"flexible[{k}].body", hint=f"bodies: {names}")
    return spec


def _quat(rot: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot).ravel())
    return q


def _rot(quat: np.ndarray) -> np.ndarray:
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, np.asarray(quat, float))
    return r.reshape(3, 3)


def _loop_residuals(model: mujoco.MjModel, data: mujoco.MjData, q: dict[str, float]) -> None:
    """Refuse a pose at which an active ``<equality connect|weld>`` does not close (its residual in the model as
    read, whose closures MuJoCo's compiler set at the model's own reference pose)."""
    if model.neq == 0:
        return
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    mujoco.mj_forward(model, data)
    check_loops_closed(model, data, q)


def check_loops_closed(model: mujoco.MjModel, data: mujoco.MjData, q: Mapping[str, float]) -> None:
    """After the position stage (constraints on): refuse the joint values ``q`` when an active ``<equality
    connect|weld>`` does not close there, by the equality's name (its residual above :data:`LOOP_TOL`)."""
    worst: dict[int, float] = {}
    for r in range(data.nefc):
        if int(data.efc_type[r]) == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY):
            e = int(data.efc_id[r])
            worst[e] = max(worst.get(e, 0.0), abs(float(data.efc_pos[r])))
    for e, res in worst.items():
        if int(model.eq_type[e]) in (int(mujoco.mjtEq.mjEQ_CONNECT), int(mujoco.mjtEq.mjEQ_WELD)) and res > LOOP_TOL:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_EQUALITY, e) or f"(equality {e})"
            given = ", ".join(f"{k} = {v:g}" for k, v in q.items()) or "the model's reference pose"
            raise _fail(
                f"the loop closure {name} does not close at {given}: residual {res:.3g} (m or rad) > {LOOP_TOL:g}",
                "q",
                hint="give every joint of the loop values that close it (the passive joints too), or pose the model "
                "in task space where its description names an [end_effector]",
            )


def constrained_model(spec: mujoco.MjSpec) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """``spec`` compiled as the rigid machine whose loop closures the pose solvers read: constraints on, contacts
    off, a dense constraint Jacobian (``efc_J`` as ``(nefc, nv)``)."""
    model = spec.compile()
    model.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return model, mujoco.MjData(model)


def posable_joints(desc: ImportedDescription) -> list[str]:
    """The names of the hinge and slide joints of ``desc``'s model (those a joint-space pose may set)."""
    return list(joint_ranges(load_spec(desc).compile()))


def joint_ranges(model: mujoco.MjModel) -> dict[str, tuple[float, float, str]]:
    """Every named hinge and slide joint of ``model`` (those a joint-space pose may set, in the model's order) with
    its range, ``{name: (lo, hi, unit)}`` (``"rad"`` or ``"m"``, as MuJoCo compiled them; ``(-inf, inf)`` where the
    joint is not limited): a joint-space pose outside one is not a pose the machine takes (:func:`range_problem`)."""
    units = {int(mujoco.mjtJoint.mjJNT_HINGE): "rad", int(mujoco.mjtJoint.mjJNT_SLIDE): "m"}
    out = {}
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if int(model.jnt_type[j]) in units and name:
            lo, hi = (float(v) for v in model.jnt_range[j]) if model.jnt_limited[j] else (-math.inf, math.inf)
            out[name] = (lo, hi, units[int(model.jnt_type[j])])
    return out


def range_problem(ranges: Mapping[str, tuple[float, float, str]], name: str, value: float) -> str | None:
    """What is wrong with joint ``name`` (a key of ``ranges``, :func:`joint_ranges`) at ``value``: ``None`` inside
    its range, else a sentence naming the value and the range (a hinge's in degrees too). A value within 1e-9
    (relative to the range's size, at least 1e-9 absolute) of a limit counts as inside: a solved pose at a limit
    lands there to round-off."""
    lo, hi, unit = ranges[name]
    tol = 1e-9 * max(1.0, hi - lo)
    if lo - tol <= value <= hi + tol:  # always for an unlimited joint: (-inf, inf), tol inf
        return None
    deg = f" ({math.degrees(lo):.6g} to {math.degrees(hi):.6g} deg)" if unit == "rad" else ""
    return f"joint {name!r} = {value:.6g} {unit} is outside its range [{lo:.6g}, {hi:.6g}] {unit}{deg}"


def _pose(spec: mujoco.MjSpec, q: dict[str, float]) -> None:
    """Set the joint values ``q`` into the bodies' frames (module docstring); a loop that does not close there is
    refused by the equality's name (:func:`_loop_residuals`)."""
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    if not q:
        _loop_residuals(model, data, q)
        return
    ranges = joint_ranges(model)
    for name, value in q.items():
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            names = ", ".join(j.name for j in spec.joints if j.name)
            raise _fail(f"no joint {name!r} in the model", "q", name, hint=f"joints: {names}")
        if name not in ranges:
            raise _fail(f"joint {name!r} is not a hinge or slide: pose it in the model file", "q", name)
        if not math.isfinite(value):
            raise _fail(f"joint {name!r}: value must be finite", "q", value)
        if problem := range_problem(ranges, name, value):
            raise _fail(problem, "q", hint="pose it inside the range, or widen the range in the model file")
        data.qpos[model.jnt_qposadr[jid]] = value
    _loop_residuals(model, data, q)
    mujoco.mj_kinematics(model, data)
    posed = {int(model.jnt_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in q}
    for bid in posed:
        parent = int(model.body_parentid[bid])
        rp, pp = data.xmat[parent].reshape(3, 3), data.xpos[parent]
        rb, pb = data.xmat[bid].reshape(3, 3), data.xpos[bid]
        body = spec.body(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, bid))
        body.pos = (rp.T @ (pb - pp)).tolist()
        body.quat = _quat(rp.T @ rb).tolist()
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
    for name, value in q.items():  # the joint's coordinate shifted by -value: zero is now the posed frame
        j = spec.joint(name)
        hinge = j.type == mujoco.mjtJoint.mjJNT_HINGE
        shift = (math.degrees(value) if hinge and spec.compiler.degree else value) - j.ref
        j.ref = 0.0
        j.springref -= shift
        if j.range[0] < j.range[1]:  # a stated range (an unset one, [0, 0], stays unset: not a limit)
            j.range = [j.range[0] - shift, j.range[1] - shift]


@dataclass
class _Beam:
    """A flexible body's beam in the body's frame, and what its link replaces."""

    index: int
    flex: FlexibleBody
    start: np.ndarray
    rot: np.ndarray  # columns: the link frame's x (along the beam), y, z in the body's frame
    length_m: float
    frm: str
    to: str
    replaced: list[str]
    kept: list[str]
    lump: tuple[float, np.ndarray, np.ndarray] | None = None


def _local(model: mujoco.MjModel, data: mujoco.MjData, bid: int, p_world: np.ndarray) -> np.ndarray:
    out: np.ndarray = data.xmat[bid].reshape(3, 3).T @ (p_world - data.xpos[bid])
    return out


def _end(model: mujoco.MjModel, data: mujoco.MjData, bid: int, f: FlexibleBody, k: int) -> tuple[np.ndarray, str]:
    """The beam's end in the body's frame: ``end_m``, ``end_site``, or the child body's joint."""
    if f.end_m is not None:
        return np.array(f.end_m), "end_m"
    if f.end_site is not None:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f.end_site)
        if sid < 0:
            raise _fail(f"no site {f.end_site!r} in the model", f"flexible[{k}].end_site", f.end_site)
        return _local(model, data, bid, data.site_xpos[sid]), f"site {f.end_site}"
    children = [c for c in range(model.nbody) if model.body_parentid[c] == bid and c != bid and model.body_jntnum[c]]
    if len(children) != 1:
        what = "no child body with a joint" if not children else "several child bodies with joints"
        raise _fail(
            f"body {f.body!r} has {what}: the beam's end is not defined",
            f"flexible[{k}].end_site",
            hint="name a site at the link's end (end_site) or give end_m",
        )
    c = children[0]
    jid = int(model.body_jntadr[c])
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, jid) or "(unnamed)"
    return _local(model, data, bid, data.xanchor[jid]), f"joint {name}"


def _start(model: mujoco.MjModel, data: mujoco.MjData, bid: int, f: FlexibleBody) -> tuple[np.ndarray, str]:
    if f.start_m is not None:
        return np.array(f.start_m), "start_m"
    if model.body_jntnum[bid]:
        jid = int(model.body_jntadr[bid])
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, jid) or "(unnamed)"
        return _local(model, data, bid, data.xanchor[jid]), f"joint {name}"
    return np.zeros(3), "body origin"


def _frame(model: mujoco.MjModel, bid: int, f: FlexibleBody, x: np.ndarray) -> np.ndarray:
    """The link frame: x along the beam, z (the section's height_m) along ``z_axis`` or the body's joint axis, made
    perpendicular to x (any perpendicular when neither gives one)."""
    candidates = [np.array(f.z_axis)] if f.z_axis is not None else []
    if model.body_jntnum[bid]:
        candidates.append(model.jnt_axis[model.body_jntadr[bid]].copy())
    candidates += [np.eye(3)[2], np.eye(3)[1], np.eye(3)[0]]
    for z in candidates:
        z = z - x * float(z @ x)
        if np.linalg.norm(z) > 1e-6:
            z = z / np.linalg.norm(z)
            return np.column_stack([x, np.cross(z, x), z])
    raise AssertionError("unreachable: a coordinate axis is always off the beam")


def _split_geoms(model: mujoco.MjModel, bid: int, beam: _Beam) -> None:
    """Which of the body's geoms the beam replaces: ``replace_geoms``, or the capsules, cylinders and boxes whose long
    axis lies along the beam, centred on it between its ends."""
    f = beam.flex
    names = {}
    own = [g for g in range(model.ngeom) if model.geom_bodyid[g] == bid]
    for i, g in enumerate(own):
        names[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or _unnamed(f.body, i)] = g
    if f.replace_geoms is not None:
        for n in f.replace_geoms:
            if n not in names:
                raise _fail(f"body {f.body!r} has no geom {n!r}", f"flexible[{beam.index}].replace_geoms", n)
        beam.replaced = list(f.replace_geoms)
    else:
        x = beam.rot[:, 0]
        for n, g in names.items():
            if model.geom_type[g] not in _ALONG_TYPES:
                continue
            axis_local = 2 if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX else int(np.argmax(model.geom_size[g]))
            axis = _rot(model.geom_quat[g])[:, axis_local]
            d = model.geom_pos[g] - beam.start
            along = float(d @ x)
            off = np.linalg.norm(d - along * x)
            if abs(float(axis @ x)) > 0.999 and off < 1e-6 + 0.5 * beam.length_m and 0 <= along <= beam.length_m:
                beam.replaced.append(n)
    beam.kept = [n for n in names if n not in beam.replaced]


def _beams(spec: mujoco.MjSpec, desc: ImportedDescription) -> list[_Beam]:
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    out = []
    for k, f in enumerate(desc.flexible):
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f.body)
        start, frm = _start(model, data, bid, f)
        end, to = _end(model, data, bid, f, k)
        length = float(np.linalg.norm(end - start))
        if length < 1e-6:
            raise _fail(
                f"body {f.body!r}: the beam from {frm} to {to} has zero length",
                f"flexible[{k}].end_m",
                hint="give the link's end (end_site or end_m) away from its start",
            )
        x = (end - start) / length
        beam = _Beam(k, f, start, _frame(model, bid, f, x), length, frm, to, [], [])
        _split_geoms(model, bid, beam)
        out.append(beam)
    return out


def _inertia_matrix(model: mujoco.MjModel, bid: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre and 3x3 inertia about the centre of body ``bid``, in its frame, as compiled."""
    r = _rot(model.body_iquat[bid])
    return float(model.body_mass[bid]), model.body_ipos[bid].copy(), r @ np.diag(model.body_inertia[bid]) @ r.T


def _about_origin(m: float, c: np.ndarray, i_c: np.ndarray) -> np.ndarray:
    out: np.ndarray = i_c + m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return out


def _beam_inertia(beam: _Beam, opts: ModelOptions) -> tuple[float, np.ndarray, np.ndarray]:
    m, c, i_c = box_part(beam.length_m, beam.flex.section, beam.flex.material, 0.0, rotary_inertia=opts.rotary_inertia)
    return m, beam.start + beam.rot @ c, beam.rot @ i_c @ beam.rot.T


def _remainder(
    total: tuple[float, np.ndarray, np.ndarray], part: tuple[float, np.ndarray, np.ndarray], body: str, k: int
) -> tuple[float, np.ndarray, np.ndarray]:
    """``total`` less ``part`` (mass, centre, inertia about the centre); refused when negative."""
    (m, c, i_c), (mb, cb, ib) = total, part
    mr = m - mb
    if mr < -1e-9 * max(m, 1e-12):
        raise _fail(
            f"body {body!r} states {m:.6g} kg, less than its beam's {mb:.6g} kg",
            f"flexible[{k}].section",
            hint="check the section and material, or give the body an <inertial> that includes the beam",
        )
    if mr <= 1e-9 * max(m, 1e-12):
        return 0.0, np.zeros(3), np.zeros((3, 3))
    cr = (m * c - mb * cb) / mr
    i_r = _about_origin(m, c, i_c) - _about_origin(mb, cb, ib)
    i_r = i_r - mr * (float(cr @ cr) * np.eye(3) - np.outer(cr, cr))
    i_r = 0.5 * (i_r + i_r.T)
    if np.linalg.eigvalsh(i_r).min() < -1e-9 * max(np.trace(i_c), 1e-12):
        raise _fail(f"body {body!r}: its inertia less the beam's is not positive", f"flexible[{k}].section")
    return mr, cr, i_r


def _kept_by_geoms(spec: mujoco.MjSpec, beams: list[_Beam]) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """The mass of each flexible body's kept geoms, as MuJoCo computes it: a copy without the replaced geoms, with a
    1 kg probe sphere at the origin (MuJoCo needs mass on a moving body), less the probe."""
    if not beams:
        return {}
    copy = spec.copy()
    radius = 1e-3
    for beam in beams:
        body = copy.body(beam.flex.body)
        geoms = list(body.geoms)
        for g in _replaced(body, beam):
            copy.delete(geoms[g])
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[radius, 0, 0], mass=1.0, contype=0, conaffinity=0)
    model = copy.compile()
    probe = (1.0, np.zeros(3), np.eye(3) * 0.4 * radius**2)
    out = {}
    for beam in beams:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, beam.flex.body)
        out[beam.flex.body] = _remainder(_inertia_matrix(model, bid), probe, beam.flex.body, beam.index)
    return out


def _unnamed(body: str, i: int) -> str:
    return f"(geom {i} of {body})"


def _replaced(body: mujoco.MjsBody, beam: _Beam) -> list[int]:
    """Indices in ``body.geoms`` of the geoms the beam replaces (unnamed ones by their place, ``geom N``)."""
    out = []
    for i, g in enumerate(body.geoms):
        if (g.name or _unnamed(body.name, i)) in beam.replaced:
            out.append(i)
    return out


def _explicit_mass(spec: mujoco.MjSpec, beams: list[_Beam], opts: ModelOptions, report: ImportReport) -> None:
    """Every body's inertial made explicit as the model states it; a flexible body's replaced by its rigid lump."""
    model = spec.compile()
    from_geoms = spec.compiler.inertiafromgeom != mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    explicit_bodies = {b.flex.body for b in beams if spec.body(b.flex.body).explicitinertial or not from_geoms}
    kept = _kept_by_geoms(spec, [b for b in beams if b.flex.body not in explicit_bodies])
    lumps = {}
    for beam in beams:
        body = spec.body(beam.flex.body)
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, beam.flex.body)
        if body.name in explicit_bodies:
            lumps[beam.flex.body] = _remainder(_inertia_matrix(model, bid), _beam_inertia(beam, opts), body.name, 0)
            report.mass_rule[body.name] = "its <inertial> less the beam's mass"
        else:
            lumps[beam.flex.body] = kept[beam.flex.body]
            report.mass_rule[body.name] = "its kept geoms' mass"
        report.lump_kg[body.name] = lumps[beam.flex.body][0]
        beam.lump = lumps[beam.flex.body]
        lumps[beam.flex.body] = (0.0, np.zeros(3), np.zeros((3, 3)))  # it rides on the beam (_hang_lump)
    for bid in range(1, model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, bid)
        body = spec.body(name) if name else None
        if body is None:
            continue
        m, c, i_c = lumps[name] if name in lumps else _inertia_matrix(model, bid)
        if m <= 0.0:  # nothing left: the body's mass is its beam's (no inertial; geoms carry none now)
            body.explicitinertial, body.mass, body.inertia = False, 0.0, [0.0, 0.0, 0.0]
            body.fullinertia = [math.nan] * 6
            continue
        w, v = np.linalg.eigh(0.5 * (i_c + i_c.T))
        if np.linalg.det(v) < 0:
            v[:, 0] = -v[:, 0]
        body.mass, body.ipos, body.inertia, body.iquat = m, c.tolist(), np.maximum(w, 0.0).tolist(), _quat(v).tolist()
        body.fullinertia = [math.nan] * 6  # principal inertia and iquat, not a full matrix
        body.explicitinertial = True
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE


def _motors(spec: mujoco.MjSpec, desc: ImportedDescription) -> list[str]:
    """The motors of ``desc``'s model in its joint order: the joints a joint ``<actuator>`` drives (but for
    ``locked_joints``) and ``servo_joints`` (checked to exist)."""
    for k, name in enumerate(desc.servo_joints):
        if spec.joint(name) is None:
            raise _fail(f"no joint {name!r} in the model", f"servo_joints[{k}]", name)
    driven = {a.target for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_JOINT} - set(desc.locked_joints)
    driven |= set(desc.servo_joints)
    return [j.name for j in spec.joints if j.name in driven]


def motor_joints(desc: ImportedDescription) -> list[str]:
    """The motors of ``desc``'s model (:func:`_motors`): what ``motors="servo"`` drives by position servos."""
    return _motors(load_spec(desc), desc)


def _servo(spec: mujoco.MjSpec, desc: ImportedDescription, motors: list[str]) -> None:
    """Each motor a position servo: the description's gains as the joint's stiffness and damping about its posed
    coordinate (``springref`` = ``ref``), the model's own actuators on it removed (they would double the servo)."""
    if not motors:
        raise _fail(
            f"{desc.name} has no motors to drive: no <actuator> drives a joint and servo_joints is empty",
            "servo_joints",
            hint="name the joints the machine's motors turn in the description: servo_joints = [...]",
        )
    for a in list(spec.actuators):
        if a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target in motors:
            spec.delete(a)
    for name in motors:
        j = spec.joint(name)
        if j.type not in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            raise _fail(
                f"motor joint {name!r} is not a hinge or slide: a servo drives one coordinate",
                "servo_joints",
                name,
                hint="build it with motors='locked' (modal analysis), or drive a hinge or slide",
            )
        k, c = desc.servos.gains("revolute" if j.type == mujoco.mjtJoint.mjJNT_HINGE else "prismatic")
        j.stiffness, j.damping, j.springref = [k, 0.0, 0.0], [c, 0.0, 0.0], j.ref


def _lock(spec: mujoco.MjSpec, desc: ImportedDescription, report: ImportReport, servo: bool = False) -> list[str]:
    """Remove the joints modal analysis locks (:func:`locked_joint_names`; the body then rigid on its parent); with
    ``servo`` the motors (:func:`_motors`) stay as position servos (:func:`_servo`). Returns the servo joints."""
    motors = _motors(spec, desc) if servo else []
    order = [n for n in locked_joint_names(spec, desc) if n not in motors]
    if servo:
        _servo(spec, desc, motors)
    locked = set(order)
    for a in list(spec.actuators):  # a locked joint drives nothing
        if a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target in locked:
            spec.delete(a)
    _drop_with_locked(spec, locked, report)
    for name in order:
        spec.delete(spec.joint(name))
        report.locked.append(name)
    return motors


def locked_joint_names(spec: mujoco.MjSpec, desc: ImportedDescription) -> list[str]:
    """The joints modal analysis locks (what :func:`_lock` removes without servos): the actuated ones (an
    ``<actuator>`` drives them), ``locked_joints`` and ``servo_joints``, each checked to exist."""
    for key, names in (("locked_joints", desc.locked_joints), ("servo_joints", desc.servo_joints)):
        for k, name in enumerate(names):
            if spec.joint(name) is None:
                raise _fail(f"no joint {name!r} in the model", f"{key}[{k}]", name)
    actuated = [a.target for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_JOINT]
    return [n for n in dict.fromkeys([*actuated, *desc.locked_joints, *desc.servo_joints]) if spec.joint(n) is not None]


def _drop_with_locked(spec: mujoco.MjSpec, locked: set[str], report: ImportReport) -> None:
    """Delete what a locked joint leaves dangling: the tendons that span it (with the actuators, equalities and
    sensors on those tendons) and the sensors on the joint; named in ``report.dropped``."""
    model = spec.compile()
    jids = {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in locked}
    tendons = set()
    for t in range(model.ntendon):
        adr, num = int(model.tendon_adr[t]), int(model.tendon_num[t])
        wraps = range(adr, adr + num)
        if any(model.wrap_type[w] == mujoco.mjtWrap.mjWRAP_JOINT and model.wrap_objid[w] in jids for w in wraps):
            tendons.add(spec.tendons[t].name or f"(tendon {t})")
    for t in [t for t in spec.tendons if (t.name or f"(tendon {list(spec.tendons).index(t)})") in tendons]:
        spec.delete(t)
        report.dropped.append(f"tendon {t.name}")
    for a in [a for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_TENDON and a.target in tendons]:
        report.dropped.append(f"actuator {a.name}")
        spec.delete(a)
    for e in [e for e in spec.equalities if e.type == mujoco.mjtEq.mjEQ_TENDON and {e.name1, e.name2} & tendons]:
        report.dropped.append(f"equality {e.name}")
        spec.delete(e)
    for x in [x for x in spec.sensors if x.objname in tendons | locked and x.objtype in _JOINTISH]:
        report.dropped.append(f"sensor {x.name}")
        spec.delete(x)


def _add_beams(
    spec: mujoco.MjSpec, desc: ImportedDescription, beams: list[_Beam], opts: ModelOptions, model: mujoco.MjModel
) -> tuple[dict[str, list[str]], dict[str, str], dict[str, tuple[str, np.ndarray, np.ndarray]]]:
    """Each beam's segment chain on its body (replaced geoms removed); the children's new parent and placement
    (from ``model``, the spec compiled before its masses were split: a body whose mass is all its beam's has none
    until the beam hangs on it)."""
    links: dict[str, list[str]] = {}
    kinds: dict[str, str] = {}
    moves: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    for beam in beams:
        body = spec.body(beam.flex.body)
        geoms = list(body.geoms)
        for g in _replaced(body, beam):
            spec.delete(geoms[g])
        name = f"{beam.flex.body}_beam"
        link = LinkSpec(
            name=name,
            pos_m=(float(beam.start[0]), float(beam.start[1]), float(beam.start[2])),
            angle_rad=0.0,
            quat=tuple(_quat(beam.rot).tolist()),
            length_m=beam.length_m,
            section=beam.flex.section,
            material=beam.flex.material,
            link_model=opts.link_model,
            segments=int(opts.segments or 1),
            axial=opts.axial,
            rotary_inertia=opts.rotary_inertia,
            damping_beta_s=desc.damping_beta_s,
        )
        build = add_link(spec, body, link)
        for jn, _ in build.joints:  # springs, whatever the body's joint class says (a class may limit its joints)
            spec.joint(jn).limited = mujoco.mjtLimited.mjLIMITED_FALSE
        _hang_lump(beam, build)
        links[name] = build.sites
        kinds.update(dict(build.joints))
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, beam.flex.body)
        for c in range(model.nbody):
            if c != bid and model.body_parentid[c] == bid:
                child = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, c)
                j = _piece_of(beam, build, model.body_pos[c]) if model.body_jntnum[c] == 0 else len(build.bodies) - 1
                origin = beam.start + beam.rot[:, 0] * float(np.sum(build.piece_lengths_m[:j]))
                rc = _rot(model.body_quat[c])
                pos = beam.rot.T @ (model.body_pos[c] - origin)
                moves[child] = (build.bodies[j].name, pos, _quat(beam.rot.T @ rc))
    return links, kinds, moves


def _piece_of(beam: _Beam, build: Any, p: np.ndarray) -> int:
    """The index of the beam's piece that holds the point ``p`` (body frame), by its place along the beam."""
    s = float(np.clip((p - beam.start) @ beam.rot[:, 0], 0.0, beam.length_m))
    edges = np.cumsum([0.0, *build.piece_lengths_m])
    return min(int(np.searchsorted(edges, s, side="right")) - 1, len(build.bodies) - 1)


def _hang_lump(beam: _Beam, build: Any) -> None:
    """The body's rigid lump onto the beam's piece that holds its centre (a motor at the link's far end rides on
    the end, one at its joint on the start)."""
    if beam.lump is None or beam.lump[0] <= 0.0:
        return
    m, c, i_c = beam.lump
    edges = np.cumsum([0.0, *build.piece_lengths_m])
    j = _piece_of(beam, build, c)
    piece = build.bodies[j]
    origin = beam.start + beam.rot[:, 0] * edges[j]
    f = piece.fullinertia
    i_piece = np.array([[f[0], f[3], f[4]], [f[3], f[1], f[5]], [f[4], f[5], f[2]]])
    parts = [
        (float(piece.mass), np.array(piece.ipos), i_piece),
        (m, beam.rot.T @ (c - origin), beam.rot.T @ i_c @ beam.rot),
    ]
    set_inertial(piece, parts)


def _rehang(xml: str, moves: dict[str, tuple[str, np.ndarray, np.ndarray]]) -> str:
    """Move each child body under its beam's last piece, at its own place (the MJCF's tree edited as text)."""
    root = ET.fromstring(xml)
    parents = {c: p for p in root.iter() for c in p}
    by_name = {e.get("name"): e for e in root.iter("body")}
    for child, (new_parent, pos, quat) in moves.items():
        e = by_name[child]
        parents[e].remove(e)
        for attr in ("euler", "axisangle", "xyaxes", "zaxis"):
            e.attrib.pop(attr, None)
        e.set("pos", " ".join(repr(float(v)) for v in pos))
        e.set("quat", " ".join(repr(float(v)) for v in quat))
        by_name[new_parent].append(e)
    return ET.tostring(root, encoding="unicode")


def _fpm_options(spec: mujoco.MjSpec, desc: ImportedDescription, opts: ModelOptions) -> None:
    base = desc.model_path.parent
    for attr in ("meshdir", "texturedir"):
        d = getattr(spec, attr) or ""
        if not d.startswith("/"):
            setattr(spec, attr, str(base / d))
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    if not opts.gravity:
        spec.option.gravity = [0.0, 0.0, 0.0]


def end_sites(model_path: str | Path, bodies: list[str]) -> dict[str, str]:
    """For each of ``bodies`` whose beam has no default end (not one child body with a joint), the body's own site
    farthest from its joint (or origin), if it has one: what ``fpm-sim import`` writes as ``end_site``. Bodies the
    model lacks are left out (the import report names them)."""
    try:
        model = mujoco.MjSpec.from_file(str(model_path)).compile()
    except ValueError as e:
        raise _fail(f"MuJoCo cannot read {model_path}: {str(e).splitlines()[0]}", "model") from e
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    out = {}
    for name in bodies:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid < 0:
            continue
        children = [
            c for c in range(model.nbody) if model.body_parentid[c] == bid and c != bid and model.body_jntnum[c]
        ]
        sites = [s for s in range(model.nsite) if model.site_bodyid[s] == bid]
        if len(children) == 1 or not sites:
            continue
        start = data.xanchor[model.body_jntadr[bid]] if model.body_jntnum[bid] else data.xpos[bid]
        far = max(sites, key=lambda s: float(np.linalg.norm(data.site_xpos[s] - start)))
        out[name] = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, far) or ""
    return {k: v for k, v in out.items() if v}


def mechanism_joints(desc: ImportedDescription) -> list[str]:
    """The joints to lock besides the description's so that the rigid machine, its locked joints locked, has no free
    motion left (a mechanism: a passive joint on an open chain, or one a loop leaves free), as ``fpm-sim import``
    writes them into ``locked_joints``.

    At the model's reference pose, with the locked joints' tendons dropped as the builder drops them
    (:func:`_drop_with_locked`), the loop closures' Jacobian (MuJoCo's equality rows, each scaled to unit size) over
    the dofs of the joints not yet locked has a null space of the mechanism's free motions (rank at 1e-9 of its
    largest singular value); the joints owning the dofs that column-pivoted QR of that basis picks first are locked,
    one per free motion. Locking them may drop a tendon that held another joint, so it is repeated until no free
    motion is left.
    """
    spec = load_spec(desc)
    locked = set(locked_joint_names(spec, desc))
    out: list[str] = []
    while True:
        new = _free_motion_joints(desc, locked | set(out))
        if not new:
            return out
        out += [n for n in new if n not in out]


def _free_motion_joints(desc: ImportedDescription, locked: set[str]) -> list[str]:
    """One pass of :func:`mechanism_joints`: the joints to lock for the free motions left with ``locked`` locked."""
    import scipy.linalg

    spec = load_spec(desc)
    _drop_with_locked(spec, locked, ImportReport())
    model, data = constrained_model(spec)
    mujoco.mj_fwdPosition(model, data)
    owner: list[str] = []
    cols: list[int] = []
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"(joint {j})"
        width = {int(mujoco.mjtJoint.mjJNT_BALL): 3, int(mujoco.mjtJoint.mjJNT_FREE): 6}.get(int(model.jnt_type[j]), 1)
        if name not in locked:
            cols += range(int(model.jnt_dofadr[j]), int(model.jnt_dofadr[j]) + width)
            owner += [name] * width
    if not cols:
        return []
    eq = np.asarray(data.efc_type[: data.nefc]) == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    jac = np.asarray(data.efc_J[: data.nefc * model.nv]).reshape(data.nefc, model.nv)[eq][:, cols]
    norms = np.linalg.norm(jac, axis=1)
    jac = jac[norms > 0] / norms[norms > 0, None]
    _, sv, vt = np.linalg.svd(jac) if jac.size else (None, np.zeros(0), np.eye(len(cols)))
    rank = int(np.sum(sv > 1e-9 * (sv[0] if sv.size else 1.0)))
    free = vt[rank:].T  # (dofs, free motions)
    if free.shape[1] == 0:
        return []
    pivots = scipy.linalg.qr(free.T, pivoting=True)[2]
    return list(dict.fromkeys(owner[k] for k in pivots[: free.shape[1]]))


def import_report(desc: ImportedDescription, options: ModelOptions | None = None) -> ImportReport:
    """What :func:`build_imported` keeps and replaces, without compiling the flexible model."""
    return _assemble(desc, {}, options or ModelOptions())[1]


def _assemble(
    desc: ImportedDescription,
    q: dict[str, float],
    opts: ModelOptions,
    *,
    servo: bool = False,
    lock: bool = True,
) -> tuple[mujoco.MjSpec, ImportReport, dict[str, list[str]], dict[str, str]]:
    if opts.link_model not in ("segments", "rigid"):
        raise _fail(
            f"link model {opts.link_model!r} is not built for imported models",
            "link_model",
            opts.link_model,
            hint="use 'segments' or 'rigid'",
        )
    report = ImportReport()
    spec = load_spec(desc)
    _pose(spec, q)
    beams = _beams(spec, desc)  # before locking: a locked joint still marks a beam's end
    if lock:
        motors = _lock(spec, desc, report, servo)
    else:  # kept as joints, named: a pose loop locks them by constraint rows (fpm_sim.batch.imported_pose_model)
        report.locked, motors = locked_joint_names(spec, desc), []
    for beam in beams:
        b = beam.flex.body
        report.replaced[b], report.kept[b] = beam.replaced, beam.kept
        report.beam[b] = {"length_m": beam.length_m, "from": beam.frm, "to": beam.to}
    tree = spec.compile()  # the bodies' places, compiled while every moving body still has its mass
    _explicit_mass(spec, beams, opts, report)
    report.loops = sum(
        1 for e in spec.equalities if e.type in (mujoco.mjtEq.mjEQ_CONNECT, mujoco.mjtEq.mjEQ_WELD) and e.active
    )
    _fpm_options(spec, desc, opts)
    links, kinds, moves = _add_beams(spec, desc, beams, opts, tree)
    spec = mujoco.MjSpec.from_string(_rehang(full_precision_xml(spec), moves))
    return spec, report, links, {**kinds, **dict.fromkeys(motors, "motor")}


def build_imported(
    desc: ImportedDescription,
    q: dict[str, float] | None = None,
    options: ModelOptions | None = None,
    *,
    motors: str = "locked",
    keep_locked: bool = False,
) -> BuiltModel:
    """The flexible model of ``desc`` posed at the joint values ``q`` (module docstring).

    ``motors``: ``"locked"`` (the default: the motors removed, what modal analysis uses) or ``"servo"`` (the motors,
    :func:`motor_joints`, kept as position servos of the description's ``[servos]`` gains about the posed coordinate,
    dof kind ``motor``; what a move drives).

    ``keep_locked``: the joints modal analysis locks (:func:`locked_joint_names`) stay joints, of kind ``"locked"``,
    for a caller that locks them itself (the pose loop, :class:`fpm_sim.batch.imported_pose_model.ImportedPoseModel`,
    by constraint rows, so that one compiled model takes every pose); with ``motors="locked"`` only.

    Raises
    ------
    ModelImportError
        A body, joint or site the description names that the model lacks, a free joint, a zero-length beam, a body
        whose stated mass is less than its beam's, a link model other than ``segments`` or ``rigid``; with
        ``motors="servo"``, a model without motors or a motor that is not a hinge or slide.
    """
    opts = options or ModelOptions()
    if motors not in ("locked", "servo"):
        raise _fail("unknown motor model", "motors", motors, hint="choose 'locked' or 'servo'")
    if keep_locked and motors != "locked":
        raise _fail("joints kept for locking by rows are modal analysis's: no servos", "motors", motors)
    spec, report, links, kinds = _assemble(desc, dict(q or {}), opts, servo=motors == "servo", lock=not keep_locked)
    if keep_locked:
        kinds = {**kinds, **dict.fromkeys(report.locked, "locked")}
    model = compile_model(spec, timestep_s=opts.timestep_s)
    dof_kinds = ["passive"] * model.nv
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        width = {int(mujoco.mjtJoint.mjJNT_BALL): 3}.get(int(model.jnt_type[j]), 1)
        adr = int(model.jnt_dofadr[j])
        dof_kinds[adr : adr + width] = [kinds.get(name, "passive")] * width
    first = next(iter(links))
    # the reductions' and the FRF's end effector: the description's [end_effector] site, else the last flexible
    # body's beam end
    tip = desc.end_effector.site if desc.end_effector is not None else links[list(links)[-1]][-1]
    return BuiltModel(
        model=model,
        spec=spec,
        name="manipulator",
        links=links,
        dof_kinds=dof_kinds,
        parameters={
            "config": desc.name,
            "model": str(desc.model_path),
            "q": {k: float(v) for k, v in (q or {}).items()},
            "locked_joints": report.locked,
            **(
                {"motors": "servo", "servo_joints": [k for k, v in kinds.items() if v == "motor"]}
                | {"servos": desc.servos.to_dict(desc.provenance)}
                if motors == "servo"
                else {}
            ),
            "options": asdict(opts),
            "timestep_s": float(model.opt.timestep),
            "nv": int(model.nv),
        },
        end_effector_site=tip,
        accelerometer_links=tuple(links),
        test_point=(first, 0.5, "z"),
        planar=False,
    )
