"""Modal analysis of a generated model by two independent methods.

``transition_fd`` (primary)
    ``mujoco.mjd_transitionFD`` (centred differences) at the static equilibrium gives the discrete
    map ``x+ = A x``. Each eigenvalue ``lambda`` maps to continuous time as ``s = ln(lambda) / h``;
    natural frequency ``|s| / 2 pi``, damping ratio ``-Re(s) / |s|``, shape = position part of the
    eigenvector. One of each conjugate pair is kept.

``constrained`` (cross-check)
    The constrained generalised eigenproblem at the same equilibrium: ``M`` from ``mj_fullM``,
    ``K = -d/dq [qfrc_passive - qfrc_bias + J(q)^T lambda*]`` by centred differences (``lambda*`` the
    equilibrium constraint forces, so the prestress of the closed loop is included), projected on the
    null space ``Z`` of the equality-constraint Jacobian: ``Z'KZ x = w^2 Z'MZ x``. Damping ratios from
    the modal projection of the joint-damping matrix ``C`` (exact for stiffness-proportional damping).

Modes dropped, by documented physical criteria (:class:`ModeFilter`), counted in ``ModalResult.dropped``.
No absolute frequency is used: a physical mode near a parallel singularity falls towards 0 Hz (its
stiffness ~ measure^2) and must be reported, with a :class:`~fpm_sim.kinematics.NearSingularityWarning`.

- ``non_oscillatory``: real eigenvalues (``Im s <= 0``), e.g. critically damped constraint motions;
- ``rigid_body``: no strain energy to within the computation's noise: ``|w^2| <= w2_tol`` with
  ``w2_tol = max((rigid_fraction * w_ref)^2, FD_NOISE_MARGIN * |x'(K(e) - K(2e))x|)`` (:func:`noise_w2`):
  ``w_ref`` is the model's own scale, the lowest uncoupled spring frequency ``min_i sqrt(k_i / M_ii)``
  (:func:`reference_frequency_hz`; the lowest link's first frequency is of the same order: 51 Hz
  against the manipulator's 70-75 Hz first mode at 12 segments, 401 Hz against the cantilever's
  221 Hz), and the second term the measured finite-difference noise of ``x'K x`` (constrained
  method; ``transition_fd`` uses the first term). With
  ``rigid_fraction = 1e-4`` the threshold sits 25x below the lowest physical frequency the
  kinematics accept (a pose refused below singularity measure 1e-3 keeps ``f1 >= ~2.5e-3 f_normal``)
  and far above the exact zeros of a floating rig's rigid-body motions;
- ``constraint``: the shape violates the loop closure, ``|J v| / (|J|_2 |v|) > max_constraint_ratio``,
  ``J`` with its rows in consistent units (:func:`constraint_rank`): motions of the soft weld itself
  (constraint stabilisation), not of the structure. Measured: lightly damped physical modes up to
  7.3e-4 (the flex chain rig's highest modes; the manipulator's ~1e-8), the welds' own motions from
  2.9e-3 (segment chain rig) to 0.3; the default 1.5e-3 sits at their geometric mean;
- ``overdamped``: damping ratio above ``max_damping_ratio``.

An eigenvalue ``w^2 < -w2_tol`` (constrained method) or a growing mode (``transition_fd``: a damping
ratio below ``-NEGATIVE_DAMPING_TOL`` or a real eigenvalue growing faster than the rigid-body
threshold) is never clipped to zero: :class:`UnstableModelError` is raised, naming the growth.

Constraint rank (:func:`constraint_rank`): the weld Jacobian's rows mix metres (position rows) and
radians (rotation rows) and its columns radians (hinges) and metres (slides). Its rank is decided on
``R J C`` with the position rows divided and the translational columns multiplied by the model's
characteristic length ``L = model.stat.extent`` (m), so both become dimensionless; the same decision
serves the ``cpu`` and the ``mjx`` pose-loop backends.

Timestep: the step map (semi-implicit Euler on the springs) raises an undamped mode's frequency by
``(omega h)^2 / 24`` relative (``cos(omega' h) = 1 - (omega h)^2 / 2``; measured 0.071 % at
``omega h = 0.130`` against 0.070 % predicted); :func:`modes_transition_fd` warns
(:class:`TimestepWarning`) when a reported mode has ``omega h > OMEGA_H_WARN`` (error > 0.4 %).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.kinematics import NEAR_SINGULAR_WARN, NearSingularityWarning
from fpm_sim.linear.equilibrium import equality_jacobian, static_equilibrium
from fpm_sim.model.options import (
    BuiltModel,
    check_count,
    dof_stiffness,
    has_internal_elasticity,
    passive_damping_matrix,
    passive_stiffness_matrix,
    tangent_jacobian,
)

__all__ = [
    "FD_NOISE_MARGIN",
    "NEGATIVE_DAMPING_TOL",
    "OMEGA_H_WARN",
    "RIGID_BODY_FRACTION",
    "ConstraintRank",
    "ModalResult",
    "Mode",
    "ModeFilter",
    "RedundantConstraintWarning",
    "TimestepWarning",
    "UnstableModelError",
    "check_n_modes",
    "check_stable",
    "constraint_rank",
    "eigenvalue_tolerances",
    "equality_jacobian",
    "mass_matrix",
    "model_length_m",
    "modes_constrained",
    "modes_transition_fd",
    "noise_w2",
    "reduced_eigenproblem",
    "reference_frequency_hz",
    "scaled_null_space",
    "stiffness_matrix",
    "system_damping_matrix",
    "unit_scales",
]

OMEGA_H_WARN = 0.3
"""``omega * h`` above which a reported frequency carries more than ~0.4 % timestep error."""

NULLSPACE_RCOND = 1e-4
"""Relative singular-value threshold for the rank of the equality-constraint Jacobian in consistent
units (:func:`constraint_rank`)."""

STRUCTURAL_RCOND = 1e-10
"""Singular-value ratios below this are exact (structural) redundancies, e.g. the axial row of a
straight inextensible clamped-clamped chain: not imposed, silently. Between this and
:data:`NULLSPACE_RCOND` a direction is dropped with a :class:`RedundantConstraintWarning`."""

RIGID_BODY_FRACTION = 1e-4
"""``ModeFilter.rigid_fraction`` default: rigid-body threshold as a fraction of the model's reference
frequency (:func:`reference_frequency_hz`)."""

FD_NOISE_MARGIN = 10.0
"""The finite-difference noise of an eigenvalue ``w_i^2`` is estimated as ``|x_i' (K(e) - K(2e)) x_i|`` (the
stiffness at two steps, the mode ``x_i`` M-normalised), times this margin (measured: 1.6e-4 rad^2/s^2 at
``w^2 = 11`` near the singular pose (83 mm, 4.5 mm, 0), where an entrywise worst-case bound gives 6e3)."""

NEGATIVE_DAMPING_TOL = 1e-6
"""A ``transition_fd`` mode with a damping ratio below ``-NEGATIVE_DAMPING_TOL`` grows: the free-free
bar's modes measure ``|zeta| ~ 3e-13`` of round-off."""

Method = Literal["transition_fd", "constrained"]


class TimestepWarning(FpmSimWarning):
    """The timestep is too coarse for the frequency band being reported."""


class RedundantConstraintWarning(FpmSimWarning):
    """A loop-closure direction is nearly redundant (scaled singular value below :data:`NULLSPACE_RCOND`)
    and was not imposed: the pose is close to a constraint singularity."""


class UnstableModelError(FpmSimError):
    """The linearised model grows: a negative stiffness eigenvalue or negative damping beyond round-off."""


@dataclass(frozen=True)
class ModeFilter:
    """Criteria that separate physical modes from the rest (see module docstring).

    Attributes
    ----------
    rigid_fraction
        A mode below ``rigid_fraction`` times :func:`reference_frequency_hz` (and its round-off)
        carries no strain energy: rigid-body motion or mechanism.
    max_constraint_ratio
        Largest loop-closure violation ``|J v| / (|J|_2 |v|)`` (consistent units) of a physical mode.
    max_damping_ratio
        Larger damping ratios are overdamped motions (dropped).
    """

    rigid_fraction: float = RIGID_BODY_FRACTION
    max_constraint_ratio: float = 1.5e-3
    max_damping_ratio: float = 0.5

    def __post_init__(self) -> None:
        for name in ("rigid_fraction", "max_constraint_ratio", "max_damping_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise FpmSimError(f"ModeFilter.{name} must be a finite number >= 0, got {v!r}")


@dataclass
class Mode:
    """One physical mode.

    Attributes
    ----------
    frequency_hz
        Undamped natural frequency.
    damping_ratio
        Viscous damping ratio.
    shape
        Generalised shape (one entry per degree of freedom), real, max-abs normalised to 1.
    character
        Fraction of the mode's strain energy in each spring kind (bend_in, bend_out, twist, ...).
    constraint_ratio
        Loop-closure violation of the shape (``|J v| / (|J|_2 |v|)``).
    """

    frequency_hz: float
    damping_ratio: float
    shape: np.ndarray
    character: dict[str, float]
    constraint_ratio: float

    @property
    def dominant(self) -> str:
        return max(self.character, key=self.character.__getitem__) if self.character else "-"


@dataclass
class ModalResult:
    """Modes of one model by one method, with what was dropped and why."""

    method: str
    built: BuiltModel
    qpos: np.ndarray
    modes: list[Mode]
    dropped: dict[str, int] = field(default_factory=dict)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.array([m.frequency_hz for m in self.modes])

    @property
    def damping_ratios(self) -> np.ndarray:
        return np.array([m.damping_ratio for m in self.modes])

    def point_displacements(self, index: int) -> dict[str, np.ndarray]:
        """Cartesian displacement (m per unit generalised amplitude) of points along each link.

        Returns link name -> array (n_points, 3), points from the link's start to its end.
        """
        model = self.built.model
        data = mujoco.MjData(model)
        data.qpos[:] = self.qpos
        mujoco.mj_forward(model, data)
        v = self.modes[index].shape
        jacp = np.zeros((3, model.nv))
        out: dict[str, np.ndarray] = {}
        for link, sites in self.built.links.items():
            pts = []
            for s in sites:
                sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
                mujoco.mj_jacSite(model, data, jacp, None, sid)
                pts.append(jacp @ v)
            out[link] = np.array(pts)
        return out

    def point_positions(self) -> dict[str, np.ndarray]:
        """Positions (m) of the same points at the equilibrium."""
        model = self.built.model
        data = mujoco.MjData(model)
        data.qpos[:] = self.qpos
        mujoco.mj_forward(model, data)
        return {link: np.array([data.site(s).xpos.copy() for s in sites]) for link, sites in self.built.links.items()}

    def to_dict(self, n_modes: int | None = None) -> dict[str, Any]:
        """JSON-ready modes (frequency Hz, damping ratio, character), what was dropped, the resolution."""
        from fpm_sim.model.options import resolution_of_parameters

        modes = self.modes[:n_modes] if n_modes else self.modes
        return {
            "method": self.method,
            "modes": [
                {
                    "frequency_hz": m.frequency_hz,
                    "damping_ratio": m.damping_ratio,
                    "dominant": m.dominant,
                    "character": {k: round(v, 4) for k, v in m.character.items()},
                }
                for m in modes
            ],
            "dropped": dict(self.dropped),
            "resolution": resolution_of_parameters(self.built.parameters),
            "parameters": self.built.parameters,
        }

    def table(self, n_modes: int | None = None) -> str:
        """A plain-text table of the modes, ending with the model's resolution (segments per link and the
        estimated discretisation error of f1) where the model records it."""
        from fpm_sim.model.options import resolution_footer

        modes = self.modes[:n_modes] if n_modes else self.modes
        lines = [f"{'mode':>4}  {'freq (Hz)':>11}  {'damping':>8}  {'character':<30}"]
        for i, m in enumerate(modes, 1):
            top = sorted(m.character.items(), key=lambda kv: -kv[1])[:2]
            char = ", ".join(f"{k} {v:.0%}" for k, v in top if v > 0.005)
            lines.append(f"{i:>4}  {m.frequency_hz:>11.3f}  {m.damping_ratio:>8.4f}  {char:<30}")
        footer = resolution_footer(self.built.parameters)
        return "\n".join([*lines, footer] if footer else lines)

    def plot(self, ax: Any = None, *, index: int | None = None, n_modes: int = 1, scale_m: float = 0.03) -> Any:
        """Draw mode shapes in 3D over the equilibrium shape (matplotlib); returns the ``Figure``.

        Parameters
        ----------
        ax
            A 3D axes (``projection="3d"``) to draw mode ``index`` (default 0) on; ``None`` makes a new
            figure with the first ``n_modes`` modes side by side (or mode ``index`` alone).
        index
            The mode to draw (0-based).
        n_modes
            Modes drawn on a new figure when ``index`` is not given.
        scale_m
            Drawn length of the largest point displacement (m); out-of-plane modes show along z.
        """
        import matplotlib.pyplot as plt

        if ax is not None:
            self._plot_mode(ax, 0 if index is None else index, scale_m)
            return ax.figure
        indices = [index] if index is not None else list(range(max(1, min(n_modes, len(self.modes)))))
        fig = plt.figure(figsize=(4.5 * len(indices), 4.5))
        for k, i in enumerate(indices):
            self._plot_mode(fig.add_subplot(1, len(indices), k + 1, projection="3d"), i, scale_m)
        fig.tight_layout()
        return fig

    def _plot_mode(self, ax: Any, index: int, scale_m: float) -> None:
        pos = self.point_positions()
        disp = self.point_displacements(index)
        peak = max(float(np.max(np.linalg.norm(d, axis=1))) for d in disp.values()) or 1.0
        ends, ends0 = [], []
        for k, (link, p) in enumerate(pos.items()):
            ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.55", lw=1, ls="--", label="equilibrium" if k == 0 else None)
            q = p + disp[link] * (scale_m / peak)
            label = f"mode shape (largest displacement drawn {scale_m * 1e3:g} mm)" if k == 0 else None
            ax.plot(q[:, 0], q[:, 1], q[:, 2], lw=2, color="C0", label=label)
            if link.startswith("distal"):
                ends.append(q[-1])
                ends0.append(p[-1])
        if len(ends) == 3:  # the platform triangle through the platform joints, deformed and at equilibrium
            tri0 = np.array(ends0 + ends0[:1])
            ax.plot(tri0[:, 0], tri0[:, 1], tri0[:, 2], color="0.55", lw=1, ls="--")
            tri = np.array(ends + ends[:1])
            ax.plot(tri[:, 0], tri[:, 1], tri[:, 2], color="k", lw=1.5, label="platform")
        ax.legend(fontsize=7, loc="upper left")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        span = max(float(np.ptp(np.concatenate(list(pos.values()))[:, :2], axis=0).max()), 1e-3)
        ax.set_zlim(-span / 2, span / 2)
        m = self.modes[index]
        ax.set_title(f"mode {index + 1}: {m.frequency_hz:.2f} Hz, {m.dominant}")


# ---------------------------------------------------------------------------------------------
# building blocks


def _forward_at(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, qvel: np.ndarray | None = None) -> None:
    data.qpos[:] = qpos
    data.qvel[:] = 0.0 if qvel is None else qvel
    mujoco.mj_forward(model, data)


def mass_matrix(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """Dense joint-space inertia matrix after a forward pass."""
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    return mass


def stiffness_matrix(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """Tangent stiffness ``-d/dq [qfrc_passive - qfrc_bias + J(q)^T lambda*]`` at ``qpos``, zero velocity.

    ``lambda*`` (the equality-constraint forces at ``qpos``) is held fixed so that the closed loop's
    prestress enters as geometric stiffness.
    """
    _forward_at(model, data, qpos)
    rows = np.asarray(data.efc_type[: data.nefc]) == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    lam = np.asarray(data.efc_force[: data.nefc])[rows].copy()

    def force(q: np.ndarray) -> np.ndarray:
        # position and velocity stages only: forces and efc_J need no constraint solve
        data.qpos[:] = q
        data.qvel[:] = 0.0
        mujoco.mj_fwdPosition(model, data)
        mujoco.mj_fwdVelocity(model, data)
        f: np.ndarray = data.qfrc_passive - data.qfrc_bias
        if lam.size:
            f = f + equality_jacobian(model, data).T @ lam
        return f

    k = -tangent_jacobian(model, qpos, force, eps)
    sym: np.ndarray = 0.5 * (k + k.T)
    return sym


def damping_matrix(model: mujoco.MjModel) -> np.ndarray:
    """``-d qfrc_passive / d qdot``: the joint dampers, the only velocity-dependent passive forces of
    the generated models (no fluid, no tendons)."""
    return np.diag(np.asarray(model.dof_damping, float))


def _energy_stiffness(model: mujoco.MjModel) -> np.ndarray:
    """Per-dof stiffness that splits a mode's strain energy by kind: the joint springs, or for
    ``cable``/``flex`` links the diagonal of the passive stiffness at ``qpos0`` (an estimate: it
    leaves out the coupling terms)."""
    if has_internal_elasticity(model):
        return np.clip(np.diag(passive_stiffness_matrix(model)), 0.0, None)
    return dof_stiffness(model)


def _character(shape: np.ndarray, k_dof: np.ndarray, kinds: list[str]) -> dict[str, float]:
    energy = 0.5 * k_dof * shape**2
    total = float(energy.sum())
    out: dict[str, float] = {}
    if total <= 0.0:
        return out
    for kind, e in zip(kinds, energy):
        if e > 0:
            out[kind] = out.get(kind, 0.0) + float(e) / total
    return out


def _real_shape(v: np.ndarray) -> np.ndarray:
    """Rotate a complex shape to its dominant real form, max-abs normalised with a positive peak."""
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) == 0.0:
        return np.real(v)
    r = np.real(v * np.conj(v[k]) / abs(v[k]))
    normalised: np.ndarray = r / r[k]
    return normalised


def system_damping_matrix(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """The model's full viscous damping ``-d qfrc_passive / d qdot`` at ``qpos``: the joint dampers
    (:func:`damping_matrix`), or for ``cable``/``flex`` links the differentiated passive forces (the
    cable joints' and the flex's own damping), as :func:`modes_constrained` uses."""
    if has_internal_elasticity(model):
        return passive_damping_matrix(model, qpos)
    return damping_matrix(model)


def check_n_modes(n_modes: int | None, available: int, *, name: str = "n_modes") -> None:
    """``n_modes`` must be ``None`` (all) or an integer in ``[1, available]`` (the model's degrees of freedom).

    Raises
    ------
    FpmSimError
        Naming ``name`` and the allowed range.
    """
    if n_modes is not None:
        check_count(name, n_modes, low=1, high=available, hint=" (the model's degrees of freedom)")


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
    jac: np.ndarray, row_scale: np.ndarray, col_scale: np.ndarray, *, rcond: float = NULLSPACE_RCOND,
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
    rank decision of the package: the ``cpu`` path (:func:`reduced_eigenproblem`) and the ``mjx``
    backend both use it.

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


def reference_frequency_hz(model: mujoco.MjModel, mass: np.ndarray) -> float:
    """The model's own frequency scale (Hz): the lowest uncoupled spring frequency ``min sqrt(k_i / M_ii) / 2 pi``
    over the degrees of freedom that carry a spring (:func:`_energy_stiffness`); 0 without springs.

    Measured: 51 Hz for the manipulator at 12 segments (first mode 70-75 Hz), 28 Hz at 3 segments,
    401 Hz for the cantilever rig (first mode 221 Hz), 281 Hz for the free-free bar (985 Hz).
    """
    k = _energy_stiffness(model)
    m = np.diag(mass)
    live = (k > 0) & (m > 0)
    if not np.any(live):
        return 0.0
    return float(np.sqrt(np.min(k[live] / m[live])) / (2 * np.pi))


def noise_w2(model: mujoco.MjModel, mass: np.ndarray, filt: ModeFilter, fd_noise: float = 0.0) -> float:
    """``w2_tol`` (rad^2/s^2): eigenvalues within ``+-w2_tol`` of zero carry no strain energy to within the
    computation's noise (module docstring); ``fd_noise = |x'(K(e) - K(2e))x|`` for an ``M``-normalised shape."""
    w_ref = 2 * np.pi * reference_frequency_hz(model, mass)
    return max((filt.rigid_fraction * w_ref) ** 2, FD_NOISE_MARGIN * fd_noise)


def _constraint_ratio(jac: np.ndarray, jnorm: float, v: np.ndarray) -> float:
    if jac.shape[0] == 0 or jnorm == 0.0:
        return 0.0
    return float(np.linalg.norm(jac @ v) / (jnorm * np.linalg.norm(v)))


def _classify(w2: float, w2_tol: float, zeta: float, ratio: float, filt: ModeFilter) -> str | None:
    if abs(w2) <= w2_tol:
        return "rigid_body"
    if ratio > filt.max_constraint_ratio:
        return "constraint"
    if zeta > filt.max_damping_ratio:
        return "overdamped"
    return None


def _finish(result: ModalResult, n_modes: int | None, *, stacklevel: int) -> ModalResult:
    """Truncate to ``n_modes``, say when fewer physical modes exist, and warn about a near-singular pose."""
    if n_modes is not None:
        if len(result.modes) < n_modes:
            warnings.warn(
                f"n_modes={n_modes} asked for, but the model has only {len(result.modes)} physical modes "
                f"({result.method}; dropped: {result.dropped}); all are reported",
                FpmSimWarning,
                stacklevel=stacklevel,
            )
        result.modes = result.modes[:n_modes]
    measure = result.built.parameters.get("singularity_measure")
    if result.modes and isinstance(measure, (int, float)) and measure < NEAR_SINGULAR_WARN:
        m1 = result.modes[0]
        warnings.warn(
            f"the pose is near a parallel singularity (measure {measure:.3g} < {NEAR_SINGULAR_WARN:g}): mode 1 at "
            f"{m1.frequency_hz:.3g} Hz ({m1.dominant}) is a physical low mode whose stiffness vanishes at the "
            "singularity; it is very sensitive to the pose",
            NearSingularityWarning,
            stacklevel=stacklevel,
        )
    return result


# ---------------------------------------------------------------------------------------------
# the two methods


def modes_transition_fd(
    built: BuiltModel,
    *,
    n_modes: int | None = 10,
    eps: float = 1e-6,
    filt: ModeFilter | None = None,
    qpos: np.ndarray | None = None,
) -> ModalResult:
    """Modes from ``mjd_transitionFD`` (centred) at the static equilibrium (see module docstring).

    Parameters
    ----------
    n_modes
        Keep the lowest ``n_modes`` physical modes (``None``: all); an integer in ``[1, nv]``.
    eps
        Finite-difference step of ``mjd_transitionFD`` (rad, m, rad/s, m/s).
    qpos
        Linearisation point; default the static equilibrium under gravity.

    Raises
    ------
    UnstableModelError
        A mode grows (negative damping ratio beyond round-off, or a real eigenvalue growing faster
        than the rigid-body threshold): the equilibrium is unstable or the timestep too coarse.
    """
    filt = filt or ModeFilter()
    model = built.model
    check_n_modes(n_modes, model.nv)
    if not (math.isfinite(eps) and eps > 0):
        raise FpmSimError(f"eps must be a positive step, got {eps!r}")
    data = mujoco.MjData(model)
    q_eq = static_equilibrium(model, data) if qpos is None else np.asarray(qpos, float)
    _forward_at(model, data, q_eq)
    rank = constraint_rank(model, data, warn=False)
    jac = _scaled_jacobian(model, data, rank.length_m)
    jnorm = float(np.linalg.norm(jac, 2)) if jac.size else 0.0
    mass = mass_matrix(model, data)
    w_tol = float(np.sqrt(noise_w2(model, mass, filt)))
    nx = 2 * model.nv + model.na
    a = np.zeros((nx, nx))
    mujoco.mjd_transitionFD(model, data, eps, True, a, None, None, None)
    if not np.all(np.isfinite(a)):
        raise UnstableModelError(
            "the linearised step map has non-finite entries (the simulation diverges at the equilibrium); "
            "check the description (thickness, Young's modulus, masses) or pass a smaller timestep_s"
        )
    lam, vec = np.linalg.eig(a)
    h = model.opt.timestep
    with np.errstate(divide="ignore", invalid="ignore"):  # lambda = 0: an infinitely damped state, s = -inf
        s = np.log(lam.astype(complex)) / h
    k_dof = _energy_stiffness(model)
    dropped: dict[str, int] = {}
    modes: list[Mode] = []
    growing: list[str] = []
    for idx in np.argsort(np.abs(s)):
        si = s[idx]
        if not np.isfinite(si):
            dropped["non_oscillatory"] = dropped.get("non_oscillatory", 0) + 1
            continue
        if si.imag <= 1e-9 * max(abs(si), 1.0):
            if si.imag < -1e-9 * max(abs(si), 1.0):
                continue  # the conjugate of a kept mode
            if si.real > w_tol:
                growing.append(f"real growth rate {si.real:.3g} 1/s")
            dropped["non_oscillatory"] = dropped.get("non_oscillatory", 0) + 1
            continue
        w = abs(si)
        f_hz, zeta = w / (2 * np.pi), float(-si.real / w)
        shape_c = vec[: model.nv, idx]
        ratio = _constraint_ratio(jac, jnorm, _real_shape(shape_c))
        reason = _classify(w**2, w_tol**2, zeta, ratio, filt)
        if reason is None and zeta < -NEGATIVE_DAMPING_TOL:
            growing.append(f"damping ratio {zeta:.3g} at {f_hz:.4g} Hz")
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
            continue
        shape = _real_shape(shape_c)
        modes.append(Mode(f_hz, zeta, shape, _character(shape, k_dof, built.dof_kinds), ratio))
    if growing:
        raise UnstableModelError(
            f"{len(growing)} mode(s) of the linearised step map grow ({'; '.join(growing[:3])}): the equilibrium "
            f"is unstable or timestep_s={h:.3g} s is too coarse for the stiffest springs; check the description "
            "(section thickness, Young's modulus, masses) or pass a smaller timestep_s"
        )
    result = _finish(ModalResult("transition_fd", built, q_eq, modes, dropped), n_modes, stacklevel=3)
    if result.modes:
        w_top = 2 * np.pi * result.modes[-1].frequency_hz
        if w_top * h > OMEGA_H_WARN:
            warnings.warn(
                f"timestep_s={h:.3g} s is coarse for the reported band up to {result.modes[-1].frequency_hz:.0f} Hz "
                f"(omega*h = {w_top * h:.2f} > {OMEGA_H_WARN}); pass a smaller timestep_s (<= "
                f"{OMEGA_H_WARN / w_top:.2g} s) or report fewer modes",
                TimestepWarning,
                stacklevel=2,
            )
    return result


def _scaled_jacobian(model: mujoco.MjModel, data: mujoco.MjData, length_m: float) -> np.ndarray:
    """The equality Jacobian in consistent units (rows of constraint_rank's ``R J C``) acting on the
    model's own coordinates: ``R J`` (the shape stays in model units; used for the constraint ratio)."""
    jac = equality_jacobian(model, data)
    if jac.shape[0] == 0:
        return jac
    row_scale, _ = unit_scales(model, data, length_m)
    scaled: np.ndarray = row_scale[:, None] * jac
    return scaled


def modes_constrained(
    built: BuiltModel,
    *,
    n_modes: int | None = 10,
    filt: ModeFilter | None = None,
    qpos: np.ndarray | None = None,
) -> ModalResult:
    """Modes from the constrained generalised eigenproblem (see module docstring).

    Raises
    ------
    UnstableModelError
        A stiffness eigenvalue below ``-w2_tol`` (:func:`noise_w2`): the equilibrium is unstable.
    """
    filt = filt or ModeFilter()
    model = built.model
    check_n_modes(n_modes, model.nv)
    data = mujoco.MjData(model)
    q_eq = static_equilibrium(model, data) if qpos is None else np.asarray(qpos, float)
    if built.floating:
        # floating rig: linearise in the tangent space at qpos0 (no gravity by construction)
        q_eq = model.qpos0.copy()
        return _constrained_floating(built, q_eq, n_modes, filt)
    _forward_at(model, data, q_eq)
    mass = mass_matrix(model, data)
    rank = constraint_rank(model, data)
    stiff = stiffness_matrix(model, data, q_eq)

    def change() -> np.ndarray:  # the finite differences' noise, measured only when a mode needs it
        diff: np.ndarray = stiff - stiffness_matrix(model, mujoco.MjData(model), q_eq, eps=2e-7)
        return diff

    damp = system_damping_matrix(model, q_eq)
    return _solve_reduced(built, q_eq, mass, stiff, change, damp, rank.basis, n_modes, filt)


def _constrained_floating(built: BuiltModel, q0: np.ndarray, n_modes: int | None, filt: ModeFilter) -> ModalResult:
    """Floating models have no constraints here: K from the spring stiffness (no gravity), M at qpos0."""
    model = built.model
    data = mujoco.MjData(model)
    _forward_at(model, data, q0)
    mass = mass_matrix(model, data)
    # joint springs only: the diagonal; a cable plugin's torques: differentiated (no gravity here)
    internal = has_internal_elasticity(model)
    stiff = passive_stiffness_matrix(model, q0) if internal else np.diag(dof_stiffness(model))

    def noise() -> np.ndarray:
        diff: np.ndarray = stiff - passive_stiffness_matrix(model, q0, eps=2e-7)
        return diff

    change = noise if internal else None  # joint springs alone: an exact diagonal, no noise
    damp = system_damping_matrix(model, q0)
    return _solve_reduced(built, q0, mass, stiff, change, damp, np.eye(model.nv), n_modes, filt)


def reduced_eigenproblem(
    mass: np.ndarray, stiff: np.ndarray, basis: np.ndarray, *, n_modes: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The constrained generalised eigenproblem ``Z'KZ x = w^2 Z'MZ x`` on the admissible motions ``Z``.

    ``basis`` is ``Z``: :attr:`ConstraintRank.basis` from :func:`constraint_rank` (the one rank
    decision), or the identity for an unconstrained model. ``n_modes``: only the lowest ``n_modes``
    eigenpairs (LAPACK's subset driver; the pose loop's floor); default all.

    Returns ``(z, kr, mr, w2, x)``: the null-space basis, the symmetrised reduced stiffness and mass,
    the eigenvalues ``w^2`` (ascending) and the ``mr``-normalised eigenvectors.
    """
    z = np.asarray(basis, float)
    kr = z.T @ stiff @ z
    kr = 0.5 * (kr + kr.T)
    mr = z.T @ mass @ z
    mr = 0.5 * (mr + mr.T)
    try:
        if n_modes is not None and 0 < n_modes < kr.shape[0]:
            w2, x = scipy.linalg.eigh(kr, mr, subset_by_index=[0, n_modes - 1])
        else:
            w2, x = scipy.linalg.eigh(kr, mr)
    except np.linalg.LinAlgError as e:
        m = np.diag(mass)
        raise FpmSimError(
            f"the mass matrix is not positive definite to working precision (diagonal from {m.min():.3g} to "
            f"{m.max():.3g} kg or kg m^2): masses span too many orders of magnitude; check hardware masses "
            "(hardware.*.mass_kg), material.density_kg_m3 and the section"
        ) from e
    return z, kr, mr, w2, x


def eigenvalue_tolerances(
    model: mujoco.MjModel,
    mass: np.ndarray,
    shapes: np.ndarray,
    w2: np.ndarray,
    stiff_change: Callable[[], np.ndarray] | None,
    filt: ModeFilter,
) -> np.ndarray:
    """Per-mode ``w2_tol`` (:func:`noise_w2`) of the eigenvalues ``w2`` with ``M``-normalised full-space shapes
    ``shapes`` (columns). ``stiff_change() = K(e) - K(2e)`` (``None``: an exact stiffness, no finite-difference
    noise) is evaluated only when a mode lies below a tenth of the reference frequency (one more stiffness
    evaluation): above it the noise (measured 1e-4 rad^2/s^2) is below 1e-6 of ``w^2`` and cannot change a
    classification."""
    w_ref = 2 * np.pi * reference_frequency_hz(model, mass)
    if stiff_change is None or np.min(w2) > (0.1 * w_ref) ** 2:
        fd = np.zeros(shapes.shape[1])
    else:
        fd = np.abs(np.einsum("ik,ij,jk->k", shapes, stiff_change(), shapes))
    return np.array([noise_w2(model, mass, filt, float(v)) for v in fd])


def check_stable(w2: np.ndarray, tol: np.ndarray, *, what: str = "the equilibrium") -> None:
    """Raise :class:`UnstableModelError` when an eigenvalue lies below ``-tol`` (never clipped to zero)."""
    bad = w2 < -tol
    if np.any(bad):
        worst = float(np.min(w2[bad]))
        raise UnstableModelError(
            f"{what} is unstable: {int(np.sum(bad))} negative stiffness eigenvalue(s), the most negative "
            f"{worst:.4g} rad^2/s^2 (growth time {1.0 / math.sqrt(-worst):.3g} s), beyond the round-off bound "
            f"{float(np.max(tol[bad])):.2g}; the structure buckles under gravity or the compliances are too soft "
            "(check section, material, hardware masses and compliance)"
        )


def _solve_reduced(
    built: BuiltModel,
    q_eq: np.ndarray,
    mass: np.ndarray,
    stiff: np.ndarray,
    stiff_change: Callable[[], np.ndarray] | None,
    damp: np.ndarray,
    basis: np.ndarray,
    n_modes: int | None,
    filt: ModeFilter,
) -> ModalResult:
    z, _, _, w2, x = reduced_eigenproblem(mass, stiff, basis)
    cr = z.T @ damp @ z
    k_dof = _energy_stiffness(built.model)
    tol = eigenvalue_tolerances(built.model, mass, z @ x, w2, stiff_change, filt)
    check_stable(w2, tol)
    dropped: dict[str, int] = {}
    modes: list[Mode] = []
    for i in range(len(w2)):
        w = float(np.sqrt(max(w2[i], 0.0)))
        f_hz = w / (2 * np.pi)
        xi = x[:, i]  # M-normalised by eigh
        zeta = float(xi @ cr @ xi / (2 * w)) if w > 0 else 0.0
        reason = _classify(float(w2[i]), float(tol[i]), zeta, 0.0, filt)
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
            continue
        shape = _real_shape(z @ xi)
        modes.append(Mode(f_hz, zeta, shape, _character(shape, k_dof, built.dof_kinds), 0.0))
    return _finish(ModalResult("constrained", built, q_eq, modes, dropped), n_modes, stacklevel=4)
