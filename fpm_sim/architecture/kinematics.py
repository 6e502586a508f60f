"""Kinematics of any described manipulator: inverse and forward kinematics, closure, mobility, singularity.

**Unknowns.** Every moving joint's coordinates (chain by chain, path order; a revolute or prismatic joint has one,
a universal two, a spherical three: a rotation vector) and the end effector's coordinates that the task leaves
free (planar: of ``x, y, phi``; spatial: of ``x, y, z`` and a rotation vector).

**Closure.** A chain ending on the end effector through joint ``J`` at attachment point ``a`` must bring its end
frame ``(p, R)`` onto it: ``p = p_E + R_E a`` (three rows), and by ``J``'s type a revolute's axis ``R n = R_E n``
(the cross product: two independent rows), a fixed joint's frame ``R = R_E`` (nine rows, three independent), a
spherical nothing more. Rotation rows are scaled by the characteristic length (:func:`characteristic_length_m`).

**Inverse kinematics** solves the closures for the unknowns at the task coordinates by Gauss-Newton with
minimum-norm steps (a rod between two spherical joints keeps its spin at zero), from the working mode's start
(each branch interval's middle), then from seeded random starts; the first solution whose coordinates lie in every
working-mode interval is taken. A pose no start reaches is refused (:class:`UnreachableTaskPoseError`). Where every
chain's attachment point follows from the task coordinates and every chain has a closed form
(:mod:`fpm_sim.architecture.closed_forms`: the 3RRR's, the 3PRR's, the five-bar's and the serial arm's chains; a free
planar ``phi`` read from the chain the tool is fixed on), the closed forms' assembly is taken instead when it passes
the same closure tolerance, working-mode and upright tests; Newton decides everything else. What a description needs
at every pose (layouts, lengths, attachment points, the closed forms) is worked out once per description
(``_plan``).

**Mobility and singularity** come from the closure's Jacobian in consistent units (rotation columns times the
characteristic length ``ell``): with the actuated joints locked, the free end effector and the passive joints must
not move (type 2: ``[J_passive, J_ee]`` full column rank, less the idle spins of links between two spherical
joints); with the task coordinates held, the joints must not move (type 1: ``[J_joints, J_ee_free]``). Each
measure is the smallest kept singular value over the largest; 0 at a singularity.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import weakref
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from fpm_sim.architecture.closed_forms import ChainSolver, chain_solver
from fpm_sim.architecture.description import ChainDesc, Description, JointDesc, LinkDesc
from fpm_sim.errors import FpmSimError

__all__ = [
    "CLOSURE_TOL_M",
    "ChainFrames",
    "MobilityError",
    "TaskAssembly",
    "TaskPose",
    "UnreachableTaskPoseError",
    "actuated_coordinates",
    "check_mobility",
    "solve_task_pose",
    "task_unknowns",
]

CLOSURE_TOL_M = 1e-11
"""Inverse kinematics converges when every closure residual is below this (m; rotations times ``ell``)."""
RANK_RTOL = 1e-7
"""A singular value below ``RANK_RTOL`` times the largest counts as zero in the mobility count. Round-off puts
such values at ~1e-14 relative, and a structure's softest direction at 1e-3 or more (a pose that close to a
singularity is refused anyway), so the decision has seven orders of margin on either side."""
MAX_RANDOM_STARTS = 24


class UnreachableTaskPoseError(FpmSimError):
    """No assembly in the working mode reaches the task pose."""


class MobilityError(FpmSimError):
    """With the actuators locked the described machine is not a structure: it has degrees of freedom left."""


@dataclass(frozen=True)
class TaskPose:
    """Task coordinates of the end effector: metres and radians; those the architecture lacks stay 0."""

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    phi_rad: float = 0.0

    @classmethod
    def from_mm(cls, x_mm: float = 0.0, y_mm: float = 0.0, z_mm: float = 0.0, phi_rad: float = 0.0) -> TaskPose:
        return cls(x_mm * 1e-3, y_mm * 1e-3, z_mm * 1e-3, phi_rad)

    @classmethod
    def from_coordinates(cls, values: Mapping[str, float]) -> TaskPose:
        """The pose of ``{coordinate: value}`` (SI: m, rad; a description's check pose), those not given 0."""
        return cls(*(float(values.get(c, 0.0)) for c in ("x", "y", "z", "phi")))

    def value(self, coordinate: str) -> float:
        return float({"x": self.x_m, "y": self.y_m, "z": self.z_m, "phi": self.phi_rad}[coordinate])

    def label(self, task: tuple[str, ...] = ("x", "y", "z", "phi")) -> str:
        """``(x=.. mm, y=.. mm)``: the task coordinates ``task`` only."""
        parts = [f"{c}={self.value(c):.3f} rad" if c == "phi" else f"{c}={self.value(c) * 1e3:.1f} mm" for c in task]
        return "(" + ", ".join(parts) + ")"


@dataclass(frozen=True)
class ChainFrames:
    """One chain at an assembly: the frame (position m, rotation 3x3) before each path entry, and its end frame."""

    name: str
    positions_m: np.ndarray  # (len(path) + 1, 3)
    rotations: np.ndarray  # (len(path) + 1, 3, 3)
    coordinates: dict[str, np.ndarray]  # joint name -> its coordinates (rad, m, or a rotation vector)


@dataclass(frozen=True)
class TaskAssembly:
    """The machine assembled at a task pose: every chain's frames, the end effector's frame, and measures."""

    pose: TaskPose
    chains: dict[str, ChainFrames]
    ee_position_m: np.ndarray
    ee_rotation: np.ndarray
    closure_residual_m: float
    singularity_type1: float
    singularity_type2: float

    @property
    def singularity(self) -> float:
        return min(self.singularity_type1, self.singularity_type2)


# ---------------------------------------------------------------------------------------------------------------
# frames


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix about the unit ``axis`` by ``angle`` (rad): Rodrigues' ``c I + s [a]x + (1 - c) a a'``,
    written out (the inverse kinematics builds thousands per pose)."""
    x, y, z = float(axis[0]), float(axis[1]), float(axis[2])
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array(
        [
            [c + t * x * x, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, c + t * y * y, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, c + t * z * z],
        ]
    )


def rotvec_matrix(v: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (rad)."""
    angle = float(np.linalg.norm(v))
    if angle < 1e-15:
        return np.eye(3)
    return rotation(v / angle, angle)


def joint_motion(j: JointDesc, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint's displacement ``(translation, rotation)`` in the frame before it, at coordinates ``q``."""
    if j.type == "revolute":
        return np.zeros(3), rotation(np.array(j.axis), float(q[0]))
    if j.type == "prismatic":
        return np.array(j.axis) * float(q[0]), np.eye(3)
    if j.type == "universal":
        r1 = rotation(np.array(j.axis), float(q[0]))
        return np.zeros(3), r1 @ rotation(np.array(j.axis2), float(q[1]))
    if j.type == "spherical":
        return np.zeros(3), rotvec_matrix(q)
    return np.zeros(3), np.eye(3)


def chain_frames(chain: ChainDesc, q: dict[str, np.ndarray], base_p: np.ndarray, base_r: np.ndarray) -> ChainFrames:
    """Walk a chain's path from its base frame at the joint coordinates ``q`` (name -> coordinates)."""
    p = base_p + base_r @ np.array(chain.base_position_m)
    r = base_r @ np.array(chain.base_rotation)
    ps, rs = [p], [r]
    end = chain.end_joint
    for e in chain.path:
        if isinstance(e, LinkDesc):
            p = p + r[:, 0] * e.length_m
        elif e is end or e.type == "fixed":
            pass
        elif e.type == "revolute":  # no translation (adding r @ 0 changes nothing)
            r = r @ rotation(np.array(e.axis), float(q[e.name][0]))
        elif e.type == "prismatic":  # no rotation (r @ I is r)
            p = p + r @ (np.array(e.axis) * float(q[e.name][0]))
        else:
            dp, dr = joint_motion(e, q[e.name])
            p, r = p + r @ dp, r @ dr
        ps.append(p)
        rs.append(r)
    return ChainFrames(chain.name, np.array(ps), np.array(rs), dict(q))


# ---------------------------------------------------------------------------------------------------------------
# the unknowns


@dataclass(frozen=True)
class _Layout:
    """Where each joint's and end-effector coordinate sits in the unknown vector; per joint also its index in its
    chain's path and the chains it moves (its own and those on it)."""

    joints: list[tuple[str, JointDesc, slice]]  # (chain name, joint, slice)
    ee_free: list[str]  # end-effector coordinates that are unknowns
    ee_slice: slice
    size: int
    path_index: list[int] = dataclasses.field(default_factory=list)  # per joint: its index in its chain's path
    moves: list[set[str]] = dataclasses.field(default_factory=list)  # per joint: the chains it moves
    wrap: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, int))  # revolute/universal coordinates
    own: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0), bool))  # (closed chain, column)
    axes: np.ndarray | None = None  # (joint, 3) when every joint is revolute or prismatic (one column each)
    turns: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))  # per joint: 1 revolute, 0 prismatic


def _ee_coordinates(desc: Description) -> list[str]:
    return ["x", "y", "phi"] if desc.planar else ["x", "y", "z", "rx", "ry", "rz"]


def _layout(desc: Description, *, ee_free: list[str] | None = None) -> _Layout:
    joints, k = [], 0
    for c in desc.chains:
        for j in c.moving_joints:
            joints.append((c.name, j, slice(k, k + j.dof)))
            k += j.dof
    free = [c for c in _ee_coordinates(desc) if c not in desc.task] if ee_free is None else ee_free
    index = [next(i for i, e in enumerate(desc.chain(cn).path) if e is j) for cn, j, _ in joints]
    moves = [_descendants(desc, cn) for cn, _, _ in joints]
    wrap = np.array([i for _, j, s in joints if j.type in ("revolute", "universal") for i in range(s.start, s.stop)])
    closed = [c.name for c in desc.chains if c.end_joint is not None]
    own = np.zeros((len(closed), k + len(free)), bool)  # the joint's column moves the closed chain's end
    for (_, _, s), m in zip(joints, moves):
        own[[i for i, n in enumerate(closed) if n in m], s] = True
    simple = all(j.type in ("revolute", "prismatic") for _, j, _ in joints)
    axes = np.array([j.axis for _, j, _ in joints], float).reshape(-1, 3) if simple else None
    turns = np.array([j.type == "revolute" for _, j, _ in joints], float)
    size = k + len(free)
    return _Layout(joints, free, slice(k, size), size, index, moves, wrap.astype(int), own, axes, turns)


@dataclass(frozen=True)
class _Drives:
    """The singularity measures' columns of the layout with every end-effector coordinate free: the passive joints'
    (``passive``), each end-effector column's divisor (``ee_div``: ``ell_c`` for rotations), and per actuated joint
    ``(chain, path index, path index of the next joint or the chain's end, its axis or None when prismatic,
    columns)`` with the groups of actuated columns (index into the actuated ones) hanging from one base chain."""

    passive: list[int]
    ee_div: np.ndarray
    acts: list[tuple[str, int, int, np.ndarray | None, list[int]]]
    groups: list[list[int]]


def _drives(desc: Description) -> _Drives:
    full = _layout(desc, ee_free=_ee_coordinates(desc))
    ell_c = singularity_char_length_m(desc)
    acts, roots = [], []
    for (cn, j, s), k in zip(full.joints, full.path_index):
        if not j.actuated:
            continue
        path = desc.chain(cn).path
        nxt = next((i for i in range(k + 1, len(path)) if isinstance(path[i], JointDesc)), len(path))
        axis = None if j.type == "prismatic" else np.array(j.axis, float)
        acts.append((cn, k, nxt, axis, list(range(s.start, s.stop))))
        roots += [_root(desc, cn)] * (s.stop - s.start)
    return _Drives(
        [k for _, j, s in full.joints if not j.actuated for k in range(s.start, s.stop)],
        np.array([ell_c if c in ("phi", "rx", "ry", "rz") else 1.0 for c in full.ee_free]),
        acts,
        [[k for k, g in enumerate(roots) if g == root] for root in dict.fromkeys(roots)],
    )


@dataclass(frozen=True)
class _Plan:
    """What the kinematics of one description needs at every pose, worked out once (:func:`_plan`): its layouts
    (the task's, and one with every end-effector coordinate free), lengths, attachment points, reach bounds, the
    independent parts a given end-effector pose splits it into, and the chains' closed forms."""

    lay: _Layout
    full: _Layout
    ell: float
    attach: dict[str, np.ndarray]
    reach: list[tuple[int, ChainDesc, np.ndarray, float]]
    parts: list[tuple[Description, list[int]]] | None  # None: one solve of the whole
    closed: _ChainForms | None  # None: no closed form of the whole
    phi_from: str | None  # the chain whose end frame gives the free phi (with ``closed``: :func:`_phi_chain`)
    rods: bool  # a chain of one spherical joint and one link (aimed at its attachment point before Newton)
    span_m: float
    ends: _Ends
    ell_c: float
    drives: _Drives


_PLANS: dict[int, tuple[weakref.ref[Description], _Plan]] = {}
"""Plans by the description's ``id`` (checked against a weak reference: a dead description's id may be reused)."""


def _plan(desc: Description) -> _Plan:
    """``desc``'s :class:`_Plan`, made on first use (a description is not changed once built)."""
    hit = _PLANS.get(id(desc))
    if hit is not None and hit[0]() is desc:
        return hit[1]
    plan = _make_plan(desc)
    if len(_PLANS) > 256:
        _PLANS.clear()
    _PLANS[id(desc)] = (weakref.ref(desc), plan)
    return plan


def _make_plan(desc: Description) -> _Plan:
    lay = _layout(desc)
    roots = [c.name for c in desc.chains if c.parent is None]
    parts = None
    if not lay.ee_free and len(roots) > 1:  # the end effector's pose is all given: each base chain closes on its own
        where = {(cn, j.name): s for cn, j, s in lay.joints}
        parts = []
        for root in roots:
            part = dataclasses.replace(desc, chains=tuple(c for c in desc.chains if _root(desc, c.name) == root))
            slices = [where[cn, j.name] for cn, j, _ in _layout(part).joints]
            idx = [k for s in slices for k in range(s.start, s.stop)]
            parts.append((part, idx))
    return _Plan(
        lay,
        _layout(desc, ee_free=_ee_coordinates(desc)),
        characteristic_length_m(desc),
        {k: np.array(a, float) for k, a in desc.end_effector.attachments_m.items()},
        closure_reach(desc),
        parts,
        _closed_forms(desc, lay),
        _phi_chain(desc, lay),
        any(_is_rod(c) for c in desc.chains),
        sum(lk.length_m for c in desc.chains for lk in c.links),
        _ends(desc),
        singularity_char_length_m(desc),
        _drives(desc),
    )


_ChainForms = list[tuple[slice, ChainSolver, tuple[JointDesc, ...], str]]
"""Per chain: its coordinates' slice, closed-form solver, moving joints and attachment point's name."""


def _closed_forms(desc: Description, lay: _Layout) -> _ChainForms | None:
    """The closed forms (:mod:`fpm_sim.architecture.closed_forms`) of ``desc``'s chains, when each chain's
    attachment point follows from the task coordinates and every chain has one; else ``None``.

    The attachment points follow when the end effector's pose is all given, or when its only free coordinate is a
    planar machine's ``phi`` that turns no attachment point (each on the end effector's z axis) and that one chain
    fixed on the end effector gives (:func:`_phi_chain`: the five-bar's and the serial arm's tool). That ``phi`` is
    then read from the chain's end frame (:func:`_closed_form_assembly`): the tool upright on its link, never the
    fixed joint's spurious root half a turn away on which Newton may settle (its closure rows vanish there too)."""
    if lay.ee_free and _phi_chain(desc, lay) is None:
        return None
    out = []
    for c in desc.chains:
        solver, end = chain_solver(c), c.end_joint
        slices = [s for cn, _, s in lay.joints if cn == c.name]
        if solver is None or end is None or not slices:
            return None
        out.append((slice(slices[0].start, slices[-1].stop), solver, c.moving_joints, str(end.at)))
    return out


def _phi_chain(desc: Description, lay: _Layout) -> str | None:
    """The chain whose end frame gives a planar end effector's free ``phi`` (:func:`_closed_forms`): the only chain
    fixed on the end effector, when ``phi`` is the only free coordinate and no attachment point of a closed chain
    lies off the end effector's z axis (``phi`` then moves none); else ``None``."""
    if not desc.planar or lay.ee_free != ["phi"]:
        return None
    ends = [(c.name, c.end_joint) for c in desc.chains if c.end_joint is not None]
    fixed = [name for name, e in ends if e.type == "fixed"]
    attach = desc.end_effector.attachments_m
    if len(fixed) != 1 or any(math.hypot(*attach[str(e.at)][:2]) > 0.0 for _, e in ends):
        return None
    return fixed[0]


def _is_rod(chain: ChainDesc) -> bool:
    """A chain of one spherical moving joint and one link, closed on the end effector (:func:`_aimed`)."""
    moving = chain.moving_joints
    return len(moving) == 1 and moving[0].type == "spherical" and chain.end_joint is not None and len(chain.links) == 1


_Z_AXIS = np.array([0.0, 0.0, 1.0])


def _ee_frame(desc: Description, pose: TaskPose, free: list[str], zf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if desc.planar:
        vals = {"x": pose.x_m, "y": pose.y_m, "phi": pose.phi_rad}
        vals.update(zip(free, zf))
        return np.array([vals["x"], vals["y"], 0.0]), rotation(_Z_AXIS, vals["phi"])
    vals = {"x": pose.x_m, "y": pose.y_m, "z": pose.z_m, "rx": 0.0, "ry": 0.0, "rz": 0.0}
    vals.update(zip(free, zf))
    p = np.array([vals["x"], vals["y"], vals["z"]])
    return p, rotvec_matrix(np.array([vals["rx"], vals["ry"], vals["rz"]]))


def _frames(desc: Description, lay: _Layout, z: np.ndarray) -> dict[str, ChainFrames]:
    q: dict[str, dict[str, np.ndarray]] = {c.name: {} for c in desc.chains}
    for cname, j, s in lay.joints:
        q[cname][j.name] = z[s]
    out: dict[str, ChainFrames] = {}
    for c in desc.chains:
        if c.parent is None:
            bp, br = np.zeros(3), np.eye(3)
        else:
            bp, br = out[c.parent].positions_m[-1], out[c.parent].rotations[-1]
        out[c.name] = chain_frames(c, q[c.name], bp, br)
    return out


@dataclass(frozen=True)
class _Ends:
    """The closed chains (those ending on the end effector), for the closure rows of all of them at once: their
    names, attachment points (end effector's frame, m), which end on a revolute joint (``rev``, with its axis) or a
    fixed one (``fixed``), and ``order``: the stacked row blocks ``[positions, revolute rows, fixed rows]`` (three
    rows each) in chain order (each chain's position rows, then its rotation rows)."""

    names: list[str]
    attach: np.ndarray  # (m, 3)
    rev: np.ndarray  # indices into names
    rev_axis: np.ndarray  # (len(rev), 3)
    fixed: np.ndarray  # indices into names
    order: np.ndarray


def _ends(desc: Description) -> _Ends:
    closed = [(c, c.end_joint) for c in desc.chains if c.end_joint is not None]
    attach = desc.end_effector.attachments_m
    rev = [i for i, (_, e) in enumerate(closed) if e is not None and e.type == "revolute"]
    fixed = [i for i, (_, e) in enumerate(closed) if e is not None and e.type == "fixed"]
    order = []
    for i in range(len(closed)):
        order.append(i)
        if i in rev:
            order.append(len(closed) + rev.index(i))
        elif i in fixed:
            order.append(len(closed) + len(rev) + fixed.index(i))
    return _Ends(
        [c.name for c, _ in closed],
        np.array([attach[str(e.at)] for _, e in closed if e is not None], float).reshape(-1, 3),
        np.array(rev, int),
        np.array([closed[i][1].axis for i in rev if closed[i][1] is not None], float).reshape(-1, 3),
        np.array(fixed, int),
        np.array(order, int),
    )


def _end_frames(ends: _Ends, frames: dict[str, ChainFrames]) -> tuple[np.ndarray, np.ndarray]:
    """The closed chains' end positions ``(m, 3)`` and rotations ``(m, 3, 3)``."""
    return (
        np.array([frames[n].positions_m[-1] for n in ends.names]).reshape(-1, 3),
        np.array([frames[n].rotations[-1] for n in ends.names]).reshape(-1, 3, 3),
    )


def _vee(d: np.ndarray) -> np.ndarray:
    """Half the skew part of ``(..., 3, 3)`` matrices as vectors: a relative rotation's vector to first order
    (``d21 - d12, d02 - d20, d10 - d01``, halved)."""
    out: np.ndarray = 0.5 * (d[..., [2, 0, 1], [1, 2, 0]] - d[..., [1, 2, 0], [2, 0, 1]])
    return out


def _residual(
    desc: Description,
    lay: _Layout,
    pose: TaskPose,
    z: np.ndarray,
    ell: float,
    frames: dict[str, ChainFrames] | None = None,
) -> np.ndarray:
    """Every closed chain's closure residual (module docstring), chain by chain: its end frame ``(p, R)`` against
    its attachment point (three rows) and, by its end joint's type, the axes' cross product or the relative
    rotation (three rows each, times ``ell``). ``frames``: :func:`_frames` at ``z``, when already built."""
    ends = _plan(desc).ends
    frames = _frames(desc, lay, z) if frames is None else frames
    pe, re = _ee_frame(desc, pose, lay.ee_free, z[lay.ee_slice])
    p, r = _end_frames(ends, frames)
    blocks = [p - (pe + ends.attach @ re.T)]
    if ends.rev.size:
        blocks.append(ell * _cross((r[ends.rev] @ ends.rev_axis[:, :, None])[:, :, 0], ends.rev_axis @ re.T))
    if ends.fixed.size:  # the relative rotation's vector (its norm is the angle, to first order)
        blocks.append(ell * _vee(re.T @ r[ends.fixed]))
    out: np.ndarray = np.concatenate(blocks)[ends.order].ravel()
    return out


def characteristic_length_m(desc: Description) -> float:
    """The length that puts rotations and translations in one unit (m): :func:`singularity_char_length_m`."""
    return singularity_char_length_m(desc)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of 3-vectors, or row by row of ``(n, 3)`` arrays (``np.cross``'s axis handling costs ten times the
    product at these sizes; the inverse kinematics takes thousands per pose)."""
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    b1, b2, b3 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a2 * b3 - a3 * b2
    out[..., 1] = a3 * b1 - a1 * b3
    out[..., 2] = a1 * b2 - a2 * b1
    return out


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _right_jacobian(v: np.ndarray) -> np.ndarray:
    """SO(3)'s right Jacobian: ``exp(v + d) = exp(v) exp(J_r(v) d)`` to first order."""
    t = float(np.linalg.norm(v))
    k = _skew(v)
    if t < 1e-8:
        out: np.ndarray = np.eye(3) - 0.5 * k
        return out
    out = np.eye(3) - (1 - math.cos(t)) / t**2 * k + (t - math.sin(t)) / t**3 * (k @ k)
    return out


def _joint_twists(j: JointDesc, q: np.ndarray, r_before: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """World angular and linear velocity (about the joint's centre) per unit rate of each of the joint's
    coordinates."""
    zero = np.zeros(3)
    if j.type == "revolute":
        return [(r_before @ np.array(j.axis), zero)]
    if j.type == "prismatic":
        return [(zero, r_before @ np.array(j.axis))]
    if j.type == "universal":
        a1 = r_before @ np.array(j.axis)
        a2 = r_before @ rotation(np.array(j.axis), float(q[0])) @ np.array(j.axis2)
        return [(a1, zero), (a2, zero)]
    cols = r_before @ rotvec_matrix(q) @ _right_jacobian(q)
    return [(cols[:, i], zero) for i in range(3)]


def _rows_rate(
    desc: Description,
    frames: dict[str, ChainFrames],
    re: np.ndarray,
    cols: _Columns,
    ell: float,
) -> np.ndarray:
    """Rate of every closure row (rows) for each column's motion (columns): a joint's twist ``w``, ``v`` about its
    ``centre`` moving the ends of the closed chains downstream of it (``own``), or the end effector's (``ee``). All
    columns and all closed chains at once (arrays ``(chain, column, 3)``)."""
    ends = _plan(desc).ends
    p, r = _end_frames(ends, frames)
    own = cols.own[:, :, None]
    ee = cols.ee[:, None]
    w_c, w_e = cols.w[None] * own, (cols.w * ee)[None]
    dp = _cross(w_c, p[:, None, :] - cols.centre[None]) + cols.v[None] * own
    dpe = (cols.v + _cross(w_e, (ends.attach @ re.T)[:, None, :])) * ee[None]
    blocks = [dp - dpe]
    if ends.rev.size:
        n_c = (r[ends.rev] @ ends.rev_axis[:, :, None]).transpose(0, 2, 1)
        n_e = (ends.rev_axis @ re.T)[:, None, :]
        blocks.append(ell * (_cross(_cross(w_c[ends.rev], n_c), n_e) + _cross(n_c, _cross(w_e, n_e))))
    if ends.fixed.size:  # d/dt of R_E' R's vector: R_E' [u]x R with u the relative angular velocity
        u = w_c[ends.fixed] - w_e
        zero = np.zeros(u.shape[:2])
        skew = np.stack(
            [
                np.stack([zero, -u[..., 2], u[..., 1]], -1),
                np.stack([u[..., 2], zero, -u[..., 0]], -1),
                np.stack([-u[..., 1], u[..., 0], zero], -1),
            ],
            -2,
        )
        blocks.append(ell * _vee(np.einsum("ji,fnjk,fkl->fnil", re, skew, r[ends.fixed])))
    stacked = np.concatenate(blocks)[ends.order]  # (blocks, columns, 3)
    out: np.ndarray = stacked.transpose(0, 2, 1).reshape(-1, len(cols.w))
    return out


@dataclass
class _Columns:
    """The unknowns' motions, one row each: angular and linear velocity (world), the point the rotation is about,
    whether it moves the end effector (``ee``), and per closed chain whether it moves that chain's end (``own``:
    ``(chains, columns)``)."""

    w: np.ndarray
    v: np.ndarray
    centre: np.ndarray
    ee: np.ndarray
    own: np.ndarray


def _descendants(desc: Description, name: str) -> set[str]:
    out = {name}
    for c in desc.chains:
        if c.parent in out:
            out.add(c.name)
    return out


def _jacobian(
    desc: Description,
    lay: _Layout,
    pose: TaskPose,
    z: np.ndarray,
    ell: float,
    frames: dict[str, ChainFrames] | None = None,
) -> np.ndarray:
    """The closure residual's Jacobian over the unknowns, from the joints' twists (the geometric Jacobian; tested
    against central differences). ``frames``: :func:`_frames` at ``z``, when already built."""
    frames = _frames(desc, lay, z) if frames is None else frames
    pe, re = _ee_frame(desc, pose, lay.ee_free, z[lay.ee_slice])
    if lay.size == 0:
        return np.zeros((_residual(desc, lay, pose, z, ell, frames).size, 0))
    w, v, centre = _joint_columns(lay, z, frames)
    zf = z[lay.ee_slice]
    for c in lay.ee_free:
        we, ve = np.zeros(3), np.zeros(3)
        if c in ("x", "y", "z"):
            ve["xyz".index(c)] = 1.0
        elif c == "phi":
            we[2] = 1.0
        else:
            rv = np.array([dict(zip(lay.ee_free, zf)).get(k, 0.0) for k in ("rx", "ry", "rz")])
            we = re @ _right_jacobian(rv)[:, "xyz".index(c[1])]
        w, v, centre = [*w, we], [*v, ve], [*centre, pe]
    ee = np.zeros(lay.size)
    ee[lay.ee_slice] = 1.0
    cols = _Columns(np.vstack(w), np.vstack(v), np.vstack(centre), ee, lay.own)
    return _rows_rate(desc, frames, re, cols, ell)


def _joint_columns(
    lay: _Layout, z: np.ndarray, frames: dict[str, ChainFrames]
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """The joints' columns' angular and linear velocities (world) and centres (blocks of rows): all at once when
    every joint is revolute or prismatic (``lay.axes``), else joint by joint (:func:`_joint_twists`)."""
    at = [(frames[cn], k) for (cn, _, _), k in zip(lay.joints, lay.path_index)]
    centre = np.array([f.positions_m[k] for f, k in at]).reshape(-1, 3)
    if lay.axes is not None:
        axes = np.einsum("nij,nj->ni", np.array([f.rotations[k] for f, k in at]).reshape(-1, 3, 3), lay.axes)
        turns = lay.turns[:, None]
        return [axes * turns], [axes * (1.0 - turns)], [centre]
    w, v, c = [], [], []
    for (_, j, s), (f, k), p in zip(lay.joints, at, centre):
        for wj, vj in _joint_twists(j, z[s], f.rotations[k]):
            w.append(wj)
            v.append(vj)
            c.append(p)
    return [np.array(w).reshape(-1, 3)], [np.array(v).reshape(-1, 3)], [np.array(c).reshape(-1, 3)]


def _jacobian_fd(desc: Description, lay: _Layout, pose: TaskPose, z: np.ndarray, ell: float) -> np.ndarray:
    """Central differences of the residual (rows) over the unknowns (columns; rotations as they are)."""
    r0 = _residual(desc, lay, pose, z, ell)
    jac = np.empty((r0.size, z.size))
    h = 1e-7
    for k in range(z.size):
        dz = np.zeros(z.size)
        dz[k] = h
        jac[:, k] = (_residual(desc, lay, pose, z + dz, ell) - _residual(desc, lay, pose, z - dz, ell)) / (2 * h)
    return jac


def _lazy(make: Callable[[], list[np.ndarray]]) -> Iterator[np.ndarray]:
    yield from make()


def _in_branch(j: JointDesc, q: np.ndarray) -> bool:
    if j.branch is None:
        return True
    lo, hi = j.branch
    v = float(q[0])
    if j.type == "revolute":
        v = lo + (v - lo) % (2 * math.pi)
    return lo <= v <= hi


def _wrapped(lay: _Layout, z: np.ndarray) -> np.ndarray:
    """Revolute coordinates into (-pi, pi]; a branch interval keeps its own window."""
    z = z.copy()
    if lay.wrap.size:
        v = z[lay.wrap]
        v = np.where(v > math.pi, v - 2 * math.pi * np.floor((v + math.pi) / (2 * math.pi)), v)
        z[lay.wrap] = v - 2 * math.pi * np.floor((v + math.pi) / (2 * math.pi))
    return z


def _newton(desc: Description, lay: _Layout, pose: TaskPose, z: np.ndarray, ell: float) -> tuple[np.ndarray, float]:
    """Gauss-Newton with minimum-norm steps (the Jacobian's pseudo-inverse, lstsq's cut-off), each step capped at
    0.5 (rad or m); given up when ten steps have not halved the residual (a start that leads nowhere: the next one is
    tried). The pseudo-inverse is kept while each step cuts the residual at least fourfold (chord steps: from a
    neighbouring pose's solution, a sweep's usual start, one Jacobian serves the whole solve); the solution is the
    same, the residual is what is tested. Once converged, one more chord step (a residual's cost) takes the solution
    from the tolerance to round-off, as a full Newton step would."""
    res = float("inf")
    history: list[float] = []
    inverse: np.ndarray | None = None
    for _ in range(60):
        r = _residual(desc, lay, pose, z, ell)
        res = float(np.max(np.abs(r))) if r.size else 0.0
        history.append(res)
        if res < CLOSURE_TOL_M and inverse is not None:
            z_fine = z - inverse @ r
            r_fine = _residual(desc, lay, pose, z_fine, ell)
            res_fine = float(np.max(np.abs(r_fine)))
            return (z_fine, res_fine) if res_fine < res else (z, res)
        if res < CLOSURE_TOL_M or not np.isfinite(res) or (len(history) > 10 and res > 0.5 * history[-11]):
            break
        if inverse is None or res > 0.25 * history[-2]:
            jac = _jacobian(desc, lay, pose, z, ell)
            inverse = np.linalg.pinv(jac, rcond=np.finfo(float).eps * max(jac.shape))
        step = inverse @ r
        norm = float(np.max(np.abs(step)))
        z = z - step * (0.5 / norm if norm > 0.5 else 1.0)
    return z, res


def _starts(desc: Description, lay: _Layout, span_m: float) -> list[np.ndarray]:
    """The working mode's start (branch midpoints, zeros elsewhere), then seeded random starts."""
    first = np.zeros(lay.size)
    for _, j, s in lay.joints:
        if j.branch is not None:
            first[s.start] = 0.5 * (j.branch[0] + j.branch[1])
    starts = [first]
    rng = np.random.default_rng(0)
    for _ in range(MAX_RANDOM_STARTS):
        z = np.zeros(lay.size)
        for _, j, s in lay.joints:
            if j.branch is not None:
                z[s.start] = rng.uniform(*j.branch)
            elif j.type in ("revolute", "universal"):
                z[s] = rng.uniform(-math.pi, math.pi, s.stop - s.start)
            elif j.type == "prismatic":
                z[s] = rng.uniform(-span_m, span_m)
            else:
                z[s] = rng.normal(0.0, 0.5, 3)
        z[lay.ee_slice] = [
            rng.uniform(-math.pi, math.pi) if c in ("phi", "rx", "ry", "rz") else 0.0 for c in lay.ee_free
        ]
        starts.append(z)
    return starts


def _aimed(desc: Description, lay: _Layout, pose: TaskPose, z: np.ndarray) -> np.ndarray:
    """``z`` with every chain of one spherical joint and one link (a rod) pointed at its attachment point: a
    Delta's rods then start nearly closed."""
    z = z.copy()
    frames = _frames(desc, lay, z)
    pe, re = _ee_frame(desc, pose, lay.ee_free, z[lay.ee_slice])
    for cname, j, s in lay.joints:
        chain = desc.chain(cname)
        moving, end = chain.moving_joints, chain.end_joint
        if j.type != "spherical" or moving != (j,) or end is None or len(chain.links) != 1:
            continue
        k = chain.path.index(j)
        p0, r0 = frames[cname].positions_m[k], frames[cname].rotations[k]
        d = r0.T @ (pe + re @ _plan(desc).attach[str(end.at)] - p0)
        norm = float(np.linalg.norm(d))
        if norm == 0.0:
            continue
        d /= norm
        axis = _cross(np.array([1.0, 0.0, 0.0]), d)
        sin, cos = float(np.linalg.norm(axis)), float(d[0])
        z[s] = axis / sin * math.atan2(sin, cos) if sin > 1e-12 else np.zeros(3)
    return z


def solve_task_pose(desc: Description, pose: TaskPose, *, start: np.ndarray | None = None) -> TaskAssembly:
    """Assemble ``desc`` at ``pose`` in its working mode (module docstring).

    ``start``: the unknowns of a neighbouring pose (``TaskAssembly`` of a sweep) to try first.

    Where every chain has a closed form (:mod:`fpm_sim.architecture.closed_forms`), its assembly is taken when it
    passes the same closure tolerance and working-mode test as Newton's; otherwise Newton runs.

    Raises
    ------
    UnreachableTaskPoseError
        No start converges to an assembly inside every working-mode interval.
    """
    plan = _plan(desc)
    fast = _closed_form_assembly(desc, plan, pose)
    if fast is not None:  # an assembly closed to round-off: within every chain's reach
        return fast
    _check_reach(desc, pose)
    return _assembly(desc, plan.lay, pose, _general_unknowns(desc, plan, pose, start), plan.ell)


def _general_unknowns(desc: Description, plan: _Plan, pose: TaskPose, start: np.ndarray | None) -> np.ndarray:
    """The unknowns by Newton (:func:`_solve`): of the whole, or part by part when the end effector's pose is all
    given and several base chains carry it (each base chain, with the chains on it, closes on its own)."""
    if plan.parts is None:
        return _solve(desc, plan.lay, pose, start, plan.ell)
    z = np.zeros(plan.lay.size)
    for part, idx in plan.parts:
        z[idx] = _solve(part, _plan(part).lay, pose, None if start is None else np.asarray(start)[idx], plan.ell)
    return z


def _closed_form_assembly(desc: Description, plan: _Plan, pose: TaskPose) -> TaskAssembly | None:
    """The assembly from the chains' closed forms (:func:`_closed_forms`), or ``None`` (no closed form, no assembly
    or two inside the working-mode intervals, or a closure residual above :data:`CLOSURE_TOL_M` or a tool not
    upright: Newton decides). A free ``phi`` is the in-plane angle of the end frame of the chain fixed on the end
    effector (``plan.phi_from``): their relative rotation the identity."""
    if plan.closed is None:
        return None
    lay = plan.lay
    pe, re = _ee_frame(desc, pose, lay.ee_free, np.zeros(len(lay.ee_free)))  # phi turns no attachment point
    z = np.zeros(lay.size)
    for sl, solver, joints, at in plan.closed:
        target = pe + re @ plan.attach[at]
        fits = [q for q in solver(target) if all(_in_branch(j, q[k : k + 1]) for k, j in enumerate(joints))]
        if len(fits) != 1:
            return None
        z[sl] = fits[0]
    z = _wrapped(lay, z)
    frames = _frames(desc, lay, z)
    if plan.phi_from is not None:
        r_end = frames[plan.phi_from].rotations[-1]
        z[lay.ee_slice] = math.atan2(float(r_end[1, 0]), float(r_end[0, 0]))
    r = _residual(desc, lay, pose, z, plan.ell, frames)
    if r.size and not float(np.max(np.abs(r))) < CLOSURE_TOL_M:
        return None
    if plan.phi_from is not None and not _upright(desc, lay, pose, z, frames):
        return None
    return _assembly(desc, lay, pose, z, plan.ell, frames=frames, r=r)


def _solve(desc: Description, lay: _Layout, pose: TaskPose, start: np.ndarray | None, ell: float) -> np.ndarray:
    """Newton from ``start``, the working mode's start and the random ones: the first solution in every working-mode
    interval, wrapped."""
    plan = _plan(desc)
    starts = itertools.chain([start] if start is not None else [], _lazy(lambda: _starts(desc, lay, plan.span_m)))
    for z0 in starts:  # a neighbour's solution first; the working mode's and random starts only when it fails
        z0 = np.array(z0, float)
        z, res = _newton(desc, lay, pose, _aimed(desc, lay, pose, z0) if plan.rods else z0, ell)
        if res < CLOSURE_TOL_M and not _upright(desc, lay, pose, z) and "phi" in lay.ee_free:
            z, res = _newton(desc, lay, pose, _half_turned(lay, z), ell)  # the same closure, the end effector upright
        if res < CLOSURE_TOL_M and all(_in_branch(j, z[s]) for _, j, s in lay.joints) and _upright(desc, lay, pose, z):
            return _wrapped(lay, z)
    raise UnreachableTaskPoseError(
        f"no assembly of {desc.name!r} in its working mode reaches {pose.label(desc.task)}",
        parameter="pose",
        hint="choose a pose inside the workspace, or check the chains' lengths and working modes (branch_deg)",
    )


def _upright(
    desc: Description, lay: _Layout, pose: TaskPose, z: np.ndarray, frames: dict[str, ChainFrames] | None = None
) -> bool:
    """Every chain fixed to the end effector turned less than 90 deg against it. The closure's rotation rows (the
    skew part of the relative rotation) vanish at a half turn too, which is not an assembly: a tool turned by pi
    against the link it is fixed on. ``frames``: :func:`_frames` at ``z``, when already built."""
    ends = _plan(desc).ends
    if not ends.fixed.size:
        return True
    _, re = _ee_frame(desc, pose, lay.ee_free, z[lay.ee_slice])
    _, r = _end_frames(ends, _frames(desc, lay, z) if frames is None else frames)
    rel = re.T @ r[ends.fixed]
    return bool(np.all(np.trace(rel, axis1=-2, axis2=-1) > 1.0))


def _half_turned(lay: _Layout, z: np.ndarray) -> np.ndarray:
    """``z`` with the end effector's free in-plane rotation turned by pi."""
    z = z.copy()
    k = lay.ee_free.index("phi")
    z[lay.ee_slice.start + k] += math.pi
    return z


def closure_reach(desc: Description) -> list[tuple[int, ChainDesc, np.ndarray, float]]:
    """For each closed chain of revolute, universal and spherical joints: ``(index, chain, root base (m), reach (m))``
    where reach bounds the distance from its root chain's base to its attachment point: every link and every base
    offset along the chain and its ancestors (chains with prismatic joints are left out)."""
    out = []
    for i, c in enumerate(desc.chains):
        end = c.end_joint
        line = [c]
        while line[-1].parent is not None:
            line.append(desc.chain(str(line[-1].parent)))
        if end is None or any(j.type == "prismatic" for ch in line for j in ch.joints):
            continue
        reach = sum(lk.length_m for ch in line for lk in ch.links)
        reach += sum(float(np.linalg.norm(ch.base_position_m)) for ch in line[:-1])
        out.append((i, c, np.array(line[-1].base_position_m), reach))
    return out


def _check_reach(desc: Description, pose: TaskPose) -> None:
    """Refuse a pose beyond a chain's reach (:func:`closure_reach`), naming the chain, before any Newton step."""
    plan = _plan(desc)
    pe, re = _ee_frame(desc, pose, [c for c in ("x", "y", "phi") if c not in desc.task], np.zeros(3))
    for i, chain, base, reach in plan.reach:
        at = str(chain.end_joint.at) if chain.end_joint is not None else ""
        a = plan.attach[at]
        if desc.planar:
            target = pe + (re @ a if "phi" in desc.task else np.zeros(3))
            slack = 0.0 if "phi" in desc.task else float(np.linalg.norm(a))
        else:
            target, slack = np.array([pose.x_m, pose.y_m, pose.z_m]), float(np.linalg.norm(a))
        dist = float(np.linalg.norm(target - base)) - slack
        if dist > reach * (1 + 1e-12):
            raise UnreachableTaskPoseError(
                f"chain {chain.name!r} cannot reach its attachment point {at!r} at {pose.label(desc.task)}: "
                f"{dist * 1e3:.1f} mm away, its links span at most {reach * 1e3:.1f} mm",
                parameter=f"chains[{i}]",
                hint="choose a pose inside the workspace, or check the chain's base and link lengths",
            )


def _assembly(
    desc: Description,
    lay: _Layout,
    pose: TaskPose,
    z: np.ndarray,
    ell: float,
    *,
    frames: dict[str, ChainFrames] | None = None,
    r: np.ndarray | None = None,
) -> TaskAssembly:
    """The assembly at the unknowns ``z`` (``frames`` and the residual ``r`` at ``z``, when already built)."""
    frames = _frames(desc, lay, z) if frames is None else frames
    pe, re = _ee_frame(desc, pose, lay.ee_free, z[lay.ee_slice])
    r = _residual(desc, lay, pose, z, ell, frames) if r is None else r
    t1, t2 = singularity_measures(desc, lay, pose, z, ell, frames)
    return TaskAssembly(pose, frames, pe, re, float(np.max(np.abs(r))) if r.size else 0.0, t1, t2)


def idle_motions(desc: Description) -> int:
    """Motions that move no mass centre off its line: the spin of each link between two spherical joints."""
    count = 0
    for c in desc.chains:
        for k, e in enumerate(c.path):
            if isinstance(e, LinkDesc) and 0 < k < len(c.path) - 1:
                before, after = c.path[k - 1], c.path[k + 1]
                if all(isinstance(x, JointDesc) and x.type == "spherical" for x in (before, after)):
                    count += 1
    return count


def _scaled_columns(lay: _Layout, jac: np.ndarray, ell: float) -> np.ndarray:
    """Rotation columns over ``ell``: every column in metres of residual per metre of motion."""
    out = jac.copy()
    for _, j, s in lay.joints:
        if j.type != "prismatic":
            out[:, s] /= ell
    for k, c in enumerate(lay.ee_free):
        if c in ("phi", "rx", "ry", "rz"):
            out[:, lay.ee_slice.start + k] /= ell
    return out


def singularity_char_length_m(desc: Description) -> float:
    """The length that weighs the end effector's rotations against its translations in the type-2 measure (m): the
    largest attachment radius or a quarter of the closing links' mean length, whichever is larger (the 3RRR's
    ``max(r_p, L2 / 4)``)."""
    radius = max(float(np.linalg.norm(a[:2] if desc.planar else a)) for a in desc.end_effector.attachments_m.values())
    last = [c.links[-1].length_m for c in desc.chains if c.end_joint is not None and c.links]
    return max(radius, float(np.mean(last)) / 4.0 if last else 0.0)


def _basis(b: np.ndarray) -> np.ndarray:
    """An orthonormal basis (columns) of the column space of ``b`` (rank at :data:`RANK_RTOL`)."""
    if b.size == 0:
        return np.zeros((b.shape[0], 0))
    u, sv, _ = np.linalg.svd(b, full_matrices=False)
    keep = sv > RANK_RTOL * sv[0] if sv.size and sv[0] > 0 else np.zeros(0, bool)
    out: np.ndarray = u[:, keep]
    return out


def _root(desc: Description, name: str) -> str:
    chain = desc.chain(name)
    return name if chain.parent is None else _root(desc, chain.parent)


def _lever(frames: ChainFrames, k: int, nxt: int, axis: np.ndarray | None) -> float:
    """How far the next joint (path index ``nxt``, or the chain's end) moves per unit of the actuated joint at path
    index ``k`` (m per rad or m per m): the lever of a revolute actuator (``axis``), 1 for a prismatic one
    (``None``)."""
    if axis is None:
        return 1.0
    a1, a2, a3 = (frames.rotations[k] @ axis).tolist()
    d1, d2, d3 = (frames.positions_m[nxt] - frames.positions_m[k]).tolist()
    lever = math.sqrt((a2 * d3 - a3 * d2) ** 2 + (a3 * d1 - a1 * d3) ** 2 + (a1 * d2 - a2 * d1) ** 2)
    return lever if lever > 0 else 1.0


def singularity_measures(
    desc: Description,
    lay: _Layout,
    pose: TaskPose,
    z: np.ndarray,
    ell: float,
    frames: dict[str, ChainFrames] | None = None,
) -> tuple[float, float]:
    """Type 1 and type 2 singularity measures (0 at a singularity; the 3RRR's serial and parallel measures).

    Type 2: with the actuators locked, the closures' Jacobian over the end effector's coordinates (rotations over
    :func:`singularity_char_length_m`) with every passive joint's effect projected out; its smallest singular value
    over its largest. Type 1: for each group of chains hanging from one base chain, the Jacobian over its actuated
    joints (each over its lever, :func:`_lever`) with the passive joints' and the free end-effector
    coordinates' effects projected out; ``sqrt(det(C' C))``, the smallest over the groups (``|sin|`` of a 3RRR's
    elbow angle). ``frames``: :func:`_frames` at ``z``, when already built (the end effector's coordinates do not
    move the chains).
    """
    plan = _plan(desc)
    full = plan.full
    zf = np.concatenate([z[: lay.ee_slice.start], _full_ee(desc, lay, pose, z)])
    frames = _frames(desc, full, zf) if frames is None else frames
    jac = _jacobian(desc, full, pose, zf, ell, frames)
    if jac.size == 0:
        return 1.0, 1.0
    n_ee = full.ee_slice.stop - full.ee_slice.start
    jx = jac[:, full.ee_slice] / plan.drives.ee_div
    basis = _basis(jac[:, plan.drives.passive])
    sv = np.linalg.svd(jx - basis @ (basis.T @ jx), compute_uv=False)
    type2 = float(sv[n_ee - 1] / sv[0]) if sv.size >= n_ee and sv[0] > 0 else 0.0
    return _type1(plan, jac, lay, frames, basis), type2


def _type1(plan: _Plan, jac: np.ndarray, lay: _Layout, frames: dict[str, ChainFrames], basis: np.ndarray) -> float:
    """Type 1 (module docstring): ``C`` = the actuated joints' columns (each over its lever) with the passive joints'
    and the free end-effector coordinates' columns projected out; per group of chains hanging from one base chain,
    ``sqrt(det(C_g' C_g))``; the smallest. ``basis``: :func:`_basis` of the passive joints' columns (used as it is
    when no end-effector coordinate is free)."""
    full, drives = plan.full, plan.drives
    if not drives.acts:
        return 1.0
    free = [full.ee_slice.start + k for k, c in enumerate(full.ee_free) if c in lay.ee_free]
    cols: list[int] = []
    levers: list[float] = []
    for cn, k, nxt, axis, cs in drives.acts:
        cols += cs
        levers += [_lever(frames[cn], k, nxt, axis)] * len(cs)
    if free:
        basis = _basis(jac[:, drives.passive + free])
    m = jac[:, cols] / np.array(levers)
    c = m - basis @ (basis.T @ m)
    worst = 1.0
    for g in drives.groups:
        cg = c[:, g]
        gram = float(cg[:, 0] @ cg[:, 0]) if len(g) == 1 else float(np.linalg.det(cg.T @ cg))  # det of 1x1: itself
        worst = min(worst, math.sqrt(max(gram, 0.0)))
    return worst


def _full_ee(desc: Description, lay: _Layout, pose: TaskPose, z: np.ndarray) -> np.ndarray:
    """All end-effector coordinates (task ones from the pose, free ones from ``z``)."""
    vals = dict(zip(lay.ee_free, z[lay.ee_slice]))
    return np.array([vals.get(c, pose.value(c) if c in ("x", "y", "z", "phi") else 0.0) for c in _ee_coordinates(desc)])


def check_mobility(desc: Description, assembly: TaskAssembly) -> None:
    """Refuse a machine that moves with its actuators locked (:class:`MobilityError`), naming how many degrees of
    freedom it keeps. Counted from the closure Jacobian's rank at the assembly (:data:`RANK_RTOL`)."""
    full = _plan(desc).full
    z = _unknowns_of(desc, full, assembly)
    ell = characteristic_length_m(desc)
    jac = _scaled_columns(full, _jacobian(desc, full, assembly.pose, z, ell), ell)
    passive = [k for _, j, s in full.joints if not j.actuated for k in range(s.start, s.stop)]
    cols = jac[:, passive + list(range(full.ee_slice.start, full.ee_slice.stop))]
    s = np.linalg.svd(cols, compute_uv=False) if cols.size else np.zeros(0)
    rank = int(np.sum(s > RANK_RTOL * s[0])) if s.size and s[0] > 0 else 0
    left = cols.shape[1] - rank - idle_motions(desc)
    if left > 0:
        raise MobilityError(
            f"with its actuators locked, {desc.name!r} keeps {left} degree(s) of freedom at "
            f"{assembly.pose.label(desc.task)}: "
            "it is a mechanism, not a structure, and has no modes there",
            parameter="chains",
            hint="mark more joints actuated = true, or check the joint types (a locked machine needs as many "
            "actuators as degrees of freedom)",
        )


def task_unknowns(desc: Description, assembly: TaskAssembly) -> np.ndarray:
    """The unknowns of :func:`solve_task_pose` at ``assembly``: its ``start`` for a neighbouring pose (a sweep's
    continuation)."""
    return _unknowns_of(desc, _plan(desc).lay, assembly)


def actuated_coordinates(desc: Description, asm: TaskAssembly) -> np.ndarray:
    """The actuated joints' coordinates at ``asm`` (rad or m), in the description's order (one per joint: revolute
    or prismatic)."""
    return np.array(
        [float(asm.chains[c.name].coordinates[j.name][0]) for c in desc.chains for j in c.joints if j.actuated]
    )


def _unknowns_of(desc: Description, full: _Layout, asm: TaskAssembly) -> np.ndarray:
    z = np.zeros(full.size)
    for cname, j, s in full.joints:
        z[s] = asm.chains[cname].coordinates[j.name]
    ee = {"x": asm.ee_position_m[0], "y": asm.ee_position_m[1]}
    if desc.planar:
        ee["phi"] = math.atan2(asm.ee_rotation[1, 0], asm.ee_rotation[0, 0])
    else:
        ee["z"] = asm.ee_position_m[2]
        ee.update(zip(("rx", "ry", "rz"), _rotvec(asm.ee_rotation)))
    z[full.ee_slice] = [ee[c] for c in full.ee_free]
    return z


def _rotvec(r: np.ndarray) -> np.ndarray:
    angle = math.acos(max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0)))
    if angle < 1e-12:
        return np.zeros(3)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2 * math.sin(angle))
    return w * angle
