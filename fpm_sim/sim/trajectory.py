"""Point-to-point moves of the flexible manipulator: servo tracking, residual vibration and input shaping.

The end effector is commanded along a path ``pose(t)`` (:class:`MovePath`): a straight move in ``(x, y, phi)`` from
the start pose to the end pose with a motion profile ``s(t / T)`` (``trapezoidal``: a third accelerating, a
third cruising, a third braking; ``s-curve``: the same with the acceleration ramped over a third of each
accelerating phase, jerk-limited; ``minimum-jerk``: ``10 u^3 - 15 u^4 + 6 u^5``), or the samples of a CSV
``t_s, x_mm, y_mm, phi_rad`` (linear interpolation; the last row is held).

Each motor follows the rigid inverse kinematics (:func:`fpm_sim.kinematics.inverse_kinematics`) of the commanded
pose through its position servo. The servo is the description's (``motors.mode = "servo"``: stiffness ``k`` and
damping ``c``) or, for locked motors, the stated defaults :data:`DEFAULT_SERVO_STIFFNESS_NM_PER_RAD` and
:data:`DEFAULT_SERVO_DAMPING_NMS_PER_RAD` (shared with the dm_control environment). The servo hinge is a
spring-damper about the assembled angle; the command moves the spring's set point (``k theta_ref``) and feeds the
reference velocity forward through the damper (``c dtheta_ref / dt``), so that the motor torque is the PD law
``k (theta_ref - theta) + c (dtheta_ref / dt - dtheta / dt)``.

The full nonlinear model is stepped by :func:`fpm_sim.sim.rollout.rollout` (discrete integrator at the step of
the band, :mod:`fpm_sim.sim.stepping`). Reported (:class:`MoveResult`): the tracking error (end-effector pose
minus the commanded pose) and the deflection (pose minus the rigid-link pose of the motor angles: what link
bending adds), the residual vibration after the move (peak, settling time to a tolerance, dominant frequency
compared with the modal f1 and the dominant in-plane mode at the end pose) and the motor torques.

**Input shaping** (:func:`shaper`). ZV and ZVD shapers (Singer & Seering 1990) designed from the frequency
``f`` and damping ratio ``zeta`` of the end pose's dominant in-plane mode (the mode with the largest share of
the end effector's in-plane static compliance): with ``K = exp(-zeta pi / sqrt(1 - zeta^2))`` and the damped
half period ``T_d / 2``, ZV is the impulses ``(1, K) / (1 + K)`` at ``(0, T_d / 2)``, ZVD ``(1, 2K, K^2) /
(1 + K)^2`` at ``(0, T_d / 2, T_d)``; the shaped command is the profile convolved with them (the move lasts
``T_d / 2`` or ``T_d`` longer).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.config import Geometry, Manipulator, Motors
from fpm_sim.errors import FpmSimError, read_text_input
from fpm_sim.kinematics import Pose, inverse_kinematics
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel
from fpm_sim.sim.stepping import DEFAULT_INTEGRATOR, Stepping

__all__ = [
    "DEFAULT_SERVO_DAMPING_NMS_PER_RAD",
    "DEFAULT_SERVO_STIFFNESS_NM_PER_RAD",
    "DEFAULT_SETTLE_TOL_M",
    "PROFILES",
    "SHAPERS",
    "MoveError",
    "MovePath",
    "MoveResult",
    "ResidualVibration",
    "check_move",
    "check_profile",
    "dominant_frequency_hz",
    "path_duration_s",
    "path_poses",
    "profile",
    "read_path_csv",
    "residual_vibration",
    "settling_time_s",
    "shaper",
    "simulate_move",
    "track_servos",
    "with_servo_motors",
]

PROFILES = ("trapezoidal", "s-curve", "minimum-jerk")
SHAPERS = ("none", "zv", "zvd")
DEFAULT_SETTLE_TOL_M = 20e-6
"""Settling tolerance (m) on the end effector's in-plane residual vibration: 20 um, a precision-positioning
tolerance for 228 mm links (assumed; the default 30 mm move leaves 0.7 mm unshaped, 0.04 mm with ZVD)."""


DEFAULT_SERVO_STIFFNESS_NM_PER_RAD = 500.0
"""Assumed position-loop stiffness of each motor servo (N m/rad): a geared servo motor; the study's
motors were locked during its tests and no servo gains are given."""
DEFAULT_SERVO_DAMPING_NMS_PER_RAD = 1.0
"""Assumed velocity-loop damping of each servo (N m s/rad)."""


class MoveError(FpmSimError):
    """A bad move (profile, path file, duration, shaper), named in the message."""


# ---------------------------------------------------------------------------------------------
# profiles and paths


def _s_curve() -> Any:
    """``s(u)`` of the jerk-limited profile, exact: the acceleration is piecewise linear (trapezoids over the first
    and last third, ramped over a third of each), integrated twice as a piecewise polynomial."""
    from scipy.interpolate import PPoly

    knots = np.arange(10) / 9.0
    acc = np.array([0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0, -1.0, 0.0])
    slope = np.diff(acc) / np.diff(knots)
    pos = PPoly(np.vstack([slope, acc[:-1]]), knots).antiderivative(2)
    return lambda u: pos(u) / pos(1.0)


_S_CURVE: Any = None


def profile(kind: str, u: np.ndarray | float) -> np.ndarray:
    """Normalised motion profile ``s(u)``, ``u = t / T`` clipped to [0, 1]; ``s(0) = 0``, ``s(1) = 1``."""
    global _S_CURVE
    x = np.clip(np.asarray(u, float), 0.0, 1.0)
    if kind == "minimum-jerk":
        return np.asarray(10 * x**3 - 15 * x**4 + 6 * x**5)
    if kind == "trapezoidal":
        ta = 1.0 / 3.0
        v = 1.0 / (1.0 - ta)  # cruise speed (units of distance / T)
        a = v / ta
        return np.where(
            x < ta, 0.5 * a * x**2, np.where(x <= 1 - ta, 0.5 * a * ta**2 + v * (x - ta), 1.0 - 0.5 * a * (1 - x) ** 2)
        )
    if kind == "s-curve":
        if _S_CURVE is None:
            _S_CURVE = _s_curve()
        return np.asarray(_S_CURVE(x))
    raise MoveError(
        "unknown motion profile", parameter="profile", value=kind, hint=f"choose one of {', '.join(PROFILES)}"
    )


def shaper(kind: str, freq_hz: float, damping: float) -> tuple[np.ndarray, np.ndarray]:
    """Impulse amplitudes and times (s) of a ZV or ZVD shaper for a mode of ``freq_hz`` and ``damping`` (module
    docstring); ``"none"``: one unit impulse at 0."""
    if kind == "none":
        return np.array([1.0]), np.array([0.0])
    if not (math.isfinite(freq_hz) and freq_hz > 0 and 0 <= damping < 1):
        raise MoveError(
            "a shaper needs a positive frequency and a damping ratio in [0, 1)",
            parameter="shaper",
            value=(freq_hz, damping),
            hint="design it for a vibrating mode",
        )
    k = math.exp(-damping * math.pi / math.sqrt(1 - damping**2))
    half = 0.5 / (freq_hz * math.sqrt(1 - damping**2))
    if kind == "zv":
        return np.array([1.0, k]) / (1 + k), np.array([0.0, half])
    if kind == "zvd":
        return np.array([1.0, 2 * k, k * k]) / (1 + k) ** 2, np.array([0.0, half, 2 * half])
    raise MoveError("unknown input shaper", parameter="shaper", value=kind, hint=f"choose one of {', '.join(SHAPERS)}")


@dataclass(frozen=True)
class MovePath:
    """A commanded end-effector path: ``pose(t)`` for ``0 <= t`` (held after :attr:`duration_s`).

    Either a profile move (``start``, ``end``, ``move_s``, ``kind``) or samples (``samples``: ``(n, 4)`` rows
    ``t_s, x_m, y_m, phi_rad``); ``impulses`` (amplitudes, times) shape the profile (:func:`shaper`).
    """

    start: Pose
    end: Pose
    move_s: float
    kind: str = "minimum-jerk"
    samples: np.ndarray | None = None
    impulses: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.array([1.0]), np.array([0.0])))

    @classmethod
    def from_csv(cls, path: str | Path) -> MovePath:
        """The sampled path of a CSV ``t_s, x_mm, y_mm, phi_rad`` (:func:`read_path_csv`); it starts at its first
        row's pose and ends at its last."""
        samples = read_path_csv(path)
        return cls(Pose(*samples[0, 1:]), Pose(*samples[-1, 1:]), float(samples[-1, 0]), samples=samples)

    def check(self) -> None:
        check_profile(self.kind, self.move_s, self.samples)

    @property
    def duration_s(self) -> float:
        """When the command stops changing (s): the move plus the shaper's last impulse time."""
        return path_duration_s(self.move_s, self.samples, self.impulses)

    def poses(self, t_s: np.ndarray) -> np.ndarray:
        """``(n, 3)`` commanded ``x, y, phi`` (m, m, rad) at ``t_s``."""
        return path_poses(t_s, self.start.as_array(), self.end.as_array(), self)


def check_profile(kind: str, move_s: float, samples: np.ndarray | None) -> None:
    """Refuse an unknown profile or a move time that is not a positive finite time (a sampled path has neither)."""
    if samples is None:
        profile(kind, 0.0)
        if not (math.isfinite(move_s) and move_s > 0):
            raise MoveError("the move time must be a positive finite time (s)", parameter="move_s", value=move_s)


def path_duration_s(move_s: float, samples: np.ndarray | None, impulses: tuple[np.ndarray, np.ndarray]) -> float:
    """When a commanded path stops changing (s): a sampled path's last time, or the move plus the shaper's last
    impulse time."""
    if samples is not None:
        return float(samples[-1, 0])
    return move_s + float(impulses[1][-1])


def path_poses(t_s: np.ndarray, start: np.ndarray, end: np.ndarray, path: Any) -> np.ndarray:
    """``(n, len(start))`` commanded coordinates at ``t_s`` of ``path`` (its ``samples``, or its ``kind`` of profile
    over ``move_s`` from ``start`` to ``end``, convolved with its shaper's ``impulses``)."""
    t = np.asarray(t_s, float)
    if path.samples is not None:
        return np.column_stack([np.interp(t, path.samples[:, 0], path.samples[:, k]) for k in range(1, 1 + start.size)])
    amps, times = path.impulses
    s = sum(a * profile(path.kind, (t - t0) / path.move_s) for a, t0 in zip(amps, times))
    return start[None, :] + np.asarray(s)[:, None] * (end - start)[None, :]


def read_path_csv(path: str | Path, coordinates: tuple[str, ...] = ("x", "y", "phi")) -> np.ndarray:
    """Rows ``t_s, x_mm, y_mm, phi_rad`` of a path CSV (header row) as ``(n, 4)`` in SI (m, rad); a described
    architecture's ``coordinates`` make the columns ``t_s`` and its task columns (``x_mm, y_mm[, z_mm][, phi_rad]``)."""
    p = Path(path)
    if not p.is_file():
        raise MoveError("path CSV not found", parameter="path_csv", value=str(p), hint="give an existing file")
    header = ",".join(["t_s"] + [c + ("_rad" if c == "phi" else "_mm") for c in coordinates])
    width = len(coordinates) + 1
    text = read_text_input(
        p, error=MoveError, parameter="path_csv", kind="a CSV file", hint=f"give a path CSV ({header})", newline=""
    )
    lines = csv.reader(io.StringIO(text, newline=""))  # (row number in the file, cells); comments, blanks skipped
    rows = [(i, r) for i, r in enumerate(lines, 1) if r and not r[0].lstrip().startswith("#")]
    if not rows or [c.strip() for c in rows[0][1]] != header.split(","):
        raise MoveError(
            "the first row must be the header",
            parameter="path_csv",
            value=",".join(rows[0][1]) if rows else "",
            hint=f"write {header}",
            file=p,
            row=rows[0][0] if rows else None,
        )
    values: list[list[float]] = []
    for i, r in rows[1:]:
        if len(r) != width:
            raise MoveError(
                f"needs {width} values per row", parameter="path_csv", value=",".join(r), hint=header, file=p, row=i
            )
        try:
            v = [float(c) for c in r]
        except ValueError:
            raise MoveError("a value is not a number", parameter="path_csv", value=",".join(r), file=p, row=i) from None
        if not all(math.isfinite(x) for x in v):
            raise MoveError("every value must be finite", parameter="path_csv", value=",".join(r), file=p, row=i)
        if values and not v[0] > values[-1][0]:
            raise MoveError(
                "t_s must increase strictly",
                parameter="path_csv",
                value=v[0],
                hint="sort the rows by time",
                file=p,
                row=i,
            )
        if not values and v[0] != 0.0:
            raise MoveError("t_s must start at 0", parameter="path_csv", value=v[0], file=p, row=i)
        values.append(v)
    if len(values) < 2:
        raise MoveError(
            f"needs at least two rows of {width} values after the header",
            parameter="path_csv",
            value=len(values),
            file=p,
        )
    data = np.array(values, float)
    for k, c in enumerate(coordinates, 1):
        if c != "phi":
            data[:, k] *= 1e-3
    return data


# ---------------------------------------------------------------------------------------------
# servos, modes, residual vibration


def with_servo_motors(manip: Manipulator) -> Manipulator:
    """``manip`` with position servos: its own if ``motors.mode = "servo"``, else the stated defaults
    (:data:`DEFAULT_SERVO_STIFFNESS_NM_PER_RAD`, :data:`DEFAULT_SERVO_DAMPING_NMS_PER_RAD`)."""
    if manip.motors.mode == "servo":
        return manip
    return manip.replace(
        motors=Motors(
            mode="servo",
            servo_stiffness_nm_per_rad=DEFAULT_SERVO_STIFFNESS_NM_PER_RAD,
            servo_damping_nms_per_rad=DEFAULT_SERVO_DAMPING_NMS_PER_RAD,
        )
    )


def dominant_inplane_mode(system: Any) -> tuple[int, float, float]:
    """Index, frequency (Hz) and damping ratio of the mode with the largest share of the end effector's in-plane
    static compliance (``|C_xy phi_r|^2 / omega_r^2``) of a :class:`fpm_sim.rom.reduction.ModalSystem`."""
    share = np.sum((system.c_q[:2] @ system.phi) ** 2, axis=0) / system.omega_rad_s**2
    r = int(np.argmax(share))
    w = float(system.omega_rad_s[r])
    return r, w / (2 * math.pi), float(system.xi[r, r] / (2 * w))


def dominant_frequency_hz(t_s: np.ndarray, x: np.ndarray, *, f_min_hz: float = 1.0) -> float:
    """Frequency (Hz) of the largest spectral peak of ``x(t)`` above ``f_min_hz`` (Hann window, zero padding to
    ~0.01 Hz lines, parabolic interpolation of the log magnitude); NaN for fewer than 8 samples."""
    if len(t_s) < 8:
        return math.nan
    dt = float(t_s[1] - t_s[0])
    y = (x - np.mean(x)) * np.hanning(len(x))
    n = int(2 ** math.ceil(math.log2(max(len(x), 100.0 / dt))))
    mag = np.abs(np.fft.rfft(y, n))
    f = np.fft.rfftfreq(n, dt)
    mag[f < f_min_hz] = 0.0
    k = int(np.argmax(mag))
    if 0 < k < len(mag) - 1 and mag[k - 1] > 0 and mag[k + 1] > 0:
        a, b, c = np.log(mag[k - 1 : k + 2])
        k_off = 0.5 * (a - c) / (a - 2 * b + c)
        return float((k + k_off) * (f[1] - f[0]))
    return float(f[k])


def settling_time_s(t_s: np.ndarray, magnitude: np.ndarray, tol: float, t0_s: float, hold_s: float = 0.0) -> float:
    """Time after ``t0_s`` from which ``magnitude`` stays within ``tol`` (0 if it always is); ``inf`` when it is
    above within the last ``hold_s`` of the record (an oscillation passes through zero: give it a period)."""
    after = t_s >= t0_s
    above = np.flatnonzero(after & (magnitude > tol))
    if above.size == 0:
        return 0.0
    if above[-1] == len(t_s) - 1 or t_s[above[-1]] > t_s[-1] - hold_s:
        return math.inf
    return float(t_s[above[-1] + 1] - t0_s)


@dataclass
class ResidualVibration:
    """The end effector's in-plane residual vibration after the move (SI units)."""

    peak_m: float
    settling_time_s: float
    tol_m: float
    dominant_hz: float
    modal_f1_hz: float
    inplane_mode_hz: float
    inplane_mode_damping: float
    final_offset_m: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {
            "peak_m": self.peak_m,
            "settling_time_s": self.settling_time_s if math.isfinite(self.settling_time_s) else None,
            "settled": math.isfinite(self.settling_time_s),
            "tol_m": self.tol_m,
            "dominant_hz": self.dominant_hz,
            "modal_f1_hz": self.modal_f1_hz,
            "dominant_over_modal_f1": self.dominant_hz / self.modal_f1_hz,
            "inplane_mode_hz": self.inplane_mode_hz,
            "inplane_mode_damping": self.inplane_mode_damping,
            "dominant_over_inplane_mode": self.dominant_hz / self.inplane_mode_hz,
            "final_offset_m": self.final_offset_m.tolist(),
        }


def residual_vibration(
    t_s: np.ndarray, error_xy: np.ndarray, t_end_s: float, tol_m: float, modes: tuple[float, float, float]
) -> ResidualVibration:
    """Residual vibration of the in-plane tracking error ``(n, 2)`` after ``t_end_s``: about its final offset (the
    mean over the last half of the record after the move), its peak, settling time to ``tol_m`` and dominant
    frequency (settled: within ``tol_m`` for at least the last period of it); ``modes`` = (modal f1, dominant
    in-plane mode's frequency and damping) at the end pose."""
    after = t_s >= t_end_s
    if after.sum() < 8:
        raise MoveError(
            "no residual vibration to analyse: fewer than 8 samples after the move",
            parameter="settle_s",
            hint="give a longer settle time",
        )
    ta = t_s[after]
    tail = after & (t_s >= ta[0] + 0.5 * (ta[-1] - ta[0]))
    offset = error_xy[tail].mean(axis=0)
    r = error_xy - offset
    mag = np.linalg.norm(r, axis=1)
    k = int(np.argmax(np.var(r[after], axis=0)))
    f_dom = dominant_frequency_hz(ta, r[after, k])
    return ResidualVibration(
        peak_m=float(mag[after].max()),
        settling_time_s=settling_time_s(t_s, mag, tol_m, t_end_s, 1.0 / f_dom if f_dom > 0 else 0.0),
        tol_m=tol_m,
        dominant_hz=f_dom,
        modal_f1_hz=modes[0],
        inplane_mode_hz=modes[1],
        inplane_mode_damping=modes[2],
        final_offset_m=offset,
    )


# ---------------------------------------------------------------------------------------------
# the move


@dataclass
class MoveResult:
    """A simulated move (SI units; see the module docstring).

    Attributes
    ----------
    t_s
        Sample times (s).
    command
        ``(n, 3)`` commanded end-effector ``x, y, phi``.
    ee_pose
        ``(n, 3)`` simulated end-effector pose.
    deflection
        ``(n, 3)`` pose minus the rigid-link pose of the motor angles (link bending).
    motor_ref_rad, motor_angles_rad
        ``(n, 3)`` motor reference and motor angles (rad, absolute).
    motor_torque_nm
        ``(n, 3)`` servo torques ``k (ref - theta) + c (dref/dt - dtheta/dt)`` (N m).
    residual
        The residual vibration after the move.
    move_end_s
        When the command stops changing (s).
    shaper
        ``none``, ``zv`` or ``zvd``, with its impulses.
    stepping
        How the model was stepped.
    """

    t_s: np.ndarray
    command: np.ndarray
    ee_pose: np.ndarray
    deflection: np.ndarray
    motor_ref_rad: np.ndarray
    motor_angles_rad: np.ndarray
    motor_torque_nm: np.ndarray
    residual: ResidualVibration
    move_end_s: float
    shaper: str
    impulses: tuple[np.ndarray, np.ndarray]
    stepping: Stepping | None
    wall_s: float
    parameters: dict[str, Any] = field(default_factory=dict)
    coordinates: tuple[str, ...] = ("x", "y", "phi")
    """The end effector's coordinates in the columns (a described architecture's task coordinates)."""
    motor_names: tuple[str, ...] = ("0", "1", "2")
    """The motors' names in the columns (``motor_<name>_rad``)."""

    @property
    def translational(self) -> list[int]:
        """The columns of the end effector's position (all but ``phi``): what the residual vibration measures."""
        return [k for k, c in enumerate(self.coordinates) if c != "phi"]

    @property
    def tracking_error(self) -> np.ndarray:
        """``(n, 3)`` end-effector pose minus the commanded pose."""
        return self.ee_pose - self.command

    def columns(self) -> dict[str, np.ndarray]:
        """Flat name -> column (units in the names)."""
        cols: dict[str, np.ndarray] = {"t_s": self.t_s}
        names = [c + ("_rad" if c == "phi" else "_m") for c in self.coordinates]
        for prefix, arr in (
            ("command", self.command),
            ("ee", self.ee_pose),
            ("error", self.tracking_error),
            ("deflection", self.deflection),
        ):
            for k, n in enumerate(names):
                cols[f"{prefix}_{n}"] = arr[:, k]
        for i, m in enumerate(self.motor_names):
            cols[f"motor_{m}_ref_rad"] = self.motor_ref_rad[:, i]
            cols[f"motor_{m}_rad"] = self.motor_angles_rad[:, i]
            cols[f"motor_{m}_torque_nm"] = self.motor_torque_nm[:, i]
        return cols

    def save(self, path: str | Path) -> Path:
        """Write ``.csv`` (one column per signal) or ``.npz`` by suffix."""
        from fpm_sim.sim.rollout import save_columns

        return save_columns(path, self.columns(), MoveError)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: tracking error and deflection peaks, residual vibration, torques, stepping,
        resolution."""
        from fpm_sim.model.options import resolution_of_parameters

        moving = self.t_s <= self.move_end_s
        err = np.linalg.norm(self.tracking_error[:, self.translational], axis=1)
        defl = np.linalg.norm(self.deflection[:, self.translational], axis=1)
        return {
            "move_end_s": self.move_end_s,
            "duration_s": float(self.t_s[-1]),
            "shaper": self.shaper,
            "shaper_impulses": {"amplitudes": self.impulses[0].tolist(), "times_s": self.impulses[1].tolist()},
            "peak_tracking_error_m": float(err[moving].max()),
            "peak_deflection_m": float(defl[moving].max()),
            "peak_motor_torque_nm": np.abs(self.motor_torque_nm).max(axis=0).tolist(),
            "residual": self.residual.to_dict(),
            "stepping": self.stepping.to_dict() if self.stepping is not None else None,
            "wall_s": self.wall_s,
            "parameters": self.parameters,
            "resolution": resolution_of_parameters(self.parameters),
        }

    def table(self) -> str:
        """The summary in mm, ms and Hz."""
        d = self.to_dict()
        r = self.residual
        settle = f"{r.settling_time_s * 1e3:.1f} ms" if math.isfinite(r.settling_time_s) else "not within the record"
        lines = [
            f"move {self.move_end_s * 1e3:.1f} ms (shaper {self.shaper}) + "
            f"{(self.t_s[-1] - self.move_end_s) * 1e3:.0f} ms settling, wall {self.wall_s:.1f} s",
            f"  peak tracking error       {d['peak_tracking_error_m'] * 1e3:10.4f} mm (pose minus command, moving)",
            f"  peak deflection           {d['peak_deflection_m'] * 1e3:10.4f} mm (pose minus rigid-link pose)",
            f"  residual vibration peak   {r.peak_m * 1e3:10.4f} mm after the move",
            f"  settling time             {settle} (to {r.tol_m * 1e3:g} mm)",
            f"  dominant frequency        {r.dominant_hz:10.2f} Hz: {r.dominant_hz / r.modal_f1_hz:.3f} x modal f1 "
            f"({r.modal_f1_hz:.2f} Hz), {r.dominant_hz / r.inplane_mode_hz:.3f} x the dominant in-plane mode "
            f"({r.inplane_mode_hz:.2f} Hz, zeta {r.inplane_mode_damping:.4f}) at the end pose",
            "  peak motor torque         " + ", ".join(f"{v:.3g}" for v in d["peak_motor_torque_nm"]) + " N m",
        ]
        if self.stepping is not None:
            lines.append("  " + self.stepping.line())
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Commanded and simulated path, tracking error and deflection, residual vibration; the ``Figure``.

        ``ax``: ``None`` (a new figure of the three panels), three axes, or one axes (the main panel: the
        residual vibration).
        """
        import matplotlib.pyplot as plt

        if ax is None:
            fig = plt.figure(figsize=(10, 7))
            axes = [fig.add_subplot(2, 2, 1), fig.add_subplot(2, 2, 2), fig.add_subplot(2, 1, 2)]
        elif hasattr(ax, "plot"):
            self._plot_residual(ax)
            return ax.figure
        else:
            axes = list(ax)
        a = axes[0]
        a.plot(self.command[:, 0] * 1e3, self.command[:, 1] * 1e3, "k--", lw=1, label="command")
        a.plot(self.ee_pose[:, 0] * 1e3, self.ee_pose[:, 1] * 1e3, lw=1, label="simulated")
        a.set_xlabel("x (mm)")
        a.set_ylabel("y (mm)")
        a.set_title("end-effector path", fontsize=9)
        a.axis("equal")
        a.legend(fontsize=8)
        a = axes[1]
        tr = self.translational
        a.plot(self.t_s * 1e3, np.linalg.norm(self.tracking_error[:, tr], axis=1) * 1e3, label="|pose - command|")
        a.plot(self.t_s * 1e3, np.linalg.norm(self.deflection[:, tr], axis=1) * 1e3, label="|deflection|")
        a.axvline(self.move_end_s * 1e3, color="0.5", ls=":", lw=1)
        a.set_xlabel("t (ms)")
        a.set_ylabel("mm")
        a.set_title("tracking error and link deflection", fontsize=9)
        a.legend(fontsize=8)
        self._plot_residual(axes[2])
        out: Any = axes[0].figure
        out.tight_layout()
        return out

    def _plot_residual(self, a: Any) -> None:
        r = self.residual
        after = self.t_s >= self.move_end_s
        res = np.linalg.norm(self.tracking_error[:, self.translational] - r.final_offset_m, axis=1)
        a.plot(self.t_s[after] * 1e3, res[after] * 1e3, lw=1, label=f"shaper {self.shaper}")
        a.axhline(r.tol_m * 1e3, color="r", ls="--", lw=0.8, label=f"tolerance {r.tol_m * 1e3:g} mm")
        a.set_xlabel("t (ms)")
        a.set_ylabel("residual (mm)")
        a.set_title(
            f"residual vibration: peak {r.peak_m * 1e3:.4f} mm, {r.dominant_hz:.1f} Hz\n"
            f"(modal f1 {r.modal_f1_hz:.1f} Hz, in-plane {r.inplane_mode_hz:.1f} Hz)",
            fontsize=9,
        )
        a.legend(fontsize=8)


def simulate_move(
    manip: Manipulator,
    path: MovePath,
    *,
    settle_s: float = 0.3,
    options: ModelOptions | None = None,
    output_step_s: float = 1e-4,
    shaper_kind: str = "none",
    settle_tol_m: float = DEFAULT_SETTLE_TOL_M,
    integrator: str = DEFAULT_INTEGRATOR,
    band_hz: float | None = None,
    progress: bool = False,
) -> MoveResult:
    """Simulate the move ``path`` on the full flexible model (module docstring).

    Parameters
    ----------
    manip
        The description; locked motors get the default servos (:func:`with_servo_motors`).
    path
        The commanded path (its ``impulses`` are replaced by the shaper's).
    settle_s
        Simulated time after the command stops changing (s).
    options
        Model options (default: the standard resolution, no axial springs).
    output_step_s
        Sample period (s); the command is held over it.
    shaper_kind
        ``"none"``, ``"zv"`` or ``"zvd"``, designed at the end pose (:func:`shaper`).
    settle_tol_m
        Settling tolerance (m) on the in-plane residual.
    integrator, band_hz
        Time stepping (:func:`fpm_sim.sim.stepping.choose_stepping`); the default band is 5 x f1 at the end pose.

    Long because: the signature and the documentation of its options are a third of it; the rest is the move's
    steps in order (the end pose's modes and shaper, the motor references, the rollout, the residual vibration).
    """
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.rom.reduction import modal_system
    from fpm_sim.sim.rollout import aligned_options

    check_move(path, shaper_kind, settle_s=settle_s, settle_tol_m=settle_tol_m, output_step_s=output_step_s)
    manip = with_servo_motors(manip)
    opts = options or ModelOptions(axial=False)
    end = path.end if path.samples is None else Pose(*path.samples[-1, 1:])
    start = path.start if path.samples is None else Pose(*path.samples[0, 1:])
    # the end pose's modes: f1 (the default band, the comparison) and the dominant in-plane mode (the shaper)
    end_system = modal_system(build_manipulator(manip, end, opts))
    f1_end = float(end_system.frequencies_hz[0])
    _, f_in, z_in = dominant_inplane_mode(end_system)
    impulses = shaper(shaper_kind, f_in, z_in)
    if path.samples is None:
        path = dataclasses.replace(path, impulses=impulses)
    built = build_manipulator(manip, start, aligned_options(manip, start, opts, output_step_s))
    g = manip.geometry
    theta0 = np.asarray(inverse_kinematics(g, start).motor_angles_rad, float)
    duration = path.duration_s + settle_s
    n = round(duration / output_step_s)
    t = np.arange(n + 1) * output_step_s
    cmd = path.poses(t)
    ref, dref = _motor_references(g, cmd, theta0, output_step_s)
    k, c = manip.motors.servo_stiffness_nm_per_rad, manip.motors.servo_damping_nms_per_rad
    res, torque, wall = track_servos(
        built,
        manip,
        ref,
        dref,
        theta0,
        (k, c),
        duration_s=duration,
        output_step_s=output_step_s,
        integrator=integrator,
        band_hz=band_hz,
        f1_hz=f1_end,
        progress=progress,
    )
    m = len(res.t_s)
    angles = res.motor_angles_rad
    err = res.ee_pose - cmd[:m]
    residual = residual_vibration(res.t_s, err[:, :2], path.duration_s, settle_tol_m, (f1_end, f_in, z_in))
    return MoveResult(
        t_s=res.t_s,
        command=cmd[:m],
        ee_pose=res.ee_pose,
        deflection=res.deflection,
        motor_ref_rad=ref[:m],
        motor_angles_rad=angles,
        motor_torque_nm=torque,
        residual=residual,
        move_end_s=path.duration_s,
        shaper=shaper_kind,
        impulses=impulses,
        stepping=res.stepping,
        wall_s=wall,
        parameters={
            **res.parameters,
            "start": dataclasses.asdict(start),
            "end": dataclasses.asdict(end),
            "profile": path.kind if path.samples is None else "csv",
            "move_s": path.move_s,
            "settle_s": settle_s,
            "servo_stiffness_nm_per_rad": k,
            "servo_damping_nms_per_rad": c,
        },
    )


def track_servos(
    built: BuiltModel,
    machine: Any,
    ref: np.ndarray,
    dref: np.ndarray,
    start: np.ndarray,
    gains: tuple[Any, Any],
    *,
    duration_s: float,
    output_step_s: float,
    integrator: str,
    band_hz: float | None,
    f1_hz: float,
    progress: bool,
) -> tuple[Any, np.ndarray, float]:
    """The rollout of the servos tracking the motor references ``ref`` (rad or m, one row per output sample,
    ``start`` the assembled coordinates) with the rates ``dref`` fed forward through the damping, and the servo
    torques (N m or N) the servo law ``k (ref - q) + c (dref - dq/dt)`` gives along it (``gains = (k, c)``, scalars
    or one per motor): ``(rollout result, torques, wall seconds of the rollout)``. ``machine``: the rollout's
    (:func:`fpm_sim.sim.rollout.rollout`), the 3RRR's description or a described machine's adapter."""
    from fpm_sim.sim.rollout import rollout  # imported when called, as simulate_move always did

    k, c = gains
    n = len(ref) - 1

    def sample(arr: np.ndarray) -> Any:
        return lambda tt: arr[min(round(tt / output_step_s), n)]

    wall0 = time.perf_counter()
    res = rollout(
        built,
        machine,
        duration_s=duration_s,
        output_step_s=output_step_s,
        motor_reference=sample(ref - start),
        motor_torque=sample(c * dref),
        integrator=integrator,
        band_hz=band_hz,
        f1_hz=f1_hz,
        progress=progress,
    )
    wall = time.perf_counter() - wall0
    m = len(res.t_s)
    q = res.motor_angles_rad
    torque = k * (ref[:m] - q) + c * (dref[:m] - np.gradient(q, output_step_s, axis=0))
    return res, torque, wall


def check_move(path: Any, shaper_kind: str, *, settle_s: float, settle_tol_m: float, output_step_s: float) -> None:
    """The path (a :class:`MovePath` or a described architecture's ``TaskPath``), the settling time and tolerance,
    the output step and the shaper (none on a sampled path)."""
    path.check()
    for name, v in (("settle_s", settle_s), ("settle_tol_m", settle_tol_m), ("output_step_s", output_step_s)):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
            raise MoveError("must be a positive finite number", parameter=name, value=v)
    if shaper_kind not in SHAPERS:
        raise MoveError(
            "unknown input shaper", parameter="shaper", value=shaper_kind, hint=f"choose one of {', '.join(SHAPERS)}"
        )
    if shaper_kind != "none" and path.samples is not None:
        raise MoveError(
            "a shaper shapes a profile move; a sampled (CSV) path is commanded as it is",
            parameter="shaper",
            value=shaper_kind,
            hint="drop the shaper ('none') or give a profile move",
        )


def _motor_references(
    g: Geometry, cmd: np.ndarray, theta0: np.ndarray, output_step_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Motor angles (rad, continuous from ``theta0``) and rates (rad/s) along the commanded poses ``cmd``."""
    try:
        ref = np.array([inverse_kinematics(g, Pose(*c), check_singularity=False).motor_angles_rad for c in cmd])
    except FpmSimError as e:
        raise MoveError(f"the commanded path leaves the workspace: {e}") from None
    ref = theta0 + np.unwrap(ref - theta0, axis=0)
    return ref, np.gradient(ref, output_step_s, axis=0)
