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

Modes dropped, by documented criteria (:class:`ModeFilter`), counted in ``ModalResult.dropped``:

- ``non_oscillatory``: real eigenvalues (``Im s <= 0``), e.g. critically damped constraint motions;
- ``zero``: natural frequency below ``zero_freq_hz`` (rigid-body motion of a floating rig, mechanisms);
- ``constraint``: the shape violates the loop closure, ``|J v| / (|J|_2 |v|) > max_constraint_ratio``:
  motions of the soft weld itself (constraint stabilisation), not of the structure. Physical modes
  measure ~1e-5 or less; constraint motions ~0.1 to 1;
- ``overdamped``: damping ratio above ``max_damping_ratio``.

Timestep: the step map (semi-implicit Euler on the springs) raises an undamped mode's frequency by
``(omega h)^2 / 24`` relative (``cos(omega' h) = 1 - (omega h)^2 / 2``; measured 0.071 % at
``omega h = 0.130`` against 0.070 % predicted); :func:`modes_transition_fd` warns
(:class:`TimestepWarning`) when a reported mode has ``omega h > OMEGA_H_WARN`` (error > 0.4 %).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.errors import FpmSimWarning
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.model.options import (
    BuiltModel,
    dof_stiffness,
    has_internal_elasticity,
    passive_damping_matrix,
    passive_stiffness_matrix,
    tangent_jacobian,
)

__all__ = [
    "Mode",
    "ModeFilter",
    "ModalResult",
    "TimestepWarning",
    "OMEGA_H_WARN",
    "modes_transition_fd",
    "modes_constrained",
    "modal_analysis",
    "equality_jacobian",
    "reduced_eigenproblem",
    "mass_matrix",
    "stiffness_matrix",
]

OMEGA_H_WARN = 0.3
"""``omega * h`` above which a reported frequency carries more than ~0.4 % timestep error."""

NULLSPACE_RCOND = 1e-4
"""Relative singular-value threshold for the rank of the equality-constraint Jacobian."""

Method = Literal["transition_fd", "constrained"]


class TimestepWarning(FpmSimWarning):
    """The timestep is too coarse for the frequency band being reported."""


@dataclass(frozen=True)
class ModeFilter:
    """Criteria that separate physical modes from the rest (see module docstring)."""

    zero_freq_hz: float = 1.0
    max_constraint_ratio: float = 1e-2
    max_damping_ratio: float = 0.5


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
        return max(self.character, key=self.character.get) if self.character else "-"


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
        """A plain-text table of the modes."""
        modes = self.modes[:n_modes] if n_modes else self.modes
        lines = [f"{'mode':>4}  {'freq (Hz)':>11}  {'damping':>8}  {'character':<30}"]
        for i, m in enumerate(modes, 1):
            top = sorted(m.character.items(), key=lambda kv: -kv[1])[:2]
            char = ", ".join(f"{k} {v:.0%}" for k, v in top if v > 0.005)
            lines.append(f"{i:>4}  {m.frequency_hz:>11.3f}  {m.damping_ratio:>8.4f}  {char:<30}")
        return "\n".join(lines)

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
        ends = []
        for link, p in pos.items():
            ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.75", lw=1)
            q = p + disp[link] * (scale_m / peak)
            ax.plot(q[:, 0], q[:, 1], q[:, 2], lw=2)
            if link.startswith("distal"):
                ends.append(q[-1])
        if len(ends) == 3:  # the platform triangle through the platform joints
            tri = np.array(ends + ends[:1])
            ax.plot(tri[:, 0], tri[:, 1], tri[:, 2], color="k", lw=1.5)
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


def equality_jacobian(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """Rows of the (dense) constraint Jacobian that belong to equality constraints, after a forward pass."""
    rows = np.asarray(data.efc_type[: data.nefc]) == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    jac = np.asarray(data.efc_J[: data.nefc * model.nv]).reshape(data.nefc, model.nv)
    return jac[rows].copy()


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
        f = data.qfrc_passive - data.qfrc_bias
        if lam.size:
            f = f + equality_jacobian(model, data).T @ lam
        return f

    k = -tangent_jacobian(model, qpos, force, eps)
    return 0.5 * (k + k.T)


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
    return r / r[k]


def _constraint_ratio(jac: np.ndarray, jnorm: float, v: np.ndarray) -> float:
    if jac.shape[0] == 0 or jnorm == 0.0:
        return 0.0
    return float(np.linalg.norm(jac @ v) / (jnorm * np.linalg.norm(v)))


def _classify(freq_hz: float, zeta: float, ratio: float, filt: ModeFilter) -> str | None:
    if freq_hz < filt.zero_freq_hz:
        return "zero"
    if ratio > filt.max_constraint_ratio:
        return "constraint"
    if zeta > filt.max_damping_ratio:
        return "overdamped"
    return None


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
        Keep the lowest ``n_modes`` physical modes (``None``: all).
    eps
        Finite-difference step of ``mjd_transitionFD`` (rad, m, rad/s, m/s).
    qpos
        Linearisation point; default the static equilibrium under gravity.
    """
    filt = filt or ModeFilter()
    model = built.model
    data = mujoco.MjData(model)
    q_eq = static_equilibrium(model, data) if qpos is None else np.asarray(qpos, float)
    _forward_at(model, data, q_eq)
    jac = equality_jacobian(model, data)
    jnorm = float(np.linalg.norm(jac, 2)) if jac.size else 0.0
    nx = 2 * model.nv + model.na
    a = np.zeros((nx, nx))
    mujoco.mjd_transitionFD(model, data, eps, True, a, None, None, None)
    lam, vec = np.linalg.eig(a)
    h = model.opt.timestep
    s = np.log(lam.astype(complex)) / h
    k_dof = _energy_stiffness(model)
    dropped: dict[str, int] = {}
    modes: list[Mode] = []
    for idx in np.argsort(np.abs(s)):
        si = s[idx]
        if si.imag <= 1e-9 * max(abs(si), 1.0):
            if si.imag < -1e-9 * max(abs(si), 1.0):
                continue  # the conjugate of a kept mode
            dropped["non_oscillatory"] = dropped.get("non_oscillatory", 0) + 1
            continue
        w = abs(si)
        f_hz, zeta = w / (2 * np.pi), float(-si.real / w)
        shape_c = vec[: model.nv, idx]
        ratio = _constraint_ratio(jac, jnorm, _real_shape(shape_c))
        reason = _classify(f_hz, zeta, ratio, filt)
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
            continue
        shape = _real_shape(shape_c)
        modes.append(Mode(f_hz, zeta, shape, _character(shape, k_dof, built.dof_kinds), ratio))
    if n_modes is not None:
        modes = modes[:n_modes]
    if modes:
        w_top = 2 * np.pi * modes[-1].frequency_hz
        if w_top * h > OMEGA_H_WARN:
            warnings.warn(
                f"timestep_s={h:.3g} s is coarse for the reported band up to {modes[-1].frequency_hz:.0f} Hz "
                f"(omega*h = {w_top * h:.2f} > {OMEGA_H_WARN}); pass a smaller timestep_s (<= "
                f"{OMEGA_H_WARN / w_top:.2g} s) or report fewer modes",
                TimestepWarning,
                stacklevel=2,
            )
    return ModalResult("transition_fd", built, q_eq, modes, dropped)


def modes_constrained(
    built: BuiltModel,
    *,
    n_modes: int | None = 10,
    filt: ModeFilter | None = None,
    qpos: np.ndarray | None = None,
) -> ModalResult:
    """Modes from the constrained generalised eigenproblem (see module docstring)."""
    filt = filt or ModeFilter()
    model = built.model
    data = mujoco.MjData(model)
    q_eq = static_equilibrium(model, data) if qpos is None else np.asarray(qpos, float)
    if built.floating:
        # floating rig: linearise in the tangent space at qpos0 (no gravity by construction)
        q_eq = model.qpos0.copy()
        return _constrained_floating(built, q_eq, n_modes, filt)
    _forward_at(model, data, q_eq)
    mass = mass_matrix(model, data)
    jac = equality_jacobian(model, data)
    stiff = stiffness_matrix(model, data, q_eq)
    damp = passive_damping_matrix(model, q_eq) if has_internal_elasticity(model) else damping_matrix(model)
    return _solve_reduced(built, q_eq, mass, stiff, damp, jac, n_modes, filt)


def _constrained_floating(built: BuiltModel, q0: np.ndarray, n_modes: int | None, filt: ModeFilter) -> ModalResult:
    """Floating models have no constraints here: K from the spring stiffness (no gravity), M at qpos0."""
    model = built.model
    data = mujoco.MjData(model)
    _forward_at(model, data, q0)
    mass = mass_matrix(model, data)
    # joint springs only: the diagonal; a cable plugin's torques: differentiated (no gravity here)
    internal = has_internal_elasticity(model)
    stiff = passive_stiffness_matrix(model, q0) if internal else np.diag(dof_stiffness(model))
    damp = passive_damping_matrix(model, q0) if internal else damping_matrix(model)
    jac = np.zeros((0, model.nv))
    return _solve_reduced(built, q0, mass, stiff, damp, jac, n_modes, filt)


def reduced_eigenproblem(
    mass: np.ndarray, stiff: np.ndarray, jac: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The constrained generalised eigenproblem ``Z'KZ x = w^2 Z'MZ x`` on ``Z = null(jac)``.

    Constraint directions whose singular value is below ``NULLSPACE_RCOND * sigma_max`` are redundant
    to first order (e.g. the axial row of a straight, inextensible clamped-clamped chain) and are not
    imposed: imposing them would remove physical motions.

    Returns ``(z, kr, mr, w2, x)``: the null-space basis, the symmetrised reduced stiffness and mass,
    the eigenvalues ``w^2`` (ascending) and the ``mr``-normalised eigenvectors.
    """
    nv = mass.shape[0]
    z = scipy.linalg.null_space(jac, rcond=NULLSPACE_RCOND) if jac.shape[0] else np.eye(nv)
    kr = z.T @ stiff @ z
    kr = 0.5 * (kr + kr.T)
    mr = z.T @ mass @ z
    mr = 0.5 * (mr + mr.T)
    w2, x = scipy.linalg.eigh(kr, mr)
    return z, kr, mr, w2, x


def _solve_reduced(
    built: BuiltModel,
    q_eq: np.ndarray,
    mass: np.ndarray,
    stiff: np.ndarray,
    damp: np.ndarray,
    jac: np.ndarray,
    n_modes: int | None,
    filt: ModeFilter,
) -> ModalResult:
    z, _, _, w2, x = reduced_eigenproblem(mass, stiff, jac)
    cr = z.T @ damp @ z
    k_dof = _energy_stiffness(built.model)
    dropped: dict[str, int] = {}
    modes: list[Mode] = []
    scale = max(float(np.max(np.abs(w2))), 1.0)
    if np.any(w2 < -1e-9 * scale):
        n_neg = int(np.sum(w2 < -1e-9 * scale))
        warnings.warn(
            f"{n_neg} negative eigenvalue(s) of K: the equilibrium is unstable (buckling under gravity?)",
            stacklevel=3,
        )
        dropped["unstable"] = n_neg
    for i in range(len(w2)):
        if w2[i] < -1e-9 * scale:
            continue
        w = float(np.sqrt(max(w2[i], 0.0)))
        f_hz = w / (2 * np.pi)
        xi = x[:, i]  # M-normalised by eigh
        zeta = float(xi @ cr @ xi / (2 * w)) if w > 0 else 0.0
        reason = _classify(f_hz, zeta, 0.0, filt)
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
            continue
        shape = _real_shape(z @ xi)
        modes.append(Mode(f_hz, zeta, shape, _character(shape, k_dof, built.dof_kinds), 0.0))
    if n_modes is not None:
        modes = modes[:n_modes]
    return ModalResult("constrained", built, q_eq, modes, dropped)


def modal_analysis(built: BuiltModel, *, method: Method = "transition_fd", n_modes: int | None = 10) -> ModalResult:
    """Modes of ``built`` by ``method`` (``"transition_fd"`` or ``"constrained"``)."""
    if method == "transition_fd":
        return modes_transition_fd(built, n_modes=n_modes)
    if method == "constrained":
        return modes_constrained(built, n_modes=n_modes)
    raise ValueError(f"unknown method {method!r}; choose 'transition_fd' or 'constrained'")
