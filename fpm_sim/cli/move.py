"""``fpm-sim move``: a point-to-point move of the end effector, tracked by the motor servos, with its residual
vibration (and an optional input shaper)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_output_args,
    add_pose_args,
    add_resolution_args,
    check_output_file,
    emit,
    load_machine,
    model_options,
    pose_of,
    resolution_line,
    task_pose_of,
    with_resolution,
)
from fpm_sim.cli.main import PLOT_SUFFIXES, save_figure
from fpm_sim.cli.rollout import add_stepping_args, stepping_kwargs

__all__ = ["register"]

PROFILES = ("trapezoidal", "s-curve", "minimum-jerk")
""":data:`fpm_sim.sim.trajectory.PROFILES` (a test checks they agree; the parser imports no MuJoCo)."""
SHAPERS = ("none", "zv", "zvd")
""":data:`fpm_sim.sim.trajectory.SHAPERS` (checked by a test)."""
DEFAULT_SETTLE_TOL_MM = 0.02
""":data:`fpm_sim.sim.trajectory.DEFAULT_SETTLE_TOL_M` in mm (checked by a test)."""


_TO_FLAGS = {"x": "to_x_mm", "y": "to_y_mm", "z": "to_z_mm", "phi": "to_phi_rad"}


def _check_numbers(args: argparse.Namespace) -> None:
    for flag in ("move_s", "settle_s", "settle_tol_mm", "output_step_s"):
        v = getattr(args, flag)
        if not (math.isfinite(v) and v > 0):
            raise CliError(f"--{flag.replace('_', '-')} must be a positive number, got {v!r}")
    for flag in _TO_FLAGS.values():
        v = getattr(args, flag)
        if v is not None and not math.isfinite(v):
            raise CliError(f"--{flag.replace('_', '-')} must be a finite number, got {v!r}")
    if args.to_phi_rad is not None and abs(args.to_phi_rad) > math.pi:
        raise CliError(f"--to-phi-rad {args.to_phi_rad:g} is outside -pi..pi; give it in radians within -pi..pi")


def _imported_start(args: argparse.Namespace, mover: Any) -> Any:
    """An imported model's start pose: the end-effector site's pose at the model's reference, the pose options
    given replacing its coordinates (those the model names; others refused by name)."""
    from dataclasses import replace

    desc = mover.desc
    given = {"x": args.x_mm, "y": args.y_mm, "z": getattr(args, "z_mm", None), "phi": args.phi_rad}
    for c, v in given.items():
        flag = "--phi-rad" if c == "phi" else f"--{c}-mm"
        if v is not None and c not in desc.task:
            raise CliError(f"{flag}: {desc.name}'s task coordinates are {', '.join(desc.task)}; drop {flag}")
        if v is not None and not math.isfinite(v):
            raise CliError(f"{flag}: must be a finite number, got {v}")
    si = {
        ("phi_rad" if c == "phi" else f"{c}_m"): v * (1.0 if c == "phi" else 1e-3)
        for c, v in given.items()
        if v is not None
    }
    return replace(mover.reference_pose(), **si)


def _path(args: argparse.Namespace, machine: Any) -> Any:
    """The commanded path: the 3RRR's :class:`~fpm_sim.sim.trajectory.MovePath`, or a described architecture's or
    an imported model's (its :class:`~fpm_sim.sim.imported_move.ImportedMover`) ``TaskPath`` (its task coordinates;
    an end coordinate not given is the start's, x 30 mm further when none is given)."""
    from fpm_sim.architecture import Description
    from fpm_sim.kinematics import Pose
    from fpm_sim.sim.imported_move import ImportedMover
    from fpm_sim.sim.task import TaskPath, pose_vector
    from fpm_sim.sim.trajectory import MovePath

    if not isinstance(machine, Description | ImportedMover):
        if args.to_z_mm is not None:
            raise CliError("--to-z-mm: the 3RRR's task coordinates are x, y and phi; drop --to-z-mm")
        if args.path_csv is not None:
            return MovePath.from_csv(args.path_csv)
        to = [v if v is not None else d for v, d in zip((args.to_x_mm, args.to_y_mm, args.to_phi_rad), (30.0, 0, 0))]
        return MovePath(pose_of(args), Pose.from_mm(*to), args.move_s, kind=args.profile)
    task = machine.task
    name = machine.name if isinstance(machine, Description) else machine.desc.name
    for c, flag in _TO_FLAGS.items():
        if getattr(args, flag) is not None and c not in task:
            f = "--" + flag.replace("_", "-")
            raise CliError(
                f"{f}: {name} has no task coordinate {c} (its task coordinates are {', '.join(task)}); drop {f}"
            )
    start = task_pose_of(args, machine) if isinstance(machine, Description) else _imported_start(args, machine)
    if args.path_csv is not None:
        return TaskPath.from_csv(args.path_csv, task)
    given = {c: getattr(args, _TO_FLAGS[c]) for c in task}
    x0 = pose_vector(start, task)
    end = x0.copy()
    if all(v is None for v in given.values()):
        end[0] += 0.030
    for k, c in enumerate(task):
        if given[c] is not None:
            end[k] = given[c] if c == "phi" else given[c] * 1e-3
    return TaskPath(task, x0, end, args.move_s, kind=args.profile)


def cmd_move(args: argparse.Namespace) -> int:
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.config import Manipulator
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.sim.imported_move import ImportedMover
    from fpm_sim.sim.task import simulate_task_move
    from fpm_sim.sim.trajectory import simulate_move

    check_output_file(args.out, "--out", (".csv", ".npz"))
    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    _check_numbers(args)
    stepping = stepping_kwargs(args)
    machine: Any = load_machine(args, "move")
    if isinstance(machine, ImportedDescription):  # no end effector or no motors: refused here, in one line
        machine = ImportedMover(machine)
    path = _path(args, machine)
    opts = model_options(args)
    warn_if_coarse(opts)
    simulate: Any = simulate_move if isinstance(machine, Manipulator) else simulate_task_move
    res = simulate(
        machine,
        path,
        settle_s=args.settle_s,
        options=opts,
        output_step_s=args.output_step_s,
        shaper_kind=args.shaper,
        settle_tol_m=args.settle_tol_mm * 1e-3,
        progress=not args.json,
        **stepping,
    )
    if args.out:
        with atomic_file(args.out) as tmp:
            res.save(tmp)
    if args.plot:
        save_figure(args.plot, res.plot)
    payload = with_resolution(res.to_dict(), opts)
    payload["out"] = str(args.out) if args.out else None
    payload["plot"] = str(args.plot) if args.plot else None
    text = res.table() + "\n" + resolution_line(opts) + "".join(f"\nwrote {f}" for f in (args.out, args.plot) if f)
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "move",
        help="point-to-point move tracked by the motor servos: tracking error, residual vibration, input shaping",
        description=(
            "The end effector follows a straight move from the pose (--x-mm, --y-mm, --phi-rad) to --to-x-mm, "
            "--to-y-mm, --to-phi-rad with a motion profile, or the path of --path-csv (t_s,x_mm,y_mm,phi_rad); the "
            "motors follow the rigid inverse kinematics through their position servos (the description's, else "
            "500 N m/rad and 1 N m s/rad, assumed). An imported model moves its end-effector site (its "
            "[end_effector]) by its motors (the joints an <actuator> drives, and servo_joints), from the site's "
            "pose at the model's reference unless --x-mm... are given. Reported: tracking error, link deflection, "
            "residual vibration "
            "after the move (peak, settling time, dominant frequency against the modal f1 at the end pose) and "
            "motor torques; --shaper zv|zvd shapes the profile for the end pose's dominant in-plane mode."
        ),
    )
    add_pose_args(p)
    g = p.add_argument_group("move")
    g.add_argument(
        "--to-x-mm",
        type=float,
        default=None,
        help="end pose x (mm; default 30; a described architecture: the start's x + 30 mm when no --to-* is given)",
    )
    g.add_argument(
        "--to-y-mm", type=float, default=None, help="end pose y (mm; default 0, a described one: the start's)"
    )
    g.add_argument("--to-z-mm", type=float, default=None, help="end pose z (mm; spatial machines; default the start's)")
    g.add_argument("--to-phi-rad", type=float, default=None, help="end pose rotation (rad; default 0 / the start's)")
    g.add_argument("--move-s", type=float, default=0.3, help="move time (s, default 0.3)")
    g.add_argument("--profile", choices=PROFILES, default="minimum-jerk", help="motion profile (default minimum-jerk)")
    g.add_argument(
        "--path-csv",
        type=Path,
        help="a commanded path t_s,x_mm,y_mm,phi_rad instead of a profile move (a described architecture: t_s and "
        "its task columns x_mm,y_mm[,z_mm][,phi_rad])",
    )
    g.add_argument(
        "--shaper", choices=SHAPERS, default="none", help="input shaper for the end pose's in-plane mode (default none)"
    )
    g.add_argument("--settle-s", type=float, default=0.3, help="simulated time after the move (s, default 0.3)")
    g.add_argument(
        "--settle-tol-mm",
        type=float,
        default=DEFAULT_SETTLE_TOL_MM,
        help=f"settling tolerance on the in-plane residual (mm, default {DEFAULT_SETTLE_TOL_MM:g})",
    )
    g.add_argument("--output-step-s", type=float, default=1e-4, help="sample period (s, default 1e-4)")
    add_resolution_args(p, axial=False)
    add_stepping_args(p)
    p.add_argument("--out", type=Path, help="time histories, .csv or .npz")
    p.add_argument("--plot", type=Path, help="plot: path, tracking error, residual vibration (.png, .pdf, .svg)")
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_move)
