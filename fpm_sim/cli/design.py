"""``fpm-sim design``: first frequencies over designs x poses (``--vary FIELD=SPEC``), on the Dask engine."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

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
    held_task_coordinates,
    is_described,
    is_imported,
    load_manipulator,
    model_options,
    with_resolution,
    workers_of,
)

if TYPE_CHECKING:
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription

__all__ = ["cmd_design", "register"]

READINGS = ("x+", "x-", "y+", "y-")
_STUDY_ONLY = {"posterior": None, "reading": "x+", "scheduler": None, "resume": False, "chunk_poses": None}
"""Options of the 3RRR's design study (their defaults): on a described architecture they are refused by name."""
_WHY = {
    "posterior": "robust design over a calibration's draws is the 3RRR's (its calibration's parameters)",
    "reading": "it reads the study's table of 3RRR poses",
    "scheduler": "a described architecture's or an imported model's designs run on their own pose loop, not on the "
    "Dask engine",
    "resume": "a described architecture's or an imported model's designs run on their own pose loop, not on the Dask "
    "engine",
    "chunk_poses": "a described architecture's or an imported model's designs run on their own pose loop, not on the "
    "Dask engine",
}


def _refuse_study_only(args: argparse.Namespace) -> None:
    """Refuse, by name, the options of the 3RRR's design study (:data:`_STUDY_ONLY`) and ask for exactly one of
    ``--vary`` and ``--designs``."""
    for key, default in _STUDY_ONLY.items():
        if getattr(args, key, default) != default:
            flag = "--" + key.replace("_", "-")
            raise CliError(f"{flag}: an option of the 3RRR's design study ({_WHY[key]}); drop {flag}")
    if bool(args.vary) == bool(args.designs):
        raise CliError("give --vary PATH=SPEC (one or more) or --designs FILE.csv, not both and not neither")


def _poses(args: argparse.Namespace, config: Any) -> tuple[list[Any], str]:
    from fpm_sim.batch.pose_loop import read_poses_csv
    from fpm_sim.study.poses import parse_reading, study_poses
    from fpm_sim.study.sweep import dense_grid

    if args.z_mm is not None:
        raise CliError("--z-mm: the 3RRR's task coordinates are x, y and phi; drop --z-mm")
    if args.poses is not None:
        return read_poses_csv(args.poses), "poses"
    if args.grid in (None, "paper"):
        return [p.pose for p in study_poses(parse_reading(args.reading))], "paper"
    return dense_grid(config, step_mm=args.step_mm, phi_rad=args.phi_rad), "dense"


def _described_poses(args: argparse.Namespace, desc: Description) -> tuple[list[Any], str]:
    """A described architecture's task poses: ``--poses`` (its task coordinates' columns), ``--grid dense``, or its
    check poses (the default)."""
    from fpm_sim.architecture import TaskPose
    from fpm_sim.batch.task_sweep import read_task_poses_csv, task_grid

    if args.grid == "paper":
        raise CliError(
            "--grid paper: the study's 25 poses are the 3RRR's; use --grid dense, --poses or the "
            "description's check poses (the default) on this machine"
        )
    held = held_task_coordinates(args, desc)
    if args.poses is not None:
        return read_task_poses_csv(args.poses, desc), "poses"
    if args.grid == "dense":
        poses, _, _ = task_grid(desc, step_mm=args.step_mm, held=held)
        return poses, "dense"
    if not desc.check_poses:
        raise CliError(f"--config {args.config}: {desc.name} has no check_poses; give --grid dense or --poses")
    return [TaskPose.from_coordinates(p) for p in desc.check_poses], "check poses"


def _design_described(args: argparse.Namespace, desc: Description) -> int:
    """``fpm-sim design --config machine.toml``: dotted paths into its file (``sections.bar.height_m``) over its task
    poses, on its own pose loop (:func:`fpm_sim.designs.design_study` dispatches)."""
    _refuse_study_only(args)
    poses, grid = _described_poses(args, desc)
    return _study_and_report(args, desc, poses, grid, workers_of(args))


def _study_and_report(args: argparse.Namespace, desc: Any, poses: list[Any], grid: str, workers: int) -> int:
    """The design study of ``--vary`` or ``--designs`` on ``desc`` (a described or imported machine) at ``poses``,
    written and reported (:func:`_write_and_report`)."""
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.designs import design_study, parse_vary, read_designs_csv
    from fpm_sim.model.options import warn_if_coarse

    vary = parse_vary(args.vary, desc) if args.vary else None
    designs = read_designs_csv(args.designs, desc) if args.designs else None
    opts = model_options(args, gravity=False)
    warn_if_coarse(opts)
    result = design_study(
        desc,
        poses=poses,
        vary=vary,
        designs=designs,
        n_modes=args.n_modes,
        f_min_hz=args.f_min_hz,
        options=opts,
        engine=EngineOptions(workers=workers),
    )
    return _write_and_report(args, result, len(poses), grid, opts)


def _design_imported(args: argparse.Namespace, desc: ImportedDescription) -> int:
    """``fpm-sim design --config imported.toml --poses FILE.csv``: dotted paths into the imported description's file
    (``materials.steel.young_pa``, ``sections.bar.height_m``) over its poses (joint columns, or task columns where it
    names an ``[end_effector]``), each design on the imported pose loop (:mod:`fpm_sim.designs.imported`)."""
    from fpm_sim.batch.joint_sweep import read_imported_poses_csv

    _refuse_study_only(args)
    if args.grid is not None or args.z_mm is not None:
        flag = "--grid" if args.grid is not None else "--z-mm"
        raise CliError(
            f"{flag}: an imported model states no reach or check poses to grid; give its poses as --poses FILE.csv "
            "(one column per joint, or its task coordinates' columns where it names an [end_effector])"
        )
    if args.poses is None:
        raise CliError(
            "--poses: an imported model states no reach or check poses; give a CSV with one column per joint (rad or "
            "m), or its task coordinates' columns (x_mm, y_mm, ...) where it names an [end_effector]"
        )
    return _study_and_report(args, desc, read_imported_poses_csv(args.poses, desc), "poses", 1)


def _write_and_report(args: argparse.Namespace, result: Any, n_poses: int, grid: str, opts: Any) -> int:
    """Write the study's files into ``--out`` (atomically) and print or emit its summary."""
    from fpm_sim.outputs import atomic_dir

    out = args.out
    with atomic_dir(out, overwrite=True) as tmp:  # the folder was checked first (--overwrite)
        paths = [out / p.name for p in result.write(tmp)]
    finish_store(out)
    text = (
        f"{result.config.name}\n  {len(result.designs)} designs x {n_poses} poses ({grid}), "
        f"{result.elapsed_s:.1f} s\n\n{result.table()}\n\n  wrote " + ", ".join(str(p) for p in paths)
    )
    payload = {"summary": result.summary(), "files": [str(p) for p in paths], "elapsed_s": result.elapsed_s}
    from fpm_sim.cli.bands import bands_hint

    hint = bands_hint(args, "design")
    if hint:  # the embedded default's study without --posterior: say the bands exist
        text += "\n" + hint
        payload["bands_available"] = hint.strip()
    emit(args, with_resolution(payload, opts), text)
    return 0


def cmd_design(args: argparse.Namespace) -> int:
    from fpm_sim.designs import design_study, parse_vary, read_designs_csv
    from fpm_sim.model.options import warn_if_coarse

    out = args.out
    # first, before the inputs are read (a posterior: seconds). --resume continues OUT.partial/ (the folder itself
    # appears only at the end): a finished run in --out, of this study or another, is replaced only with --overwrite
    check_output_dir(out, "--out", overwrite=args.overwrite)
    if is_described(args):
        from fpm_sim.architecture import load_description

        return _design_described(args, load_description(args.config))
    if is_imported(args):
        from fpm_sim.architecture.imported import load_imported

        return _design_imported(args, load_imported(args.config))
    # --posterior: designs over its draws (fpm_sim.cli.bands)
    posterior = load_posterior(args, study_only="robust design over a calibration's draws")
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
    return _write_and_report(args, result, len(poses), f"{grid} grid", opts)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design study: first frequencies over designs (--vary FIELD=SPEC) x workspace poses, on Dask",
        description="For every design (the full factorial of the --vary fields, or the rows of --designs) and "
        "every pose: the first --n-modes frequencies, mode 1's in-plane share, the singularity measure and the "
        "status. Writes OUT/design.nc (xarray, netCDF-4), OUT/design.csv (tidy), OUT/summary.csv (per design: "
        "min and mean f1 over the computed poses, share of the reachable workspace above --f-min-hz, masses) "
        "and figures, atomically. On a described architecture (--config machine.toml with [[chains]]) the fields are "
        "dotted paths into its file (sections.bar.height_m, chains.left.proximal.length_m; docs/architectures.md) "
        "and the poses its check poses, --grid dense or --poses in its task coordinates. On an imported model "
        "(kind = 'imported') the fields are dotted paths into its file (materials.steel.young_pa; docs/import.md) "
        "and the poses --poses: joint columns, or its task coordinates' where it names an [end_effector].",
    )
    p.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="FIELD=SPEC",
        help="a dotted field of the description (SI units, e.g. section.thickness_m, hardware.payload.mass_kg, "
        "geometry.distal_length_m; a described architecture: a path into its file, e.g. sections.bar.height_m) and "
        "its values a,b,c or start:stop:count; several make a full factorial",
    )
    p.add_argument("--designs", type=Path, help="CSV of designs instead of --vary: one column per dotted field")
    p.add_argument(
        "--grid",
        choices=("paper", "dense"),
        default=None,
        help="the study's 25 poses (the 3RRR's default) or a dense grid; a described architecture: its check poses "
        "by default",
    )
    p.add_argument("--step-mm", type=float, default=10.0, help="dense grid spacing (mm, default 10)")
    p.add_argument("--phi-rad", type=float, default=0.0, help="platform rotation of the dense grid (rad)")
    p.add_argument(
        "--z-mm",
        type=float,
        default=None,
        help="a spatial architecture's dense grid height (mm; default its first check pose's)",
    )
    p.add_argument(
        "--reading", default="x+", choices=READINGS, help="how to read the study's table for --grid paper (x+)"
    )
    p.add_argument(
        "--poses",
        type=Path,
        help="CSV of poses (columns x_mm,y_mm,phi_rad; a described architecture: its task coordinates' columns; an "
        "imported model: one column per joint, or its task coordinates') instead of --grid",
    )
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
