"""``fpm-sim reproduce``: the study's subsystem tests and 25 poses, with a report and figures."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fpm_sim.cli.bands import (
    add_posterior_args,
    posterior_line,
    posterior_payload,
    reproduce_bands,
    reproduce_pointer,
    reproduce_posterior,
)
from fpm_sim.cli.common import (
    WORKERS_HELP,
    CliError,
    add_config_args,
    add_engine_args,
    add_output_args,
    add_overwrite_arg,
    add_resolution_args,
    check_output_dir,
    emit,
    engine_options,
    finish_store,
    load_manipulator,
    model_options,
    with_resolution,
    workers_of,
)

__all__ = ["add_study_args", "cmd_reproduce", "default_out", "register", "study_manipulator", "study_options"]

READINGS = ("x+", "x-", "y+", "y-")


def add_study_args(p: argparse.ArgumentParser) -> None:
    """Options shared by ``reproduce`` and ``sweep``."""
    p.add_argument(
        "--reading",
        default="x+",
        choices=READINGS,
        help="how to read the study's table: x+, x-, y+ or y- (rows are x or y; sign of the 0.2 rad turn); default x+",
    )
    p.add_argument("--thickness-mm", type=float, help="in-plane link thickness (mm); the study: 30, 10, 5")
    add_resolution_args(p, axial=False)
    p.add_argument("--workers", type=int, default=None, help=WORKERS_HELP)
    p.add_argument(
        "--backend",
        default="cpu",
        choices=("cpu", "jax", "mjx"),
        help="pose-loop backend: cpu (SciPy, one compiled model re-posed per pose, on the engine), jax (MuJoCo's "
        "formulas in JAX, all poses batched; compiles once, ~10 s) or mjx (MJX's own pipeline, batched; compiles "
        "for minutes on a CPU; the path to measure on a GPU); default cpu",
    )
    add_overwrite_arg(p)


def study_manipulator(args: argparse.Namespace) -> Any:
    """The manipulator of ``--config`` with ``--thickness-mm`` applied."""
    manip = load_manipulator(args)
    if args.thickness_mm is not None:
        manip = manip.with_section(thickness_m=args.thickness_mm * 1e-3)
        manip = manip.replace(name=f"{manip.name} [links {args.thickness_mm:g} mm in-plane]")
    return manip


def study_options(args: argparse.Namespace) -> Any:
    """Pose-loop model options (gravity off: the fast path's linearisation; see batch.pose_loop) and checks."""
    from fpm_sim.batch.frequencies import BACKENDS

    args.workers = workers_of(args)
    if args.workers < 1:
        raise CliError(f"--workers must be >= 1, got {args.workers}")
    if args.backend not in BACKENDS:
        raise CliError(f"unknown --backend {args.backend!r}; available: {', '.join(sorted(BACKENDS))}")
    return model_options(args, gravity=False)


def default_out(command: str, manip: Any, reading: str) -> Path:
    """``out/<command>_<thickness>mm_<reading>``: a default folder that names what it holds."""
    return Path("out") / f"{command}_{manip.section.thickness_m * 1e3:g}mm_{reading}"


def cmd_reproduce(args: argparse.Namespace) -> int:
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_dir
    from fpm_sim.study.poses import parse_reading
    from fpm_sim.study.reproduce import reproduce_study

    reading = parse_reading(args.reading)
    if args.out is not None:  # first: before the inputs are read (a posterior: seconds) and anything is computed
        check_output_dir(args.out, "--out", overwrite=args.overwrite)
    manip = None if args.posterior is not None else study_manipulator(args)
    if args.out is None and manip is not None:  # the default folder names the description's thickness
        check_output_dir(default_out("reproduce", manip, args.reading), "--out", overwrite=args.overwrite)
    posterior, note = reproduce_posterior(args)  # --posterior, or the shipped default's (fpm_sim.cli.bands)
    if manip is None:
        from fpm_sim.config import Manipulator

        assert posterior is not None  # --posterior given: its median is the description
        median = posterior.median_config()
        assert isinstance(median, Manipulator)  # a described machine's posterior: refused when loaded
        manip = median
    opts = study_options(args)
    out = args.out or default_out("reproduce", manip, args.reading)
    check_output_dir(out, "--out", overwrite=args.overwrite)
    warn_if_coarse(opts)
    rep = reproduce_study(
        manip,
        reading=reading,
        options=opts,
        backend=args.backend,
        workers=args.workers,
        progress=not args.json,
        engine=engine_options(args, out) if args.backend == "cpu" else None,
    )
    bands = reproduce_bands(args, posterior, reading) if posterior is not None else None
    with atomic_dir(out, overwrite=args.overwrite) as tmp:
        band_files = [p.name for p in bands.write(tmp)] if bands is not None else []
        if bands is not None and posterior is not None:
            rep.posterior = reproduce_pointer(posterior, bands, band_files)  # the report's verdict points to them
        paths = [out / p.name for p in rep.write(tmp)] + [out / n for n in band_files]
    finish_store(out)
    lines = [rep.table()]
    if bands is not None and posterior is not None:
        lines += [posterior_line(posterior, bands.bands.n_draws), bands.table()]
    lines += [note] if note else []
    lines.append("wrote " + ", ".join(str(p) for p in paths))
    payload = with_resolution(rep.to_dict(), opts)
    payload["bands"] = bands.to_dict() if bands is not None else None
    payload["posterior"] = posterior_payload(posterior) if posterior is not None else (note or None)
    payload["files"] = [str(p) for p in paths]
    emit(args, payload, "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce the study: subsystem tests, the 25 poses vs COMSOL, report and figures",
        description="Runs the study's single-link and chain tests and its 25 poses on a manipulator description "
        "and writes OUT/poses.csv, OUT/report.md and figures (atomically: the folder appears complete or not at all).",
    )
    add_config_args(p)
    add_study_args(p)
    add_posterior_args(
        p,
        what="f1 at the 12 measured poses (with in-sample coverage) and the six withheld ones (default: the shipped "
        "default posterior, if any, for the embedded description)",
    )
    add_engine_args(p)
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/reproduce_<thickness>mm_<reading>)"
    )
    add_output_args(p)
    p.set_defaults(func=cmd_reproduce)
