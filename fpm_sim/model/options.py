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
  frequencies carry an error that grows as ``(omega h)^2`` (see :mod:`fpm_sim.linear.solvers`).
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.model.parts import DEFAULT_RESOLUTION, check_link_model

__all__ = [
    "DEFAULT_FIDELITY",
    "DEFAULT_SEGMENTS",
    "DISCRETISATION_COEFF",
    "FIDELITIES",
    "FIDELITY_RESOLUTION",
    "FIDELITY_SCALE",
    "RESOLUTION_WARN",
    "TIMESTEP_MAX_S",
    "TIMESTEP_SAFETY",
    "WELD_SOLIMP",
    "BuiltModel",
    "ModelOptions",
    "MujocoWarning",
    "ResolutionWarning",
    "TimestepError",
    "check_count",
    "check_finite",
    "compile_model",
    "discretisation_error",
    "dof_stiffness",
    "has_internal_elasticity",
    "highest_frequency_rad_s",
    "mujoco_messages",
    "new_spec",
    "open_for_writing",
    "passive_damping_matrix",
    "passive_stiffness_matrix",
    "resolution_footer",
    "resolution_label",
    "resolution_of_parameters",
    "resolution_summary",
    "resolution_text",
    "resolve_segments",
    "route_mujoco_warnings",
    "tangent_jacobian",
    "warn_if_coarse",
]

DEFAULT_SEGMENTS = DEFAULT_RESOLUTION["segments"]
"""Default spring locations per link (fidelity ``standard``): the 10 x 10 x 228 mm steel cantilever's
first three bending frequencies are then +0.16, +0.56, +0.91 % from Euler-Bernoulli (error ~ 1/n^2; see docs)."""

# ---------------------------------------------------------------------------------------------
# The one resolution policy of every command (``--fidelity`` / ``--segments``)

FIDELITIES = ("fast", "standard", "fine")
"""Named resolutions; ``--segments N`` overrides them."""
DEFAULT_FIDELITY = "standard"
"""Every command's default: the same model, hence the same first frequency, whatever the command."""
FIDELITY_RESOLUTION = {
    "segments": {"fast": 8, "standard": DEFAULT_RESOLUTION["segments"], "fine": 24},
    "cable": {"fast": 8, "standard": DEFAULT_RESOLUTION["cable"], "fine": 24},
    "flex": {"fast": 8, "standard": DEFAULT_RESOLUTION["flex"], "fine": 32},
    "rigid": {"fast": 1, "standard": 1, "fine": 1},
}
"""Resolution per link of each preset and link model (``standard`` is
:data:`fpm_sim.model.parts.DEFAULT_RESOLUTION`). ``fast`` is the coarsest resolution whose estimated f1 error
stays below :data:`RESOLUTION_WARN` (8: 0.64 %; the old pose-loop default 6 gives 1.1 %); ``fine`` halves
the spacing of ``standard`` (error / 4)."""
FIDELITY_SCALE = FIDELITY_RESOLUTION["segments"]

DISCRETISATION_COEFF = {"segments": 0.41, "cable": 0.41}
"""``c`` in the relative error of the first frequency ``e(n) ~ c / n^2`` (n per link), per link model.

Measured on the manipulator at (0, 0, 0) (the embedded description, constrained and transitionFD alike):
f1 = 73.5026 Hz at n = 6 and 72.8808 Hz at n = 12; Richardson's extrapolation with the 1/n^2 law gives
72.674 Hz, so e(12) = 0.285 % and c = 0.285 % * 144 = 0.41 (e(6) = 1.14 %). ``cable`` is the same linear
model as ``segments`` (agreement 5e-10). ``flex`` converges differently (from below, docs/link_models.md)
and gets no estimate; ``rigid`` has no discretisation."""

RESOLUTION_WARN = 0.01
"""Estimated relative discretisation error of f1 above which a :class:`ResolutionWarning` is issued."""


class ResolutionWarning(FpmSimWarning):
    """The estimated discretisation error of the first frequency exceeds :data:`RESOLUTION_WARN`."""


def resolve_segments(
    *, fidelity: str | None = None, segments: int | None = None, link_model: str = "segments"
) -> int:
    """Resolution per link of ``link_model``: ``segments`` if given, else the ``fidelity`` preset.

    Parameters
    ----------
    fidelity
        ``"fast"``, ``"standard"`` (default) or ``"fine"``; see :data:`FIDELITY_RESOLUTION`.
    segments
        Explicit resolution per link (spring locations, cable joints or flex edges); wins over ``fidelity``.
    link_model
        ``"segments"``, ``"rigid"``, ``"cable"`` or ``"flex"``.
    """
    if segments is not None:
        return segments
    fid = DEFAULT_FIDELITY if fidelity is None else fidelity
    if fid not in FIDELITY_SCALE:
        raise FpmSimError(
            "unknown fidelity", parameter="fidelity", value=fid, hint=f"choose one of {', '.join(FIDELITIES)}"
        )
    return FIDELITY_RESOLUTION.get(link_model, FIDELITY_RESOLUTION["segments"])[fid]


def discretisation_error(segments: int, link_model: str = "segments") -> float:
    """Estimated relative error of the first natural frequency at ``segments`` per link (``c / n^2``).

    Returns 0 for rigid links and NaN where no estimate is known (``flex``); see :data:`DISCRETISATION_COEFF`.
    """
    if link_model == "rigid":
        return 0.0
    c = DISCRETISATION_COEFF.get(link_model)
    if c is None or segments < 1:
        return math.nan
    return c / segments**2


def resolution_summary(options: ModelOptions) -> dict[str, Any]:
    """What every result states about its resolution (JSON-ready).

    Keys: ``link_model``, ``segments`` (per link), ``fidelity`` (the preset, or ``None`` if
    ``segments`` was set explicitly), ``f1_error_estimate`` (relative, ``c / n^2``; NaN if unknown).
    """
    n = int(options.segments or 1)
    return {
        "link_model": options.link_model,
        "segments": n,
        "fidelity": options.fidelity,
        "f1_error_estimate": discretisation_error(n, options.link_model),
        "axial": options.axial,
        "gravity": options.gravity,
    }


def resolution_of_parameters(parameters: dict[str, Any]) -> dict[str, Any]:
    """:func:`resolution_summary` from a built model's ``parameters`` (its ``options`` entry); ``{}`` if absent."""
    o = parameters.get("options") if isinstance(parameters, dict) else None
    if not isinstance(o, dict) or "segments" not in o:
        return {}
    lm = o.get("link_model", "segments")
    n = int(o.get("segments") or 1)
    out: dict[str, Any] = {
        "link_model": lm,
        "segments": n,
        "fidelity": o.get("fidelity"),
        "f1_error_estimate": discretisation_error(n, lm),
    }
    out.update({k: bool(o[k]) for k in ("axial", "gravity") if k in o})
    return out


def resolution_text(summary: dict[str, Any]) -> str:
    """One line from a :func:`resolution_summary` (or :func:`resolution_of_parameters`) dict, e.g.
    ``12 segments per link (fidelity standard), estimated f1 discretisation error 0.28 %; axial springs off
    (inextensible links), gravity off``; the axial springs and gravity are named where the dict records them
    (commands differ in both, so every result says which it used)."""
    lm = summary.get("link_model", "segments")
    if lm == "rigid":
        text = "rigid links (no discretisation)"
    else:
        n = int(summary.get("segments") or 1)
        fid = summary.get("fidelity")
        if fid:
            how = f"fidelity {fid}"
        else:  # no preset recorded: set explicitly, or read from a file (an atlas, a reduced model)
            same = [f for f, r in FIDELITY_RESOLUTION.get(lm, {}).items() if r == n]
            how = f"= fidelity {same[0]}" if same else "set explicitly"
        err = summary.get("f1_error_estimate", discretisation_error(n, lm))
        est = "not estimated" if err is None or math.isnan(err) else f"{100 * err:.2g} %"
        text = f"{n} {lm} per link ({how}), estimated f1 discretisation error {est}"
    extra = []
    if "axial" in summary:
        extra.append("axial springs on" if summary["axial"] else "axial springs off (inextensible links)")
    if "gravity" in summary:
        extra.append("gravity on" if summary["gravity"] else "gravity off")
    return text + ("; " + ", ".join(extra) if extra else "")


def resolution_footer(source: ModelOptions | dict[str, Any] | None) -> str:
    """The line every result's table ends with, ``resolution: ...`` (:func:`resolution_text`), from model
    options or a built model's ``parameters``; '' when ``source`` records no resolution."""
    if source is None:
        return ""
    summary = resolution_summary(source) if isinstance(source, ModelOptions) else resolution_of_parameters(source)
    return "resolution: " + resolution_text(summary) if summary else ""


def resolution_label(options: ModelOptions) -> str:
    """One line: ``12 segments per link (fidelity standard), estimated f1 discretisation error 0.28 %; axial
    springs off (inextensible links), gravity off`` (:func:`resolution_text`)."""
    return resolution_text(resolution_summary(options))


def warn_if_coarse(options: ModelOptions, *, stacklevel: int = 2) -> None:
    """Warn (:class:`ResolutionWarning`) when the estimated f1 error passes :data:`RESOLUTION_WARN`."""
    err = discretisation_error(int(options.segments or 1), options.link_model)
    if err > RESOLUTION_WARN:
        finer = max(n for n in range(1, 201) if DISCRETISATION_COEFF[options.link_model] / n**2 > RESOLUTION_WARN) + 1
        warnings.warn(
            ResolutionWarning(
                f"coarse resolution: {options.segments} {options.link_model} per link gives an estimated "
                f"discretisation error of {100 * err:.2g} % on the first frequency; use segments >= {finer} "
                f"or fidelity 'standard' for below {100 * RESOLUTION_WARN:g} %",
                parameter="segments",
            ),
            stacklevel=stacklevel + 1,
        )

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
        edges (``flex``); ``None`` takes the ``fidelity`` preset (:func:`resolve_segments`).
    fidelity
        ``"fast"``, ``"standard"`` or ``"fine"`` (:data:`FIDELITY_RESOLUTION`); ``None`` with ``segments``
        ``None`` means ``"standard"``; recorded as ``None`` when ``segments`` is given explicitly.
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
    fidelity: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.segments is None and self.link_model in DEFAULT_RESOLUTION:
            fid = DEFAULT_FIDELITY if self.fidelity is None else self.fidelity
            object.__setattr__(
                self, "segments", resolve_segments(fidelity=fid, segments=None, link_model=self.link_model)
            )
            object.__setattr__(self, "fidelity", fid)
        elif self.fidelity is not None:
            if self.fidelity not in FIDELITY_SCALE:
                raise FpmSimError(
                    "unknown fidelity",
                    parameter="fidelity",
                    value=self.fidelity,
                    hint=f"choose one of {', '.join(FIDELITIES)}",
                )
            if self.segments != resolve_segments(fidelity=self.fidelity, link_model=self.link_model):
                object.__setattr__(self, "fidelity", None)  # an explicit resolution overrides the preset
        check_link_model(self.link_model, self.segments)
        if self.timestep_s is not None and not (0.0 < self.timestep_s <= 1e-2):
            raise TimestepError("must be in (0, 0.01] s", parameter="timestep_s", value=self.timestep_s)


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
        xml: str = self.spec.to_xml()
        return xml


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


# ---------------------------------------------------------------------------------------------
# MuJoCo's warnings and validation helpers


class MujocoWarning(FpmSimWarning):
    """A warning raised inside MuJoCo (e.g. "Nan, Inf or huge value in QACC": the simulation is unstable)."""


def _emit_mujoco_warning(message: str) -> None:
    warnings.warn(f"MuJoCo: {message.strip()}", MujocoWarning, stacklevel=2)


def route_mujoco_warnings() -> None:
    """Send MuJoCo's warnings to Python's ``warnings`` (:class:`MujocoWarning`) instead of ``MUJOCO_LOG.TXT``
    in the working directory and the console (``mujoco.set_mju_user_warning``).

    Called by :func:`compile_model`, so every fpm-sim model is covered; a handler the caller installed
    first is kept. Inside :func:`mujoco_messages` the messages are collected instead.
    """
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_emit_mujoco_warning)


@contextlib.contextmanager
def mujoco_messages() -> Iterator[list[str]]:
    """Collect MuJoCo's warnings raised inside the ``with`` block into the yielded list (never written to a
    file); the previous handler is restored on exit."""
    previous = mujoco.get_mju_user_warning()
    messages: list[str] = []
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)


def check_finite(name: str, value: Any, *, positive: bool = False) -> np.ndarray:
    """``value`` as a float array, all finite (and ``> 0`` with ``positive``).

    Raises :class:`FpmSimError` naming ``name`` otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise FpmSimError("must be a number", parameter=name, value=value) from None
    if not np.all(np.isfinite(arr)):
        raise FpmSimError("must be finite", parameter=name, value=value)
    if positive and not np.all(arr > 0):
        raise FpmSimError("must be positive", parameter=name, value=value)
    return arr


def check_count(name: str, value: Any, *, low: int = 1, high: int | None = None, hint: str = "") -> int:
    """``value`` as an integer in ``[low, high]``, else :class:`FpmSimError` naming ``name`` and the range."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if not ok and isinstance(value, float) and math.isfinite(value) and value.is_integer():
        ok, value = True, int(value)
    if not ok or value < low or (high is not None and value > high):
        bound = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise FpmSimError(f"must be an integer {bound}{hint}", parameter=name, value=value)
    return int(value)


@contextlib.contextmanager
def open_for_writing(
    path: str | Path, *, parameter: str = "out", error: type[FpmSimError] = FpmSimError
) -> Iterator[IO[bytes]]:
    """Open ``path`` for binary writing (parent folders created), turning a failure (read-only place, a folder
    in the way, ...) into ``error`` naming the file and ``parameter`` instead of a library's own message."""
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        handle = open(p, "wb")  # closed below
    except OSError as e:
        raise error(
            f"cannot write {str(p)!r} ({e.strerror or e})", parameter=parameter, hint="choose a writable path"
        ) from e
    with handle:
        yield handle
