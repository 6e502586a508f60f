"""``fpm-sim sweep``: first natural frequencies over the workspace, with the singularity loci."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fpm_sim.cli.bands import add_posterior_args, bands_hint, sweep_bands
from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_engine_args,
    add_output_args,
    check_output_dir,
    emit,
    engine_options,
    finish_store,
    held_task_coordinates,
    is_described,
    refuse_task_pose,
    resolution_line,
    with_resolution,
)
from fpm_sim.cli.reproduce import add_study_args, default_out, study_manipulator, study_options

if TYPE_CHECKING:
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.model.options import ModelOptions

__all__ = ["cmd_sweep", "register"]

_STUDY_ONLY = {"reading": "x+", "thickness_mm": None, "posterior": None}
"""Options of the study's own sweep (their defaults): on a described architecture they are refused by name."""


def _write_and_emit(args: argparse.Namespace, sw: Any, out: Path, opts: ModelOptions) -> int:
    """Write a described or imported machine's sweep (``sw.write``) into ``out`` atomically, then print its table
    (or JSON) with the resolution and the files written."""
    from fpm_sim.outputs import atomic_dir

    with atomic_dir(out, overwrite=args.overwrite) as tmp:
        names = [p.name for p in sw.write(tmp)]
    finish_store(out)
    paths = [Path(out) / n for n in names]
    text = sw.table() + "\n" + resolution_line(sw.options or opts) + "\n  wrote " + ", ".join(str(p) for p in paths)
    payload = {**sw.to_dict(), "files": [str(p) for p in paths]}
    emit(args, with_resolution(payload, sw.options or opts), text)
    return 0


def _sweep_described(args: argparse.Namespace, desc: Description) -> int:
    """``fpm-sim sweep --config machine.toml``: the general pose loop (:mod:`fpm_sim.batch.task_sweep`)."""
    from fpm_sim.batch.task_sweep import read_task_poses_csv, sweep_task, task_grid
    from fpm_sim.model.options import warn_if_coarse

    for key, default in _STUDY_ONLY.items():
        if getattr(args, key, default) != default:
            flag = "--" + key.replace("_", "-")
            raise CliError(f"{flag}: an option of the study's 3RRR sweep; a described architecture has no {flag}")
    if args.grid == "paper":
        raise CliError("--grid paper: the study's 25 poses are the 3RRR's; use --grid dense or --poses on this machine")
    opts = study_options(args)
    held = held_task_coordinates(args, desc)
    if args.poses is not None:
        poses, grid = read_task_poses_csv(args.poses, desc), "poses"
    else:
        poses, _, _ = task_grid(desc, step_mm=args.step_mm, held=held)
        grid = "dense"
    out = args.out or Path("out") / f"sweep_{grid}_{Path(args.config).stem}"
    check_output_dir(out, "--out", overwrite=args.overwrite)
    warn_if_coarse(opts)
    sw = sweep_task(
        desc, poses, options=opts, workers=args.workers, grid=grid, step_mm=args.step_mm, backend=args.backend
    )
    return _write_and_emit(args, sw, out, opts)


def _sweep_imported(args: argparse.Namespace, desc: ImportedDescription) -> int:
    """``fpm-sim sweep --config imported.toml --poses joints.csv``: the frequencies at each joint-space pose
    (:func:`fpm_sim.batch.joint_sweep.sweep_joints`)."""
    from fpm_sim.batch.joint_sweep import read_joint_poses_csv, sweep_joints
    from fpm_sim.model.options import warn_if_coarse

    for key, default in {**_STUDY_ONLY, "grid": "dense", "step_mm": 10.0, "backend": "cpu"}.items():
        if getattr(args, key, default) != default:
            flag = "--" + key.replace("_", "-")
            raise CliError(f"{flag}: not an option of an imported model's sweep (its poses are --poses, joint values)")
    refuse_task_pose(args)
    if args.poses is None:
        raise CliError(
            "--poses: an imported model has no task grid; give its joint-space poses as a CSV with one column per "
            "joint name (rad for a hinge, m for a slide)"
        )
    opts = study_options(args)
    poses = read_joint_poses_csv(args.poses, desc)
    out = args.out or Path("out") / f"sweep_poses_{Path(args.config).stem}"
    check_output_dir(out, "--out", overwrite=args.overwrite)
    warn_if_coarse(opts)
    sw = sweep_joints(desc, poses, options=opts)
    return _write_and_emit(args, sw, out, opts)


def cmd_sweep(args: argparse.Namespace) -> int:
    from fpm_sim.architecture.imported import is_imported_file, load_imported
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_dir
    from fpm_sim.study.poses import parse_reading
    from fpm_sim.study.sweep import sweep_workspace

    if args.out is not None:  # before the inputs are read (a posterior: seconds) and anything is computed
        check_output_dir(args.out, "--out", overwrite=args.overwrite)
    if args.config is not None and Path(args.config).is_file() and is_imported_file(args.config):
        return _sweep_imported(args, load_imported(args.config))
    if is_described(args):
        from fpm_sim.architecture import load_description

        return _sweep_described(args, load_description(args.config))
    if args.posterior is not None:  # predictions with bands (fpm_sim.cli.bands; --z-mm for a described machine's)
        return sweep_bands(args)
    if args.z_mm is not None:
        raise CliError("--z-mm: the 3RRR's task coordinates are x, y and phi; drop --z-mm")
    reading = parse_reading(args.reading)
    manip = study_manipulator(args)
    opts = study_options(args)
    poses = None
    if args.poses is not None:
        from fpm_sim.batch.pose_loop import read_poses_csv

        poses, args.grid = read_poses_csv(args.poses), "poses"
    label = {"paper": args.reading, "poses": Path(args.poses or "").stem}.get(
        args.grid, f"step{args.step_mm:g}mm_phi{args.phi_rad:g}"
    )
    out = args.out or default_out(f"sweep_{args.grid}", manip, label)
    check_output_dir(out, "--out", overwrite=args.overwrite)
    warn_if_coarse(opts)
    sw = sweep_workspace(
        manip,
        poses=poses,
        engine=engine_options(args, out) if args.backend == "cpu" else None,
        grid=args.grid,
        step_mm=args.step_mm,
        phi_rad=args.phi_rad,
        reading=reading,
        options=opts,
        backend=args.backend,
        workers=args.workers,
        progress=not args.json,
    )
    with atomic_dir(out, overwrite=args.overwrite) as tmp:
        names = [p.name for p in sw.write(tmp)]
        if args.grid == "paper":  # the reproduce command's poses.csv, from the same frequencies
            from fpm_sim.study.reproduce import StudyReproduction

            StudyReproduction.from_sweep(sw, reading).write_csv(tmp / "poses.csv")
            names.append("poses.csv")
    finish_store(out)
    paths = [Path(out) / n for n in names]
    f1 = sw.frequencies.f1_hz
    counts = sw.counts()
    text = (
        f"{manip.name}\n  grid {args.grid}"
        + (
            f", step {args.step_mm:g} mm, phi {args.phi_rad:g} rad"
            if args.grid == "dense"
            else (f", reading {reading.name}" if args.grid == "paper" else f", poses from {args.poses}")
        )
        + f"\n  points: {len(f1)} ("
        + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        + ")"
        + (f"\n  f1 range: {f1[f1 == f1].min():.2f} .. {f1[f1 == f1].max():.2f} Hz" if (f1 == f1).any() else "")
        + "\n"
        + resolution_line(opts)
        + "\n  wrote "
        + ", ".join(str(p) for p in paths)
    )
    payload = {"grid": args.grid, "counts": counts, "rows": sw.rows(), "files": [str(p) for p in paths]}
    hint = bands_hint(args, "sweep")
    if hint:
        text += "\n" + hint
        payload["bands_available"] = hint.strip()
    emit(args, with_resolution(payload, opts), text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="first natural frequencies over the workspace (dense grid or the study's 25 poses)",
        description="Writes OUT/sweep_<grid>.csv (OUT/sweep_poses.csv with --poses; every point, with its status: ok, "
        "near_singular, singular, "
        "unreachable) and a heatmap with the singularity loci; with --grid paper also OUT/poses.csv (as reproduce).",
    )
    p.add_argument("--grid", choices=("paper", "dense"), default="dense", help="dense grid or the study's poses")
    p.add_argument("--step-mm", type=float, default=10.0, help="dense grid spacing (mm, default 10)")
    p.add_argument("--phi-rad", type=float, default=0.0, help="platform rotation for the dense grid (rad)")
    p.add_argument(
        "--z-mm",
        type=float,
        default=None,
        help="height of the dense grid's horizontal slice (mm; spatial architectures; default: the first check pose's)",
    )
    add_config_args(p)
    p.add_argument(
        "--poses",
        type=Path,
        help="CSV of poses (columns x_mm,y_mm,phi_rad) instead of --grid; on an imported model, one column per joint "
        "name (rad or m)",
    )
    add_study_args(p)
    add_posterior_args(p, what="the first three frequencies at each pose")
    add_engine_args(p)
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default out/sweep_<grid>_<thickness>mm_<reading or step and phi>)",
    )
    add_output_args(p)
    p.set_defaults(func=cmd_sweep)
