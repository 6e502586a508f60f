"""Common model plumbing: options, the spec skeleton, compilation and the timestep rule.

Every generated model shares these settings:

- ``implicitfast`` integrator, contacts disabled (links pass through each other; only the joints
  and equality constraints act), dense constraint Jacobian (small constraint count);
- gravity along the motor axes (``-z``) unless switched off;
- loops closed by ``weld`` equalities at the stiff limit: ``solref = (2 h, 1)`` (time constant twice
  the timestep, MuJoCo's smallest safe value) and ``solimp = (0.9999, 0.9999, 0.001, 0.5, 2)``;
- the timestep ``h`` is chosen from the model's highest natural frequency (unconstrained spring
  stiffness over mass), ``h = TIMESTEP_SAFETY / omega_max`` capped at :data:`TIMESTEP_MAX_S`: the
  spring hinges are integrated explicitly and are unstable for ``omega h > 2``, and the linearised
  frequencies carry an error that grows as ``(omega h)^2`` (see :mod:`fpm_sim.linear.modal`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.errors import FpmSimError
from fpm_sim.model.parts import DEFAULT_RESOLUTION, check_link_model

__all__ = [
    "ModelOptions",
    "DEFAULT_SEGMENTS",
    "BuiltModel",
    "TimestepError",
    "TIMESTEP_MAX_S",
    "TIMESTEP_SAFETY",
    "new_spec",
    "compile_model",
    "highest_frequency_rad_s",
    "WELD_SOLIMP",
    "dof_stiffness",
    "has_internal_elasticity",
    "passive_stiffness_matrix",
    "tangent_jacobian",
    "passive_damping_matrix",
]

DEFAULT_SEGMENTS = 12
"""Default spring locations per link: the 10 x 10 x 228 mm steel cantilever's first three bending
frequencies are then +0.16, +0.56, +0.91 % from Euler-Bernoulli (error ~ 1/n^2; see docs)."""

TIMESTEP_MAX_S = 1e-4
"""Largest timestep the automatic rule picks (s)."""
TIMESTEP_SAFETY = 0.5
"""Automatic timestep: ``h = TIMESTEP_SAFETY / omega_max`` (explicit springs are stable below 2)."""
WELD_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)


class TimestepError(FpmSimError):
    """The requested timestep cannot integrate the model's stiffest spring stably."""


@dataclass(frozen=True)
class ModelOptions:
    """How a model is discretised and simulated.

    Parameters
    ----------
    link_model
        ``"segments"`` (rigid-finite-element chain, default), ``"rigid"``, ``"cable"`` (MuJoCo's
        cable plugin) or ``"flex"`` (a 1D flex); see :mod:`fpm_sim.model.deformable_links`.
    segments
        Resolution per link: spring locations (``segments``), elastic joints (``cable``) or flex
        edges (``flex``); ``None`` takes the model's default
        (:data:`fpm_sim.model.links.DEFAULT_RESOLUTION`: 12, 12, 16).
    axial
        Add an axial spring at each spring location (default). Without it the links are
        inextensible: 2.4 times cheaper for the manipulator and within 0.1 % on its in-plane modes,
        but a straight chain clamped at both ends then cannot sag without stretching, and the tension
        that gravity builds in it is set by the weld's softness instead of the links' EA.
    rotary_inertia
        Add the rotary inertia of the link sections about their bending axes: the chain then
        converges to a Rayleigh beam instead of an Euler-Bernoulli beam (for the 10 mm x 228 mm steel
        bar this lowers the free-free modes 1-3 by 0.4, 0.9 and 1.5 %). Off by default, as shear is
        not modelled either (``shear`` adds it: both together give a Timoshenko beam).
    shear
        Add transverse shear springs ``kappa G A / l`` at each spring location (``segments`` links only):
        with ``rotary_inertia`` the links converge to Timoshenko beams (30 mm deep links on ~150 mm spans:
        about 1.5 % below Euler-Bernoulli on their first in-plane mode).
    gravity
        Gravity (9.81 m/s^2) along ``-z``, the motor axes.
    timestep_s
        Simulation step; ``None`` picks it from the highest natural frequency (see module doc).
    """

    link_model: str = "segments"
    segments: int | None = None
    axial: bool = True
    rotary_inertia: bool = False
    shear: bool = False
    gravity: bool = True
    timestep_s: float | None = None

    def __post_init__(self) -> None:
        if self.segments is None and self.link_model in DEFAULT_RESOLUTION:
            object.__setattr__(self, "segments", DEFAULT_RESOLUTION[self.link_model])
        check_link_model(self.link_model, self.segments)
        if self.timestep_s is not None and not (0.0 < self.timestep_s <= 1e-2):
            raise TimestepError(f"timestep_s must be in (0, 0.01] s, got {self.timestep_s!r}")


@dataclass
class BuiltModel:
    """A compiled model with the bookkeeping the analyses need.

    Attributes
    ----------
    model
        The compiled :class:`mujoco.MjModel`; ``qpos0`` is the assembled configuration at rest.
    spec
        The :class:`mujoco.MjSpec` it came from (``spec.to_xml()`` gives the MJCF).
    name
        ``"manipulator"`` or the rig name.
    links
        Link name -> site names from the link's start to its end (points for Cartesian mode shapes).
    dof_kinds
        Per degree of freedom: ``bend_in``, ``bend_out``, ``twist``, ``axial``, ``passive``,
        ``tilt``, ``motor``, ``clamp`` or ``free``.
    parameters
        What was used to build it (JSON-ready).
    """

    model: mujoco.MjModel
    spec: mujoco.MjSpec
    name: str
    links: dict[str, list[str]]
    dof_kinds: list[str]
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def floating(self) -> bool:
        return bool(np.any(self.model.jnt_type == mujoco.mjtJoint.mjJNT_FREE))

    @property
    def timestep_s(self) -> float:
        return float(self.model.opt.timestep)

    def to_xml(self) -> str:
        return self.spec.to_xml()


def new_spec(model_name: str, *, gravity: bool) -> mujoco.MjSpec:
    """A spec with the project's common options (see module docstring)."""
    spec = mujoco.MjSpec()
    spec.modelname = model_name
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.degree = False
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    spec.option.gravity = [0.0, 0.0, -9.81] if gravity else [0.0, 0.0, 0.0]
    spec.visual.global_.offwidth = 640
    return spec


def add_weld(spec: mujoco.MjSpec, name: str, body1: str, body2: str) -> None:
    """Weld two bodies in their relative pose at ``qpos0`` (stiff limit; solref set at compile)."""
    eq = spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY)
    eq.name1 = body1
    eq.name2 = body2
    # data = anchor (3, on body2, at its origin), relpose pos (3) and quat (4; all zeros = "as at
    # qpos0"), torquescale, unused. The spec's default anchor (0, 1, 0) would measure the position
    # error a metre away from the joint.
    eq.data = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0])
    eq.solimp = list(WELD_SOLIMP)


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
        return data.qfrc_passive.copy()

    k = -tangent_jacobian(model, q0, passive, eps)
    return 0.5 * (k + k.T)


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


def highest_frequency_rad_s(model: mujoco.MjModel) -> float:
    """Highest natural frequency of the passive stiffness (constraints ignored) at ``qpos0`` (rad/s).

    Joint springs give a diagonal stiffness; models with a cable plugin or a flex use
    :func:`passive_stiffness_matrix`.
    """
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    if has_internal_elasticity(model):
        stiff = passive_stiffness_matrix(model)
        if not np.any(np.abs(stiff) > 0):
            return 0.0
    else:
        k = dof_stiffness(model)
        if not np.any(k > 0):
            return 0.0
        stiff = np.diag(k)
    w2 = scipy.linalg.eigh(stiff, mass, eigvals_only=True, subset_by_index=[model.nv - 1, model.nv - 1])
    return float(np.sqrt(max(w2[0], 0.0)))


def compile_model(spec: mujoco.MjSpec, *, timestep_s: float | None) -> mujoco.MjModel:
    """Compile with the timestep rule and the stiff weld time constant ``2 h``.

    Raises
    ------
    TimestepError
        If an explicit ``timestep_s`` makes the stiffest spring unstable (``omega_max h > 2``).
    """
    model = spec.compile()
    w_max = highest_frequency_rad_s(model)
    if timestep_s is None:
        h = TIMESTEP_MAX_S if w_max == 0.0 else min(TIMESTEP_MAX_S, TIMESTEP_SAFETY / w_max)
    else:
        h = timestep_s
        if w_max * h >= 2.0:
            raise TimestepError(
                f"timestep_s={h:g} s is unstable for this model: its stiffest spring has omega_max = {w_max:.4g} rad/s "
                f"and omega_max * h = {w_max * h:.2f} >= 2; use timestep_s <= {TIMESTEP_SAFETY / w_max:.3g} s, fewer "
                f"segments, or leave timestep_s unset (automatic)"
            )
    spec.option.timestep = h
    for eq in spec.equalities:
        eq.solref = [2.0 * h, 1.0]
    return spec.compile()
