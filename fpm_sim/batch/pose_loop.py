"""Fast first natural frequencies of the manipulator over many poses (the pose loop of reproduce/sweep).

The full analysis (:func:`fpm_sim.linear.analysis.manipulator_modes`: 12 segments per link, axial springs,
gravity equilibrium, ``mjd_transitionFD``) costs seconds per pose. Here each pose is solved by the
constrained eigenproblem at the assembled configuration with gravity off:

``M`` from ``mj_fullM`` at ``qpos0``, ``K = diag(joint spring stiffness)``, the weld Jacobian ``J``
from one ``mj_forward``; ``Z = null(J)``, ``Z'KZ x = w^2 Z'MZ x``.

This is exact for the linear model without prestress (straight, unstressed links at ``qpos0``); what
it leaves out is the geometric stiffness of gravity's prestress, a small effect for motor axes along
gravity (measured in ``docs/benchmarks.md`` and ``tests/test_fast_frequencies.py`` against the full
analysis). Coarser links (default :data:`FAST_SEGMENTS`) cost a discretisation error that scales as
``1/n^2`` and is also measured there.

:func:`first_frequencies` is the replaceable pose loop: ``backend="cpu"`` is this module; another
backend (e.g. MJX on an accelerator) registers itself with :func:`register_backend` and receives the
same arguments.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from fpm_sim.config import Manipulator
from fpm_sim.kinematics import NEAR_SINGULAR_WARN, SINGULAR_TOL, Assembly, Pose, assemble_many
from fpm_sim.linear.modal import equality_jacobian, mass_matrix, reduced_eigenproblem
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import BuiltModel, ModelOptions, dof_stiffness

__all__ = [
    "assemble_pose",
    "FAST_SEGMENTS",
    "PoseFrequencies",
    "fast_options",
    "IN_PLANE_KINDS",
]

FAST_SEGMENTS = 6
"""Spring locations per link of the fast path (the cantilever's first mode is +0.6 % at n = 6)."""

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


class PoseModel:
    """One compiled manipulator model, re-posed in place for every pose (no recompile per pose).

    The topology, masses, inertias and spring stiffnesses do not depend on the pose: only nine body
    orientations do (:func:`_pose_angles`), and the welds' relative poses, which the compiler takes from
    the bodies at ``qpos0``. The model is compiled once, at ``reference`` (an assembled pose of the same
    configuration); :meth:`solve` sets the orientations, recomputes the weld relative poses as the
    compiler does, runs the position stage (``mj_fwdPosition``: kinematics, mass matrix, constraint
    Jacobian) and solves the constrained eigenproblem (:func:`fpm_sim.linear.modal.reduced_eigenproblem`).

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
        self.in_plane = np.array([kind in IN_PLANE_KINDS for kind in self.built.dof_kinds])
        bid = self.model.body
        self._body_ids = [bid(name).id for name, _ in _pose_angles(reference)]
        weld = self.model.eq_type == mujoco.mjtEq.mjEQ_WELD
        self._welds = np.where(weld)[0]

    def set_pose(self, asm: Assembly) -> None:
        """Re-pose the model at ``asm``: body orientations, then the welds' relative poses at ``qpos0``."""
        m, d = self.model, self.data
        for body, (_, ang) in zip(self._body_ids, _pose_angles(asm)):
            m.body_quat[body] = (math.cos(ang / 2.0), 0.0, 0.0, math.sin(ang / 2.0))
        d.qpos[:] = m.qpos0
        mujoco.mj_kinematics(m, d)
        inv = np.zeros(4)
        for e in self._welds:  # relpose of body 2 in body 1 with mj_setConst's operations (eq_data[3:10])
            b1, b2 = m.eq_obj1id[e], m.eq_obj2id[e]
            mujoco.mju_mulMatTVec3(m.eq_data[e, 3:6], d.xmat[b1], d.xpos[b2] - d.xpos[b1])
            mujoco.mju_negQuat(inv, d.xquat[b1])
            mujoco.mju_mulQuat(m.eq_data[e, 6:10], inv, d.xquat[b2])

    def solve(self, asm: Assembly, n_modes: int) -> tuple[np.ndarray, np.ndarray]:
        """``(frequencies_hz, in_plane)`` of the lowest ``n_modes`` modes at ``asm`` (NaN-padded)."""
        self.set_pose(asm)
        mujoco.mj_fwdPosition(self.model, self.data)
        return _modes(self.model, self.data, self.stiffness, self.in_plane, n_modes)


REPOSABLE_LINK_MODELS = ("segments", "rigid")
"""Link models :class:`PoseModel` re-poses (chains of rigid bodies); the others compile one model per pose."""


def _modes(
    model: mujoco.MjModel, data: mujoco.MjData, stiffness: np.ndarray, in_plane: np.ndarray, n_modes: int
) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``n_modes`` constrained modes after the position stage at ``qpos0``: frequencies, in-plane share."""
    z, _, _, w2, x = reduced_eigenproblem(mass_matrix(model, data), np.diag(stiffness), equality_jacobian(model, data))
    n = min(n_modes, w2.size)
    freq = np.full(n_modes, np.nan)
    frac = np.full(n_modes, np.nan)
    freq[:n] = np.sqrt(np.maximum(w2[:n], 0.0)) / (2 * np.pi)
    energy = stiffness[:, None] * (z @ x[:, :n]) ** 2
    tot = energy.sum(axis=0)
    frac[:n] = np.where(tot > 0, energy[in_plane].sum(axis=0) / np.where(tot > 0, tot, 1.0), np.nan)
    return freq, frac


_POSE_MODELS: dict[str, PoseModel] = {}
"""Per-process cache of re-posable models by configuration and options (workers reuse them across chunks)."""


def _pose_model(config: Manipulator, options: ModelOptions, reference: Assembly) -> PoseModel:
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
    many = assemble_many(
        config.geometry, [p.x_m for p in poses], [p.y_m for p in poses], [p.phi_rad for p in poses]
    )
    sing = many.singularity
    status = [_status(float(v), bool(r)) for v, r in zip(sing, many.reachable)]
    reposable = options.link_model in REPOSABLE_LINK_MODELS and not recompile
    for i, pose in enumerate(poses):
        if status[i] in (STATUS_UNREACHABLE, STATUS_SINGULAR):
            continue
        asm = many.assembly(i, pose)
        if reposable:
            freq[i], frac[i] = _pose_model(config, options, asm).solve(asm, n_modes)
        else:
            built = build_manipulator(config, pose, options, assembly=asm)
            data = mujoco.MjData(built.model)
            mujoco.mj_forward(built.model, data)
            k = dof_stiffness(built.model)
            inplane = np.array([kind in IN_PLANE_KINDS for kind in built.dof_kinds])
            freq[i], frac[i] = _modes(built.model, data, k, inplane, n_modes)
    return PoseFrequencies(poses=poses, frequencies_hz=freq, in_plane=frac, singularity=sing, status=status)
