"""Static equilibrium of a generated model under gravity (the linearisation point).

Solves the hard-constraint statics

    f(q) + J(q)^T lam = 0,    r(q) = 0,

with ``f = qfrc_smooth`` at zero velocity (springs, gravity and any loads the caller put in
``data.qfrc_applied``, ``data.xfrc_applied`` or ``data.ctrl``) and ``r``, ``J`` the
equality-constraint residual (``efc_pos``) and Jacobian (``efc_J``) of the loop closures, by a
Newton-KKT iteration whose tangent stiffness ``K = -df/dq`` (centred differences) is taken once at
``qpos0`` (the springs are linear; gravity's contribution barely changes over the sag).

Why not ``qacc = 0`` of the simulated model directly: MuJoCo's soft welds at the stiff limit make
``qacc`` depend on round-off in the constraint solver amplified by the weld stiffness (~1/(2h)^2);
for thin links the condition number of ``d qacc / d q`` reaches 1e11 and Newton on it diverged
(5 mm links, 12 segments, axial springs). The hard-constraint equilibrium differs from the soft one
by ``weld compliance x force`` (below 1e-9 m here) and is the state the linearisation needs:
prestressed, not drifting.
"""

from __future__ import annotations

import mujoco
import numpy as np

from fpm_sim.errors import FpmSimError
from fpm_sim.model.passive import tangent_jacobian

__all__ = ["EquilibriumError", "applied_forces", "equality_jacobian", "force_jacobian", "static_equilibrium"]


class EquilibriumError(FpmSimError, RuntimeError):
    """No static equilibrium found (buckling, a mechanism, or a floating model under gravity)."""


def _smooth(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray) -> None:
    """All stages but the constraint solve: kinematics, efc rows, and every non-constraint force."""
    data.qpos[:] = qpos
    data.qvel[:] = 0.0
    data.act[:] = 0.0
    mujoco.mj_fwdPosition(model, data)
    mujoco.mj_fwdVelocity(model, data)
    mujoco.mj_fwdActuation(model, data)
    mujoco.mj_fwdAcceleration(model, data)


def applied_forces(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray) -> np.ndarray:
    """``qfrc_smooth`` at ``qpos``, zero velocity: springs, gravity, ``qfrc_applied``,
    ``xfrc_applied`` and actuator forces (from ``data.ctrl``) — everything but the constraints."""
    _smooth(model, data, qpos)
    force: np.ndarray = data.qfrc_smooth.copy()
    return force


def force_jacobian(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """Centred finite-difference ``d f / d q`` of :func:`applied_forces`, in the tangent space."""
    return tangent_jacobian(model, qpos, lambda q: applied_forces(model, data, q), eps)


def _moved(model: mujoco.MjModel, qpos: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """``qpos`` moved by the tangent vector ``dq`` (plain addition for hinges and slides; quaternion
    integration for the ball joints of ``cable`` links)."""
    q = qpos.copy()
    mujoco.mj_integratePos(model, q, dq, 1.0)
    return q


def _constraints(
    model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(f, r, J)`` at ``qpos``: applied forces, equality residuals and their Jacobian."""
    f = applied_forces(model, data, qpos)
    rows = np.asarray(data.efc_type[: data.nefc]) == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    return f, np.asarray(data.efc_pos[: data.nefc])[rows].copy(), equality_jacobian(model, data)


def equality_jacobian(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """Rows of the (dense) constraint Jacobian that belong to equality constraints, after a forward pass."""
    rows = np.asarray(data.efc_type[: data.nefc]) == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    jac = np.asarray(data.efc_J[: data.nefc * model.nv]).reshape(data.nefc, model.nv)
    eq_rows: np.ndarray = jac[rows].copy()
    return eq_rows


def static_equilibrium(
    model: mujoco.MjModel,
    data: mujoco.MjData | None = None,
    *,
    rtol: float = 1e-9,
    pos_tol_m: float = 1e-12,
    step_tol: float = 1e-12,
    max_iter: int = 50,
) -> np.ndarray:
    """``qpos`` of the static equilibrium nearest ``qpos0`` (see module docstring).

    Parameters
    ----------
    model
        A model without free joints, or one without applied forces at ``qpos0`` (returned as is);
        ball joints (``cable`` links) are stepped in the tangent space.
    rtol
        Converged when the force imbalance ``|f + J^T lam|_inf`` is below ``rtol`` times ``|f(qpos0)|_inf``
        and the loop-closure residual below ``pos_tol_m``, ...
    step_tol
        ... or when an iteration moves no coordinate by more than ``step_tol`` (m or rad) with the loops
        closed: the imbalance has reached its round-off floor (flex bending forces: ~4e-7 relative).
    max_iter
        Newton-KKT iterations allowed.

    Raises
    ------
    EquilibriumError
        If a floating model carries loads, or the iteration does not converge.
    """
    data = data if data is not None else mujoco.MjData(model)
    q: np.ndarray = model.qpos0.copy()
    f, r, jac = _constraints(model, data, q)
    scale = float(np.max(np.abs(f))) if f.size else 0.0
    if scale < 1e-12 and (r.size == 0 or np.max(np.abs(r)) < pos_tol_m):
        return q
    if np.any(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
        raise EquilibriumError(
            "a floating model (free joint) has no static equilibrium under gravity; switch gravity off"
        )
    stiffness = -force_jacobian(model, data, q)
    nc = r.size
    lam = np.zeros(nc)
    # Scale the constraint block to the stiffness (spring constants reach 1e9 N/m, J is O(1)):
    # unscaled, the KKT matrix had a condition number of 1e14 and the loop residual stalled.
    s = max(float(np.max(np.abs(np.diag(stiffness)))), 1.0)
    steps = 0
    for steps in range(1, max_iter + 1):  # noqa: B007 (the count is reported after the loop)
        kkt = np.block([[stiffness, -s * jac.T], [s * jac, np.zeros((nc, nc))]])
        rhs = np.concatenate([f + jac.T @ lam, -s * r])
        sol = np.linalg.lstsq(kkt, rhs, rcond=1e-13)[0]
        q = _moved(model, q, sol[: model.nv])
        lam = lam + s * sol[model.nv :]
        f, r, jac = _constraints(model, data, q)
        imbalance = float(np.max(np.abs(f + jac.T @ lam)))
        closure = float(np.max(np.abs(r))) if nc else 0.0
        small_step = float(np.max(np.abs(sol[: model.nv]))) < step_tol
        if closure <= pos_tol_m and (imbalance <= rtol * scale or small_step):
            return q
        if not (np.isfinite(imbalance) and np.isfinite(closure)):
            break  # the iteration diverged: a further step would ask LAPACK for the SVD of non-finite numbers
    raise EquilibriumError(
        f"no static equilibrium after {steps} Newton steps (force imbalance {imbalance:.3e} of {scale:.3e}, "
        f"loop-closure residual {closure:.3e} m); the structure may buckle under gravity or be a mechanism "
        "(check compliances and motors.mode)"
    )
