"""``fpm-sim design``: frequencies over designs x poses (``--vary FIELD=SPEC``), on Dask; and the engine options
(``--scheduler``, ``--resume``) that ``sweep`` and ``reproduce`` share."""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import FAST_SEGMENTS, fast_options, read_poses_csv
from fpm_sim.cli.main import add_config_args, add_output_args, emit, load_manipulator

__all__ = ["register", "cmd_design", "add_engine_args", "engine_options", "chunk_store"]


def add_engine_args(p: argparse.ArgumentParser, *, workers: bool = False) -> None:
    """``--scheduler`` and ``--resume`` (and ``--workers`` when the command has none yet)."""
    g = p.add_argument_group("engine (Dask)")
    g.add_argument(
        "--scheduler",
        default=None,
        help="where the pose loop runs: local (a Dask LocalCluster of --workers processes), serial (this process) "
        "or the address of a running scheduler, e.g. tcp://10.0.0.5:8786 (used unchanged); default: local for "
        "runs of 4000 poses or more, else serial",
    )
    g.add_argument(
        "--resume",
        action="store_true",
        help="continue a killed run with the same --out: reuse the chunks it finished (in OUT.partial/)",
    )
    g.add_argument(
        "--chunk-poses",
        type=int,
        default=None,
        help="poses per task (default: about four tasks per worker, 16-512; see docs/design.md, Scale on paper)",
    )
    if workers:
        g.add_argument("--workers", type=int, default=None, help="local cluster processes (default: CPU count)")


def chunk_store(out: Path) -> Path:
    """Folder of a run's finished chunks, beside ``out`` (removed when the run completes)."""
    out = Path(out)
    return out.parent / f"{out.name}.partial"


def engine_options(args: argparse.Namespace, out: Path | None, *, progress: bool = True) -> EngineOptions:
    """The engine of ``--scheduler``, ``--workers`` and ``--resume`` (chunks streamed to :func:`chunk_store`)."""
    return EngineOptions(
        scheduler=getattr(args, "scheduler", None),
        workers=getattr(args, "workers", None),
        chunk=getattr(args, "chunk_poses", None),
        store=chunk_store(out) if out is not None else None,
        resume=bool(getattr(args, "resume", False)),
        progress=progress and not getattr(args, "json", False),
    )


def finish_store(out: Path | None) -> None:
    """Remove the chunk folder after a complete run."""
    import shutil

    if out is not None and chunk_store(out).exists():
        shutil.rmtree(chunk_store(out), ignore_errors=True)


def _poses(args: argparse.Namespace, config):  # noqa: ANN001, ANN202
    from fpm_sim.study.poses import parse_reading, study_poses
    from fpm_sim.study.sweep import dense_grid

    if args.poses is not None:
        return read_poses_csv(args.poses), "poses"
    if args.grid == "paper":
        return [p.pose for p in study_poses(parse_reading(args.reading))], "paper"
    return dense_grid(config, step_mm=args.step_mm, phi_rad=args.phi_rad), "dense"


def cmd_design(args: argparse.Namespace) -> int:
    import sys

    from fpm_sim.errors import FpmSimError

    try:
        return _design(args)
    except FpmSimError as exc:
        print(f"fpm-sim: error: {exc}", file=sys.stderr)
        return 2


def _design(args: argparse.Namespace) -> int:
    from fpm_sim.design import design_study, parse_vary, read_designs_csv
    from fpm_sim.design.study import DesignError

    config = load_manipulator(args)
    if bool(args.vary) == bool(args.designs):
        raise DesignError("give --vary FIELD=SPEC (one or more) or --designs FILE.csv")
    vary = parse_vary(args.vary, config) if args.vary else None
    designs = read_designs_csv(args.designs, config) if args.designs else None
    poses, grid = _poses(args, config)
    if args.segments < 1:
        raise DesignError(f"--segments must be >= 1, got {args.segments}")
    opts = fast_options(segments=args.segments, axial=args.axial)
    result = design_study(
        config,
        poses=poses,
        vary=vary,
        designs=designs,
        n_modes=args.n_modes,
        f_min_hz=args.f_min_hz,
        options=opts,
        engine=engine_options(args, args.out),
    )
    paths = result.write(args.out)
    finish_store(args.out)
    text = (
        f"{config.name}\n  {len(result.designs)} designs x {len(poses)} poses ({grid} grid), "
        f"{args.segments} segments per link, {result.elapsed_s:.1f} s\n\n{result.table()}\n\n  wrote "
        + ", ".join(str(p) for p in paths)
    )
    payload = {"summary": result.summary(), "files": [str(p) for p in paths], "elapsed_s": result.elapsed_s}
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design study: first frequencies over designs (--vary FIELD=SPEC) x workspace poses, on Dask",
        description="For every design (the full factorial of the --vary fields, or the rows of --designs) and "
        "every pose: the first --n-modes frequencies, mode 1's in-plane share, the singularity measure and the "
        "status. Writes OUT/design.nc (xarray, netCDF-4), OUT/design.csv (tidy), OUT/summary.csv (per design: "
        "min and mean f1 over the computed poses, share of the reachable workspace above --f-min-hz, masses) "
        "and figures.",
    )
    p.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="FIELD=SPEC",
        help="a dotted field of the description (SI units, e.g. section.thickness_m, hardware.payload.mass_kg, "
        "geometry.distal_length_m) and its values a,b,c or start:stop:count; several make a full factorial",
    )
    p.add_argument("--designs", type=Path, help="CSV of designs instead of --vary: one column per dotted field")
    p.add_argument("--grid", choices=("paper", "dense"), default="paper", help="the study's 25 poses or a dense grid")
    p.add_argument("--step-mm", type=float, default=10.0, help="dense grid spacing (mm, default 10)")
    p.add_argument("--phi-rad", type=float, default=0.0, help="platform rotation of the dense grid (rad)")
    p.add_argument("--reading", default="x+", help="how to read the study's table for --grid paper (default x+)")
    p.add_argument("--poses", type=Path, help="CSV of poses (columns x_mm,y_mm,phi_rad) instead of --grid")
    p.add_argument("--n-modes", type=int, default=3, help="frequencies per pose (default 3)")
    p.add_argument("--f-min-hz", type=float, default=None, help="summary: share of the workspace with f1 >= this")
    p.add_argument(
        "--segments", type=int, default=FAST_SEGMENTS, help=f"spring locations per link (default {FAST_SEGMENTS})"
    )
    p.add_argument("--axial", action="store_true", help="add axial springs (extensible links; slower)")
    add_config_args(p)
    add_engine_args(p, workers=True)
    p.add_argument("--out", type=Path, default=Path("out/design"), help="output folder (default out/design)")
    add_output_args(p)
    p.set_defaults(func=cmd_design)
