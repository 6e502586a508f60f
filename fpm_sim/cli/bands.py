"""``--posterior PATH [--draws N]``: predictions with bands (:mod:`fpm_sim.study.posterior`) in ``modes``,
``sweep``, ``design`` and ``reproduce``. Not a command of its own: the options and the posterior branch of
each command live here, so that every command reads the posterior, picks its draws and resolution and words
its bands one way."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fpm_sim.cli.common import (
    CliError,
    check_output_dir,
    count_arg,
    emit,
    engine_options,
    finish_store,
    held_task_coordinates,
    model_options,
    pose_of,
    resolution_line,
    task_pose_of,
    with_resolution,
)

if TYPE_CHECKING:
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.study.posterior import Posterior

__all__ = [
    "DEFAULT_DRAWS",
    "add_posterior_args",
    "band_options",
    "bands_hint",
    "load_posterior",
    "posterior_payload",
]

DEFAULT_DRAWS = 100
"""Posterior draws used by default: the 5 % and 95 % quantiles of 100 draws move by about
``sqrt(0.05 * 0.95 / 100) ~ 2`` percentile points between random subsets, enough for a band's edge."""
MAX_DRAWS = 100_000


def add_posterior_args(p: argparse.ArgumentParser, *, what: str = "each frequency") -> None:
    """``--posterior PATH`` and ``--draws N``."""
    g = p.add_argument_group("posterior (predictions with bands)")
    g.add_argument(
        "--posterior",
        type=Path,
        default=None,
        help=f"posterior.nc written by 'fpm-sim calibrate': predict with its draws and report the median and the "
        f"5/25/75/95 %% quantiles of {what} over the draws (the description is the posterior's; no --config)",
    )
    g.add_argument(
        "--draws",
        type=count_arg("--draws", high=MAX_DRAWS),
        default=DEFAULT_DRAWS,
        help=f"posterior draws to use: a seeded random subset (default {DEFAULT_DRAWS}; all when fewer)",
    )


def bands_hint(args: argparse.Namespace, command: str) -> str | None:
    """On the embedded default without ``--posterior``: the line saying that bands exist (the shipped posterior's
    path and the option), else ``None``."""
    if getattr(args, "posterior", None) is not None or getattr(args, "config", None) is not None:
        return None
    if getattr(args, "thickness_mm", None) is not None:
        return None
    from fpm_sim.study.posterior import default_posterior_path

    path = default_posterior_path()
    if path is None:
        return None
    return (
        f"  one description's frequencies; bands exist: 'fpm-sim {command} --posterior {path}' gives the median and "
        "the 5-95 % band over the shipped posterior's draws (docs/identification.md)"
    )


def load_posterior(
    args: argparse.Namespace, path: Path | None = None, *, study_only: str | None = None
) -> Posterior | None:
    """The posterior of ``--posterior`` (or ``path``), or ``None``; refuses ``--config``/``--thickness-mm``
    beside it (the posterior carries its own description), and a described machine's posterior where the command's
    use of it is the 3RRR's (``study_only``: what is the 3RRR's)."""
    path = path if path is not None else getattr(args, "posterior", None)
    if path is None:
        return None
    for name in ("config", "thickness_mm"):
        if getattr(args, name, None) is not None:
            flag = "--" + name.replace("_", "-")
            raise CliError(
                f"{flag} and --posterior: the posterior carries its own description (the base its draws apply to); "
                f"drop {flag}"
            )
    from fpm_sim.study.posterior import Posterior

    posterior = Posterior.from_netcdf(path)
    if study_only and posterior.described:
        raise CliError(
            f"--posterior {path}: {study_only} is the study's 3RRR's; this posterior is the described machine "
            f"{posterior.base.name!r}'s (use it with modes, sweep or plan-tests)"
        )
    return posterior


def band_options(args: argparse.Namespace, posterior: Posterior) -> ModelOptions:
    """The pose loop's options (gravity off) at the likelihood's resolution (the posterior's ``segments``)
    unless ``--segments`` or ``--fidelity`` says otherwise; a described machine's pose loop is inextensible."""
    import dataclasses

    if getattr(args, "segments", None) is None and getattr(args, "fidelity", None) is None and posterior.segments:
        opts = model_options(args, gravity=False, segments=posterior.segments)
    else:
        opts = model_options(args, gravity=False)
    return dataclasses.replace(opts, axial=False) if posterior.described else opts


def posterior_payload(posterior: Posterior) -> dict[str, Any]:
    """What the JSON says about the posterior used."""
    return {
        "file": str(posterior.source) if posterior.source else None,
        "n_draws_in_file": posterior.n_draws,
        "free_groups": list(posterior.groups),
        "segments": posterior.segments,
        "command": posterior.command,
        "parameters": posterior.summary(),
    }


def posterior_line(posterior: Posterior, n_used: int) -> str:
    """One line naming the posterior and the draws used."""
    return (
        f"posterior {posterior.source}: {n_used} of {posterior.n_draws} draws, free groups "
        f"{','.join(posterior.groups)} over {posterior.base.name}"
    )


# --------------------------------------------------------------------------------------------- modes


def modes_bands(args: argparse.Namespace) -> tuple[Any, dict[str, Any], str]:
    """``modes --posterior``: the bands of the lowest ``--n-modes`` frequencies at the pose (the pose loop's
    constrained eigenproblem, gravity off). Returns the bands, the JSON payload and the text."""
    from fpm_sim.architecture import Description
    from fpm_sim.study.posterior import AnyPose, predict_bands

    posterior = load_posterior(args)
    assert posterior is not None
    base = posterior.base
    pose: AnyPose
    if isinstance(base, Description):
        task_pose = task_pose_of(args, base)
        pose, where = task_pose, task_pose.label(base.task)
    else:
        pose = pose_of(args)
        where = pose.label()
    opts = band_options(args, posterior)
    eng = engine_options(args, None)
    bands = predict_bands(posterior, [pose], n_draws=args.draws, n_modes=args.n_modes, options=opts, engine=eng)
    payload = with_resolution(bands.to_dict(), opts)
    payload["posterior"] = posterior_payload(posterior)
    text = "\n".join(
        [
            posterior_line(posterior, bands.n_draws),
            f"  pose {where}; the pose loop (constrained eigenproblem, gravity off)",
            bands.table(),
            resolution_line(opts),
        ]
    )
    return bands, payload, text


# --------------------------------------------------------------------------------------------- sweep


def measure_next(bands: Any, mode: int = 1) -> dict[str, Any] | None:
    """The pose with the widest relative 90 % band of frequency ``mode`` ("measure here next")."""
    w = bands.widest(mode)
    if w is None:
        return None
    return {
        "pose": w,
        **bands.coordinates(w),
        "relative_width": float(bands.relative_width[w, mode - 1]),
        "median_hz": float(bands.median_hz[w, mode - 1]),
    }


def bands_summary(bands: Any, *, full_table_max: int = 40) -> str:
    """The bands' table (up to ``full_table_max`` poses), else a summary; and the "measure here next" line."""
    import numpy as np

    lines = []
    if len(bands.poses) <= full_table_max:
        lines.append(bands.table())
    else:
        med = bands.median_hz[:, 0]
        width = bands.relative_width[:, 0]
        ok = np.isfinite(med)
        lines.append(
            f"  {int(ok.sum())} of {len(bands.poses)} poses reached by at least one draw; median f1 "
            + (f"{np.nanmin(med):.2f} .. {np.nanmax(med):.2f} Hz" if ok.any() else "-")
            + "; 90 % band width / median: "
            + (f"median {100 * np.nanmedian(width):.1f} %, largest {100 * np.nanmax(width):.1f} %" if ok.any() else "-")
        )
    nxt = measure_next(bands)
    if nxt is not None:
        at = (
            f"({nxt['x_mm']:g}, {nxt['y_mm']:g}) mm, phi {nxt['phi_rad']:g} rad"
            if bands.task is None
            else f"{bands.label(nxt['pose'])} ({'mm, rad' if 'phi' in bands.task else 'mm'})"
        )
        lines.append(
            f"  measure here next: {at}: the widest "
            f"relative 90 % band of f1 ({100 * nxt['relative_width']:.1f} % of the median {nxt['median_hz']:.2f} Hz)"
        )
    return "\n".join(lines)


def _described_sweep_poses(args: argparse.Namespace, desc: Any) -> tuple[list[Any], str]:
    """A described machine's poses of ``sweep --posterior``: ``--poses`` in its task coordinates, or the task grid of
    the posterior median's machine every ``--step-mm`` (z and phi held: ``--z-mm``, ``--phi-rad``)."""
    from fpm_sim.batch.task_sweep import read_task_poses_csv, task_grid

    if args.grid == "paper":
        raise CliError("--grid paper: the study's 25 poses are the 3RRR's; use --grid dense or --poses on this machine")
    if args.reading != "x+":
        raise CliError("--reading: an option of the study's 3RRR sweep; a described machine's posterior has none")
    if args.poses is not None:
        return read_task_poses_csv(args.poses, desc, parameter="--poses"), "poses"
    return task_grid(desc, step_mm=args.step_mm, held=held_task_coordinates(args, desc))[0], "dense"


def _sweep_poses(args: argparse.Namespace, posterior: Posterior) -> tuple[list[Any], str, list[str] | None]:
    """The poses of ``sweep --posterior``, the grid's name and the poses' labels (the study's cells)."""
    from fpm_sim.architecture import Description
    from fpm_sim.batch.pose_loop import read_poses_csv
    from fpm_sim.study.poses import parse_reading, study_poses
    from fpm_sim.study.sweep import dense_grid

    median = posterior.median_config()
    if isinstance(median, Description):
        return (*_described_sweep_poses(args, median), None)
    if args.z_mm is not None:
        raise CliError("--z-mm: the 3RRR's task coordinates are x, y and phi; drop --z-mm")
    if args.poses is not None:
        return read_poses_csv(args.poses), "poses", None
    if args.grid == "paper":
        sp = study_poses(parse_reading(args.reading))
        return [p.pose for p in sp], "paper", [f"{p.row_mm:g},{p.col_mm:g}" for p in sp]
    return dense_grid(median, step_mm=args.step_mm, phi_rad=args.phi_rad), "dense", None


def sweep_bands(args: argparse.Namespace) -> int:
    """``sweep --posterior``: per pose of the grid (or ``--poses``) the median and bands of the first three
    frequencies; writes ``bands.csv``, ``bands.nc``, ``bands.png`` and ``bands_map.png`` (the median f1 map, the
    band-width map and the pose of the widest band). A described machine's posterior: its task poses."""
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_dir
    from fpm_sim.study.posterior import predict_bands

    posterior = load_posterior(args)
    assert posterior is not None
    if args.backend != "cpu":
        raise CliError(f"--posterior runs the cpu pose loop (one model per draw), not --backend {args.backend}")
    opts = band_options(args, posterior)
    poses, grid, labels = _sweep_poses(args, posterior)
    out = args.out or Path("out") / f"sweep_bands_{grid}"
    check_output_dir(out, "--out", overwrite=args.overwrite)
    warn_if_coarse(opts)
    bands = predict_bands(
        posterior, poses, n_draws=args.draws, n_modes=3, options=opts, engine=engine_options(args, out), labels=labels
    )
    with atomic_dir(out, overwrite=args.overwrite) as tmp:
        names = [p.name for p in bands.write(tmp)]
    finish_store(out)
    paths = [Path(out) / n for n in names]
    text = "\n".join(
        [
            posterior_line(posterior, bands.n_draws),
            f"  grid {grid}: {len(poses)} poses, {bands.elapsed_s:.1f} s",
            bands_summary(bands),
            resolution_line(opts),
            "  wrote " + ", ".join(str(p) for p in paths),
        ]
    )
    payload = with_resolution(bands.to_dict(), opts)
    payload.update({"grid": grid, "posterior": posterior_payload(posterior), "measure_here_next": measure_next(bands)})
    payload["files"] = [str(p) for p in paths]
    emit(args, payload, text)
    return 0


# --------------------------------------------------------------------------------------------- reproduce


def reproduce_posterior(args: argparse.Namespace) -> tuple[Posterior | None, str]:
    """The posterior of ``reproduce``: ``--posterior``, else the shipped default's
    (``fpm_sim/data/default_posterior.nc``) when the description is the embedded default (no ``--config``,
    no ``--thickness-mm``); with a note when the default ships none."""
    from fpm_sim.study.posterior import DEFAULT_POSTERIOR_NAME, default_posterior_path

    if args.posterior is not None:
        return load_posterior(args, study_only="the reproduction of the study"), ""
    if args.config is not None or args.thickness_mm is not None:
        return None, ""
    path = default_posterior_path()
    if path is None:
        return None, (
            f"no posterior shipped (fpm_sim/data/{DEFAULT_POSTERIOR_NAME}): the frequencies above are one "
            "description's, without bands; give --posterior PATH (from 'fpm-sim calibrate') for bands"
        )
    return load_posterior(args, path), f"bands from the shipped posterior {path.name}"


def reproduce_pointer(posterior: Posterior, bands: Any, files: list[str]) -> str:
    """What the report's verdict says about the posterior used (:attr:`fpm_sim.study.reproduce.StudyReproduction.
    posterior`): the file, the draws, where the bands are and how many measured f1 they cover."""
    c = bands.coverage()
    cover = (
        f"; {100 * c['in_90_band']:.0f} % of the {c['measured_poses']} measured f1 inside the 90 % band"
        if c["measured_poses"]
        else ""
    )
    source = posterior.source.name if posterior.source is not None else "a posterior in memory"
    loo = f"; {bands.loo.summary_line()}" if bands.loo is not None else ""
    if bands.bands.read_quantiles_hz is not None:
        loo += (
            "; latent-mode model: the measured values are compared with what the test reads (the first clear peak "
            "at the sensor, the bands), not with the table's f1 (the machine's lowest mode, which hides from the "
            "sensor where the posterior says another mode was read)"
        )
    return (
        f"{source}, {bands.bands.n_draws} of {posterior.n_draws} draws, free groups {','.join(posterior.groups)}; "
        f"the bands of f1 at the measured and withheld poses are in {', '.join(files)}{cover}{loo}"
    )


def reproduce_bands(args: argparse.Namespace, posterior: Posterior, reading: Any) -> Any:
    """``reproduce`` with a posterior: bands and in-sample coverage at the 12 measured poses, predictive bands at
    the six withheld poses (:func:`fpm_sim.study.posterior.study_bands`)."""
    from fpm_sim.study.posterior import study_bands

    return study_bands(
        posterior,
        reading=reading,
        n_draws=args.draws,
        options=band_options(args, posterior),
        engine=engine_options(args, None),
    )


# --------------------------------------------------------------------------------------------- design


def design_bands(
    args: argparse.Namespace, posterior: Posterior, vary: Any, designs: Any, poses: list[Any], grid: str, opts: Any
) -> int:
    """``design --posterior``: per design, P(min f1 over the ok poses >= ``--f-min-hz``) over the posterior's
    draws (:func:`fpm_sim.designs.robust.design_over_draws`); writes ``design_bands.csv``, ``design_bands.json``
    and ``design_bands.png``."""
    from fpm_sim.designs.robust import design_over_draws
    from fpm_sim.outputs import atomic_dir

    if args.f_min_hz is None:
        raise CliError("--posterior on design needs --f-min-hz (the target whose probability it reports)")
    from fpm_sim.config import Manipulator

    out = args.out
    draws = [c for c in posterior.configs(args.draws) if isinstance(c, Manipulator)]
    assert len(draws) == min(args.draws, posterior.n_draws)  # a described machine's posterior: refused when loaded
    result = design_over_draws(
        draws,
        poses=poses,
        f_min_hz=args.f_min_hz,
        vary=vary,
        designs=designs,
        n_modes=1,
        options=opts,
        engine=engine_options(args, out),
    )
    with atomic_dir(out, overwrite=True) as tmp:  # the folder was checked by the caller (--overwrite, --resume)
        names = [p.name for p in result.write(tmp)]
    finish_store(out)
    paths = [out / n for n in names]
    text = "\n".join(
        [
            posterior_line(posterior, len(draws)),
            f"  {len(result.designs)} designs x {len(draws)} draws x {len(poses)} poses ({grid} grid), "
            f"{result.elapsed_s:.1f} s",
            resolution_line(opts),
            "",
            result.table(),
            "",
            "  wrote " + ", ".join(str(p) for p in paths),
        ]
    )
    payload = with_resolution(result.to_dict(), opts)
    payload["posterior"] = posterior_payload(posterior)
    payload["files"] = [str(p) for p in paths]
    emit(args, payload, text)
    return 0
