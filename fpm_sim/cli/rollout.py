"""``fpm-sim rollout``: headless nonlinear simulation of the full manipulator under loads."""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fpm_sim.cli.main import (
    add_config_args,
    add_model_args,
    add_output_args,
    add_pose_args,
    emit,
    load_manipulator,
    model_options,
    pose_of,
)
from fpm_sim.config import Manipulator, Motors
from fpm_sim.linear.equilibrium import EquilibriumError
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.rom.reduction import ReductionError, accel_site_names
from fpm_sim.sim.rollout import RolloutError, aligned_options, constant, rollout, sine, step_at

__all__ = ["register", "user_errors", "add_motor_args", "apply_motor_args"]


def user_errors(func: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Report this feature's user errors like the core ones: a message on stderr and exit status 2."""

    @functools.wraps(func)
    def wrapped(args: argparse.Namespace) -> int:
        try:
            return func(args)
        except (RolloutError, ReductionError) as exc:
            print(f"fpm-sim: error: {exc}", file=sys.stderr)
            return 2
        except EquilibriumError as exc:
            hint = (
                "; thin links with axial springs can stall the equilibrium solver (measured for 5 mm links): "
                "try --no-axial"
                if not getattr(args, "no_axial", True)
                else ""
            )
            print(f"fpm-sim: error: {exc}{hint}", file=sys.stderr)
            return 2

    return wrapped


def add_motor_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("motors")
    g.add_argument("--motors", choices=("config", "servo"), default="config", help="motors as configured, or servo")
    g.add_argument("--servo-stiffness-nm-per-rad", type=float, help="servo stiffness (with --motors servo)")
    g.add_argument("--servo-damping-nms-per-rad", type=float, default=0.0, help="servo damping (with --motors servo)")


def apply_motor_args(manip: Manipulator, args: argparse.Namespace) -> Manipulator:
    """``manip`` with servo motors if ``--motors servo`` (locked motors have no joint to drive)."""
    if args.motors != "servo":
        return manip
    if not args.servo_stiffness_nm_per_rad or args.servo_stiffness_nm_per_rad <= 0:
        raise RolloutError("--motors servo needs --servo-stiffness-nm-per-rad > 0")
    return manip.replace(
        motors=Motors(
            mode="servo",
            servo_stiffness_nm_per_rad=args.servo_stiffness_nm_per_rad,
            servo_damping_nms_per_rad=args.servo_damping_nms_per_rad,
        )
    )


def _profile(kind: str, values: list[float], t0_s: float, freq_hz: float):  # noqa: ANN202
    if kind == "constant":
        return constant(*values)
    if kind == "step":
        return step_at(t0_s, *values)
    if kind == "sine":
        return sine(freq_hz, *values)
    raise RolloutError(f"--load-profile must be constant, step or sine, got {kind!r}")


@user_errors
def cmd_rollout(args: argparse.Namespace) -> int:
    manip = load_manipulator(args)
    if args.thickness_m is not None:
        manip = manip.with_section(thickness_m=args.thickness_m)
    manip = apply_motor_args(manip, args)
    if args.out is not None and args.out.suffix not in (".csv", ".npz"):
        raise RolloutError(f"--out {args.out} must end in .csv or .npz")
    if args.plot is not None and args.plot.suffix not in (".png", ".pdf", ".svg"):
        raise RolloutError(f"--plot {args.plot} must end in .png, .pdf or .svg")
    pose = pose_of(args)
    if not args.output_step_s > 0:
        raise RolloutError(f"--output-step-s must be positive, got {args.output_step_s!r}")
    # timestep rounded down so that the output step is a whole number of steps
    built = build_manipulator(manip, pose, aligned_options(manip, pose, model_options(args), args.output_step_s))
    wrench = [args.force_x_n, args.force_y_n, args.moment_z_nm]
    ee = _profile(args.load_profile, wrench, args.load_start_s, args.load_freq_hz) if any(wrench) else None
    torque = (
        _profile(args.load_profile, args.motor_torque_nm, args.load_start_s, args.load_freq_hz)
        if any(args.motor_torque_nm)
        else None
    )
    sites = accel_site_names(built, args.accel_fraction) if args.accel_fraction is not None else []
    res = rollout(
        built,
        manip,
        duration_s=args.duration_s,
        output_step_s=args.output_step_s,
        ee_wrench=ee,
        motor_torque=torque,
        accel_sites=sites,
        progress=not args.json,
    )
    if args.out:
        res.save(args.out)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        axes = res.plot()
        axes[0].figure.tight_layout()
        axes[0].figure.savefig(args.plot, dpi=120)
        plt.close(axes[0].figure)
    d = res.ee_disp
    payload = {
        "parameters": res.parameters,
        "n_samples": len(res.t_s),
        "n_steps": res.n_steps,
        "wall_s": res.wall_s,
        "final_disp": {"x_m": d[-1, 0], "y_m": d[-1, 1], "phi_rad": d[-1, 2]},
        "peak_abs_disp": {k: float(np.max(np.abs(d[:, i]))) for i, k in enumerate(("x_m", "y_m", "phi_rad"))},
        "peak_abs_accel_m_s2": {s: float(np.max(np.linalg.norm(a, axis=1))) for s, a in res.accel.items()},
        "out": str(args.out) if args.out else None,
        "plot": str(args.plot) if args.plot else None,
    }
    lines = [
        f"rollout {res.parameters['duration_s']:.4g} s: {res.n_steps} steps of {built.timestep_s:.3g} s "
        f"(nv = {built.model.nv}), {len(res.t_s)} samples, wall {res.wall_s:.2f} s",
        f"{'signal':<22} {'final':>12} {'peak |.|':>12}",
    ]
    for i, (k, unit, sc) in enumerate((("disp x", "mm", 1e3), ("disp y", "mm", 1e3), ("disp phi", "mrad", 1e3))):
        lines.append(f"{k + ' (' + unit + ')':<22} {d[-1, i] * sc:>12.5f} {np.max(np.abs(d[:, i])) * sc:>12.5f}")
    for s, a in res.accel.items():
        lines.append(
            f"{'acc ' + s + ' (m/s2)':<22} {np.linalg.norm(a[-1]):>12.4g} {np.max(np.linalg.norm(a, axis=1)):>12.4g}"
        )
    for f in (args.out, args.plot):
        if f:
            lines.append(f"wrote {f}")
    emit(args, payload, "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "rollout",
        help="headless nonlinear simulation from the static equilibrium under end-effector and motor loads",
        description=(
            "Steps the full MuJoCo model from its static equilibrium under gravity. Loads are held over each "
            "output step. The default resolution (12 segments, axial springs) needs ~1 us steps: for long "
            "rollouts use e.g. --segments 6 --no-axial. Motor torques need --motors servo (locked motors have no "
            "joint). Writes a CSV/NPZ of end-effector pose, displacement, deflection (pose minus rigid-link "
            "kinematics), motor angles, loads and accelerations, and a plot."
        ),
    )
    p.add_argument("--duration-s", type=float, default=0.2, help="simulated time (s, default 0.2)")
    p.add_argument("--output-step-s", type=float, default=1e-4, help="output step (s, default 1e-4)")
    p.add_argument("--force-x-n", type=float, default=0.0, help="end-effector force along x (N)")
    p.add_argument("--force-y-n", type=float, default=0.0, help="end-effector force along y (N)")
    p.add_argument("--moment-z-nm", type=float, default=0.0, help="end-effector moment about z (N m)")
    p.add_argument("--motor-torque-nm", type=float, nargs=3, default=[0.0, 0.0, 0.0], help="motor torques (N m)")
    p.add_argument("--load-profile", choices=("constant", "step", "sine"), default="constant", help="load time profile")
    p.add_argument("--load-start-s", type=float, default=0.0, help="step time (s) for --load-profile step")
    p.add_argument("--load-freq-hz", type=float, default=10.0, help="frequency (Hz) for --load-profile sine")
    add_motor_args(p)
    p.add_argument("--thickness-m", type=float, help="link in-plane thickness override (m)")
    p.add_argument(
        "--accel-fraction", type=float, default=0.5, help="record accelerations on each distal link at this fraction"
    )
    p.add_argument("--out", type=Path, help="time histories, .csv or .npz")
    p.add_argument("--plot", type=Path, help="plot file (.png, .pdf, .svg)")
    add_pose_args(p)
    add_config_args(p)
    add_model_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_rollout)
