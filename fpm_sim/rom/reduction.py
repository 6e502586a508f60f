"""Reduced-order models per pose: modal truncation in physical modal coordinates.

The full model is linearised at its static equilibrium under gravity (the same point as
:mod:`fpm_sim.linear.solvers`): ``M`` from ``mj_fullM``, the tangent stiffness ``K`` with the closed loop's
prestress, the joint-damper matrix ``C`` and the loop-closure Jacobian ``J``. Motions respect the
loop closure, ``q = Z p`` with ``Z`` the null space of ``J``; the constrained eigenproblem
``Z'KZ x = w^2 Z'MZ x`` gives mass-normalised modes ``Phi = Z X`` (``Phi' M Phi = I``). In the modal
coordinates ``eta`` (``q - q_eq = Phi eta``) the model is::

    eta'' + Xi eta' + Omega^2 eta = Phi' B_q u          Xi = Phi' C Phi (projected damping)

and the state-space model has ``x = [eta; eta']``::

    A = [[0, I], [-Omega^2, -Xi]]      B = [[0], [Phi' B_q]]

Inputs (columns of ``B_q``, generalised forces of unit inputs):

- ``force_x``, ``force_y`` (N), ``moment_z`` (N m): a wrench on the end effector at
  ``platform_center``, world axes (``B_q = J_site'``);
- ``motor_torque_i`` (N m): a torque on motor hinge ``motor_i``; present only when the motors have a
  hinge (``motors.mode = "servo"`` or a finite ``compliance.motor_clamp_nm_per_rad``). Locked motors
  have no joint, so no torque input.

Outputs (rows of ``C_q`` or ``C_a``, linearised at the equilibrium):

- ``disp_x``, ``disp_y`` (m), ``rot_z`` (rad): end-effector displacement from the equilibrium;
- ``acc_distal_i`` (m/s^2): acceleration at a point of distal link ``i`` (``accel_fraction`` of its
  length from the elbow), in the base plane, normal to the link (the bending direction a uniaxial
  accelerometer on the link measures).

Static correction (``static_correction=True``): the truncated modes' quasi-static contribution to
the displacement outputs enters as the feedthrough ``D = C_q (G - Phi_k Omega_k^-2 Phi_k') B_q``,
``G = Z (Z'KZ)^-1 Z'`` the constrained static flexibility (the mode-acceleration method). The
acceleration outputs always carry their direct term ``C_a Phi_k Phi_k' B_q``.

Modes are chosen by count (``n_modes``), frequency band (``band_hz``: all modes up to it) or error
bound (``error_bound``: the fewest modes whose *uncorrected* static displacement-per-force gain has a
relative Frobenius error at most ``error_bound``; see :func:`static_truncation_error`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import scipy.linalg

from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.linear.matrices import mass_matrix, stiffness_matrix, system_damping_matrix
from fpm_sim.linear.mode_filter import ModeFilter, check_stable, eigenvalue_tolerances
from fpm_sim.linear.nullspace import constraint_rank
from fpm_sim.linear.solvers import reduced_eigenproblem
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.spec import BuiltModel
from fpm_sim.outputs import open_for_writing
from fpm_sim.results import to_jsonable

__all__ = [
    "END_EFFECTOR_SITE",
    "ModalSystem",
    "ReducedModel",
    "ReductionError",
    "StepResponse",
    "accel_site_names",
    "load_reduced_model",
    "modal_system",
    "motor_dofs",
    "reduce_model",
    "static_truncation_error",
]

END_EFFECTOR_SITE = "platform_center"
WRENCH_INPUTS = (("force_x", "N"), ("force_y", "N"), ("moment_z", "N m"))
DISP_OUTPUTS = (("disp_x", "m"), ("disp_y", "m"), ("rot_z", "rad"))


class ReductionError(FpmSimError):
    """A reduction was asked for with inconsistent or impossible options."""


# ---------------------------------------------------------------------------------------------
# the linearised, constrained system in modal coordinates (all modes)


@dataclass
class ModalSystem:
    """All constrained modes of one model at its equilibrium, with input/output maps (SI units).

    Attributes
    ----------
    built
        The model linearised.
    qpos
        The linearisation point (static equilibrium), generalised coordinates.
    omega_rad_s
        Undamped natural frequencies (ascending), rad/s.
    phi
        Mass-normalised mode shapes, ``(nv, n)``.
    xi
        Projected damping ``Phi' C Phi``, ``(n, n)`` (1/s).
    flexibility
        Constrained static flexibility ``G = Z (Z'KZ)^-1 Z'``, ``(nv, nv)``.
    b_q, c_q, c_a
        Generalised forces of unit inputs ``(nv, n_in)``; displacement outputs ``(3, nv)``;
        acceleration outputs ``(n_acc, nv)`` (rows of the accelerometer directions times the site
        Jacobians).
    input_names, input_units, output_names, output_units
        Names and units of the inputs and of the outputs (displacements first, then accelerations).
    accel_sites
        Site of each acceleration output.
    """

    built: BuiltModel
    qpos: np.ndarray
    omega_rad_s: np.ndarray
    phi: np.ndarray
    xi: np.ndarray
    flexibility: np.ndarray
    b_q: np.ndarray
    c_q: np.ndarray
    c_a: np.ndarray
    input_names: list[str]
    input_units: list[str]
    output_names: list[str]
    output_units: list[str]
    accel_sites: list[str]

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.omega_rad_s / (2.0 * np.pi)

    def static_gain(self) -> np.ndarray:
        """Exact static displacement outputs per unit input, ``C_q G B_q`` (3, n_in)."""
        return self.c_q @ self.flexibility @ self.b_q


def _site_id(model: mujoco.MjModel, name: str) -> int:
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if sid < 0:
        raise ReductionError(f"the model has no site {name!r}")
    return sid


def _ee_site_id(model: mujoco.MjModel) -> int:
    """The 3RRR's ``platform_center``, else a described architecture's ``end_effector_site``
    (:mod:`fpm_sim.model.general`)."""
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, END_EFFECTOR_SITE) < 0:
        return _site_id(model, "end_effector_site")
    return _site_id(model, END_EFFECTOR_SITE)


def motor_dofs(model: mujoco.MjModel) -> list[int]:
    """DOF addresses of the motor hinges ``motor_0..2`` (empty when the motors are locked)."""
    out = []
    for i in range(3):
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"motor_{i}")
        if jid >= 0:
            out.append(int(model.jnt_dofadr[jid]))
    return out


def accel_site_names(built: BuiltModel, fraction: float) -> list[str]:
    """Site on each distal link nearest ``fraction`` of its length from the elbow."""
    if not (0.0 <= fraction <= 1.0):
        raise ReductionError(f"accel_fraction must lie in [0, 1], got {fraction!r}")
    out = []
    for i in range(3):
        sites = built.links.get(f"distal_{i}")
        if not sites:
            raise ReductionError("acceleration outputs need the manipulator model (distal links)")
        model = built.model
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        pos = np.array([data.site(s).xpos for s in sites])
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])
        out.append(sites[int(np.argmin(np.abs(arc - fraction * arc[-1])))])
    return out


def _io_maps(
    built: BuiltModel, data: mujoco.MjData, accel_sites: list[str]
) -> tuple[np.ndarray, list[str], list[str], np.ndarray, np.ndarray]:
    model = built.model
    nv = model.nv
    jacp, jacr = np.zeros((3, nv)), np.zeros((3, nv))
    mujoco.mj_jacSite(model, data, jacp, jacr, _ee_site_id(model))
    wrench_rows = np.vstack([jacp[0], jacp[1], jacr[2]])
    cols = [wrench_rows.T]
    names = [n for n, _ in WRENCH_INPUTS]
    units = [u for _, u in WRENCH_INPUTS]
    for i, dof in enumerate(motor_dofs(model)):
        e = np.zeros((nv, 1))
        e[dof] = 1.0
        cols.append(e)
        names.append(f"motor_torque_{i}")
        units.append("N m")
    b_q = np.hstack(cols)
    c_q = wrench_rows.copy()
    c_a = np.zeros((len(accel_sites), nv))
    for k, s in enumerate(accel_sites):
        sid = _site_id(model, s)
        mujoco.mj_jacSite(model, data, jacp, None, sid)
        normal = data.site_xmat[sid].reshape(3, 3)[:, 1].copy()  # link frame y: in-plane normal
        normal[2] = 0.0
        normal /= np.linalg.norm(normal)
        c_a[k] = normal @ jacp
    return b_q, names, units, c_q, c_a


def modal_system(
    built: BuiltModel,
    *,
    qpos: np.ndarray | None = None,
    accel_fraction: float = 0.5,
    filt: ModeFilter | None = None,
) -> ModalSystem:
    """Linearise ``built`` at its static equilibrium and solve the constrained eigenproblem (all modes).

    Parameters
    ----------
    qpos
        Linearisation point; default the static equilibrium under gravity.
    accel_fraction
        Position of the accelerometer on each distal link, as a fraction of its length from the
        elbow (nearest segment site).
    filt
        Rigid-body threshold (``filt.rigid_fraction``, as :mod:`fpm_sim.linear.mode_filter`): a mode within it
        (rigid-body motion, a mechanism) raises :class:`ReductionError`, as no static correction exists
        then; a negative stiffness eigenvalue beyond it raises
        :class:`~fpm_sim.linear.mode_filter.UnstableModelError`.

    The damping is the model's full viscous damping (:func:`~fpm_sim.linear.matrices.system_damping_matrix`):
    the joint dampers, or the differentiated passive forces of ``cable``/``flex`` links, as ``modes`` uses.
    """
    filt = filt or ModeFilter()
    model = built.model
    if model.nq != model.nv:
        raise ReductionError("reduced models need a model without free joints (the manipulator or a clamped rig)")
    data = mujoco.MjData(model)
    q_eq = static_equilibrium(model, data) if qpos is None else np.asarray(qpos, float)
    stiff = stiffness_matrix(model, data, q_eq)  # leaves data at a perturbed state: reset below
    data.qpos[:] = q_eq
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    mass = mass_matrix(model, data)
    rank = constraint_rank(model, data)
    damp = system_damping_matrix(model, q_eq)
    with blas_threads():  # one BLAS thread around the dense solve (fpm_sim.linear.threads)
        z, kr, _, w2, x = reduced_eigenproblem(mass, stiff, rank.basis)  # the constrained method's own solve
    tol = eigenvalue_tolerances(  # finite-difference noise of K (modal.noise_w2), measured when a mode needs it
        model, mass, z @ x, w2, lambda: stiff - stiffness_matrix(model, mujoco.MjData(model), q_eq, eps=2e-7), filt
    )
    check_stable(w2, tol, what="the equilibrium of the model to reduce")
    w = np.sqrt(np.maximum(w2, 0.0))
    rigid = np.abs(w2) <= tol
    if np.any(rigid):
        raise ReductionError(
            f"{int(np.sum(rigid))} mode(s) carry no strain energy (a mechanism or rigid-body motion, below "
            f"{np.sqrt(float(np.max(tol[rigid]))) / (2 * np.pi):.2g} Hz): a static correction does not exist; lock or "
            "stiffen the motors (motors.mode = 'servo' with servo_stiffness_nm_per_rad > 0)"
        )
    phi = z @ x
    xi = phi.T @ damp @ phi
    flex = z @ scipy.linalg.solve(kr, z.T, assume_a="sym")
    # the accelerometers sit on the 3RRR's distal links; a described architecture's model has none of them
    accel_sites = accel_site_names(built, accel_fraction) if "distal_0" in built.links else []
    b_q, in_names, in_units, c_q, c_a = _io_maps(built, data, accel_sites)
    out_names = [n for n, _ in DISP_OUTPUTS] + [f"acc_distal_{i}" for i in range(len(accel_sites))]
    out_units = [u for _, u in DISP_OUTPUTS] + ["m/s^2"] * len(accel_sites)
    return ModalSystem(
        built=built,
        qpos=q_eq,
        omega_rad_s=w,
        phi=phi,
        xi=0.5 * (xi + xi.T),
        flexibility=0.5 * (flex + flex.T),
        b_q=b_q,
        c_q=c_q,
        c_a=c_a,
        input_names=in_names,
        input_units=in_units,
        output_names=out_names,
        output_units=out_units,
        accel_sites=accel_sites,
    )


def static_truncation_error(system: ModalSystem, n_modes: int) -> float:
    """Relative error of the static displacement-per-force gain kept by ``n_modes`` modes, no correction.

    ``|C_q (G - Phi_k Omega_k^-2 Phi_k') B_w|_F / |C_q G B_w|_F`` with ``B_w`` the end-effector
    wrench inputs. Force and moment columns are made commensurate by scaling the moment by
    ``1 / 0.1 m`` and the rotation row by ``0.1 m`` (a wrench of 1 N at a 0.1 m arm).
    """
    arm = 0.1
    scale_in = np.array([1.0, 1.0, 1.0 / arm])
    scale_out = np.array([1.0, 1.0, arm])
    b = system.b_q[:, :3] * scale_in
    c = system.c_q * scale_out[:, None]
    full = c @ system.flexibility @ b
    pk = system.phi[:, :n_modes]
    kept = c @ (pk / system.omega_rad_s[:n_modes] ** 2) @ pk.T @ b
    return float(np.linalg.norm(full - kept) / np.linalg.norm(full))


# ---------------------------------------------------------------------------------------------
# the reduced model


@dataclass
class StepResponse:
    """Response of a model to a unit step on one input, all outputs (SI units)."""

    t_s: np.ndarray
    y: np.ndarray  # (n_t, n_out)
    input_name: str
    output_names: list[str]
    output_units: list[str]

    def output(self, name: str) -> np.ndarray:
        return self.y[:, self.output_names.index(name)]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the input, each output's name, unit, final and peak value, and the samples."""
        return {
            "input": self.input_name,
            "t_s": self.t_s.tolist(),
            "outputs": [
                {
                    "name": n,
                    "unit": u,
                    "final": float(self.y[-1, j]),
                    "peak": float(self.y[np.argmax(np.abs(self.y[:, j])), j]),
                    "values": self.y[:, j].tolist(),
                }
                for j, (n, u) in enumerate(zip(self.output_names, self.output_units))
            ],
        }

    def table(self) -> str:
        """Each output's final and peak value after the unit step (SI units)."""
        lines = [f"unit step on {self.input_name}, {self.t_s[-1]:.4g} s", f"{'output':<24} {'final':>12} {'peak':>12}"]
        for j, (n, u) in enumerate(zip(self.output_names, self.output_units)):
            peak = self.y[np.argmax(np.abs(self.y[:, j])), j]
            lines.append(f"{n + ' (' + u + ')':<24} {self.y[-1, j]:>12.4g} {peak:>12.4g}")
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, outputs: list[str] | None = None, label: str | None = None) -> Any:
        """The outputs (default those that are not accelerations) against time; returns the ``Figure``."""
        import matplotlib.pyplot as plt

        outputs = outputs or [n for n in self.output_names if not n.startswith("acc")]
        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        for n in outputs:
            ax.plot(
                self.t_s,
                self.output(n),
                label=f"{n} ({self.output_units[self.output_names.index(n)]})" + (f" {label}" if label else ""),
            )
        ax.set_xlabel("t (s)")
        ax.set_title(f"unit step on {self.input_name}")
        ax.legend(fontsize=8)
        return ax.figure


@dataclass
class ReducedModel:
    """Continuous state-space reduced model ``x' = A x + B u``, ``y = C x + D u`` of one pose.

    The state is ``x = [eta; eta']``: the amplitudes (and rates) of the kept mass-normalised modes,
    so ``q - q_eq = mode_shapes @ eta``. All quantities SI; see the module docstring for the inputs
    and outputs. Build with :func:`reduce_model`; save with :meth:`save`, load with
    :func:`load_reduced_model`.

    Attributes
    ----------
    a, b, c, d
        State-space matrices ``(2k, 2k)``, ``(2k, n_in)``, ``(n_out, 2k)``, ``(n_out, n_in)``.
    input_names, input_units, output_names, output_units, state_names
        Signal names and units.
    pose
        End-effector pose of the linearisation (m, m, rad).
    frequencies_hz, damping_ratios
        Undamped natural frequency and damping ratio ``Xi_ii / (2 omega_i)`` of each kept mode.
    modal_masses
        ``diag(Phi' M Phi)`` of the kept modes (1 by the mass normalisation; kg or kg m^2 mixtures).
    mode_shapes
        ``(nv, k)`` generalised shapes (mass-normalised) of the kept modes; empty after loading a file
        saved without them.
    qpos
        Linearisation point (generalised coordinates of the full model).
    static_correction
        Whether ``D`` carries the truncated modes' static flexibility for the displacement outputs.
    parameters
        How the full model was built and reduced (JSON-ready).
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    input_names: list[str]
    input_units: list[str]
    output_names: list[str]
    output_units: list[str]
    pose: Pose
    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    modal_masses: np.ndarray
    mode_shapes: np.ndarray
    qpos: np.ndarray
    static_correction: bool
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def n_modes(self) -> int:
        return int(self.a.shape[0] // 2)

    @property
    def state_names(self) -> list[str]:
        k = self.n_modes
        return [f"eta_{i + 1}" for i in range(k)] + [f"eta_dot_{i + 1}" for i in range(k)]

    def input_index(self, name: str) -> int:
        if name not in self.input_names:
            raise ReductionError(f"unknown input {name!r}; inputs are {', '.join(self.input_names)}")
        return self.input_names.index(name)

    def output_index(self, name: str) -> int:
        if name not in self.output_names:
            raise ReductionError(f"unknown output {name!r}; outputs are {', '.join(self.output_names)}")
        return self.output_names.index(name)

    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of ``A`` (1/s), upper half plane, sorted by modulus."""
        ev = np.linalg.eigvals(self.a)
        ev = ev[ev.imag >= 0]
        return ev[np.argsort(np.abs(ev))]

    def discretise(self, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact zero-order-hold discretisation ``(A_d, B_d)`` for the step ``dt_s``."""
        n, m = self.b.shape
        big = np.zeros((n + m, n + m))
        big[:n, :n] = self.a * dt_s
        big[:n, n:] = self.b * dt_s
        e = scipy.linalg.expm(big)
        return e[:n, :n], e[:n, n:]

    def simulate(self, t_s: np.ndarray, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Outputs ``(n_t, n_out)`` for inputs ``u`` ``(n_t, n_in)`` on a uniform grid ``t_s``, held between
        samples (zero-order hold, exact for piecewise-constant loads)."""
        t_s = np.asarray(t_s, float)
        u = np.asarray(u, float).reshape(len(t_s), -1)
        if u.shape[1] != self.b.shape[1]:
            raise ReductionError(f"u needs {self.b.shape[1]} columns ({', '.join(self.input_names)}), got {u.shape[1]}")
        dt = float(t_s[1] - t_s[0])
        if not np.allclose(np.diff(t_s), dt, rtol=1e-6, atol=1e-12):
            raise ReductionError("simulate needs a uniform time grid t_s")
        ad, bd = self.discretise(dt)
        x = np.zeros(self.a.shape[0]) if x0 is None else np.asarray(x0, float)
        xs = np.empty((len(t_s), len(x)))
        for k in range(len(t_s)):
            xs[k] = x
            x = ad @ x + bd @ u[k]
        return xs @ self.c.T + u @ self.d.T

    def step_response(self, input_name: str, *, duration_s: float = 0.2, dt_s: float = 1e-4) -> StepResponse:
        """Response to a unit step (1 N or 1 N m) on ``input_name`` from rest at the equilibrium."""
        j = self.input_index(input_name)
        t = np.arange(round(duration_s / dt_s) + 1) * dt_s
        u = np.zeros((len(t), len(self.input_names)))
        u[:, j] = 1.0
        return StepResponse(t, self.simulate(t, u), input_name, list(self.output_names), list(self.output_units))

    def static_gain(self) -> np.ndarray:
        """``D - C A^-1 B``: outputs per unit constant input at steady state."""
        return self.d - self.c @ np.linalg.solve(self.a, self.b)

    def frequency_response(self, freq_hz: np.ndarray) -> np.ndarray:
        """``H(j 2 pi f) = C (sI - A)^-1 B + D``, shape ``(n_f, n_out, n_in)``."""
        freq_hz = np.atleast_1d(np.asarray(freq_hz, float))
        eye = np.eye(self.a.shape[0])
        return np.array([self.c @ np.linalg.solve(2j * np.pi * f * eye - self.a, self.b) + self.d for f in freq_hz])

    def table(self) -> str:
        lines = [f"{'mode':>4}  {'freq (Hz)':>11}  {'damping':>8}"]
        for i, (f, z) in enumerate(zip(self.frequencies_hz, self.damping_ratios), 1):
            lines.append(f"{i:>4}  {f:>11.3f}  {z:>8.4f}")
        from fpm_sim.model.options import resolution_footer

        footer = resolution_footer(self.parameters)
        return "\n".join([*lines, footer] if footer else lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no matrices)."""
        from fpm_sim.model.options import resolution_of_parameters

        return {
            "pose": dataclasses.asdict(self.pose),
            "n_modes": self.n_modes,
            "frequencies_hz": self.frequencies_hz.tolist(),
            "damping_ratios": self.damping_ratios.tolist(),
            "inputs": [f"{n} ({u})" for n, u in zip(self.input_names, self.input_units)],
            "outputs": [f"{n} ({u})" for n, u in zip(self.output_names, self.output_units)],
            "static_correction": self.static_correction,
            "resolution": resolution_of_parameters(self.parameters),
            "parameters": self.parameters,
        }

    def to_control(self) -> Any:
        """A ``control.StateSpace`` with named signals (needs the optional ``control`` package)."""
        try:
            import control
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("to_control() needs python-control: pip install 'fpm-sim[control]'") from exc
        return control.ss(
            self.a,
            self.b,
            self.c,
            self.d,
            inputs=list(self.input_names),
            outputs=list(self.output_names),
            states=self.state_names,
            name="fpm_rom",
        )

    def plot(self, ax: Any = None, *, input_name: str = "force_x", duration_s: float = 0.2) -> Any:
        """Step response of the displacement outputs to ``input_name`` over ``duration_s`` (s); the ``Figure``."""
        return self.step_response(input_name, duration_s=duration_s).plot(ax=ax)

    # -- files -------------------------------------------------------------------------------

    def _arrays(self) -> dict[str, Any]:
        return {
            "A": self.a,
            "B": self.b,
            "C": self.c,
            "D": self.d,
            "input_names": np.array(self.input_names, dtype=object),
            "input_units": np.array(self.input_units, dtype=object),
            "output_names": np.array(self.output_names, dtype=object),
            "output_units": np.array(self.output_units, dtype=object),
            "state_names": np.array(self.state_names, dtype=object),
            "pose": self.pose.as_array(),
            "pose_units": np.array(["m", "m", "rad"], dtype=object),
            "frequencies_hz": self.frequencies_hz,
            "damping_ratios": self.damping_ratios,
            "modal_masses": self.modal_masses,
            "mode_shapes": self.mode_shapes,
            "qpos": self.qpos,
            "static_correction": int(self.static_correction),
            "parameters_json": json.dumps(to_jsonable(self.parameters)),
        }

    def save(self, path: str | Path) -> Path:
        """Write ``.mat`` (``scipy.io.savemat``, MATLAB 5) or ``.npz`` by suffix."""
        p = Path(path)
        arrays = self._arrays()
        if p.suffix == ".mat":
            import scipy.io

            cellify = {
                k: (v.tolist() if isinstance(v, np.ndarray) and v.dtype == object else v) for k, v in arrays.items()
            }
            for k, v in cellify.items():
                if isinstance(v, list):
                    cellify[k] = np.array(v, dtype=object)
            with open_for_writing(p, error=ReductionError) as f:
                scipy.io.savemat(f, cellify, oned_as="column")
        elif p.suffix == ".npz":
            with open_for_writing(p, error=ReductionError) as f:
                np.savez(
                    f,
                    allow_pickle=True,  # named (its default): else mypy matches the unpacked arrays to it
                    **{
                        k: (v.astype(str) if isinstance(v, np.ndarray) and v.dtype == object else v)
                        for k, v in arrays.items()
                    },
                )
        else:
            raise ReductionError(f"output file {str(p)!r} must end in .mat or .npz", parameter="out")
        return p


def _strings(v: Any) -> list[str]:
    arr = np.asarray(v, dtype=object).ravel()
    out = []
    for item in arr:
        while isinstance(item, np.ndarray):
            item = item.ravel()[0] if item.size else ""
        out.append(str(item))
    return out


def load_reduced_model(path: str | Path) -> ReducedModel:
    """Read a model written by :meth:`ReducedModel.save` (``.mat`` or ``.npz``)."""
    p = Path(path)
    if p.suffix == ".mat":
        import scipy.io

        raw = scipy.io.loadmat(p)
    elif p.suffix == ".npz":
        raw = dict(np.load(p, allow_pickle=False))
    else:
        raise ReductionError(f"{str(p)!r}: expected a .mat or .npz file")

    def vec(key: str) -> np.ndarray:
        return np.asarray(raw[key], float).ravel()

    pose = vec("pose")
    return ReducedModel(
        a=np.asarray(raw["A"], float),
        b=np.asarray(raw["B"], float),
        c=np.asarray(raw["C"], float),
        d=np.asarray(raw["D"], float),
        input_names=_strings(raw["input_names"]),
        input_units=_strings(raw["input_units"]),
        output_names=_strings(raw["output_names"]),
        output_units=_strings(raw["output_units"]),
        pose=Pose(float(pose[0]), float(pose[1]), float(pose[2])),
        frequencies_hz=vec("frequencies_hz"),
        damping_ratios=vec("damping_ratios"),
        modal_masses=vec("modal_masses"),
        mode_shapes=np.asarray(raw["mode_shapes"], float),
        qpos=vec("qpos"),
        static_correction=bool(int(np.asarray(raw["static_correction"]).ravel()[0])),
        parameters=json.loads(_strings(raw["parameters_json"])[0]) if "parameters_json" in raw else {},
    )


def _choose_modes(system: ModalSystem, n_modes: int | None, band_hz: float | None, error_bound: float | None) -> int:
    given = [n for n, v in (("n_modes", n_modes), ("band_hz", band_hz), ("error_bound", error_bound)) if v is not None]
    if len(given) != 1:
        raise ReductionError(
            "choose the modes kept by exactly one of n_modes, band_hz or error_bound; "
            f"got {', '.join(given) or 'none'}",
            parameter=given[-1] if given else "n_modes",
        )
    n_all = len(system.omega_rad_s)
    if n_modes is not None:
        if not (isinstance(n_modes, (int, np.integer)) and 1 <= n_modes <= n_all):
            raise ReductionError(f"must be an integer in [1, {n_all}]", parameter="n_modes", value=n_modes)
        return int(n_modes)
    if band_hz is not None:
        if not (math.isfinite(band_hz) and band_hz > 0):
            raise ReductionError("must be a positive frequency", parameter="band_hz", value=band_hz)
        k = int(np.sum(system.frequencies_hz <= band_hz))
        if k == 0:
            raise ReductionError(
                f"no mode below {band_hz:g} Hz (the first is {system.frequencies_hz[0]:.3g} Hz)",
                parameter="band_hz",
                hint="raise it",
            )
        return k
    assert error_bound is not None
    if not (0.0 < error_bound < 1.0):
        raise ReductionError("must lie in (0, 1)", parameter="error_bound", value=error_bound)
    for k in range(1, n_all + 1):
        if static_truncation_error(system, k) <= error_bound:
            return k
    return n_all


def reduce_model(
    built: BuiltModel | ModalSystem,
    *,
    n_modes: int | None = None,
    band_hz: float | None = None,
    error_bound: float | None = None,
    static_correction: bool = True,
    accel_fraction: float = 0.5,
    qpos: np.ndarray | None = None,
) -> ReducedModel:
    """Reduced-order state-space model of ``built`` at its static equilibrium (see module docstring).

    Parameters
    ----------
    built
        The full model (a :class:`~fpm_sim.model.spec.BuiltModel`) or its already solved
        :class:`ModalSystem` (to reduce one linearisation several ways).
    n_modes, band_hz, error_bound
        Exactly one: keep the lowest ``n_modes`` modes; all modes up to ``band_hz`` (Hz); or the fewest
        modes whose uncorrected static truncation error is at most ``error_bound`` (relative).
    static_correction
        Add the truncated modes' static flexibility as feedthrough on the displacement outputs.
    accel_fraction
        Accelerometer position on each distal link (fraction of its length from the elbow).
    qpos
        Linearisation point (default: static equilibrium under gravity).
    """
    system = built if isinstance(built, ModalSystem) else modal_system(built, qpos=qpos, accel_fraction=accel_fraction)
    k = _choose_modes(system, n_modes, band_hz, error_bound)
    w = system.omega_rad_s[:k]
    pk = system.phi[:, :k]
    xi = system.xi[:k, :k]
    gamma = pk.T @ system.b_q  # modal input influence (k, n_in)
    n_in = system.b_q.shape[1]
    a = np.block([[np.zeros((k, k)), np.eye(k)], [-np.diag(w**2), -xi]])
    b = np.vstack([np.zeros((k, n_in)), gamma])
    c_disp = np.hstack([system.c_q @ pk, np.zeros((3, k))])
    d_disp = np.zeros((3, n_in))
    if static_correction:
        residual = system.flexibility - (pk / w**2) @ pk.T
        d_disp = system.c_q @ residual @ system.b_q
    ca_phi = system.c_a @ pk
    c_acc = np.hstack([-ca_phi * w**2, -ca_phi @ xi])
    d_acc = ca_phi @ gamma
    model = system.built.model
    data = mujoco.MjData(model)
    data.qpos[:] = system.qpos
    mujoco.mj_forward(model, data)
    modal_masses = np.einsum("ik,ij,jk->k", pk, mass_matrix(model, data), pk)
    pose_d = system.built.parameters.get("pose", {"x_m": 0.0, "y_m": 0.0, "phi_rad": 0.0})
    params = dict(system.built.parameters)
    params.update(
        {
            "reduction": {
                "n_modes": k,
                "n_modes_full": len(system.omega_rad_s),
                "static_correction": static_correction,
                "static_truncation_error": static_truncation_error(system, k),
                "accel_sites": system.accel_sites,
            }
        }
    )
    return ReducedModel(
        a=a,
        b=b,
        c=np.vstack([c_disp, c_acc]),
        d=np.vstack([d_disp, d_acc]),
        input_names=list(system.input_names),
        input_units=list(system.input_units),
        output_names=list(system.output_names),
        output_units=list(system.output_units),
        pose=Pose(**pose_d),
        frequencies_hz=w / (2 * np.pi),
        damping_ratios=np.diag(xi) / (2 * w),
        modal_masses=modal_masses,
        mode_shapes=pk.copy(),
        qpos=system.qpos.copy(),
        static_correction=static_correction,
        parameters=params,
    )
