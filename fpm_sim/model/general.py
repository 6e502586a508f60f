"""The MuJoCo model of any described manipulator (:mod:`fpm_sim.architecture`) assembled at a task pose.

Built with :class:`mujoco.MjSpec` like the 3RRR's own builder, with every body placed at the assembly so that
``qpos0`` is the assembled machine at rest with straight, unstressed links:

- each chain is a branch of the body tree from the ground (or from its parent chain's end body); every link is
  built by :func:`fpm_sim.model.links.add_link` (``segments``, or one rigid body for ``flexible = false``) in its
  own frame (x along the link, y along the section's ``thickness_m``, z along its ``height_m``);
- actuated joints are locked (``motors="locked"``, the default: no joint, the next body is rigid on the one before;
  what modal analysis uses) or position servos (``motors="servo"``: a hinge or slide with the description's servo
  stiffness and damping about the assembled coordinate, kind ``motor``,
  :class:`~fpm_sim.architecture.description.ServoGains`; what rollouts with motor torques and moves drive);
  passive joints are MuJoCo joints on the next body (revolute: hinge, prismatic: slide, universal: two hinges,
  spherical: ball), at the joint's centre;
- a joint's lump sits on the body before it (the previous link's end); a link's ``end_lump`` on its end;
- the end effector (its lumps and attachment points) is a child of the first chain that ends on it, through that
  chain's end joint; every other chain closes its loop with an equality: a ``connect`` for a spherical end joint, a
  pin body on a hinge ``weld``-ed to the end effector for a revolute one, a ``weld`` for a fixed one;
- a ball joint's three degrees of freedom are ``passive``. A rod between two ball joints spins freely about its
  axis: a zero-frequency motion, not a mode. Its first ball joint is built as two hinges across the rod, which
  removes the spin, and the rod's inertia about its own axis is dropped (``LinkSpec.spin_inertia``): with its spin
  free it takes no part in any other mode, so the other modes are those of the ball-jointed rod (tested).

What the analyses instrument by default (:class:`fpm_sim.model.spec.BuiltModel`'s ``accelerometer_links``,
``test_point``, ``end_effector_site``), the same rule for every machine (:func:`instrumentation`):

- an accelerometer on the **last flexible link of each chain** (the 3RRR's distal links), at ``accel_fraction``
  of its length from its start (reduced models' outputs ``acc_<chain>_<link>``);
- the default excitation (FRF input, impact hammer and accelerometer) at **mid-span of the first of those links**
  (the first chain that has a flexible link), along the link frame's **z** axis: the section's ``height_m``
  direction, out of the plane for a planar machine (as the study's hammer on the 3RRR), the direction the
  description's joint axes and section orientation state for a spatial one;
- the end effector's reference point is its frame's origin (site ``end_effector_site``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from types import SimpleNamespace
from typing import Any

import mujoco
import numpy as np

from fpm_sim.architecture.description import ChainDesc, Description, JointDesc, LinkDesc
from fpm_sim.architecture.kinematics import TaskAssembly, TaskPose, check_mobility, solve_task_pose
from fpm_sim.config import LumpedMass
from fpm_sim.errors import FpmSimError
from fpm_sim.model.links import add_link
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.parts import LinkSpec, lump_part, set_inertial
from fpm_sim.model.spec import WELD_SOLIMP, BuiltModel, add_weld, compile_model, new_spec

__all__ = [
    "MOTOR_MODES",
    "GeneralModelError",
    "PoseFrames",
    "Reposer",
    "actuated_joint_names",
    "build_general",
    "build_reposable",
    "instrumentation",
]

MOTOR_MODES = ("locked", "servo")
"""How :func:`build_general` builds the actuated joints (module docstring)."""

MIN_BODY_MASS_KG = 1e-4
"""Mass given to a body that would carry none (a pin between a hinge and a weld): MuJoCo needs mass on every
moving body. The same as the 3RRR builder's ``MIN_PIN_MASS_KG``; three pins add 3e-4 kg to the 3PRR's 1 kg
platform, about 1.5e-4 relative on its frequencies (give the end joints ``lump_after`` hardware to replace it)."""
_JOINT_TYPES = {
    "revolute": mujoco.mjtJoint.mjJNT_HINGE,
    "prismatic": mujoco.mjtJoint.mjJNT_SLIDE,
    "spherical": mujoco.mjtJoint.mjJNT_BALL,
}


class GeneralModelError(FpmSimError):
    """What the general builder cannot build (a link model or option it does not support)."""


def _quat(rot: np.ndarray) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot).ravel())
    return q.tolist()


@dataclass
class _Body:
    """A body of the spec being built and its world frame at ``qpos0``."""

    body: mujoco.MjsBody
    p: np.ndarray
    r: np.ndarray
    parts: list[tuple[float, np.ndarray, np.ndarray]]
    jointed: bool = False

    def local(self, p_world: np.ndarray) -> np.ndarray:
        out: np.ndarray = self.r.T @ (p_world - self.p)
        return out

    def add_lump(self, lump: LumpedMass, p_world: np.ndarray) -> None:
        if lump.mass_kg > 0:
            self.parts.append(lump_part(lump, self.local(p_world)))


@dataclass
class _Pending:
    """Passive joints waiting for the next body (world centre and axes)."""

    joints: list[tuple[str, JointDesc, np.ndarray, np.ndarray]]  # (name, joint, centre, frame before the joint)


@dataclass
class PoseFrames:
    """What the pose sets in a described machine's model, by name (:class:`Reposer`): each body's placement in
    its parent (``pos``, ``quat``), each joint's centre and axis in its body, each equality's ``data``. Everything else
    (masses, inertias in the bodies' own frames, springs, the bodies inside a link) is the same at every pose."""

    bodies: dict[str, tuple[list[float], list[float]]] = field(default_factory=dict)
    joints: dict[str, tuple[list[float], list[float]]] = field(default_factory=dict)
    equalities: dict[str, Any] = field(default_factory=dict)


class _Recorder:
    """A stand-in for the spec and its bodies in the frames pass (:class:`Reposer`): it records the placements
    that :class:`PoseFrames` holds and adds nothing else."""

    def __init__(self, frames: PoseFrames, name: str = "world") -> None:
        self.frames, self.name = frames, name

    @property
    def worldbody(self) -> _Recorder:
        return self

    def add_body(self, *, name: str, pos: list[float], quat: list[float]) -> _Recorder:
        self.frames.bodies[name] = (list(pos), list(quat))
        return _Recorder(self.frames, name)

    def add_joint(self, *, name: str, axis: list[float], pos: list[float], **_: Any) -> None:
        self.frames.joints[name] = (list(pos), list(axis))

    def add_site(self, **_: Any) -> None:
        pass

    def add_geom(self, **_: Any) -> None:
        pass

    def add_equality(self, *, name: str, **_: Any) -> SimpleNamespace:
        eq = SimpleNamespace(name1="", name2="", data=np.zeros(11), solimp=[])
        self.frames.equalities[name] = eq
        return eq


@dataclass
class _LinkShape:
    """What the frames pass keeps of a link built once: its first body's name and where the link ends on its last."""

    first: str
    last_length_m: float


class _Builder:
    def __init__(
        self,
        desc: Description,
        asm: TaskAssembly,
        opts: ModelOptions,
        shapes: dict[str, _LinkShape] | None = None,
        *,
        servo: bool = False,
    ) -> None:
        """``shapes``: the links of a model already built (its ``shapes``): a frames pass into a
        :class:`_Recorder` instead of a spec. ``servo``: the actuated joints as servo-driven joints."""
        self.desc, self.asm, self.opts, self.servo = desc, asm, opts, servo
        self.frames_only = shapes is not None
        self.shapes: dict[str, _LinkShape] = shapes if shapes is not None else {}
        self.recorded = PoseFrames()
        self.spec: Any = (
            _Recorder(self.recorded)
            if self.frames_only
            else new_spec(f"fpm_{desc.name.split(' ')[0]}", gravity=opts.gravity)
        )
        world = _Body(self.spec.worldbody, np.zeros(3), np.eye(3), [])
        self.ground = world
        self.kinds: dict[str, str] = {}
        self.links: dict[str, list[str]] = {}
        self.chain_end: dict[str, _Body] = {}
        self.inertial: list[_Body] = []
        self.ee: _Body | None = None

    def new_body(self, parent: _Body, name: str, p: np.ndarray, r: np.ndarray) -> _Body:
        b = parent.body.add_body(name=name, pos=parent.local(p).tolist(), quat=_quat(parent.r.T @ r))
        out = _Body(b, p, r, [])
        self.inertial.append(out)
        return out

    def attach_joints(self, body: _Body, pending: _Pending, *, spin_free: bool = True) -> None:
        """The pending passive joints on ``body`` (at their centres, axes in its frame). ``spin_free=False``: a
        spherical joint becomes two hinges across the body's x axis (the link it starts), its spin removed."""
        for name, j, centre, frame in pending.joints:
            pos = body.local(centre).tolist()
            if j.type == "universal":
                axes = [frame @ np.array(j.axis), frame @ np.array(j.axis2)]
                names = [f"{name}_1", f"{name}_2"]
            elif j.type == "spherical":
                # three hinges along the body's axes (no gimbal lock at qpos0, the same tangent space as a ball
                # joint: the linearisation is exact); the first, about the link's own axis, dropped with its spin
                axes = [body.r[:, 0], body.r[:, 1], body.r[:, 2]][0 if spin_free else 1 :]
                names = [f"{name}_{a}" for a in "xyz"][0 if spin_free else 1 :]
            else:
                axes, names = [frame @ np.array(j.axis)], [name]
            for jn, ax in zip(names, axes):
                jt = _JOINT_TYPES[j.type] if len(axes) == 1 else _JOINT_TYPES["revolute"]
                mj = body.body.add_joint(name=jn, type=jt, axis=(body.r.T @ ax).tolist(), pos=pos)
                self.kinds[jn] = "passive"
                if j.actuated:  # a servo: a spring-damper about the assembled coordinate (module docstring)
                    k, c = self.desc.servos.gains(j.type)
                    mj.stiffness, mj.damping = [k, 0.0, 0.0], [c, 0.0, 0.0]
                    self.kinds[jn] = "motor"
                body.jointed = True
        pending.joints.clear()

    def link(self, chain: ChainDesc, k: int, lk: LinkDesc, parent: _Body, pending: _Pending) -> _Body:
        frames = self.asm.chains[chain.name]
        p0, r0 = frames.positions_m[k], frames.rotations[k]
        nxt = chain.path[k + 1] if k + 1 < len(chain.path) else None
        prev = chain.path[k - 1] if k > 0 else None
        end_lumps = (lk.end_lump,) + ((nxt.lump,) if isinstance(nxt, JointDesc) else ())
        start_lumps = (prev.lump_after,) if isinstance(prev, JointDesc) else ()
        name = f"{chain.name}_{lk.name}"
        p_local = parent.local(p0)
        spec = LinkSpec(
            name=name,
            pos_m=(float(p_local[0]), float(p_local[1]), float(p_local[2])),
            angle_rad=0.0,
            quat=tuple(_quat(parent.r.T @ r0)),  # type: ignore[arg-type]
            length_m=lk.length_m,
            section=lk.section,
            material=lk.material,
            link_model=self.opts.link_model if lk.flexible else "rigid",
            lump_bodies=lk.flexible and self.opts.link_model == "rigid",
            segments=int(self.opts.segments or 1),
            axial=self.opts.axial,
            rotary_inertia=self.opts.rotary_inertia,
            damping_beta_s=self.desc.damping_beta_s,
            end_lumps=tuple(x for x in end_lumps if x.mass_kg > 0),
            start_lumps=tuple(x for x in start_lumps if x.mass_kg > 0),
            spin_inertia=not _between_spherical(chain, k),
        )
        if self.frames_only:  # the link's inside is the same at every pose: only its first body is placed
            shape = self.shapes[name]
            first_body = parent.body.add_body(name=shape.first, pos=list(spec.pos), quat=spec.start_quat)
            last_body = _Recorder(self.recorded, f"{name} (last piece)")  # what hangs on it is placed, not it
        else:
            build = add_link(self.spec, parent.body, spec)
            shape = self.shapes[name] = _LinkShape(build.first.name, build.last_length_m)
            first_body, last_body = build.first, build.last
            self.kinds.update(dict(build.joints))
            self.links[name] = build.sites
        first = _Body(first_body, p0, r0, [])
        # a link between two spherical joints spins freely about its axis: a zero-frequency motion, not a mode;
        # its start joint loses that spin (module docstring)
        self.attach_joints(first, pending, spin_free=not _between_spherical(chain, k))
        offset = lk.length_m - shape.last_length_m
        return _Body(last_body, p0 + r0[:, 0] * offset, r0, [])

    def chain(self, chain: ChainDesc) -> None:
        body = self.ground if chain.parent is None else self.chain_end[chain.parent]
        pending = _Pending([])
        frames = self.asm.chains[chain.name]
        for k, e in enumerate(chain.path):
            if isinstance(e, LinkDesc):
                body = self.link(chain, k, e, body, pending)
            elif e is chain.end_joint:
                self.close(chain, e, body, pending, frames.positions_m[k], frames.rotations[k])
            else:
                follows_joint = k > 0 and isinstance(chain.path[k - 1], JointDesc)
                if e.lump.mass_kg > 0 and (k == 0 or follows_joint) and body is not self.ground:
                    raise GeneralModelError(
                        f"joint {chain.name}.{e.name} carries a lump but follows another joint directly",
                        parameter=f"chains.{chain.name}.{e.name}.lump",
                        hint="put the lump on the link before it (end_lump) or on a joint that follows a link",
                    )
                if e.actuated and self.servo and e.type not in ("revolute", "prismatic"):
                    raise GeneralModelError(
                        f"actuated {e.type} joint {chain.name}.{e.name}: servos drive revolute or prismatic joints",
                        parameter=f"chains.{chain.name}.{e.name}.type",
                        hint="build it with motors='locked' (modal analysis), or actuate a revolute or prismatic joint",
                    )
                if (not e.actuated or self.servo) and e.type != "fixed":
                    pending.joints.append((f"{chain.name}_{e.name}", e, frames.positions_m[k], frames.rotations[k]))
        if pending.joints:
            raise GeneralModelError(
                f"chain {chain.name!r} ends on passive joints with nothing after them",
                parameter=f"chains.{chain.name}.path",
                hint="end the chain with a link",
            )
        self.chain_end[chain.name] = body

    def end_effector(self, carrier: _Body, p: np.ndarray, r: np.ndarray) -> _Body:
        ee = self.new_body(carrier, "end_effector", p, r)
        for placed in self.desc.end_effector.lumps:
            ee.add_lump(placed.lump, p + r @ np.array(placed.position_m))
        ee.body.add_site(name="end_effector_site", pos=[0, 0, 0], size=[0.004, 0, 0])
        ee.body.add_geom(
            name="end_effector_g",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[0.01, 0, 0],
            rgba=[0.3, 0.7, 0.3, 1.0],
            contype=0,
            conaffinity=0,
        )
        self.ee = ee
        return ee

    def close(
        self, chain: ChainDesc, j: JointDesc, body: _Body, pending: _Pending, p: np.ndarray, r: np.ndarray
    ) -> None:
        """The chain's end joint onto the end effector: the end effector itself on the first chain, a loop
        closure (connect, pin + weld, or weld) on every other one."""
        if pending.joints:
            raise GeneralModelError(
                f"chain {chain.name!r}: passive joints right before its end joint",
                parameter=f"chains.{chain.name}.path",
                hint="put a link between them",
            )
        pe, re = self.asm.ee_position_m, self.asm.ee_rotation
        name = f"{chain.name}_{j.name}"
        if self.ee is None and j.type != "revolute":
            ee = self.end_effector(body, pe, re)
            if j.type == "spherical":
                self.attach_joints(ee, _Pending([(name, j, p, r)]))
            return
        if j.type == "spherical":  # a point constraint: no pin body, so no pin mass on the end effector
            eq = self.spec.add_equality(
                name=f"loop_{name}", type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_BODY
            )
            eq.name1, eq.name2 = body.body.name, "end_effector"
            eq.data = np.concatenate([body.local(p), np.zeros(9)])
            eq.solimp = list(WELD_SOLIMP)
        elif j.type == "revolute":
            # every revolute closure on a pin of the same mass, the end effector's carrier too: a symmetric machine
            # stays symmetric
            pin = self.new_body(body, f"{name}_pin", p, r)
            pin.add_lump(j.lump_after, p)
            self.attach_joints(pin, _Pending([(name, j, p, r)]))
            if self.ee is None:
                self.end_effector(pin, pe, re)
            else:
                add_weld(self.spec, f"loop_{name}", pin.body.name, "end_effector")
        else:
            add_weld(self.spec, f"loop_{name}", body.body.name, "end_effector")

    def finish(self) -> None:
        """Each new body's inertia from its lumps; a jointed body without any gets :data:`MIN_BODY_MASS_KG`, a rigid
        one none (it moves with its parent)."""
        for b in self.inertial:
            if not b.parts and not b.jointed:
                continue
            parts = b.parts or [lump_part(LumpedMass(MIN_BODY_MASS_KG, (1e-9, 1e-9, 1e-9)), np.zeros(3))]
            set_inertial(b.body, parts)


def build_general(
    desc: Description,
    pose: TaskPose,
    options: ModelOptions | None = None,
    *,
    assembly: TaskAssembly | None = None,
    motors: str = "locked",
) -> BuiltModel:
    """Generate and compile the flexible manipulator ``desc`` assembled at the task pose ``pose``.

    ``motors``: ``"locked"`` (no joint at the actuated joints) or ``"servo"`` (position servos there; module
    docstring). The mobility check is made with them locked either way.

    Raises
    ------
    fpm_sim.architecture.UnreachableTaskPoseError
        No assembly in the working mode reaches the pose.
    fpm_sim.architecture.MobilityError
        The machine moves with its actuators locked.
    GeneralModelError
        A link model other than ``segments`` or ``rigid``, or shear springs on a non-rectangular section.
    """
    opts = options or ModelOptions()
    if motors not in MOTOR_MODES:
        raise GeneralModelError(
            "unknown motor model", parameter="motors", value=motors, hint=f"choose one of {', '.join(MOTOR_MODES)}"
        )
    if opts.link_model not in ("segments", "rigid"):
        raise GeneralModelError(
            f"link model {opts.link_model!r} is built for the 3RRR only so far",
            parameter="link_model",
            value=opts.link_model,
            hint="use 'segments' (or 'rigid') for a described architecture",
        )
    return _build(desc, pose, opts, assembly, motors)[0]


def _build(
    desc: Description, pose: TaskPose, opts: ModelOptions, assembly: TaskAssembly | None, motors: str = "locked"
) -> tuple[BuiltModel, dict[str, _LinkShape]]:
    asm = assembly if assembly is not None else solve_task_pose(desc, pose)
    check_mobility(desc, asm)
    b = _built_spec(desc, asm, opts, servo=motors == "servo")
    model = compile_model(b.spec, timestep_s=opts.timestep_s)
    built = BuiltModel(
        model=model,
        spec=b.spec,
        name="manipulator",
        links=b.links,
        dof_kinds=_dof_kinds(model, b.kinds),
        parameters={
            "config": desc.name,
            "architecture": "planar" if desc.planar else "spatial",
            "pose": asdict(pose),
            "options": asdict(opts),
            "timestep_s": float(model.opt.timestep),
            "nv": int(model.nv),
            "joint_coordinates": {
                c: {k: np.asarray(v).tolist() for k, v in f.coordinates.items()} for c, f in asm.chains.items()
            },
            "singularity_type1": asm.singularity_type1,
            "singularity_type2": asm.singularity_type2,
            **({"motors": "servo", "servos": desc.servos.to_dict(desc.provenance)} if motors == "servo" else {}),
        },
        **instrumentation(desc),
    )
    return built, b.shapes


def _built_spec(
    desc: Description,
    asm: TaskAssembly,
    opts: ModelOptions,
    shapes: dict[str, _LinkShape] | None = None,
    *,
    servo: bool = False,
) -> _Builder:
    b = _Builder(desc, asm, opts, shapes, servo=servo)
    for chain in desc.chains:
        b.chain(chain)
    if not b.frames_only:
        b.finish()
    return b


@dataclass
class Reposer:
    """The frames pass of a model :func:`build_reposable` built: :meth:`frames` gives what another pose sets in it."""

    desc: Description
    options: ModelOptions
    shapes: dict[str, _LinkShape]

    def frames(self, assembly: TaskAssembly) -> PoseFrames:
        """What the pose sets at ``assembly`` (:class:`PoseFrames`): the builder's own placements (one builder,
        nothing re-derived), without building a spec. No checks: ``assembly`` is a neighbour of the pose the model
        was built at."""
        return _built_spec(self.desc, assembly, self.options, self.shapes).recorded


def build_reposable(
    desc: Description, pose: TaskPose, options: ModelOptions, *, assembly: TaskAssembly | None = None
) -> tuple[BuiltModel, Reposer]:
    """:func:`build_general`, and the :class:`Reposer` that places the same model at other poses (what
    :class:`fpm_sim.batch.task_pose_model.TaskPoseModel` copies into the compiled model)."""
    built, shapes = _build(desc, pose, options, assembly)
    return built, Reposer(desc, options, shapes)


def instrumentation(desc: Description) -> dict[str, Any]:
    """The default accelerometer links, test point, end-effector site and plane of ``desc``'s models (the rule of the
    module docstring): a link carries an accelerometer when it is its chain's last flexible link; the test point is
    mid-span of the first of them along the link frame's z."""
    accel = tuple(
        f"{c.name}_{[lk for lk in c.links if lk.flexible][-1].name}"
        for c in desc.chains
        if any(lk.flexible for lk in c.links)
    )
    return {
        "end_effector_site": "end_effector_site",
        "accelerometer_links": accel,
        "test_point": (accel[0], 0.5, "z") if accel else None,
        "planar": desc.planar,
    }


def actuated_joint_names(desc: Description) -> list[tuple[str, str]]:
    """``(chain, joint)`` of every actuated joint, in the description's order (the servo joints' names are
    ``{chain}_{joint}``)."""
    return [(c.name, j.name) for c in desc.chains for j in c.joints if j.actuated]


def _between_spherical(chain: ChainDesc, k: int) -> bool:
    before = chain.path[k - 1] if k > 0 else None
    after = chain.path[k + 1] if k + 1 < len(chain.path) else None
    return all(isinstance(x, JointDesc) and x.type == "spherical" for x in (before, after))


def _dof_kinds(model: mujoco.MjModel, kinds: dict[str, str]) -> list[str]:
    out = ["free"] * model.nv
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        adr = int(model.jnt_dofadr[j])
        width = {int(mujoco.mjtJoint.mjJNT_BALL): 3, int(mujoco.mjtJoint.mjJNT_FREE): 6}.get(int(model.jnt_type[j]), 1)
        out[adr : adr + width] = [kinds.get(name, "passive")] * width
    return out
