"""The spec skeleton, the loop-closing welds, compilation with the timestep rule, and the built model.

Every generated model shares these settings:

- ``implicitfast`` integrator, contacts disabled (links pass through each other; only the joints
  and equality constraints act), dense constraint Jacobian (small constraint count);
- gravity along the motor axes (``-z``) unless switched off;
- loops closed by ``weld`` equalities at the stiff limit: ``solref = (2 h, 1)`` (time constant twice
  the timestep, MuJoCo's smallest safe value) and ``solimp = (0.9999, 0.9999, 0.001, 0.5, 2)``;
- the timestep ``h`` is chosen from the model's highest natural frequency (unconstrained spring
  stiffness over mass), ``h = TIMESTEP_SAFETY / omega_max`` capped at :data:`TIMESTEP_MAX_S`: the
  spring hinges are integrated explicitly and are unstable for ``omega h > 2``, and the linearised
  frequencies carry an error that grows as ``(omega h)^2`` (see :mod:`fpm_sim.linear.solvers`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.model.mujoco_log import route_mujoco_warnings
from fpm_sim.model.options import TimestepError
from fpm_sim.model.passive import (
    dof_stiffness,
    has_internal_elasticity,
    passive_damping_matrix,
    passive_stiffness_matrix,
)

__all__ = [
    "FLEX_DAMPING_LIMIT",
    "TIMESTEP_MAX_S",
    "TIMESTEP_SAFETY",
    "WELD_SOLIMP",
    "BuiltModel",
    "FlexDampingWarning",
    "add_weld",
    "compile_model",
    "highest_frequency_rad_s",
    "new_spec",
]

TIMESTEP_MAX_S = 1e-4
"""Largest timestep the automatic rule picks (s)."""


TIMESTEP_SAFETY = 0.5
"""Automatic timestep: ``h = TIMESTEP_SAFETY / omega_max`` (explicit springs are stable below 2)."""


WELD_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)


FLEX_DAMPING_LIMIT = 1.0
"""Largest ``mu_max h`` of the flexes' explicit bending damping (:func:`_limit_flex_damping`): at 1 the
stiffest damped motion is removed in one step; beyond it the explicit step flips its sign, beyond 2 it grows."""


class FlexDampingWarning(FpmSimWarning):
    """A flex's bending damping was lowered to keep the step stable (MuJoCo applies it explicitly)."""


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
    end_effector_site
        The end effector's reference site: where the reduced models' wrench inputs act and their displacement
        outputs are read, and the point ``platform`` of :class:`fpm_sim.response.LinkPoint` (``""``: none).
    accelerometer_links
        The links that carry the reduced models' default accelerometers (one each, output ``acc_<link>``).
    test_point
        The default excitation (FRF input, impact hammer and accelerometer): ``(link, fraction of its length from
        its start, axis)`` as :class:`fpm_sim.response.LinkPoint` takes them; ``None``: none.
    planar
        Whether the machine moves in its base plane (x, y): the end effector's wrench is then
        ``force_x, force_y, moment_z`` and an accelerometer reads the in-plane normal of its link; else the
        full six components and the link frame's y axis.

    The 3RRR's builder sets the study's choices (``platform_center``, ``distal_0..2``, mid-span of ``distal_0``
    along z); :func:`fpm_sim.model.general.build_general` states the rule for any described machine.
    """

    model: mujoco.MjModel
    spec: mujoco.MjSpec
    name: str
    links: dict[str, list[str]]
    dof_kinds: list[str]
    parameters: dict[str, Any] = field(default_factory=dict)
    end_effector_site: str = ""
    accelerometer_links: tuple[str, ...] = ()
    test_point: tuple[str, float, str] | None = None
    planar: bool = True

    @property
    def floating(self) -> bool:
        return bool(np.any(self.model.jnt_type == mujoco.mjtJoint.mjJNT_FREE))

    @property
    def timestep_s(self) -> float:
        return float(self.model.opt.timestep)

    def to_xml(self) -> str:
        """The MJCF, numbers at full precision (:func:`fpm_sim.model.xml_precision.full_precision_xml`)."""
        from fpm_sim.model.xml_precision import full_precision_xml

        return full_precision_xml(self.spec)


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


def highest_frequency_rad_s(model: mujoco.MjModel) -> float:
    """Highest natural frequency of the passive stiffness (constraints ignored) at ``qpos0`` (rad/s).

    Joint springs give a diagonal stiffness; models with a cable plugin or a flex use
    :func:`~fpm_sim.model.passive.passive_stiffness_matrix`.
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
    route_mujoco_warnings()
    hint = (
        "a size, mass or stiffness of the description is out of range for double precision; check section.*, "
        "material.*, hardware.*.mass_kg and geometry.*"
    )
    try:
        model = spec.compile()
    except ValueError as e:
        raise FpmSimError(f"MuJoCo cannot compile the model ({str(e).splitlines()[0]}): {hint}") from e
    try:
        w_max = highest_frequency_rad_s(model)
    except (np.linalg.LinAlgError, ValueError) as e:
        raise FpmSimError(f"the model's mass or stiffness matrix is not usable ({e}): {hint}") from e
    if not math.isfinite(w_max):
        raise FpmSimError(f"the model's highest natural frequency is not finite: {hint}")
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
    _limit_flex_damping(spec, model, h)
    return spec.compile()


def _limit_flex_damping(spec: mujoco.MjSpec, model: mujoco.MjModel, h: float) -> None:
    """Scale the flexes' stiffness-proportional bending damping so that ``mu_max h <= FLEX_DAMPING_LIMIT``.

    ``mu_max`` is the largest eigenvalue of ``M^-1 D`` with ``D`` the flexes' damping matrix at ``qpos0`` (the
    passive damping less the joints' own, which ``implicitfast`` integrates implicitly). MuJoCo 3.17 applies
    flex damping explicitly (neither ``implicitfast`` nor ``implicit`` takes it in), so its stiffest damped
    motion is multiplied by ``1 - mu h`` a step: unstable beyond ``mu h = 2`` (measured: the largest
    step-map eigenvalue is ``mu h - 1``), sign-flipping beyond 1. On the default manipulator (beta = 5.3e-5 s,
    16 edges per link, gravity off) ``mu h`` was 10.7: 65 step-map modes at the Nyquist frequency grew by
    ``|lambda| = 9.8`` a step, and none without the damping. The flex's edges are left undamped for the same
    reason (:mod:`fpm_sim.model.deformable_links`). The low modes then keep only that fraction of the requested
    damping: a :class:`FlexDampingWarning` says how much.
    """
    if model.nflex == 0 or not np.any(model.flex_damping > 0):
        return
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    damp = passive_damping_matrix(model, model.qpos0.copy()) - np.diag(model.dof_damping)
    mu_max = float(scipy.linalg.eigh(damp, mass, eigvals_only=True, subset_by_index=[model.nv - 1, model.nv - 1])[0])
    if mu_max * h <= FLEX_DAMPING_LIMIT:
        return
    scale = FLEX_DAMPING_LIMIT / (mu_max * h)
    beta = max(f.damping for f in spec.flexes)
    for f in spec.flexes:
        f.damping *= scale
    warnings.warn(
        FlexDampingWarning(
            f"flex bending damping lowered from {beta:.3g} s to {beta * scale:.3g} s ({100 * scale:.2g} % of it): "
            f"MuJoCo applies it explicitly, and at timestep {h:.3g} s the explicit step would flip or grow its "
            f"stiffest damped motion (mu h = {mu_max * h:.3g} > {FLEX_DAMPING_LIMIT:g}); use link_model 'segments' "
            "or 'cable' for modal damping ratios",
            parameter="link_model",
        ),
        stacklevel=3,
    )
