"""The matrices of the linearised model at a configuration: mass (``mj_fullM``), the tangent stiffness with
the closed loop's prestress, the viscous damping, and the per-dof stiffness that splits strain energy by kind."""

from __future__ import annotations

import mujoco
import numpy as np

from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.model.passive import (
    dof_stiffness,
    has_internal_elasticity,
    passive_damping_matrix,
    passive_stiffness_matrix,
    tangent_jacobian,
)

__all__ = [
    "damping_matrix",
    "energy_stiffness",
    "forward_at",
    "mass_matrix",
    "stiffness_matrix",
    "system_damping_matrix",
]


def forward_at(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, qvel: np.ndarray | None = None) -> None:
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
    forward_at(model, data, qpos)
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


def energy_stiffness(model: mujoco.MjModel) -> np.ndarray:
    """Per-dof stiffness that splits a mode's strain energy by kind: the joint springs, or for
    ``cable``/``flex`` links the diagonal of the passive stiffness at ``qpos0`` (an estimate: it
    leaves out the coupling terms)."""
    if has_internal_elasticity(model):
        return np.clip(np.diag(passive_stiffness_matrix(model)), 0.0, None)
    return dof_stiffness(model)


def system_damping_matrix(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """The model's full viscous damping ``-d qfrc_passive / d qdot`` at ``qpos``: the joint dampers
    (:func:`damping_matrix`), or for ``cable``/``flex`` links the differentiated passive forces (the
    cable joints' and the flex's own damping), as :func:`~fpm_sim.linear.solvers.modes_constrained` uses."""
    if has_internal_elasticity(model):
        return passive_damping_matrix(model, qpos)
    return damping_matrix(model)
