"""Exact frequency derivatives for the local steps of an identification (issue 31, item 3): the eigen-solve's
sensitivities instead of finite differences of the whole frequency computation.

At a pose the pose loop solves ``K x = w^2 M x`` on the weld constraint ``G x = 0`` (:class:`fpm_sim.batch.
pose_loop.PoseModel`: ``M`` the joint-space mass matrix, ``K = diag(k)`` the joint springs, ``G`` the equality
Jacobian, all in the model's joint coordinates, which are the same set for every value of a parameter that keeps
the model's structure). With a mass-normalised mode ``x`` and the constraint's multipliers ``mu`` from
``(K - w^2 M) x = G' mu``, the derivative of a distinct eigenvalue along a parameter ``p`` is exact::

    d(w^2)/dp = x' (dK - w^2 dM) x - 2 mu' dG x

(the stationarity of ``x'Kx - w^2 (x'Mx - 1) - 2 mu'Gx``; the last term is the constraint's own motion, e.g. a
longer link moving the welds). ``df = d(w^2) / (8 pi^2 f)``. The matrix tangents ``dM``, ``dK``, ``dG`` are
forward differences of the model matrices (step :data:`REL_STEP` of the parameter's bounds' width): the matrices
are smooth closed-form functions of the parameters (MuJoCo's compiler and the closed-form inverse kinematics, not
an iterative solve), so the truncation error is ``O(step)`` relative and round-off ``~1e-16 / step``; no
eigen-solve is repeated, so no mode can swap between the nominal and the perturbed model. Per parameter: one
model compile and one position stage per pose, against one compile and one eigen-solve per pose for a
finite-difference column.

Exact for distinct eigenvalues (a repeated pair has only the sum of its derivatives defined). A parameter whose
step changes the model's structure (its degrees of freedom or constraint rows) gets a finite-difference column of
the frequencies instead.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from fpm_sim.batch.pose_loop import REPOSABLE_LINK_MODELS, PoseModel
from fpm_sim.config import Manipulator
from fpm_sim.kinematics import NearSingularityWarning, Pose, assemble_many
from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.linear.matrices import mass_matrix
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.identify.data import Observation
from fpm_sim.study.identify.parameters import ParameterSet
from fpm_sim.study.identify.problem import modes_needed, pair_modes, predict_observations, unique_poses

__all__ = ["REL_STEP", "PoseMatrices", "observation_gradients", "pose_matrices", "supported"]

REL_STEP = 1e-7
"""Forward-difference step of the model matrices, as a fraction of the parameter's bounds' width."""


@dataclass
class PoseMatrices:
    """The eigenproblem's matrices at one pose: joint-space mass, joint stiffness (diagonal), weld Jacobian."""

    mass: np.ndarray
    stiffness: np.ndarray
    jac: np.ndarray


def supported(options: ModelOptions) -> bool:
    """Whether the pose loop re-poses one compiled model for these options (then its matrices are at hand)."""
    return options.link_model in REPOSABLE_LINK_MODELS


def _assemble(config: Manipulator, poses: Sequence[Pose]) -> list[Any]:
    """Each pose's assembly (``None`` where unreachable)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        many = assemble_many(
            config.geometry, [p.x_m for p in poses], [p.y_m for p in poses], [p.phi_rad for p in poses]
        )
    return [many.assembly(i, p) if ok else None for i, (p, ok) in enumerate(zip(poses, many.reachable))]


def pose_matrices(
    config: Manipulator, poses: Sequence[Pose], options: ModelOptions, model: PoseModel | None = None
) -> tuple[list[PoseMatrices | None], PoseModel | None]:
    """The matrices at each pose (``None`` where unreachable), from one model compiled at the first reachable pose
    (or ``model``); returns the model too."""
    out: list[PoseMatrices | None] = []
    for asm in _assemble(config, poses):
        if asm is None:
            out.append(None)
            continue
        model = model or PoseModel(config, options, asm)
        model.set_pose(asm)
        mujoco.mj_fwdPosition(model.model, model.data)
        out.append(
            PoseMatrices(
                mass_matrix(model.model, model.data), model.stiffness, equality_jacobian(model.model, model.data)
            )
        )
    return out, model


@dataclass
class _Modes:
    """The nominal modes at one pose: frequencies (Hz), in-plane fractions, mass-normalised shapes ``(nv, m)``,
    ``w^2`` and the weld constraint's multipliers ``(n_rows, m)`` of each shape."""

    freq: np.ndarray
    frac: np.ndarray
    shapes: np.ndarray
    w2: np.ndarray
    mu: np.ndarray

    def dw2(self, tangent: PoseMatrices) -> np.ndarray:
        """``d(w^2)`` of each mode along the matrices' tangent (module docstring)."""
        x = self.shapes
        quad = np.einsum("ij,ij->j", x, tangent.stiffness[:, None] * x - (tangent.mass @ x) * self.w2[None, :])
        return quad - 2.0 * np.einsum("ij,ij->j", self.mu, tangent.jac @ x)


def _same_structure(a: PoseMatrices, b: PoseMatrices) -> bool:
    return a.mass.shape == b.mass.shape and a.jac.shape == b.jac.shape


def _nominal_modes(
    config: Manipulator, poses: list[Pose], options: ModelOptions, n_modes: int
) -> tuple[list[_Modes | None], list[PoseMatrices | None]]:
    """Per pose: the nominal modes (``None`` unreachable or singular) and matrices (``None`` unreachable)."""
    model: PoseModel | None = None
    modes: list[_Modes | None] = []
    mats: list[PoseMatrices | None] = []
    for asm in _assemble(config, poses):
        if asm is None:
            modes.append(None)
            mats.append(None)
            continue
        model = model or PoseModel(config, options, asm)
        freq, frac, deficient, shapes = model.solve_shapes(asm, n_modes)  # leaves the pose's position stage
        m = PoseMatrices(
            mass_matrix(model.model, model.data), model.stiffness, equality_jacobian(model.model, model.data)
        )
        mats.append(m)
        if deficient:
            modes.append(None)
            continue
        w2 = (2 * math.pi * freq[: shapes.shape[1]]) ** 2
        residual = m.stiffness[:, None] * shapes - (m.mass @ shapes) * w2[None, :]  # = G' mu
        mu = np.linalg.lstsq(m.jac.T, residual, rcond=None)[0]
        modes.append(_Modes(freq, frac, shapes, w2, mu))
    return modes, mats


def observation_gradients(
    ps: ParameterSet,
    x: np.ndarray,
    columns: Sequence[int],
    observations: Sequence[Observation],
    options: ModelOptions,
    *,
    pairing: str = "order",
) -> np.ndarray:
    """``d f_j / d x_k`` (Hz per unit of ``x_k``) of each observation ``j`` for each parameter ``k`` in
    ``columns`` (the others: 0), at parameters ``x`` (module docstring). 0 where the model gives no frequency
    (unreachable or singular pose, too few modes of the kind): the residual there is a constant penalty. Modes
    paired with the observations as :func:`~fpm_sim.study.identify.problem.pair_modes` pairs them."""
    x = np.asarray(x, float)
    if not observations or not columns:
        return np.zeros((len(observations), len(x)))
    with blas_threads():  # one BLAS thread around the small dense products, as the pose loop (fpm_sim.linear.threads)
        return _gradients(ps, x, columns, observations, options, pairing)


def _gradients(
    ps: ParameterSet,
    x: np.ndarray,
    columns: Sequence[int],
    observations: Sequence[Observation],
    options: ModelOptions,
    pairing: str,
) -> np.ndarray:
    """:func:`observation_gradients` (its arguments checked)."""
    grad = np.zeros((len(observations), len(x)))
    poses, index = unique_poses(observations)
    config = ps.apply(x)
    modes, mats = _nominal_modes(config, poses, options, modes_needed(observations, pairing))
    freqs = [None if m is None else m.freq for m in modes]
    which = pair_modes(observations, index, freqs, [None if m is None else m.frac for m in modes], pairing)
    width = ps.width
    for k in columns:
        h = REL_STEP * width[k] * (1.0 if x[k] + REL_STEP * width[k] <= ps.upper[k] else -1.0)
        xk = x.copy()
        xk[k] += h
        mats_k, _ = pose_matrices(ps.apply(xk), poses, options)
        if any(a is not None and (b is None or not _same_structure(a, b)) for a, b in zip(mats, mats_k)):
            grad[:, k] = _fd_column(ps, x, k, observations, options, pairing)
            continue
        dw2: dict[int, np.ndarray] = {}  # per pose: df (Hz per unit) of each mode
        for ip, (md, a, b) in enumerate(zip(modes, mats, mats_k)):
            if md is None or a is None or b is None:
                continue
            tangent = PoseMatrices((b.mass - a.mass) / h, (b.stiffness - a.stiffness) / h, (b.jac - a.jac) / h)
            dw2[ip] = md.dw2(tangent) / (8 * math.pi**2 * md.freq[: md.shapes.shape[1]])
        for j, (ip, i) in enumerate(zip(index, which)):
            if i is not None and ip in dw2 and i < len(dw2[ip]):
                grad[j, k] = dw2[ip][i]
    return grad


def _fd_column(
    ps: ParameterSet, x: np.ndarray, k: int, observations: Sequence[Observation], options: ModelOptions, pairing: str
) -> np.ndarray:
    """A central-difference column of the frequencies (step ``1e-4`` of the width), for a parameter whose step
    changes the model's structure."""
    h = 1e-4 * ps.width[k]
    lo, hi = x.copy(), x.copy()
    lo[k], hi[k] = max(x[k] - h, ps.lower[k]), min(x[k] + h, ps.upper[k])
    fl = predict_observations(ps.apply(lo), observations, options=options, pairing=pairing)
    fh = predict_observations(ps.apply(hi), observations, options=options, pairing=pairing)
    return np.nan_to_num((fh - fl) / (hi[k] - lo[k]))
