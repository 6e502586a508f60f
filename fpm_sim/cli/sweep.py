"""``fpm-sim sweep``: first natural frequencies over the workspace, with the singularity loci."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.cli.design import add_engine_args, engine_options, finish_store
from fpm_sim.cli.main import add_config_args, add_output_args, emit
from fpm_sim.cli.reproduce import add_study_args, study_manipulator
from fpm_sim.study.poses import parse_reading
from fpm_sim.study.sweep import sweep_workspace

__all__ = ["register", "cmd_sweep"]


def cmd_sweep(args: argparse.Namespace) -> int:
    try:
        reading = parse_reading(args.reading)
        manip = study_manipulator(args)
        if args.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {args.workers}")
        opts = fast_options(segments=args.segments, axial=args.axial)
        poses = None
        if args.poses is not None:
            from fpm_sim.batch.pose_loop import read_poses_csv

            poses, args.grid = read_poses_csv(args.poses), "poses"
        sw = sweep_workspace(
            manip,
            poses=poses,
            engine=engine_options(args, args.out) if args.backend == "cpu" else None,
            grid=args.grid,
            step_mm=args.step_mm,
            phi_rad=args.phi_rad,
            reading=reading,
            options=opts,
            backend=args.backend,
            workers=args.workers,
            progress=True,
        )
    except ValueError as exc:
        print(f"fpm-sim: error: {exc}", file=sys.stderr)
        return 2
    paths = sw.write(args.out)
    finish_store(args.out)
    if args.grid == "paper":  # the reproduce command's poses.csv, from the same frequencies
        from fpm_sim.study.poses import study_poses
        from fpm_sim.study.reproduce import StudyReproduction

        rep = StudyReproduction(manip, reading, study_poses(reading), sw.frequencies, [], opts)
        rep.write_csv(Path(args.out) / "poses.csv")
        paths.append(Path(args.out) / "poses.csv")
    f1 = sw.frequencies.f1_hz
    counts = sw.counts()
    text = (
        f"{manip.name}\n  grid {args.grid}"
        + (
            f", step {args.step_mm:g} mm, phi {args.phi_rad:g} rad"
            if args.grid == "dense"
            else f", reading {reading.name}"
        )
        + f"\n  points: {len(f1)} ("
        + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        + ")"
        + (f"\n  f1 range: {f1[f1 == f1].min():.2f} .. {f1[f1 == f1].max():.2f} Hz" if (f1 == f1).any() else "")
        + "\n  wrote "
        + ", ".join(str(p) for p in paths)
    )
    emit(args, {"grid": args.grid, "counts": counts, "rows": sw.rows(), "files": [str(p) for p in paths]}, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="first natural frequencies over the workspace (dense grid or the study's 25 poses)",
        description="Writes OUT/sweep_<grid>.csv (every grid point, with its status: ok, near_singular, singular, "
        "unreachable) and a heatmap with the singularity loci; with --grid paper also OUT/poses.csv (as reproduce).",
    )
    p.add_argument("--grid", choices=("paper", "dense"), default="dense", help="dense grid or the study's poses")
    p.add_argument("--step-mm", type=float, default=10.0, help="dense grid spacing (mm, default 10)")
    p.add_argument("--phi-rad", type=float, default=0.0, help="platform rotation for the dense grid (rad)")
    p.add_argument(
        "--poses", type=Path, help="CSV of poses (x_mm,y_mm,phi_rad) instead of --grid; writes OUT/sweep_poses.csv"
    )
    add_config_args(p)
    add_study_args(p)
    add_engine_args(p)
    p.add_argument("--out", type=Path, default=Path("out/sweep"), help="output folder (default out/sweep)")
    add_output_args(p)
    p.set_defaults(func=cmd_sweep)
