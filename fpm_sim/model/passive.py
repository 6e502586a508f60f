"""The passive forces' derivatives of a compiled model: the joint springs' stiffness per degree of freedom,
and by centred differences in the tangent space the passive stiffness and damping matrices (joint springs,
the cable plugin's torques, flex bending and edges alike).

They live in ``model/`` because compilation needs them (the timestep rule's highest frequency, the flexes'
damping limit: :mod:`fpm_sim.model.spec`); the linearised model's full matrices (with gravity and the
closed loop's prestress) are :mod:`fpm_sim.linear.matrices`.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

__all__ = [
    "dof_stiffness",
    "has_internal_elasticity",
    "passive_damping_matrix",
    "passive_stiffness_matrix",
    "tangent_jacobian",
]


def dof_stiffness(model: mujoco.MjModel) -> np.ndarray:
    """Linear spring stiffness of each degree of freedom (0 for free joints)."""
    k = np.zeros(model.nv)
    one_dof = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    for j in range(model.njnt):
        if int(model.jnt_type[j]) in one_dof:
            k[model.jnt_dofadr[j]] = model.jnt_stiffness[j]
    return k


def has_internal_elasticity(model: mujoco.MjModel) -> bool:
    """Whether passive forces come from more than joint springs (a plugin or a flex: ``cable``, ``flex`` links)."""
    return bool(model.nplugin > 0 or model.nflex > 0)


def tangent_jacobian(
    model: mujoco.MjModel, qpos: np.ndarray, fn: Callable[[np.ndarray], np.ndarray], eps: float = 1e-7
) -> np.ndarray:
    """Centred finite-difference ``d fn(q) / dq`` at ``qpos``, one column per degree of freedom.

    Steps are taken in the tangent space (``mj_integratePos``): plain addition for hinges and
    slides, quaternion integration for ball and free joints (``cable`` links).
    """
    jac = np.zeros((model.nv, model.nv))
    for j in range(model.nv):
        cols = []
        for sign in (1.0, -1.0):
            dq = np.zeros(model.nv)
            dq[j] = sign * eps
            q = np.array(qpos, dtype=float)
            mujoco.mj_integratePos(model, q, dq, 1.0)
            cols.append(np.array(fn(q), dtype=float))
        jac[:, j] = (cols[0] - cols[1]) / (2 * eps)
    return jac


def passive_stiffness_matrix(model: mujoco.MjModel, qpos: np.ndarray | None = None, eps: float = 1e-7) -> np.ndarray:
    """``-d qfrc_passive / dq`` at ``qpos`` (default ``qpos0``), zero velocity, by centred differences.

    Differences are taken in the tangent space (:func:`tangent_jacobian`), so ball and free joints are
    handled; this captures joint springs, the cable plugin's torques and flex bending and edge
    springs alike (gravity and constraints are not passive forces).
    """
    data = mujoco.MjData(model)
    q0 = model.qpos0.copy() if qpos is None else np.asarray(qpos, float)

    def passive(q: np.ndarray) -> np.ndarray:
        data.qpos[:] = q
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        force: np.ndarray = data.qfrc_passive.copy()
        return force

    k = -tangent_jacobian(model, q0, passive, eps)
    sym: np.ndarray = 0.5 * (k + k.T)
    return sym


def passive_damping_matrix(model: mujoco.MjModel, qpos: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """``-d qfrc_passive / d qvel`` at ``qpos`` by centred differences (joint dampers, the cable
    joints' damping and the flex's bending damping alike)."""
    data = mujoco.MjData(model)
    c = np.zeros((model.nv, model.nv))
    for j in range(model.nv):
        cols = []
        for sign in (1.0, -1.0):
            data.qpos[:] = qpos
            data.qvel[:] = 0.0
            data.qvel[j] = sign * eps
            mujoco.mj_forward(model, data)
            cols.append(data.qfrc_passive.copy())
        c[:, j] = -(cols[0] - cols[1]) / (2 * eps)
    return 0.5 * (c + c.T)
