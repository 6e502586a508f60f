"""Headless nonlinear rollouts of the full flexible manipulator.

A rollout starts at the static equilibrium under gravity (zero velocity) and steps the full MuJoCo
model (``mj_step``) for ``duration_s``: by default with MuJoCo's ``discrete`` integrator at a step chosen from
the band the result must be right in (:mod:`fpm_sim.sim.stepping`: numerical damping at most 2 % at the band's
top, 5 x f1 unless given), ``integrator="explicit"`` with the model's own integrator and step (the reference).
Loads are evaluated once per output step and held constant over it (zero-order hold, the same convention as
:meth:`fpm_sim.rom.reduction.ReducedModel.simulate`):

- ``ee_wrench(t) -> (F_x, F_y, M_z)`` (N, N, N m): a wrench on the end effector at
  ``platform_center``, world axes, applied through ``xfrc_applied`` of the platform body, whose
  centre of mass is that site, so it follows the platform as it moves; where the site is off its body's centre of
  mass (an imported model's end-effector site), the force's moment about the centre of mass is added, its arm taken
  at each output step with the load (the force acts at the site to the motion within one output step);
- ``motor_torque(t) -> (tau_0, tau_1, tau_2)`` (N m) on the motor hinges ``motor_i`` (needs
  ``motors.mode = "servo"`` or a compliant clamp; locked motors have no joint);
- ``motor_reference(t) -> (theta_0, ...)`` (rad): servo drive. The servo hinge is a spring-damper of
  stiffness ``k`` about the assembled angle; a reference ``theta_ref`` adds the torque
  ``k * theta_ref`` (the spring's set point moved to ``theta_ref``).

Outputs per sample (``t = 0, dt, 2 dt, ...``): end-effector position ``(x, y)`` and rotation ``phi``,
its displacement from the equilibrium, the *deflection* (end-effector pose minus the rigid-link
forward kinematics of the current motor angles: what link bending adds), motor angles, and the
accelerations (world frame, m/s^2, gravity excluded) at chosen sites, e.g. ``distal_0_p2``.

Divergence is an error (:class:`RolloutError`), never a result: every load value must be finite; after
each output step the run stops when MuJoCo warned (its warning counters ``data.warning``: on "Nan, Inf
or huge value in QACC" MuJoCo resets the state to ``qpos0``, which would otherwise read as zero
displacement), when the state is not finite, or when the end effector has moved more than the model's
size (``model.stat.extent``: a flexible manipulator that far from its equilibrium has left the linear,
small-deflection regime the model is built for, i.e. its energy has grown without bound). MuJoCo's
messages are collected (:func:`fpm_sim.model.mujoco_log.mujoco_messages`), never written to
``MUJOCO_LOG.TXT``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from fpm_sim.config import Manipulator
from fpm_sim.config.checks import check_finite
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose, forward_kinematics, inverse_kinematics
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.mujoco_log import mujoco_messages
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel
from fpm_sim.outputs import open_for_writing
from fpm_sim.rom.reduction import END_EFFECTOR_SITE, motor_dofs
from fpm_sim.sim.stepping import (
    DEFAULT_INTEGRATOR,
    Stepping,
    SteppingError,
    apply_stepping,
    choose_stepping,
    reraise_as,
)

__all__ = [
    "EE_SITES",
    "RolloutError",
    "RolloutMachine",
    "RolloutResult",
    "aligned_options",
    "aligned_step",
    "check_times",
    "constant",
    "end_effector_coordinates",
    "end_effector_pose",
    "end_effector_site_id",
    "machine_of_3rrr",
    "rollout",
    "save_columns",
    "sine",
    "step_at",
]

Profile = Callable[[float], ArrayLike]
"""A load as a function of time (s): three numbers, a sequence or an array (see the module docstring)."""
EE_SITES = (END_EFFECTOR_SITE, "end_effector_site")
"""The end-effector site of the 3RRR's model and of a described architecture's (:mod:`fpm_sim.model.general`)."""
_UNITS = {"x": "m", "y": "m", "z": "m", "phi": "rad"}
_LOAD_NAMES = {"x": "fx_n", "y": "fy_n", "z": "fz_n", "phi": "mz_nm"}


class RolloutError(FpmSimError):
    """Inconsistent rollout options (named in the message), or a diverging simulation."""


_BAD_STATE = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
)


def _divergence(
    model: mujoco.MjModel, data: mujoco.MjData, p0: np.ndarray, messages: list[str], site: str | None = None
) -> str | None:
    """Why the run has diverged (module docstring; ``p0``: the end-effector site's position at the start, ``site``
    its name as :func:`end_effector_site_id`), or ``None``."""
    bad = [int(w) for w in _BAD_STATE if data.warning[int(w)].number > 0]
    if bad or messages:
        what = messages[0].strip() if messages else "bad state warning"
        return f"MuJoCo reported an unstable simulation ({what})"
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        return "the state is no longer finite"
    moved = float(np.linalg.norm(data.site_xpos[end_effector_site_id(model, site)] - p0))
    if moved > model.stat.extent:
        return f"the end effector moved {moved:.3g} m, more than the model's size ({model.stat.extent:.3g} m)"
    return None


def _finite(name: str, value: Any) -> np.ndarray:
    try:
        return check_finite(name, value)
    except FpmSimError as e:
        raise reraise_as(RolloutError, e) from None


def constant(*values: float) -> Profile:
    """A constant load profile (switched on at ``t = 0``); non-finite values are refused when applied."""
    v = np.array(values, float)
    return lambda t: v


def step_at(t0_s: float, *values: float) -> Profile:
    """Zero before ``t0_s``, ``values`` from then on."""
    _finite("t0_s", t0_s)
    v = _finite("step values", values)
    z = np.zeros_like(v)
    return lambda t: v if t >= t0_s else z


def sine(freq_hz: float, *amplitudes: float) -> Profile:
    """``amplitudes * sin(2 pi f t)``; ``freq_hz`` finite and >= 0."""
    if not _finite("freq_hz", freq_hz) >= 0:
        raise RolloutError("must be >= 0 Hz", parameter="freq_hz", value=freq_hz)
    a = _finite("sine amplitudes", amplitudes)
    return lambda t: a * math.sin(2.0 * math.pi * freq_hz * t)


@dataclass
class RolloutResult:
    """Time histories of one rollout (SI units).

    Attributes
    ----------
    t_s
        Sample times (s), from 0.
    ee_pose
        ``(n, c)``: the end effector's :attr:`coordinates` (m, rad), absolute; the 3RRR's ``x, y, phi``.
    ee_disp
        ``(n, c)``: ``ee_pose`` minus its value at the equilibrium (``t = 0``).
    deflection
        ``(n, c)``: ``ee_pose`` minus the rigid-link forward kinematics of the motor angles.
    motor_angles_rad
        ``(n, m)`` motor (actuated joint) coordinates, rad (m for a prismatic one); constant when locked.
    accel
        Site name -> ``(n, 3)`` world-frame linear acceleration (m/s^2), gravity excluded.
    wrench, motor_torque
        ``(n, c)`` end-effector loads (a force along each translational coordinate, N; a moment about z for
        ``phi``, N m) and ``(n, m)`` motor torques (N m; N on a prismatic joint), applied over each sample's
        interval.
    wall_s
        Wall-clock time of the stepping loop (s).
    parameters
        Model and run description.
    """

    t_s: np.ndarray
    ee_pose: np.ndarray
    ee_disp: np.ndarray
    deflection: np.ndarray
    motor_angles_rad: np.ndarray
    accel: dict[str, np.ndarray]
    wrench: np.ndarray
    motor_torque: np.ndarray
    wall_s: float
    n_steps: int
    parameters: dict[str, Any] = field(default_factory=dict)
    stepping: Stepping | None = None
    """The integrator, its step and its error bounds in the band (:mod:`fpm_sim.sim.stepping`)."""
    coordinates: tuple[str, ...] = ("x", "y", "phi")
    """The end effector's recorded coordinates: the 3RRR's ``x, y, phi``, a described architecture's task ones."""
    motor_names: tuple[str, ...] = ("0", "1", "2")
    """The motors' names in the columns (``motor_<name>_rad``): the 3RRR's ``0..2``, else ``<chain>_<joint>``."""

    def _names(self) -> list[str]:
        return [f"{c}_{_UNITS[c]}" for c in self.coordinates]

    def columns(self) -> dict[str, np.ndarray]:
        """Flat name -> column view (units in the names)."""
        cols: dict[str, np.ndarray] = {"t_s": self.t_s}
        for prefix, arr in (("ee", self.ee_pose), ("disp", self.ee_disp), ("deflection", self.deflection)):
            for k, n in enumerate(self._names()):
                cols[f"{prefix}_{n}"] = arr[:, k]
        for i, m in enumerate(self.motor_names):
            cols[f"motor_{m}_rad"] = self.motor_angles_rad[:, i]
        for k, c in enumerate(self.coordinates):
            cols[f"load_{_LOAD_NAMES[c]}"] = self.wrench[:, k]
        for i, m in enumerate(self.motor_names):
            cols[f"motor_torque_{m}_nm"] = self.motor_torque[:, i]
        for site, a in self.accel.items():
            for k, ax in enumerate("xyz"):
                cols[f"acc_{site}_{ax}_m_s2"] = a[:, k]
        return cols

    def save(self, path: str | Path) -> Path:
        """Write ``.csv`` (one column per signal) or ``.npz`` by suffix."""
        return save_columns(path, self.columns(), RolloutError)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: final and peak end-effector displacement (m, rad), peak accelerations, resolution."""
        from fpm_sim.model.options import resolution_of_parameters

        d = self.ee_disp
        return {
            "parameters": self.parameters,
            "resolution": resolution_of_parameters(self.parameters),
            "n_samples": len(self.t_s),
            "n_steps": self.n_steps,
            "wall_s": self.wall_s,
            "stepping": self.stepping.to_dict() if self.stepping is not None else None,
            "final_disp": {k: float(d[-1, i]) for i, k in enumerate(self._names())},
            "peak_abs_disp": {k: float(np.max(np.abs(d[:, i]))) for i, k in enumerate(self._names())},
            "peak_abs_accel_m_s2": {s: float(np.max(np.linalg.norm(a, axis=1))) for s, a in self.accel.items()},
        }

    def table(self) -> str:
        """Final and peak values of the end-effector displacement (mm, mrad) and accelerations (m/s^2)."""
        d = self.ee_disp
        p = self.parameters
        lines = [
            f"rollout {p.get('duration_s', self.t_s[-1]):.4g} s: {self.n_steps} steps of "
            f"{p.get('timestep_s', 0):.3g} s (nv = {p.get('nv', '?')}), {len(self.t_s)} samples, "
            f"wall {self.wall_s:.2f} s",
            *([self.stepping.line()] if self.stepping is not None else []),
            f"{'signal':<22} {'final':>12} {'peak |.|':>12}",
        ]
        for i, c in enumerate(self.coordinates):
            k, unit = f"disp {c}", ("mrad" if c == "phi" else "mm")
            peak = np.max(np.abs(d[:, i]))
            lines.append(f"{k + ' (' + unit + ')':<22} {d[-1, i] * 1e3:>12.5f} {peak * 1e3:>12.5f}")
        for s, a in self.accel.items():
            peak = np.max(np.linalg.norm(a, axis=1))
            lines.append(f"{'acc ' + s + ' (m/s2)':<22} {np.linalg.norm(a[-1]):>12.4g} {peak:>12.4g}")
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, axes: Any = None) -> Any:
        """End-effector displacement, deflection and accelerations against time; returns the ``Figure``.

        ``ax`` (or ``axes``): a sequence of 2 (3 with accelerations) axes to draw on, or one axes for the
        end-effector displacement alone; default a new figure.
        """
        import matplotlib.pyplot as plt

        axes = ax if ax is not None else axes
        if axes is not None and not np.iterable(axes):
            axes = [axes]
        n_ax = 3 if self.accel else 2
        if axes is None:
            _, axes = plt.subplots(n_ax, 1, figsize=(8, 2.6 * n_ax), sharex=True)
        ax = axes[0]
        for k, c in enumerate(self.coordinates):
            if c != "phi":
                ax.plot(self.t_s, self.ee_disp[:, k] * 1e3, label=c)
        ax.set_ylabel("EE displacement (mm)")
        if "phi" in self.coordinates:
            ax2 = ax.twinx()
            ax2.plot(self.t_s, self.ee_disp[:, self.coordinates.index("phi")] * 1e3, color="0.5", lw=0.8, label="phi")
            ax2.set_ylabel("phi (mrad)")
        ax.legend(loc="upper left", fontsize=8)
        if len(axes) == 1:
            ax.set_xlabel("t (s)")
            return ax.figure
        ax = axes[1]
        for k, c in enumerate(self.coordinates):
            if c != "phi":
                ax.plot(self.t_s, self.deflection[:, k] * 1e3, label=c)
        ax.set_ylabel("deflection (mm)")
        ax.legend(loc="upper left", fontsize=8)
        if self.accel:
            ax = axes[2]
            for site, a in self.accel.items():
                ax.plot(self.t_s, np.linalg.norm(a[:, :2], axis=1), lw=0.8, label=site)
            ax.set_ylabel("|in-plane acc| (m/s^2)")
            ax.legend(loc="upper left", fontsize=8)
        axes[-1].set_xlabel("t (s)")
        fig = axes[0].figure
        fig.tight_layout()
        return fig


def save_columns(path: str | Path, cols: dict[str, np.ndarray], error: type[FpmSimError]) -> Path:
    """Write named columns as ``.csv`` (header row) or ``.npz`` by suffix; a bad suffix or an unwritable file
    raises ``error`` naming the ``out`` parameter."""
    p = Path(path)
    if p.suffix not in (".csv", ".npz"):
        raise error(f"output file {str(p)!r} must end in .csv or .npz", parameter="out")
    with open_for_writing(p, error=error) as f:
        if p.suffix == ".csv":
            names = list(cols)
            data = np.column_stack([cols[n] for n in names])
            np.savetxt(f, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
        else:
            np.savez(f, allow_pickle=True, **cols)  # named (its default): else mypy matches the columns to it
    return p


def aligned_options(manip: Manipulator, pose: Pose, options: ModelOptions, output_step_s: float) -> ModelOptions:
    """``options`` with the automatic timestep rounded down so that ``output_step_s`` is a whole number of
    steps (an explicit ``options.timestep_s`` is rounded the same way)."""
    h_auto = options.timestep_s or build_manipulator(manip, pose, options).timestep_s
    return aligned_step(options, h_auto, output_step_s)


def aligned_step(options: ModelOptions, step_s: float, output_step_s: float) -> ModelOptions:
    """``options`` with the timestep ``step_s`` rounded down so that ``output_step_s`` is a whole number of steps."""
    n = int(np.ceil(output_step_s / step_s * (1 - 1e-12)))
    return dataclasses.replace(options, timestep_s=output_step_s / n)


def _load(name: str, value: ArrayLike, t_s: float, n: int = 3) -> np.ndarray:
    v = np.asarray(value, float)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise RolloutError(f"must give {n} finite values at t = {t_s:g} s", parameter=name, value=value)
    return v


def _platform_phi(data: mujoco.MjData, body_id: int) -> float:
    r = data.xmat[body_id].reshape(3, 3)
    return math.atan2(r[1, 0], r[0, 0])


def end_effector_site_id(model: mujoco.MjModel, site: str | None = None) -> int:
    """The end-effector site's id: ``site`` (an imported model's named end effector) or the first of
    :data:`EE_SITES` (the 3RRR's ``platform_center``, a described architecture's ``end_effector_site``)."""
    if site is not None:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        if sid < 0:
            raise RolloutError(f"the model has no end-effector site {site!r}")
        return int(sid)
    for name in EE_SITES:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        if sid >= 0:
            return int(sid)
    raise RolloutError(f"the model has no end-effector site ({' or '.join(EE_SITES)})")


def end_effector_coordinates(
    model: mujoco.MjModel, data: mujoco.MjData, coordinates: Sequence[str], site: str | None = None
) -> np.ndarray:
    """The end effector's ``coordinates`` (of ``x, y, z`` in m, ``phi`` about z in rad) after a forward pass. A named
    ``site`` (an imported model's) gives ``phi`` as the heading of the site's own x axis
    (:mod:`fpm_sim.model.imported_pose`), the others the heading of the site's body."""
    sid = end_effector_site_id(model, site)
    p = data.site_xpos[sid]
    values = {"x": p[0], "y": p[1], "z": p[2]}
    if "phi" in coordinates and site is not None:
        x = data.site_xmat[sid].reshape(3, 3)[:, 0]
        values["phi"] = math.atan2(x[1], x[0])
    elif "phi" in coordinates:
        values["phi"] = _platform_phi(data, int(model.site_bodyid[sid]))
    return np.array([values[c] for c in coordinates])


def end_effector_pose(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """``(x, y, phi)`` of the end-effector site (``platform_center``) after a forward pass."""
    return end_effector_coordinates(model, data, ("x", "y", "phi"))


@dataclass
class RolloutMachine:
    """What a rollout reads of the machine besides its MuJoCo model: :func:`machine_of_3rrr` for the 3RRR,
    :func:`fpm_sim.sim.task.machine_of` for a described architecture."""

    coordinates: tuple[str, ...]
    """The end effector's recorded coordinates, and the components of its load (a force along each translational
    one, a moment about z for ``phi``)."""
    motor_names: tuple[str, ...]
    """Every motor (actuated joint), driven or locked: one motor torque value each."""
    motor_dofs: list[int]
    """Their degrees of freedom in the model (empty: locked, no joint)."""
    motor0: np.ndarray
    """Their coordinates at the assembly (``qpos0``), absolute (rad or m)."""
    servo_stiffness: np.ndarray | None
    """Each motor's servo stiffness (a reference acts through it); ``None``: no servo."""
    rigid_pose: Callable[[np.ndarray], np.ndarray]
    """Motor coordinates (absolute) -> the rigid-link end-effector coordinates (the deflection's reference)."""
    no_motor_hint: str
    """How to give the motors joints (the error when torques or references meet locked motors)."""
    parameters: dict[str, Any] = field(default_factory=dict)
    ee_site: str | None = None
    """The end-effector site's name where it is none of :data:`EE_SITES` (an imported model's)."""


def machine_of_3rrr(built: BuiltModel, manip: Manipulator) -> RolloutMachine:
    """The 3RRR ``manip`` built as ``built``: ``x, y, phi``, motors ``motor_0..2`` (rigid forward kinematics from
    the last pose: :func:`fpm_sim.kinematics.forward_kinematics`)."""
    pose = Pose(**built.parameters["pose"])
    motor0 = np.asarray(inverse_kinematics(manip.geometry, pose).motor_angles_rad, float)
    mdofs = motor_dofs(built.model)
    guess = [pose]

    def rigid(ma: np.ndarray) -> np.ndarray:
        if not mdofs:
            return pose.as_array()
        guess[0] = forward_kinematics(manip.geometry, ma, guess=guess[0])
        return guess[0].as_array()

    servo = manip.motors.mode == "servo"
    return RolloutMachine(
        coordinates=("x", "y", "phi"),
        motor_names=("0", "1", "2"),
        motor_dofs=mdofs,
        motor0=motor0,
        servo_stiffness=np.full(3, manip.motors.servo_stiffness_nm_per_rad) if servo else None,
        rigid_pose=rigid,
        no_motor_hint="set motors.mode = 'servo' (Motors(mode='servo', servo_stiffness_nm_per_rad=...)); locked "
        "motors have no joint",
        parameters={"motors": dataclasses.asdict(manip.motors)},
    )


def rollout(
    built: BuiltModel,
    manip: Manipulator | RolloutMachine,
    *,
    duration_s: float,
    output_step_s: float = 1e-4,
    ee_wrench: Profile | None = None,
    motor_torque: Profile | None = None,
    motor_reference: Profile | None = None,
    accel_sites: Sequence[str] = (),
    qpos: np.ndarray | None = None,
    progress: bool = False,
    integrator: str = DEFAULT_INTEGRATOR,
    band_hz: float | None = None,
    step_s: float | None = None,
    f1_hz: float | None = None,
) -> RolloutResult:
    """Simulate the full nonlinear model from its static equilibrium (see module docstring).

    Parameters
    ----------
    built, manip
        The model (from :func:`fpm_sim.model.manipulator.build_manipulator`) and the description it
        was built from (for the rigid forward kinematics and the servo stiffness); or any machine's model and its
        :class:`RolloutMachine` (:func:`fpm_sim.sim.task.machine_of`).
    duration_s
        Simulated time (s).
    output_step_s
        Output (and load hold) interval; rounded to a whole number of model timesteps.
    ee_wrench, motor_torque, motor_reference
        Load profiles ``t -> values`` (see module docstring; one per end-effector coordinate, one per motor);
        ``None``: none.
    accel_sites
        Sites whose acceleration is recorded.
    qpos
        Initial configuration (default: static equilibrium under gravity).
    progress
        Show a tqdm progress bar.
    integrator, band_hz, step_s
        ``"discrete"`` (default) at a step from the band ``band_hz`` (Hz; default 5 x f1), or at ``step_s``;
        ``"explicit"``: the model's own integrator and step (:func:`fpm_sim.sim.stepping.choose_stepping`).
    f1_hz
        The model's first natural frequency (Hz) if known (the default band needs it; else a modal analysis).

    Long because: the signature and the documentation of its fifteen options are half of it; the body (checks,
    stepping, recording and the time loop) is named steps of about 35 lines.
    """
    check_times(duration_s, output_step_s)
    machine = manip if isinstance(manip, RolloutMachine) else machine_of_3rrr(built, manip)
    q0 = static_equilibrium(built.model, mujoco.MjData(built.model)) if qpos is None else np.asarray(qpos, float)
    stepping, model, n_sub = _stepping(built, q0, output_step_s, integrator, band_hz, step_s, f1_hz)
    h = float(model.opt.timestep)
    dt_out = n_sub * h
    n_out = round(duration_s / dt_out)
    loads = _Loads(ee_wrench, motor_torque, motor_reference, machine.servo_stiffness)
    bid = _check_loads(model, machine, loads)
    acc_ids = _site_ids(model, accel_sites)
    data = mujoco.MjData(model)
    data.qpos[:] = q0
    mujoco.mj_forward(model, data)
    p0 = data.site_xpos[end_effector_site_id(model, machine.ee_site)].copy()
    ee0 = end_effector_coordinates(model, data, machine.coordinates, machine.ee_site)
    trace = _Trace(model, data, machine, bid, dict(zip(accel_sites, acc_ids)), np.arange(n_out + 1) * dt_out)
    wall = _run(trace, loads, n_sub, p0, progress=progress)
    t = trace.t_s
    return RolloutResult(
        t_s=t,
        ee_pose=trace.ee,
        ee_disp=trace.ee - ee0,
        deflection=trace.defl,
        motor_angles_rad=trace.motors,
        accel=trace.acc,
        wrench=trace.wrench,
        motor_torque=trace.torque,
        wall_s=wall,
        n_steps=n_out * n_sub,
        stepping=stepping,
        coordinates=machine.coordinates,
        motor_names=machine.motor_names,
        parameters={
            **built.parameters,
            "timestep_s": h,
            "integrator": stepping.integrator,
            "duration_s": float(t[-1]),
            "output_step_s": dt_out,
            "steps_per_output": n_sub,
            **machine.parameters,
        },
    )


def _stepping(
    built: BuiltModel,
    q0: np.ndarray,
    output_step_s: float,
    integrator: str,
    band_hz: float | None,
    step_s: float | None,
    f1_hz: float | None,
) -> tuple[Stepping, mujoco.MjModel, int]:
    """The integrator and step (:func:`fpm_sim.sim.stepping.choose_stepping`), the model that uses them, and the
    model steps per output sample."""
    try:
        stepping = choose_stepping(
            built, integrator=integrator, band_hz=band_hz, step_s=step_s, divides_s=output_step_s, f1_hz=f1_hz, qpos=q0
        )
    except SteppingError as e:
        raise reraise_as(RolloutError, e) from None
    model = apply_stepping(built, stepping).model
    h = float(model.opt.timestep)
    if not (output_step_s >= h * (1 - 1e-9)):
        raise RolloutError(f"output_step_s ({output_step_s:g} s) must be at least the model timestep ({h:.3g} s)")
    return stepping, model, max(1, round(output_step_s / h))


def check_times(duration_s: float, output_step_s: float) -> None:
    """Both must be positive finite times (s)."""
    if not (isinstance(duration_s, (int, float)) and duration_s > 0 and math.isfinite(duration_s)):
        raise RolloutError("must be a positive finite time", parameter="duration_s", value=duration_s)
    if not (isinstance(output_step_s, (int, float)) and math.isfinite(output_step_s) and output_step_s > 0):
        raise RolloutError("must be a positive finite time", parameter="output_step_s", value=output_step_s)


@dataclass(frozen=True)
class _Loads:
    """A rollout's load profiles (``None``: none) and the servo stiffness a motor reference acts through."""

    ee_wrench: Profile | None
    motor_torque: Profile | None
    motor_reference: Profile | None
    servo_stiffness: np.ndarray | None


def _check_loads(model: mujoco.MjModel, machine: RolloutMachine, loads: _Loads) -> int:
    """Refuse loads the model cannot take; returns the end effector's body id (where the wrench acts)."""
    n = len(machine.motor_names)
    if (loads.motor_torque is not None or loads.motor_reference is not None) and len(machine.motor_dofs) != n:
        raise RolloutError("motor torques or references need motor joints: " + machine.no_motor_hint)
    if loads.motor_reference is not None and machine.servo_stiffness is None:
        raise RolloutError("motor_reference drives a servo: " + machine.no_motor_hint)
    sid = end_effector_site_id(model, machine.ee_site)
    return int(model.site_bodyid[sid])


def _site_ids(model: mujoco.MjModel, sites: Sequence[str]) -> list[int]:
    """Ids of the sites whose acceleration is recorded."""
    ids = []
    for s in sites:
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
        if k < 0:
            raise RolloutError(f"unknown site {s!r} in accel_sites (e.g. distal_0_p2, platform_center)")
        ids.append(k)
    return ids


_WRENCH_SLOT = {"x": 0, "y": 1, "z": 2, "phi": 5}
"""Where each end-effector coordinate's load goes in ``xfrc_applied`` (force x, y, z; torque about z)."""


class _Trace:
    """What a rollout records at each output sample ``k`` (state at ``t_k``, loads applied from ``t_k`` on)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        machine: RolloutMachine,
        bid: int,
        acc_ids: dict[str, int],
        t_s: np.ndarray,
    ) -> None:
        self.model, self.data, self.machine = model, data, machine
        self.bid, self.acc_ids, self.t_s = bid, acc_ids, t_s
        n, c, m = t_s.size, len(machine.coordinates), len(machine.motor_names)
        self.ee = np.zeros((n, c))
        self.motors = np.zeros((n, m))
        self.defl = np.zeros((n, c))
        self.wrench = np.zeros((n, c))
        self.torque = np.zeros((n, m))
        self.acc = {s: np.zeros((n, 3)) for s in acc_ids}
        self.gravity = model.opt.gravity.copy()
        self.slots = [_WRENCH_SLOT[x] for x in machine.coordinates]
        self.sid = end_effector_site_id(model, machine.ee_site)
        # the site off its body's centre of mass (an imported model's): the force's moment about it is added
        self.offset = not np.allclose(model.body_ipos[bid], model.site_pos[self.sid], atol=1e-12)
        self.qadr = [int(model.jnt_qposadr[model.dof_jntid[d]]) for d in machine.motor_dofs]
        self._res6 = np.zeros(6)

    def record(self, k: int) -> None:
        """The end-effector pose, motor angles, deflection from the rigid pose and site accelerations at sample
        ``k``."""
        model, data, mc = self.model, self.data, self.machine
        self.ee[k] = end_effector_coordinates(model, data, mc.coordinates, mc.ee_site)
        ma = mc.motor0 + (np.array([data.qpos[a] for a in self.qadr]) if self.qadr else 0.0)
        self.motors[k] = ma
        self.defl[k] = self.ee[k] - mc.rigid_pose(ma)
        if self.acc_ids:
            mujoco.mj_rnePostConstraint(model, data)
            for s, i in self.acc_ids.items():
                mujoco.mj_objectAcceleration(model, data, mujoco.mjtObj.mjOBJ_SITE, i, self._res6, 0)
                self.acc[s][k] = self._res6[3:] + self.gravity  # cacc carries -gravity (accelerometer convention)

    def apply_loads(self, k: int, loads: _Loads) -> None:
        """Set the wrench on the end effector and the motor torques of sample ``k`` (recorded)."""
        data, tk, mc = self.data, self.t_s[k], self.machine
        data.xfrc_applied[self.bid] = 0.0
        data.qfrc_applied[:] = 0.0
        if loads.ee_wrench is not None:
            w = _load("ee_wrench", loads.ee_wrench(tk), tk, len(mc.coordinates))
            self.wrench[k] = w
            data.xfrc_applied[self.bid, self.slots] = w
            if self.offset:  # the arm from the centre of mass to the site at t_k, held with the load
                mujoco.mj_kinematics(self.model, data)
                arm = data.site_xpos[self.sid] - data.xipos[self.bid]
                data.xfrc_applied[self.bid, 3:] += np.cross(arm, data.xfrc_applied[self.bid, :3])
        m = len(mc.motor_names)
        tau = np.zeros(m)
        if loads.motor_torque is not None:
            tau += _load("motor_torque", loads.motor_torque(tk), tk, m)
        if loads.motor_reference is not None and loads.servo_stiffness is not None:
            tau += loads.servo_stiffness * _load("motor_reference", loads.motor_reference(tk), tk, m)
        if mc.motor_dofs:
            self.torque[k] = tau
            data.qfrc_applied[mc.motor_dofs] = tau


def _run(trace: _Trace, loads: _Loads, n_sub: int, p0: np.ndarray, *, progress: bool) -> float:
    """Step ``n_sub`` model steps between samples, recording each; returns the wall time (s).

    Raises
    ------
    RolloutError
        The simulation diverged (:func:`_divergence`).
    """
    model, data, t = trace.model, trace.data, trace.t_s
    n_out = t.size - 1
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_out, desc="rollout", unit="sample", leave=False)
    start = time.perf_counter()
    # sample k holds the state at t_k and the loads applied from t_k on (accelerations include them)
    with mujoco_messages() as messages:
        for k in range(n_out + 1):
            trace.apply_loads(k, loads)
            if trace.acc_ids:
                mujoco.mj_forward(model, data)
            else:
                mujoco.mj_kinematics(model, data)
            trace.record(k)
            if k == n_out:
                break
            mujoco.mj_step(model, data, nstep=n_sub)
            why = _divergence(model, data, p0, messages, trace.machine.ee_site)
            if why is not None:
                if bar is not None:
                    bar.close()
                raise RolloutError(
                    f"the simulation diverged at t = {t[k + 1]:.4g} s: {why}",
                    parameter="ee_wrench" if loads.ee_wrench is not None else "motor_torque",
                    hint="reduce the loads (ee_wrench, motor_torque) or the timestep (timestep_s)",
                )
            if bar is not None:
                bar.update(1)
    wall = time.perf_counter() - start
    if bar is not None:
        bar.close()
    return wall
