"""Fast first natural frequencies of the manipulator over many poses (the pose loop of reproduce/sweep).

The full analysis (:func:`fpm_sim.linear.analysis.manipulator_modes`: 12 segments per link, axial springs,
gravity equilibrium, ``mjd_transitionFD``) costs seconds per pose. Here each pose is solved by the
constrained eigenproblem at the assembled configuration with gravity off:

``M`` from ``mj_fullM`` at ``qpos0``, ``K = diag(joint spring stiffness)``, the weld Jacobian ``J``
from the position stage; ``Z = null(J)``, ``Z'KZ x = w^2 Z'MZ x``
(:func:`fpm_sim.linear.solvers.reduced_eigenproblem`).

The model is compiled once per structure and configuration (:class:`PoseModel`) and re-posed in place
for every pose: nine body orientations and the welds' relative poses, set as the compiler sets them, so
the result equals a per-pose compile bit for bit (``recompile=True`` of :func:`solve_poses`, tested) at a
fraction of the cost (compiling was 70-80 % of the per-pose time). Chunks of poses run on the engine
(:mod:`fpm_sim.batch.engine`: Dask, streamed to disk, resumable).

This is exact for the linear model without prestress (straight, unstressed links at ``qpos0``); what
it leaves out is the geometric stiffness of gravity's prestress, a small effect for motor axes along
gravity (measured in ``docs/benchmarks.md`` and ``tests/batch/test_fast_frequencies.py`` against the full
analysis). Coarser links (default :data:`FAST_SEGMENTS`) cost a discretisation error that scales as
``1/n^2`` and is also measured there.

:func:`fpm_sim.batch.frequencies.first_frequencies` is the replaceable pose loop: ``backend="cpu"`` is
:func:`cpu_backend`; another backend registers itself with
:func:`fpm_sim.batch.frequencies.register_backend` and receives the same arguments.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from fpm_sim.batch.engine import EngineOptions, chunk_size, run_chunks, split
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError, FpmSimWarning, read_text_input
from fpm_sim.kinematics import (
    NEAR_SINGULAR_WARN,
    SINGULAR_TOL,
    Assembly,
    Pose,
    PoseValueError,
    assemble_many,
    checked_pose_mm,
)
from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.linear.matrices import mass_matrix
from fpm_sim.linear.nullspace import NULLSPACE_RCOND, scaled_null_space, unit_scales
from fpm_sim.linear.solvers import reduced_eigenproblem
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions, resolve_segments
from fpm_sim.model.passive import dof_stiffness
from fpm_sim.model.spec import BuiltModel

__all__ = [
    "FAST_SEGMENTS",
    "IN_PLANE_DOF_KINDS",
    "IN_PLANE_KINDS",
    "REPOSABLE_LINK_MODELS",
    "PlaneSplit",
    "PoseFrequencies",
    "PoseModel",
    "PosesFileError",
    "assemble_pose",
    "cpu_backend",
    "fast_options",
    "merge",
    "plane_blocks",
    "pose_assembly",
    "pose_model",
    "read_poses_csv",
    "reset_equality_frames",
    "solve_configs",
    "solve_poses",
]

FAST_SEGMENTS = resolve_segments()
"""Spring locations per link of the pose loop: the shared default (:data:`fpm_sim.model.options.DEFAULT_FIDELITY`),
so that a sweep and ``modes`` agree at a pose."""

IN_PLANE_KINDS = ("bend_in", "axial", "motor", "clamp")
"""Spring kinds whose strain energy counts as in-plane (the rest: bend_out, twist, tilt)."""

STATUS_OK = "ok"
STATUS_NEAR = "near_singular"
STATUS_SINGULAR = "singular"
STATUS_UNREACHABLE = "unreachable"


@dataclass
class PoseFrequencies:
    """Lowest natural frequencies at many poses.

    Attributes
    ----------
    poses
        The poses, in order.
    frequencies_hz
        ``(n_poses, n_modes)``; NaN where the pose is unreachable or singular.
    in_plane
        ``(n_poses, n_modes)`` fraction of each mode's strain energy in in-plane springs
        (:data:`IN_PLANE_KINDS`); NaN where not computed.
    singularity
        Singularity measure of each pose (0 singular .. 1; NaN if unreachable).
    status
        ``ok``, ``near_singular`` (computed, measure below ``NEAR_SINGULAR_WARN``), ``singular`` or
        ``unreachable`` (not computed).
    """

    poses: list[Pose]
    frequencies_hz: np.ndarray
    in_plane: np.ndarray
    singularity: np.ndarray
    status: list[str] = field(default_factory=list)

    @property
    def f1_hz(self) -> np.ndarray:
        return self.frequencies_hz[:, 0]

    def to_xarray(self) -> Any:
        """:func:`fpm_sim.results.frequencies_dataset` (``freq_hz`` over ``pose`` x ``mode``) with
        ``in_plane`` (pose, mode) and ``singularity`` (pose)."""
        from fpm_sim.results import frequencies_dataset

        return frequencies_dataset(
            self.frequencies_hz,
            x_mm=[p.x_m * 1e3 for p in self.poses],
            y_mm=[p.y_m * 1e3 for p in self.poses],
            phi_rad=[p.phi_rad for p in self.poses],
            status=self.status,
            data_vars={"in_plane": (("pose", "mode"), self.in_plane), "singularity": ("pose", self.singularity)},
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: one row per pose (x, y mm; phi rad; status; singularity; f1.. Hz, NaN as ``"nan"``)."""
        from fpm_sim.results import to_jsonable

        rows = []
        for i, p in enumerate(self.poses):
            row: dict[str, Any] = {
                "x_mm": p.x_m * 1e3,
                "y_mm": p.y_m * 1e3,
                "phi_rad": p.phi_rad,
                "status": self.status[i] if i < len(self.status) else None,
                "singularity": self.singularity[i],
            }
            row.update({f"f{k + 1}_hz": v for k, v in enumerate(self.frequencies_hz[i])})
            rows.append(row)
        return {"n_poses": len(self.poses), "n_modes": int(self.frequencies_hz.shape[1]), "poses": to_jsonable(rows)}

    def table(self) -> str:
        """One line per pose: x, y (mm), phi (rad), status and the frequencies (Hz)."""
        n = self.frequencies_hz.shape[1]
        head = "".join(f"{f'f{k + 1} Hz':>10}" for k in range(n))
        lines = [f"{'x mm':>8} {'y mm':>8} {'phi':>6}  {'status':<13}" + head]
        for i, p in enumerate(self.poses):
            st = self.status[i] if i < len(self.status) else "-"
            lines.append(
                f"{p.x_m * 1e3:>8.1f} {p.y_m * 1e3:>8.1f} {p.phi_rad:>6.3f}  {st:<13}"
                + "".join(f"{v:>10.3f}" for v in self.frequencies_hz[i])
            )
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """First frequency (Hz) at each pose over x-y, unreachable/singular poses marked; returns the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(6, 5), constrained_layout=True)
        x = np.array([p.x_m * 1e3 for p in self.poses])
        y = np.array([p.y_m * 1e3 for p in self.poses])
        ok = np.isfinite(self.f1_hz)
        sc = ax.scatter(x[ok], y[ok], c=self.f1_hz[ok], s=80, cmap="viridis")
        if ok.any():
            ax.figure.colorbar(sc, ax=ax, label="first natural frequency (Hz)")
        if (~ok).any():
            ax.scatter(x[~ok], y[~ok], marker="x", color="0.5", label="not computed (unreachable or singular)")
            ax.legend(fontsize=7)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
        ax.set_title(f"first natural frequency at {len(self.poses)} poses ({int(ok.sum())} computed)", fontsize=9)
        return ax.figure


def fast_options(*, segments: int = FAST_SEGMENTS, axial: bool = False) -> ModelOptions:
    """Model options of the fast path: gravity off, ``segments`` per link, inextensible by default."""
    return ModelOptions(segments=segments, axial=axial, gravity=False)


def _status(singularity: float, reachable: bool) -> str:
    if not reachable:
        return STATUS_UNREACHABLE
    if singularity < SINGULAR_TOL:
        return STATUS_SINGULAR
    return STATUS_NEAR if singularity < NEAR_SINGULAR_WARN else STATUS_OK


def pose_assembly(config: Manipulator, pose: Pose) -> tuple[Assembly | None, float, str]:
    """``(assembly or None, singularity measure, status)`` of one pose (no model built).

    Unreachable and singular poses get no assembly (status :data:`STATUS_UNREACHABLE` /
    :data:`STATUS_SINGULAR`); near-singular ones are assembled and marked :data:`STATUS_NEAR`.
    """
    many = assemble_many(config.geometry, pose.x_m, pose.y_m, pose.phi_rad)
    singularity, status = float(many.singularity[0]), _status(float(many.singularity[0]), bool(many.reachable[0]))
    if status in (STATUS_UNREACHABLE, STATUS_SINGULAR):
        return None, singularity, status
    return many.assembly(0, pose), singularity, status


def assemble_pose(config: Manipulator, pose: Pose, options: ModelOptions) -> tuple[BuiltModel | None, float, str]:
    """``(built model or None, singularity measure, status)`` of one pose, for any backend.

    Compiles one model for the pose (:func:`fpm_sim.model.manipulator.build_manipulator`); see
    :func:`pose_assembly` for the statuses.
    """
    asm, singularity, status = pose_assembly(config, pose)
    if asm is None:
        return None, singularity, status
    return build_manipulator(config, pose, options, assembly=asm), singularity, status


def _pose_angles(asm: Assembly) -> list[tuple[str, float]]:
    """``(body name, rotation about z)`` of every body whose frame depends on the pose.

    The builder (:func:`fpm_sim.model.manipulator.build_manipulator`) places link ``proximal_i`` at the
    motor point ``A_i`` (fixed) turned by the proximal angle, ``distal_i`` at the proximal link's end turned
    by the elbow angle, and ``pin_i`` turned by ``phi - distal angle``; every other body sits at a fixed
    offset in its parent's frame (``tests/batch/test_fast_frequencies.py`` checks this against a per-pose
    compile).
    """
    out = []
    for i in range(3):
        a, b, c = asm.a[i], asm.b[i], asm.c[i]
        ang_p = math.atan2(*(b - a)[::-1])
        ang_d = math.atan2(*(c - b)[::-1])
        out += [(f"proximal_{i}_b0", ang_p), (f"distal_{i}_b0", ang_d - ang_p), (f"pin_{i}", asm.pose.phi_rad - ang_d)]
    return out


def reset_equality_frames(m: mujoco.MjModel, d: mujoco.MjData, equalities: Sequence[int] | np.ndarray) -> None:
    """After a re-pose of ``m``'s bodies: the kinematics at ``qpos0`` into ``d``, and the equalities' frames that
    the compiler takes from the bodies at ``qpos0``, recomputed with ``mj_setConst``'s operations: a weld's relative
    pose of body 2 in body 1 (``eq_data[3:10]``; its anchor on body 2 at the origin, as ``spec.add_weld`` builds it),
    a connect's anchor in body 2's frame (``eq_data[3:6]``) from its anchor in body 1's (``eq_data[0:3]``)."""
    d.qpos[:] = m.qpos0
    mujoco.mj_kinematics(m, d)
    inv = np.zeros(4)
    for e in equalities:
        b1, b2 = m.eq_obj1id[e], m.eq_obj2id[e]
        if m.eq_type[e] == mujoco.mjtEq.mjEQ_WELD:
            mujoco.mju_mulMatTVec3(m.eq_data[e, 3:6], d.xmat[b1], d.xpos[b2] - d.xpos[b1])
            mujoco.mju_negQuat(inv, d.xquat[b1])
            mujoco.mju_mulQuat(m.eq_data[e, 6:10], inv, d.xquat[b2])
        elif m.eq_type[e] == mujoco.mjtEq.mjEQ_CONNECT:
            world = d.xpos[b1] + d.xmat[b1].reshape(3, 3) @ m.eq_data[e, 0:3]
            mujoco.mju_mulMatTVec3(m.eq_data[e, 3:6], d.xmat[b2], world - d.xpos[b2])


class PoseModel:
    """One compiled manipulator model, re-posed in place for every pose (no recompile per pose).

    The topology, masses, inertias and spring stiffnesses do not depend on the pose: only nine body
    orientations do (:func:`_pose_angles`), and the welds' relative poses, which the compiler takes from
    the bodies at ``qpos0``. The model is compiled once, at ``reference`` (an assembled pose of the same
    configuration); :meth:`solve` sets the orientations, recomputes the weld relative poses as the
    compiler does, runs the position stage (``mj_fwdPosition``: kinematics, mass matrix, constraint
    Jacobian) and solves the constrained eigenproblem (:func:`fpm_sim.linear.solvers.reduced_eigenproblem`).

    Parameters
    ----------
    config
        The manipulator.
    options
        Discretisation; ``link_model="segments"`` or ``"rigid"`` (the chain models).
    reference
        An assembled pose of ``config`` to compile at.
    """

    def __init__(self, config: Manipulator, options: ModelOptions, reference: Assembly) -> None:
        if options.link_model not in REPOSABLE_LINK_MODELS:
            raise ValueError(f"PoseModel needs link_model 'segments' or 'rigid', got {options.link_model!r}")
        self.built = build_manipulator(config, reference.pose, options, assembly=reference)
        self.model = self.built.model
        self.data = mujoco.MjData(self.model)
        self.stiffness = dof_stiffness(self.model)
        self.in_plane = np.array([kind in IN_PLANE_DOF_KINDS for kind in self.built.dof_kinds])
        self.split = PlaneSplit(self.in_plane, self.stiffness)
        bid = self.model.body
        self._body_ids = [bid(name).id for name, _ in _pose_angles(reference)]
        weld = self.model.eq_type == mujoco.mjtEq.mjEQ_WELD
        self._welds = np.where(weld)[0]
        self.scales: tuple[np.ndarray, np.ndarray] | None = None

    def set_pose(self, asm: Assembly) -> None:
        """Re-pose the model at ``asm``: body orientations, then the welds' relative poses at ``qpos0``."""
        m, d = self.model, self.data
        for body, (_, ang) in zip(self._body_ids, _pose_angles(asm)):
            m.body_quat[body] = (math.cos(ang / 2.0), 0.0, 0.0, math.sin(ang / 2.0))
        reset_equality_frames(m, d, self._welds)

    def solve(self, asm: Assembly, n_modes: int) -> tuple[np.ndarray, np.ndarray, bool]:
        """``(frequencies_hz, in_plane, deficient)`` of the lowest ``n_modes`` modes at ``asm`` (see
        :meth:`PlaneSplit.modes`)."""
        freq, frac, deficient, _ = self.solve_shapes(asm, n_modes)
        return freq, frac, deficient

    def solve_shapes(self, asm: Assembly, n_modes: int) -> tuple[np.ndarray, np.ndarray, bool, np.ndarray]:
        """:meth:`solve` and the mode shapes (:meth:`PlaneSplit.modes_and_shapes`); afterwards :attr:`data`
        holds the pose's kinematics (``xpos``, ``xmat``: e.g. for point Jacobians)."""
        self.set_pose(asm)
        mujoco.mj_fwdPosition(self.model, self.data)
        if self.scales is None:  # structural: which rows are weld rotations, which dofs translate
            self.scales = unit_scales(self.model, self.data, structural_length_m(self.model))
        jac = equality_jacobian(self.model, self.data)
        return self.split.modes_and_shapes(mass_matrix(self.model, self.data), jac, n_modes, scales=self.scales)


def structural_length_m(model: mujoco.MjModel) -> float:
    """The length (m) that makes the weld Jacobian dimensionless in the pose loop: the largest offset of a body
    in its parent's frame (the link pieces, the base radius).

    It is structural: the same at every pose of a re-posed model and of a model compiled per pose, so the
    loop's results do not depend on which pose a worker compiled its model at (``model.stat.extent``, the
    length :func:`fpm_sim.linear.nullspace.constraint_rank` uses, does). The rank decision itself is the same
    function (:func:`fpm_sim.linear.nullspace.scaled_null_space`); its threshold is far from both lengths'
    scaled singular values (0.14-0.17 vs 1e-4).
    """
    if model.nbody < 2:
        return 1.0
    length = float(np.max(np.linalg.norm(model.body_pos[1:], axis=1)))
    return length if length > 0 else 1.0


REPOSABLE_LINK_MODELS = ("segments", "rigid")
"""Link models :class:`PoseModel` re-poses (chains of rigid bodies); the others compile one model per pose."""


IN_PLANE_DOF_KINDS = (*IN_PLANE_KINDS, "passive")
"""Degrees of freedom that move in the base plane (the z-hinges included); the rest move out of it."""


class PlaneSplit:
    """The in-plane / out-of-plane split of a model's eigenproblem (index arrays cached per model).

    A planar manipulator whose parts are symmetric about the base plane has no mass and no constraint
    coupling between in-plane and out-of-plane motion: ``M`` and the weld Jacobian are block-diagonal. Two
    smaller eigenproblems then give the same modes at a third of the cost. :meth:`blocks` checks the exact
    zeros at every pose and refuses the split (``None``) unless it keeps exactly the constraint directions
    the whole problem keeps: the singular values of a block-diagonal ``J`` are those of its blocks, and
    :func:`fpm_sim.linear.solvers.reduced_eigenproblem` drops those below ``NULLSPACE_RCOND`` times the largest.

    Parameters
    ----------
    in_plane
        Per degree of freedom: it moves in the base plane (:data:`IN_PLANE_DOF_KINDS`).
    stiffness
        Spring stiffness per degree of freedom.
    """

    def __init__(self, in_plane: ArrayLike, stiffness: ArrayLike) -> None:
        self.in_plane = np.asarray(in_plane, bool)
        self.stiffness = np.asarray(stiffness, float)
        nv = self.in_plane.size
        self.dofs = [np.flatnonzero(self.in_plane), np.flatnonzero(~self.in_plane)]
        self.usable = all(d.size for d in self.dofs)
        self._cross = np.ix_(self.dofs[0], self.dofs[1])
        self._square = [np.ix_(d, d) for d in self.dofs]
        self._k = [np.diag(self.stiffness[d]) for d in self.dofs]
        self._whole = (np.arange(nv), np.diag(self.stiffness))

    def blocks(
        self, mass: np.ndarray, jac: np.ndarray, scales: tuple[np.ndarray, np.ndarray] | None = None
    ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, int, int, np.ndarray]] | None:
        """``[(dofs, M_block, K_block, n_rows, rank, basis)]`` of the two decoupled problems, or ``None``.

        ``rank`` and ``basis`` are the block's :func:`fpm_sim.linear.nullspace.scaled_null_space` (one SVD per block,
        used both for the acceptance check and for the solve). ``scales`` are
        :func:`fpm_sim.linear.nullspace.unit_scales` (default: none, unit factors).
        """
        if not self.usable or np.any(mass[self._cross] != 0.0):
            return None
        rows = [np.any(jac[:, d] != 0.0, axis=1) for d in self.dofs]
        if np.any(rows[0] & rows[1]):
            return None
        row_scale, col_scale = scales or (np.ones(jac.shape[0]), np.ones(jac.shape[1]))
        nulls = [scaled_null_space(jac[r][:, d], row_scale[r], col_scale[d]) for r, d in zip(rows, self.dofs)]
        top = max((float(sv[0]) for _, sv, _ in nulls if sv.size), default=0.0)
        for rank, sv, _ in nulls:  # the split keeps exactly the directions the whole problem keeps
            if sv.size and np.sum(sv > NULLSPACE_RCOND * top) != rank:
                return None
        return [
            (d, mass[sq], k, int(np.sum(r)), rank, basis)
            for d, sq, k, r, (rank, _, basis) in zip(self.dofs, self._square, self._k, rows, nulls)
        ]

    def modes(
        self,
        mass: np.ndarray,
        jac: np.ndarray,
        n_modes: int,
        *,
        scales: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Lowest ``n_modes`` constrained modes: frequencies (Hz) and in-plane strain-energy share (NaN-padded).

        The eigenproblem is :func:`fpm_sim.linear.solvers.reduced_eigenproblem`, on the two blocks when they are
        exactly decoupled, else on the whole matrices. The passive hinges among the in-plane degrees of
        freedom have no spring, so the energy share counts the springs of :data:`IN_PLANE_KINDS`.
        """
        freq, frac, deficient, _ = self.modes_and_shapes(mass, jac, n_modes, scales=scales)
        return freq, frac, deficient

    def modes_and_shapes(
        self,
        mass: np.ndarray,
        jac: np.ndarray,
        n_modes: int,
        *,
        scales: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, bool, np.ndarray]:
        """:meth:`modes` and the mode shapes: ``(nv, m)`` mass-normalised generalised velocities (``m <= n_modes``
        columns, in the order of the frequencies)."""
        nv = self.in_plane.size
        problems = self.blocks(mass, jac, scales)
        if problems is None:
            rank, _, basis = scaled_null_space(jac, *(scales or (np.ones(jac.shape[0]), np.ones(nv))))
            problems = [(self._whole[0], mass, self._whole[1], jac.shape[0], rank, basis)]
        w2_all, shapes = [], []
        deficient = False
        for dofs, m_b, k_b, n_rows, rank, basis in problems:
            deficient = deficient or rank < n_rows
            z, _, _, w2, x = reduced_eigenproblem(m_b, k_b, basis, n_modes=n_modes)
            m = min(n_modes, w2.size)
            w2_all.append(w2[:m])
            v = np.zeros((nv, m))
            v[dofs] = z @ x[:, :m]
            shapes.append(v)
        w2 = np.concatenate(w2_all)
        order = np.argsort(w2, kind="stable")[:n_modes]
        v = np.concatenate(shapes, axis=1)[:, order]
        n = order.size
        freq = np.full(n_modes, np.nan)
        frac = np.full(n_modes, np.nan)
        freq[:n] = np.sqrt(np.maximum(w2[order], 0.0)) / (2 * np.pi)
        energy = self.stiffness[:, None] * v**2
        tot = energy.sum(axis=0)
        frac[:n] = np.where(tot > 0, energy[self.in_plane].sum(axis=0) / np.where(tot > 0, tot, 1.0), np.nan)
        return freq, frac, deficient, v


def plane_blocks(mass: np.ndarray, jac: np.ndarray, in_plane: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """``[(dofs, rows), (dofs, rows)]`` of the in-plane and out-of-plane problems if they are exactly decoupled
    (see :class:`PlaneSplit`), else ``None``."""
    split = PlaneSplit(in_plane, np.zeros(in_plane.size))
    if split.blocks(mass, jac) is None:
        return None
    return [(d, np.flatnonzero(np.any(jac[:, d] != 0.0, axis=1))) for d in split.dofs]


_POSE_MODELS: dict[str, PoseModel] = {}
"""Per-process cache of re-posable models by configuration and options (workers reuse them across chunks)."""


def pose_model(config: Manipulator, options: ModelOptions, reference: Assembly) -> PoseModel:
    """The process's cached :class:`PoseModel` of ``config`` (compiled at ``reference`` on first use)."""
    key = repr((config, options))
    pm = _POSE_MODELS.get(key)
    if pm is None:
        if len(_POSE_MODELS) >= 8:
            _POSE_MODELS.pop(next(iter(_POSE_MODELS)))
        pm = _POSE_MODELS[key] = PoseModel(config, options, reference)
    return pm


def solve_poses(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int,
    options: ModelOptions,
    recompile: bool = False,
) -> PoseFrequencies:
    """Lowest ``n_modes`` frequencies at ``poses``, in this process (one chunk of the pose loop).

    Parameters
    ----------
    config, poses, n_modes, options
        As :func:`fpm_sim.batch.frequencies.pose_frequencies`.
    recompile
        Compile one model per pose (the reference path, several times slower) instead of re-posing one
        compiled model (:class:`PoseModel`). Link models other than :data:`REPOSABLE_LINK_MODELS` always
        recompile.
    """
    poses = list(poses)
    freq = np.full((len(poses), n_modes), np.nan)
    frac = np.full((len(poses), n_modes), np.nan)
    if not poses:
        return PoseFrequencies(poses=[], frequencies_hz=freq, in_plane=frac, singularity=np.zeros(0), status=[])
    xs, ys, phis = [p.x_m for p in poses], [p.y_m for p in poses], [p.phi_rad for p in poses]
    many = assemble_many(config.geometry, xs, ys, phis)
    sing = many.singularity
    status = [_status(float(v), bool(r)) for v, r in zip(sing, many.reachable)]
    reposable = options.link_model in REPOSABLE_LINK_MODELS and not recompile
    pm: PoseModel | None = None
    with blas_threads():  # one BLAS thread around the dense solves (fpm_sim.linear.threads)
        for i, pose in enumerate(poses):
            if status[i] in (STATUS_UNREACHABLE, STATUS_SINGULAR):
                continue
            asm = many.assembly(i, pose)
            if reposable:
                pm = pm or pose_model(config, options, asm)
                f, s, deficient = pm.solve(asm, n_modes)
            else:
                built = build_manipulator(config, pose, options, assembly=asm)
                data = mujoco.MjData(built.model)
                mujoco.mj_forward(built.model, data)
                split = PlaneSplit([kind in IN_PLANE_DOF_KINDS for kind in built.dof_kinds], dof_stiffness(built.model))
                scales = unit_scales(built.model, data, structural_length_m(built.model))
                f, s, deficient = split.modes(
                    mass_matrix(built.model, data), equality_jacobian(built.model, data), n_modes, scales=scales
                )
            if deficient:  # the one rank decision (consistent units) says a loop direction is lost: singular
                warnings.warn(
                    f"pose {pose}: weld Jacobian is rank-deficient in consistent units; reported singular",
                    FpmSimWarning,
                    stacklevel=2,
                )
                status[i] = STATUS_SINGULAR
                continue
            freq[i], frac[i] = f, s
    return PoseFrequencies(poses=poses, frequencies_hz=freq, in_plane=frac, singularity=sing, status=status)


def _solve_chunk(poses: list[Pose], *, config: Manipulator, n_modes: int, options: ModelOptions) -> PoseFrequencies:
    return solve_poses(config, poses, n_modes=n_modes, options=options)


def merge(parts: Sequence[PoseFrequencies]) -> PoseFrequencies:
    """One :class:`PoseFrequencies` from consecutive chunks (all with the same ``n_modes``)."""
    parts = list(parts)
    if not parts:
        raise ValueError("merge: no chunks")
    return PoseFrequencies(
        poses=[p for part in parts for p in part.poses],
        frequencies_hz=np.concatenate([part.frequencies_hz for part in parts]),
        in_plane=np.concatenate([part.in_plane for part in parts]),
        singularity=np.concatenate([part.singularity for part in parts]),
        status=[s for part in parts for s in part.status],
    )


def cpu_backend(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int,
    options: ModelOptions,
    workers: int,
    progress: bool,
    desc: str,
    engine: EngineOptions | None = None,
) -> PoseFrequencies:
    """The ``cpu`` backend: :func:`solve_poses` on chunks of poses, on the engine (:mod:`fpm_sim.batch.engine`).

    ``engine`` says where (default: a local cluster of ``workers`` processes; one worker runs here);
    ``workers``, ``progress`` and ``desc`` fill its fields left unset.
    """
    poses = list(poses)
    eng = engine or EngineOptions()
    eng = dataclasses.replace(
        eng,
        workers=eng.workers or workers,
        progress=eng.progress or progress,
        desc=desc if eng.desc == "poses" else eng.desc,
    )
    if not poses:
        return solve_poses(config, poses, n_modes=n_modes, options=options)
    size = eng.chunk or chunk_size(len(poses), eng.n_workers)
    chunks = split(poses, size)
    parts = run_chunks(
        _solve_chunk,
        chunks,
        kwargs={"config": config, "n_modes": n_modes, "options": options},
        weights=[len(c) for c in chunks],
        options=eng,
    )
    return merge(parts)


def _config_chunk(item: tuple[Manipulator, list[Pose]], *, n_modes: int, options: ModelOptions) -> PoseFrequencies:
    config, poses = item
    return solve_poses(config, poses, n_modes=n_modes, options=options)


def solve_configs(
    configs: Sequence[Manipulator],
    poses: Sequence[Pose],
    *,
    n_modes: int,
    options: ModelOptions,
    engine: EngineOptions | None = None,
) -> list[PoseFrequencies]:
    """:func:`solve_poses` for every description x pose, on the engine (:mod:`fpm_sim.batch.engine`).

    Every task is one description and one chunk of ``poses``; each worker compiles one model per description
    (:class:`PoseModel`) and re-poses it. Returns one :class:`PoseFrequencies` per description, in order (the
    loop of the design studies and of the predictions over a posterior's draws).
    """
    configs, poses = list(configs), list(poses)
    eng = engine or EngineOptions()
    size = eng.chunk or chunk_size(len(poses) * len(configs), eng.n_workers)
    pose_chunks = split(poses, size)
    items = [(c, chunk) for c in configs for chunk in pose_chunks]
    parts = run_chunks(
        _config_chunk,
        items,
        kwargs={"n_modes": n_modes, "options": options},
        weights=[len(chunk) for _, chunk in items],
        options=eng,
    )
    per = len(pose_chunks)
    return [merge(parts[d * per : (d + 1) * per]) for d in range(len(configs))]


class PosesFileError(FpmSimError):
    """A poses CSV file (``poses``) is missing, empty or malformed."""


def read_poses_csv(path: str | Path, *, parameter: str = "poses", lines: list[int] | None = None) -> list[Pose]:
    """Poses from a CSV file with columns ``x_mm,y_mm,phi_rad`` (other columns are ignored; UTF-8 with or without
    a byte-order mark, any line ending); each row checked by :func:`fpm_sim.kinematics.checked_pose_mm`. Errors
    name ``parameter``, the file and the row. ``lines``: if given, each pose's row (line number) is appended to it."""
    p = Path(path)
    if not p.is_file():
        raise PosesFileError(f"{p}: no such file", parameter=parameter)
    hint = "give a CSV file of poses with the header x_mm,y_mm,phi_rad"
    text = read_text_input(p, error=PosesFileError, parameter=parameter, kind="a CSV file", hint=hint, newline="")
    reader = csv.DictReader(io.StringIO(text, newline=""))
    missing = {"x_mm", "y_mm", "phi_rad"} - {h.strip() for h in reader.fieldnames or []}
    if missing:
        raise PosesFileError(
            f"{p}: missing column(s) {', '.join(sorted(missing))}",
            parameter=parameter,
            hint="the header must hold x_mm,y_mm,phi_rad",
        )
    poses: list[Pose] = []
    for r in reader:
        r = {(k or "").strip(): v for k, v in r.items()}
        try:
            poses.append(checked_pose_mm(r["x_mm"], r["y_mm"], r["phi_rad"], row=reader.line_num))
        except PoseValueError as e:
            raise PosesFileError(f"{p}: {e}", parameter=parameter) from None
        if lines is not None:
            lines.append(reader.line_num)
    if not poses:
        raise PosesFileError(f"{p}: no rows after the header", parameter=parameter)
    return poses
