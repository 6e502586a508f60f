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

The modes kept are the physical ones (:mod:`fpm_sim.linear.mode_filter`); the equality Jacobian's rank is
decided in consistent units (:mod:`fpm_sim.linear.nullspace`).

Timestep: the step map (semi-implicit Euler on the springs) raises an undamped mode's frequency by
``(omega h)^2 / 24`` relative (``cos(omega' h) = 1 - (omega h)^2 / 2``; measured 0.071 % at
``omega h = 0.130`` against 0.070 % predicted); :func:`modes_transition_fd` warns
(:class:`TimestepWarning`) when a reported mode has ``omega h > OMEGA_H_WARN`` (error > 0.4 %).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import warnings
from collections.abc import Callable
from typing import Literal

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.config.checks import check_count
from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.kinematics import NEAR_SINGULAR_WARN, NearSingularityWarning
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.linear.matrices import energy_stiffness, forward_at, mass_matrix, stiffness_matrix, system_damping_matrix
from fpm_sim.linear.mode_filter import (
    NEGATIVE_DAMPING_TOL,
    ModeFilter,
    UnstableModelError,
    check_stable,
    classify,
    eigenvalue_tolerances,
    noise_w2,
)
from fpm_sim.linear.modes import ModalResult, Mode, real_shape, strain_energy_character
from fpm_sim.linear.nullspace import constraint_rank, constraint_ratio, scaled_jacobian
from fpm_sim.model.passive import dof_stiffness, has_internal_elasticity, passive_stiffness_matrix
from fpm_sim.model.spec import BuiltModel

__all__ = [
    "OMEGA_H_WARN",
    "STEP_HALVINGS",
    "BucklingError",
    "CoarseTimestepError",
    "StepMapError",
    "TimestepWarning",
    "check_n_modes",
    "growth_error",
    "modes_constrained",
    "modes_transition_fd",
    "reduced_eigenproblem",
]


OMEGA_H_WARN = 0.3
"""``omega * h`` above which a reported frequency carries more than ~0.4 % timestep error."""


Method = Literal["transition_fd", "constrained"]


class TimestepWarning(FpmSimWarning):
    """The timestep is too coarse for the frequency band being reported."""


def check_n_modes(n_modes: int | None, available: int, *, name: str = "n_modes") -> None:
    """``n_modes`` must be ``None`` (all) or an integer in ``[1, available]`` (the model's degrees of freedom).

    Raises
    ------
    FpmSimError
        Naming ``name`` and the allowed range.
    """
    if n_modes is not None:
        check_count(name, n_modes, low=1, high=available, hint=" (the model's degrees of freedom)")


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
        than the rigid-body threshold): :func:`growth_error` says which of the equilibrium
        (:class:`BucklingError`), the step (:class:`CoarseTimestepError`) or the finite-difference
        linearisation itself (:class:`StepMapError`) it is.
    """
    filt = filt or ModeFilter()
    model = built.model
    check_n_modes(n_modes, model.nv)
    if not (math.isfinite(eps) and eps > 0):
        raise FpmSimError(f"eps must be a positive step, got {eps!r}")
    q_eq = static_equilibrium(model, mujoco.MjData(model)) if qpos is None else np.asarray(qpos, float)
    modes, dropped, growing = _step_map_modes(built, *_linearise(model, q_eq, eps, filt), filt)
    if growing:
        raise growth_error(built, q_eq, growing, eps=eps, filt=filt)
    h = model.opt.timestep
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


def _linearise(
    model: mujoco.MjModel, q_eq: np.ndarray, eps: float, filt: ModeFilter
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """At ``q_eq``: the step map ``a`` of ``mjd_transitionFD``, the equality Jacobian in consistent units, its norm
    and the rigid-body threshold ``w_tol`` (rad/s)."""
    data = mujoco.MjData(model)
    forward_at(model, data, q_eq)
    rank = constraint_rank(model, data, warn=False)
    jac = scaled_jacobian(model, data, rank.length_m)
    jnorm = float(np.linalg.norm(jac, 2)) if jac.size else 0.0
    w_tol = float(np.sqrt(noise_w2(model, mass_matrix(model, data), filt)))
    nx = 2 * model.nv + model.na
    a = np.zeros((nx, nx))
    mujoco.mjd_transitionFD(model, data, eps, True, a, None, None, None)
    return a, jac, jnorm, w_tol


def _step_map_modes(
    built: BuiltModel, a: np.ndarray, jac: np.ndarray, jnorm: float, w_tol: float, filt: ModeFilter
) -> tuple[list[Mode], dict[str, int], list[str]]:
    """The physical modes of the step map ``a`` (one of each conjugate pair, by ascending ``|s|``), the count
    of each dropped kind, and what grows (a real eigenvalue above ``w_tol``, a damping ratio below
    ``-NEGATIVE_DAMPING_TOL``, non-finite entries), in words: empty when nothing does."""
    model = built.model
    if not np.all(np.isfinite(a)):
        return [], {}, ["non-finite entries: the simulation diverges at the equilibrium"]
    lam, vec = np.linalg.eig(a)
    h = model.opt.timestep
    with np.errstate(divide="ignore", invalid="ignore"):  # lambda = 0: an infinitely damped state, s = -inf
        s = np.log(lam.astype(complex)) / h
    k_dof = energy_stiffness(model)
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
        ratio = constraint_ratio(jac, jnorm, real_shape(shape_c))
        reason = classify(w**2, w_tol**2, zeta, ratio, filt)
        if reason is None and zeta < -NEGATIVE_DAMPING_TOL:
            growing.append(f"damping ratio {zeta:.3g} at {f_hz:.4g} Hz")
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
            continue
        shape = real_shape(shape_c)
        modes.append(Mode(f_hz, zeta, shape, strain_energy_character(shape, k_dof, built.dof_kinds), ratio))
    return modes, dropped, growing


class BucklingError(UnstableModelError):
    """The equilibrium itself is unstable: its stiffness has a negative eigenvalue, found by the constrained
    eigen-solve (no time step), so no ``timestep_s`` helps; under gravity's prestress when the same model without
    gravity is stable (the message then gives its f1)."""


class CoarseTimestepError(UnstableModelError):
    """The equilibrium is stable (the constrained eigen-solve, no time step) but the step map grows at this
    ``timestep_s``; the hint names a step whose step map was checked not to grow."""


class StepMapError(UnstableModelError):
    """The equilibrium is stable, but the step map grows at every step tried: the finite-difference linearisation
    (``transition_fd``) is unreliable for this model; the constrained eigen-solve is the one to use."""


STEP_HALVINGS = 4
"""Steps tried by :func:`growth_error` below the one that grew: ``h/2`` ... ``h/2**STEP_HALVINGS``."""


def growth_error(
    built: BuiltModel, q_eq: np.ndarray, growing: list[str], *, eps: float = 1e-6, filt: ModeFilter | None = None
) -> UnstableModelError:
    """The error for a step map that grows at the equilibrium ``q_eq``, saying which cause it is (never "or").

    The constrained eigen-solve at the same equilibrium decides, with no time step involved: a negative stiffness
    eigenvalue is the structure's own instability (:class:`BucklingError`: under gravity's prestress, with the
    pose's singularity measure and f1 without gravity, when the model is stable without gravity). Otherwise the
    step is the cause: the steps ``h/2``, ``h/4``, ... (:data:`STEP_HALVINGS` of them) are tried, each with the
    weld time constant ``2 h`` that compilation ties to the step, and the first whose step map does not grow is
    named (:class:`CoarseTimestepError`); when none works the linearisation itself is (:class:`StepMapError`).
    """
    filt = filt or ModeFilter()
    grows = f"{len(growing)} mode(s) of the linearised step map grow ({'; '.join(growing[:3])})"
    with warnings.catch_warnings():  # the diagnosis would repeat the first solve's warnings
        warnings.simplefilter("ignore")
        try:
            exact = modes_constrained(built, n_modes=1, qpos=q_eq, filt=filt)
        except UnstableModelError as exc:
            return _buckling_error(built, grows, exc.worst_w2, filt)
        return _step_error(built, q_eq, grows, exact, eps, filt)


def _buckling_error(built: BuiltModel, grows: str, worst_w2: float | None, filt: ModeFilter) -> BucklingError:
    negative = "a negative eigenvalue" + (f" ({worst_w2:.3g} rad^2/s^2)" if worst_w2 is not None else "")
    measure = built.parameters.get("singularity_measure")
    at = f" (singularity measure {measure:.3g})" if isinstance(measure, (int, float)) else ""
    gravity = bool(np.any(built.model.opt.gravity != 0.0))
    f1_free = _f1_without_gravity(built, filt) if gravity else None
    if f1_free is not None:
        return BucklingError(
            f"the structure buckles under gravity's prestress at this pose{at}: at its static equilibrium the "
            f"gravity-prestressed stiffness has {negative} (constrained eigen-solve, no time step), while without "
            f"gravity it is stable with f1 = {f1_free:.3g} Hz; {grows}, and no timestep_s helps",
            hint="move the pose away from the singularity, lighten the moving masses (the 3RRR's hardware.*.mass_kg, "
            "a described or imported machine's lumps) or stiffen the links (their sections); gravity off gives the "
            "unloaded modes",
        )
    return BucklingError(
        f"the structure is unstable at this pose{at}{' even without gravity' if gravity else ''}: at its "
        f"equilibrium the stiffness has {negative} (constrained eigen-solve, no time step); {grows}, and no "
        "timestep_s helps",
        hint="check the description's sections, materials, compliances and masses (the 3RRR's section.*, "
        "material.*, compliance.*, hardware.*.mass_kg)",
    )


def _f1_without_gravity(built: BuiltModel, filt: ModeFilter) -> float | None:
    """f1 (Hz) of the same model with gravity off (the constrained eigen-solve), ``None`` if it is unstable too."""
    model = copy.copy(built.model)
    model.opt.gravity[:] = 0.0
    try:
        free = modes_constrained(dataclasses.replace(built, model=model), n_modes=1, filt=filt)
    except UnstableModelError:
        return None
    return free.modes[0].frequency_hz if free.modes else math.nan


def _step_error(
    built: BuiltModel, q_eq: np.ndarray, grows: str, exact: ModalResult, eps: float, filt: ModeFilter
) -> UnstableModelError:
    h = float(built.model.opt.timestep)
    f1 = exact.modes[0].frequency_hz if exact.modes else math.nan
    stable = f"the equilibrium is stable (constrained eigen-solve, no time step: f1 = {f1:.4g} Hz)"
    h_try = h
    for k in range(1, STEP_HALVINGS + 1):
        h_try = float(f"{h / 2**k:.2g}")
        if not _grows_at(built, q_eq, h_try, eps, filt):
            return CoarseTimestepError(
                f"{h:.3g} s is too coarse for this model at this pose: {grows}, while {stable}",
                parameter="timestep_s",
                hint=f"timestep_s={h_try:.2g} s works (its step map checked: no mode grows)",
            )
    return StepMapError(
        f"the finite-difference linearisation is unreliable for this model: {grows} at timestep_s={h:.3g} s and at "
        f"every step down to {h_try:.2g} s, while {stable}",
        parameter="method",
        hint="use method 'constrained' (the exact eigen-solve, no time step)",
    )


def _grows_at(built: BuiltModel, q_eq: np.ndarray, h: float, eps: float, filt: ModeFilter) -> bool:
    """Whether the step map at ``q_eq`` grows at the step ``h`` (weld time constant ``2 h``, as compiled)."""
    model = copy.copy(built.model)
    model.opt.timestep = h
    model.eq_solref[:, 0] = 2.0 * h
    at_h = dataclasses.replace(built, model=model)
    return bool(_step_map_modes(at_h, *_linearise(model, q_eq, eps, filt), filt)[2])


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
        A stiffness eigenvalue below ``-w2_tol`` (:func:`~fpm_sim.linear.mode_filter.noise_w2`): the equilibrium is
        unstable.
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
    forward_at(model, data, q_eq)
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
    forward_at(model, data, q0)
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

    ``basis`` is ``Z``: :attr:`~fpm_sim.linear.nullspace.ConstraintRank.basis` from
    :func:`~fpm_sim.linear.nullspace.constraint_rank` (the one rank decision), or the identity for an
    unconstrained model. ``n_modes``: only the lowest ``n_modes`` eigenpairs (LAPACK's subset driver; the pose
    loop's floor); default all.

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
    k_dof = energy_stiffness(built.model)
    tol = eigenvalue_tolerances(built.model, mass, z @ x, w2, stiff_change, filt)
    check_stable(w2, tol)
    dropped: dict[str, int] = {}
    modes: list[Mode] = []
    for i in range(len(w2)):
        w = float(np.sqrt(max(w2[i], 0.0)))
        f_hz = w / (2 * np.pi)
        xi = x[:, i]  # M-normalised by eigh
        zeta = float(xi @ cr @ xi / (2 * w)) if w > 0 else 0.0
        reason = classify(float(w2[i]), float(tol[i]), zeta, 0.0, filt)
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
            continue
        shape = real_shape(z @ xi)
        modes.append(Mode(f_hz, zeta, shape, strain_energy_character(shape, k_dof, built.dof_kinds), 0.0))
    return _finish(ModalResult("constrained", built, q_eq, modes, dropped), n_modes, stacklevel=4)
