"""``fpm-sim design``: first frequencies over designs x poses (``--vary FIELD=SPEC``), on the Dask engine."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fpm_sim.cli.bands import add_posterior_args, band_options, design_bands, load_posterior
from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_engine_args,
    add_output_args,
    add_overwrite_arg,
    add_resolution_args,
    check_output_dir,
    count_arg,
    emit,
    engine_options,
    finish_store,
    load_manipulator,
    model_options,
    with_resolution,
)

__all__ = ["cmd_design", "register"]

READINGS = ("x+", "x-", "y+", "y-")


def _poses(args: argparse.Namespace, config: Any) -> tuple[list[Any], str]:
    from fpm_sim.batch.pose_loop import read_poses_csv
    from fpm_sim.study.poses import parse_reading, study_poses
    from fpm_sim.study.sweep import dense_grid

    if args.poses is not None:
        return read_poses_csv(args.poses), "poses"
    if args.grid == "paper":
        return [p.pose for p in study_poses(parse_reading(args.reading))], "paper"
    return dense_grid(config, step_mm=args.step_mm, phi_rad=args.phi_rad), "dense"


def cmd_design(args: argparse.Namespace) -> int:
    from fpm_sim.designs import design_study, parse_vary, read_designs_csv
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_dir

    out = args.out
    # first, before the inputs are read (a posterior: seconds). --resume continues OUT.partial/ (the folder itself
    # appears only at the end): a finished run in --out, of this study or another, is replaced only with --overwrite
    check_output_dir(out, "--out", overwrite=args.overwrite)
    posterior = load_posterior(args)  # --posterior: designs over its draws (fpm_sim.cli.bands)
    config = posterior.median_config() if posterior is not None else load_manipulator(args)
    if bool(args.vary) == bool(args.designs):
        raise CliError("give --vary FIELD=SPEC (one or more) or --designs FILE.csv, not both and not neither")
    vary = parse_vary(args.vary, config) if args.vary else None
    designs = read_designs_csv(args.designs, config) if args.designs else None
    poses, grid = _poses(args, config)
    opts = band_options(args, posterior) if posterior is not None else model_options(args, gravity=False)
    warn_if_coarse(opts)
    if posterior is not None:
        return design_bands(args, posterior, vary, designs, poses, grid, opts)
    result = design_study(
        config,
        poses=poses,
        vary=vary,
        designs=designs,
        n_modes=args.n_modes,
        f_min_hz=args.f_min_hz,
        options=opts,
        engine=engine_options(args, out),
    )
    with atomic_dir(out, overwrite=True) as tmp:  # the folder was checked above (--overwrite)
        paths = [out / p.name for p in result.write(tmp)]
    finish_store(out)
    text = (
        f"{config.name}\n  {len(result.designs)} designs x {len(poses)} poses ({grid} grid), "
        f"{result.elapsed_s:.1f} s\n\n{result.table()}\n\n  wrote "
        + ", ".join(str(p) for p in paths)
    )
    payload = {"summary": result.summary(), "files": [str(p) for p in paths], "elapsed_s": result.elapsed_s}
    emit(args, with_resolution(payload, opts), text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design study: first frequencies over designs (--vary FIELD=SPEC) x workspace poses, on Dask",
        description="For every design (the full factorial of the --vary fields, or the rows of --designs) and "
        "every pose: the first --n-modes frequencies, mode 1's in-plane share, the singularity measure and the "
        "status. Writes OUT/design.nc (xarray, netCDF-4), OUT/design.csv (tidy), OUT/summary.csv (per design: "
        "min and mean f1 over the computed poses, share of the reachable workspace above --f-min-hz, masses) "
        "and figures, atomically.",
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
    p.add_argument(
        "--reading", default="x+", choices=READINGS, help="how to read the study's table for --grid paper (x+)"
    )
    p.add_argument("--poses", type=Path, help="CSV of poses (columns x_mm,y_mm,phi_rad) instead of --grid")
    p.add_argument("--n-modes", type=count_arg("--n-modes"), default=3, help="frequencies per pose (default 3)")
    p.add_argument("--f-min-hz", type=float, default=None, help="summary: share of the workspace with f1 >= this")
    add_resolution_args(p, axial=False)
    add_config_args(p)
    add_posterior_args(p, what="min f1 per design, and P(min f1 >= --f-min-hz) over the draws")
    add_engine_args(p, workers=True)
    add_overwrite_arg(p)
    p.add_argument("--out", type=Path, default=Path("out/design"), help="output folder (default out/design)")
    add_output_args(p)
    p.set_defaults(func=cmd_design)
