"""``fpm-sim rollout``: headless nonlinear simulation of the full manipulator under loads."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_joint_args,
    add_model_args,
    add_output_args,
    add_pose_args,
    check_output_file,
    emit,
    imported_pose_of,
    load_machine,
    mm,
    model_options,
    pose_of,
    refuse_joint_values,
    resolution_line,
    task_pose_of,
    with_resolution,
)
from fpm_sim.cli.main import PLOT_SUFFIXES, save_figure

__all__ = ["add_motor_args", "add_stepping_args", "apply_motor_args", "equilibrium_hint", "register", "stepping_kwargs"]

INTEGRATORS = ("discrete", "explicit")
""":data:`fpm_sim.sim.stepping.INTEGRATORS` (a test checks they agree; the parser imports no MuJoCo)."""
BAND_F1_MULTIPLE = 5.0
""":data:`fpm_sim.sim.stepping.BAND_F1_MULTIPLE` (checked by a test)."""
MAX_NUMERICAL_DAMPING = 0.02
""":data:`fpm_sim.sim.stepping.MAX_NUMERICAL_DAMPING` (checked by a test)."""


def add_stepping_args(p: argparse.ArgumentParser, *, band_flag: str = "--band-hz") -> None:
    """``--integrator`` and the band the step is chosen from (``band_flag``)."""
    g = p.add_argument_group("time stepping (docs/time_domain.md)")
    g.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        default=INTEGRATORS[0],
        help="discrete (default): MuJoCo's implicit discrete integrator at the band's step; explicit: the model's "
        "own explicit-spring step (0.4-0.8 us at 12 segments, ~50x slower), the reference",
    )
    g.add_argument(
        band_flag,
        dest="step_band_hz",
        type=float,
        default=None,
        help=f"band (Hz) the result must be right in: the discrete step keeps the numerical damping at its top <= "
        f"{100 * MAX_NUMERICAL_DAMPING:g} %% (period error <= 0.05 %%); default {BAND_F1_MULTIPLE:g} x the model's f1",
    )


def stepping_kwargs(args: argparse.Namespace, band_flag: str = "--band-hz") -> dict[str, Any]:
    """The rollout keywords of :func:`add_stepping_args`'s options (validated here: named errors)."""
    v = args.step_band_hz
    if v is not None and not (v > 0 and v != float("inf")):
        raise CliError(f"{band_flag} must be a positive finite frequency (Hz), got {v!r}")
    return {"integrator": args.integrator, "band_hz": v}


def equilibrium_hint(exc: Exception, args: argparse.Namespace) -> str:
    """The fix to suggest when the static equilibrium fails (thin links with axial springs stall it)."""
    if getattr(args, "axial", False):
        return (
            f"{exc}; thin links with axial springs can stall the equilibrium solver (measured for 5 mm links): "
            "try --no-axial"
        )
    return str(exc)


def add_motor_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("motors")
    g.add_argument(
        "--motors",
        choices=("config", "servo"),
        default="config",
        help="motors as configured, or servo (a described architecture or an imported model: locked, or servos of its "
        "[servos] gains)",
    )
    g.add_argument("--servo-stiffness-nm-per-rad", type=float, help="servo stiffness (with --motors servo)")
    g.add_argument(
        "--servo-damping-nms-per-rad", type=float, default=None, help="servo damping (with --motors servo; default 0)"
    )


def apply_motor_args(manip: Any, args: argparse.Namespace) -> Any:
    """``manip`` with servo motors if ``--motors servo`` (locked motors have no joint to drive)."""
    from fpm_sim.config import Motors

    if args.motors != "servo":
        return manip
    if not args.servo_stiffness_nm_per_rad or args.servo_stiffness_nm_per_rad <= 0:
        raise CliError("--motors servo needs --servo-stiffness-nm-per-rad > 0; give the servo stiffness (N m/rad)")
    return manip.replace(
        motors=Motors(
            mode="servo",
            servo_stiffness_nm_per_rad=args.servo_stiffness_nm_per_rad,
            servo_damping_nms_per_rad=args.servo_damping_nms_per_rad or 0.0,
        )
    )


def _profile(kind: str, values: list[float], t0_s: float, freq_hz: float) -> Any:
    from fpm_sim.sim.rollout import constant, sine, step_at

    if kind == "constant":
        return constant(*values)
    if kind == "step":
        return step_at(t0_s, *values)
    if kind == "sine":
        return sine(freq_hz, *values)
    raise CliError(f"--load-profile must be constant, step or sine, got {kind!r}")


_LOAD_FLAGS = {"x": "--force-x-n", "y": "--force-y-n", "z": "--force-z-n", "phi": "--moment-z-nm"}


def _general_machine(args: argparse.Namespace, desc: Any, opts: Any) -> tuple[Any, Any, list[float]]:
    """A described architecture's or an imported model's model (servos with ``--motors servo``), its rollout machine
    (:func:`fpm_sim.sim.task.rollout_machine`) and its end-effector load along its task coordinates; the options it
    lacks refused by name (an imported model without an ``[end_effector]``, or without motors to servo, too)."""
    from fpm_sim.architecture import Description, solve_task_pose
    from fpm_sim.sim.task import mover_of, rollout_machine

    for flag, v in (
        ("--thickness-mm", args.thickness_mm),
        ("--servo-stiffness-nm-per-rad", args.servo_stiffness_nm_per_rad),
        ("--servo-damping-nms-per-rad", args.servo_damping_nms_per_rad),
        ("--accel-fraction", args.accel_fraction),
    ):
        if v is not None:
            raise CliError(
                f"{flag} is for the study's 3RRR; a described architecture or an imported model sets its section in "
                f"its file and its servo gains in [servos], and records no accelerations; drop {flag}"
            )
    mover: Any = mover_of(desc, need_motors=args.motors == "servo")
    given = {"x": args.force_x_n, "y": args.force_y_n, "z": args.force_z_n, "phi": args.moment_z_nm}
    for c, v in given.items():
        if v != 0.0 and c not in mover.task:
            raise CliError(
                f"{_LOAD_FLAGS[c]}: {desc.name} has no task coordinate {c} (its task coordinates are "
                f"{', '.join(mover.task)}), so no load along it; drop {_LOAD_FLAGS[c]}"
            )
    if isinstance(desc, Description):
        state = solve_task_pose(desc, task_pose_of(args, desc))
    else:
        state = mover.state_at(None, imported_pose_of(args, desc)[0])
    motors = "servo" if args.motors == "servo" else "locked"
    mc, built = rollout_machine(mover, state, opts, args.output_step_s, motors)
    return built, mc, [given[c] for c in mover.task]


def _machine(args: argparse.Namespace, opts: Any) -> tuple[Any, Any, list[float], int]:
    """The model, the machine (the 3RRR's description, or a described architecture's or an imported model's rollout
    machine), the end-effector load and the number of motors."""
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.sim.rollout import aligned_options

    machine = load_machine(args, "rollout")
    refuse_joint_values(args, machine)
    if isinstance(machine, Description | ImportedDescription):
        built, mc, wrench = _general_machine(args, machine, opts)
        return built, mc, wrench, len(mc.motor_names)
    if args.thickness_mm is not None:
        machine = machine.with_section(thickness_m=mm(args.thickness_mm))
    machine = apply_motor_args(machine, args)
    if args.force_z_n != 0.0:
        raise CliError("--force-z-n: the 3RRR's task coordinates are x, y and phi; drop --force-z-n")
    pose = pose_of(args)
    # timestep rounded down so that the output step is a whole number of steps
    built = build_manipulator(machine, pose, aligned_options(machine, pose, opts, args.output_step_s))
    return built, machine, [args.force_x_n, args.force_y_n, args.moment_z_nm], 3


def cmd_rollout(args: argparse.Namespace) -> int:
    from fpm_sim.linear.equilibrium import EquilibriumError
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.rom.reduction import accel_site_names
    from fpm_sim.sim.rollout import RolloutMachine, rollout

    check_output_file(args.out, "--out", (".csv", ".npz"))
    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    if not args.output_step_s > 0:
        raise CliError(f"--output-step-s must be positive, got {args.output_step_s!r}")
    stepping = stepping_kwargs(args)
    discrete = args.integrator == "discrete"
    if discrete and args.timestep_s is not None:
        if not args.timestep_s > 0:
            raise CliError(f"--timestep-s must be positive, got {args.timestep_s!r}")
        stepping["step_s"] = args.timestep_s  # the discrete step; the model keeps its automatic one (weld stiffness)
    opts = model_options(args, timestep_s=None) if discrete else model_options(args)
    warn_if_coarse(opts)
    built, machine, wrench, n_motors = _machine(args, opts)
    torques = args.motor_torque_nm if args.motor_torque_nm is not None else [0.0] * n_motors
    if len(torques) != n_motors:
        names = ", ".join(machine.motor_names) if isinstance(machine, RolloutMachine) else "motor_0..2"
        raise CliError(
            f"--motor-torque-nm needs {n_motors} values, one per actuated joint ({names}), got {len(torques)}"
        )
    if isinstance(machine, RolloutMachine) and any(torques) and args.motors != "servo":
        raise CliError("--motor-torque-nm drives servos: add --motors servo (locked actuated joints have no joint)")
    ee = _profile(args.load_profile, wrench, args.load_start_s, args.load_freq_hz) if any(wrench) else None
    torque = _profile(args.load_profile, torques, args.load_start_s, args.load_freq_hz) if any(torques) else None
    fraction = 0.5 if args.accel_fraction is None else args.accel_fraction
    sites = accel_site_names(built, fraction) if not isinstance(machine, RolloutMachine) else []
    try:
        res = rollout(
            built,
            machine,
            duration_s=args.duration_s,
            output_step_s=args.output_step_s,
            ee_wrench=ee,
            motor_torque=torque,
            accel_sites=sites,
            progress=not args.json,
            **stepping,
        )
    except EquilibriumError as exc:
        raise EquilibriumError(equilibrium_hint(exc, args)) from exc
    if args.out:
        with atomic_file(args.out) as tmp:
            res.save(tmp)
    if args.plot:
        save_figure(args.plot, res.plot)
    payload = res.to_dict()
    payload["out"] = str(args.out) if args.out else None
    payload["plot"] = str(args.plot) if args.plot else None
    lines = [res.table()]
    lines.append(resolution_line(opts))
    for f in (args.out, args.plot):
        if f:
            lines.append(f"wrote {f}")
    emit(args, with_resolution(payload, opts), "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "rollout",
        help="headless nonlinear simulation from the static equilibrium under end-effector and motor loads",
        description=(
            "Steps the full MuJoCo model from its static equilibrium under gravity. Loads are held over each "
            "output step, at the default resolution (fidelity standard: 12 segments): MuJoCo's implicit discrete "
            "integrator at the step of the band (--band-hz, default 5 x f1; the numerical damping and period error in "
            "the band are printed); --integrator explicit: the explicit-spring reference (~1 us steps, ~50x slower). "
            "Motor torques need --motors servo (locked motors have no joint). An imported model (kind = 'imported') "
            "needs its [end_effector] (the coordinates recorded and loaded), posed by --q and/or the pose options. "
            "Writes a CSV/NPZ of end-effector "
            "pose, displacement, deflection (pose minus rigid-link "
            "kinematics), motor angles, loads and accelerations, and a plot."
        ),
    )
    p.add_argument("--duration-s", type=float, default=0.2, help="simulated time (s, default 0.2)")
    p.add_argument("--output-step-s", type=float, default=1e-4, help="output step (s, default 1e-4)")
    p.add_argument("--force-x-n", type=float, default=0.0, help="end-effector force along x (N)")
    p.add_argument("--force-y-n", type=float, default=0.0, help="end-effector force along y (N)")
    p.add_argument("--force-z-n", type=float, default=0.0, help="end-effector force along z (N; spatial machines)")
    p.add_argument(
        "--moment-z-nm", type=float, default=0.0, help="end-effector moment about z (N m; machines with phi)"
    )
    p.add_argument(
        "--motor-torque-nm",
        type=float,
        nargs="+",
        default=None,
        help="motor torques (N m; N on a prismatic joint), one per motor: the 3RRR's three, a described "
        "architecture's actuated joints in the file's order, an imported model's motors in its joint order (needs "
        "--motors servo)",
    )
    p.add_argument("--load-profile", choices=("constant", "step", "sine"), default="constant", help="load time profile")
    p.add_argument("--load-start-s", type=float, default=0.0, help="step time (s) for --load-profile step")
    p.add_argument("--load-freq-hz", type=float, default=10.0, help="frequency (Hz) for --load-profile sine")
    add_motor_args(p)
    p.add_argument("--thickness-mm", type=float, help="link in-plane thickness override (mm)")
    p.add_argument(
        "--accel-fraction",
        type=float,
        default=None,
        help="record accelerations on each distal link at this fraction (the 3RRR; default 0.5)",
    )
    p.add_argument("--out", type=Path, help="time histories, .csv or .npz")
    p.add_argument("--plot", type=Path, help="plot file (.png, .pdf, .svg)")
    add_pose_args(p)
    add_joint_args(p)
    add_config_args(p)
    add_model_args(p)
    add_stepping_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_rollout)
