"""Static equilibrium of a generated model under gravity (the linearisation point).

The equilibrium solves ``qacc(q, v = 0) = 0`` for the model exactly as MuJoCo simulates it (springs,
gravity and the soft weld constraints), by Newton's (chord) method with a centred finite-difference
Jacobian ``d qacc / d q`` taken once at ``qpos0``. Linearising anywhere else would linearise a
drifting state: the prestress of gravity on a closed loop changes the tangent stiffness.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["EquilibriumError", "static_equilibrium", "qacc_jacobian"]


class EquilibriumError(RuntimeError):
    """Newton's method found no static equilibrium (buckling, a mechanism, or a floating model under gravity)."""


def _qacc(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray) -> np.ndarray:
    data.qpos[:] = qpos
    data.qvel[:] = 0.0
    data.act[:] = 0.0
    mujoco.mj_forward(model, data)
    return data.qacc.copy()


def _moved(model: mujoco.MjModel, qpos: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """``qpos`` moved by the tangent vector ``dq`` (plain addition for hinges and slides)."""
    q = qpos.copy()
    mujoco.mj_integratePos(model, q, dq, 1.0)
    return q


def qacc_jacobian(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """Centred finite-difference ``d qacc / d q`` at zero velocity, in the tangent space (ball joints included)."""
    jac = np.zeros((model.nv, model.nv))
    for k in range(model.nv):
        dq = np.zeros(model.nv)
        dq[k] = eps
        ap = _qacc(model, data, _moved(model, qpos, dq))
        am = _qacc(model, data, _moved(model, qpos, -dq))
        jac[:, k] = (ap - am) / (2 * eps)
    return jac


def static_equilibrium(
    model: mujoco.MjModel,
    data: mujoco.MjData | None = None,
    *,
    rtol: float = 1e-5,
    step_tol: float = 1e-12,
    max_iter: int = 30,
) -> np.ndarray:
    """``qpos`` of the static equilibrium nearest ``qpos0``.

    Parameters
    ----------
    model
        A model without free joints, or one with zero gravity (returned as ``qpos0``); ball joints
        (``cable`` links) are stepped in the tangent space.
    rtol
        Converged when ``|qacc|_inf`` falls below ``rtol`` times its value at ``qpos0``.
    step_tol
        ... or when a Newton step moves no coordinate by more than ``step_tol`` (m or rad): the
        residual has reached its round-off floor (the stiff welds amplify round-off in ``qacc`` to
        ~1e-6 of the gravity load).

    Raises
    ------
    EquilibriumError
        If a floating model has gravity, or Newton's method does not converge.
    """
    data = data if data is not None else mujoco.MjData(model)
    q = model.qpos0.copy()
    a0 = _qacc(model, data, q)
    scale = float(np.max(np.abs(a0)))
    if scale < 1e-12:
        return q
    if np.any(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
        raise EquilibriumError(
            "a floating model (free joint) has no static equilibrium under gravity; switch gravity off"
        )
    a = a0
    # Chord method: the Jacobian at qpos0 serves every step (gravity sag is small, the model nearly
    # linear), so each step costs one forward pass instead of 2 nv.
    jac = qacc_jacobian(model, data, q)
    for _ in range(max_iter):
        step = np.linalg.lstsq(jac, -a, rcond=None)[0]
        q = _moved(model, q, step)
        a = _qacc(model, data, q)
        if float(np.max(np.abs(a))) <= rtol * scale or float(np.max(np.abs(step))) < step_tol:
            return q
    raise EquilibriumError(
        f"no static equilibrium after {max_iter} Newton steps (|qacc| = {np.max(np.abs(a)):.3e} from {scale:.3e}); "
        "the structure may buckle under gravity or be a mechanism (check compliances and motors.mode)"
    )
