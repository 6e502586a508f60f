"""Constraint rank in consistent units: the weld Jacobian made dimensionless, its rank decided once, the
null space of admissible motions (the one rank decision of the package, shared by the ``cpu`` and ``mjx``
pose-loop backends).

The weld Jacobian's rows mix metres (position rows) and radians (rotation rows) and its columns radians
(hinges) and metres (slides). Its rank is decided on ``R J C`` with the position rows divided and the
translational columns multiplied by the model's characteristic length ``L = model.stat.extent`` (m), so both
become dimensionless (:func:`constraint_rank`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import mujoco
import numpy as np

from fpm_sim.errors import FpmSimWarning
from fpm_sim.linear.equilibrium import equality_jacobian

__all__ = [
    "NULLSPACE_RCOND",
    "STRUCTURAL_RCOND",
    "ConstraintRank",
    "RedundantConstraintWarning",
    "constraint_rank",
    "constraint_ratio",
    "model_length_m",
    "scaled_jacobian",
    "scaled_null_space",
    "unit_scales",
]


NULLSPACE_RCOND = 1e-4
"""Relative singular-value threshold for the rank of the equality-constraint Jacobian in consistent
units (:func:`constraint_rank`)."""


STRUCTURAL_RCOND = 1e-10
"""Singular-value ratios below this are exact (structural) redundancies, e.g. the axial row of a
straight inextensible clamped-clamped chain: not imposed, silently. Between this and
:data:`NULLSPACE_RCOND` a direction is dropped with a :class:`RedundantConstraintWarning`."""


class RedundantConstraintWarning(FpmSimWarning):
    """A loop-closure direction is nearly redundant (scaled singular value below :data:`NULLSPACE_RCOND`)
    and was not imposed: the pose is close to a constraint singularity."""


@dataclass(frozen=True)
class ConstraintRank:
    """Rank of the equality-constraint Jacobian in consistent units (:func:`constraint_rank`).

    Attributes
    ----------
    n_rows
        Equality-constraint rows.
    rank
        Rows imposed: scaled singular values above ``NULLSPACE_RCOND`` times the largest.
    singular_values
        Singular values of the scaled (dimensionless) Jacobian, descending.
    basis
        Orthonormal basis ``(nv, nv - rank)`` of the admissible motions in the model's coordinates.
    length_m
        The characteristic length used to scale (m).
    """

    n_rows: int
    rank: int
    singular_values: np.ndarray
    basis: np.ndarray
    length_m: float

    @property
    def deficient(self) -> bool:
        """Whether some constraint direction was not imposed."""
        return self.rank < self.n_rows

    @property
    def ratio(self) -> float:
        """Smallest over largest scaled singular value of the rows (1 without constraints, 0 when rows
        outnumber the degrees of freedom)."""
        sv = self.singular_values
        if self.n_rows == 0:
            return 1.0
        if self.n_rows > sv.size or sv[0] == 0.0:
            return 0.0
        return float(sv[self.n_rows - 1] / sv[0])


def model_length_m(model: mujoco.MjModel) -> float:
    """The characteristic length (m) that makes the weld Jacobian dimensionless: ``model.stat.extent``."""
    return float(model.stat.extent) if model.stat.extent > 0 else 1.0


def unit_scales(model: mujoco.MjModel, data: mujoco.MjData, length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Row and column factors that make the equality Jacobian dimensionless (see :func:`constraint_rank`).

    They depend on the model's structure only (which rows are weld rotations, which dofs translate), so a
    pose loop that re-poses one compiled model computes them once.
    """
    rows = np.flatnonzero(np.asarray(data.efc_type[: data.nefc]) == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    row_scale = np.full(rows.size, 1.0 / length_m)
    eq_ids = np.asarray(data.efc_id[: data.nefc])[rows]
    k = 0
    while k < rows.size:
        eq = int(eq_ids[k])
        n = int(np.sum(eq_ids == eq))
        kind = int(model.eq_type[eq])
        if kind == mujoco.mjtEq.mjEQ_WELD and n == 6:
            torquescale = float(model.eq_data[eq, 10]) or 1.0
            row_scale[k + 3 : k + 6] = 1.0 / torquescale  # rotation rows: rad x torquescale
        elif kind in (mujoco.mjtEq.mjEQ_JOINT,):
            row_scale[k : k + n] = 1.0  # joint equalities: rad (hinges) assumed
        k += n
    col_scale = np.ones(model.nv)
    for d in range(model.nv):
        jt = int(model.jnt_type[model.dof_jntid[d]])
        first = int(model.jnt_dofadr[model.dof_jntid[d]])
        if jt == mujoco.mjtJoint.mjJNT_SLIDE or (jt == mujoco.mjtJoint.mjJNT_FREE and d - first < 3):
            col_scale[d] = length_m  # translational dof: metres -> units of L
    return row_scale, col_scale


def scaled_null_space(
    jac: np.ndarray,
    row_scale: np.ndarray,
    col_scale: np.ndarray,
    *,
    rcond: float = NULLSPACE_RCOND,
    top: float | None = None,
) -> tuple[int, np.ndarray, np.ndarray]:
    """``(rank, singular_values, basis)`` of ``jac`` decided on the dimensionless ``R J C`` (:func:`unit_scales`).

    A direction counts when its scaled singular value exceeds ``rcond`` times ``top`` (default: the largest
    of this matrix; a block of a block-diagonal Jacobian passes the whole matrix's largest). ``basis`` is an
    orthonormal basis of the admissible motions in the model's coordinates.
    """
    nv = jac.shape[1]
    if jac.shape[0] == 0:
        return 0, np.zeros(0), np.eye(nv)
    scaled = row_scale[:, None] * jac * col_scale[None, :]
    _, sv, vt = np.linalg.svd(scaled, full_matrices=True)
    ref = float(sv[0]) if top is None else top
    rank = int(np.sum(sv > rcond * ref)) if ref > 0 else 0
    # null space of R J C is N~; that of J is C N~ (C invertible, diagonal): re-orthonormalise
    basis = col_scale[:, None] * vt[rank:].T
    if basis.shape[1]:
        basis = np.linalg.qr(basis)[0]
    return rank, sv, basis


def constraint_rank(
    model: mujoco.MjModel, data: mujoco.MjData, *, rcond: float = NULLSPACE_RCOND, warn: bool = True
) -> ConstraintRank:
    """Rank and null space of the equality-constraint Jacobian, decided in consistent units.

    After a forward pass at the configuration of interest. The Jacobian ``J`` maps generalised
    velocities (rad/s for hinges, m/s for slides) to constraint rates (m/s for weld positions and
    connects, rad/s times the weld's ``torquescale`` for weld rotations). Its rank is decided on the
    dimensionless ``R J C``: position rows divided by ``L``, rotation rows by ``torquescale``,
    translational columns multiplied by ``L``, with ``L = model.stat.extent`` (m, the model's size);
    a direction counts when its singular value exceeds ``rcond`` times the largest. This is the one
    rank decision of the package: the ``cpu`` path (:func:`~fpm_sim.linear.solvers.reduced_eigenproblem`) and the
    ``mjx`` backend both use it.

    Directions below ``rcond`` are not imposed (they are redundant to first order, e.g. the axial row
    of a straight inextensible clamped-clamped chain); when such a direction is not an exact
    (structural, below :data:`STRUCTURAL_RCOND`) redundancy, a :class:`RedundantConstraintWarning`
    is issued (``warn``).
    """
    jac = equality_jacobian(model, data)
    length = model_length_m(model)
    if jac.shape[0] == 0:
        return ConstraintRank(0, 0, np.zeros(0), np.eye(model.nv), length)
    row_scale, col_scale = unit_scales(model, data, length)
    rank, sv, basis = scaled_null_space(jac, row_scale, col_scale, rcond=rcond)
    out = ConstraintRank(jac.shape[0], rank, sv, basis, length)
    if warn and out.deficient:
        weak = sv[rank : jac.shape[0]] / sv[0]
        if np.any(weak > STRUCTURAL_RCOND):
            warnings.warn(
                f"{int(np.sum(weak > STRUCTURAL_RCOND))} loop-closure direction(s) nearly redundant (scaled "
                f"singular value ratio {float(weak.max()):.1e} < {rcond:g}): not imposed; the configuration is "
                "close to a constraint singularity, move the pose",
                RedundantConstraintWarning,
                stacklevel=3,
            )
    return out


def scaled_jacobian(model: mujoco.MjModel, data: mujoco.MjData, length_m: float) -> np.ndarray:
    """The equality Jacobian in consistent units (rows of constraint_rank's ``R J C``) acting on the
    model's own coordinates: ``R J`` (the shape stays in model units; used for the constraint ratio)."""
    jac = equality_jacobian(model, data)
    if jac.shape[0] == 0:
        return jac
    row_scale, _ = unit_scales(model, data, length_m)
    scaled: np.ndarray = row_scale[:, None] * jac
    return scaled


def constraint_ratio(jac: np.ndarray, jnorm: float, v: np.ndarray) -> float:
    if jac.shape[0] == 0 or jnorm == 0.0:
        return 0.0
    return float(np.linalg.norm(jac @ v) / (jnorm * np.linalg.norm(v)))
