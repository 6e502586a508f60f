"""``fpm-sim transient``: the study's full-vs-reduced transient (or a variant at any pose)."""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_output_args,
    add_overwrite_arg,
    add_pose_args,
    add_resolution_args,
    check_output_dir,
    count_arg,
    emit,
    load_manipulator,
    mm,
    model_options,
    pose_of,
    resolution_line,
    with_resolution,
)
from fpm_sim.cli.rollout import add_stepping_args

__all__ = ["register"]

STUDY_FORCE_N = 10.0
"""The study transient's force (N): :data:`fpm_sim.study.transient.STUDY_FORCE_N` (checked by a test)."""
STUDY_DURATION_S = 0.2
"""Simulated time (s): :data:`fpm_sim.study.transient.STUDY_DURATION_S` (checked by a test)."""
STUDY_OUTPUT_STEP_S = 1e-4
"""Output step (s): :data:`fpm_sim.study.transient.STUDY_OUTPUT_STEP_S` (checked by a test)."""
DEFAULT_BAND_HZ = 500.0
"""Kept band (Hz): :data:`fpm_sim.study.transient.DEFAULT_BAND_HZ` (checked by a test)."""


def cmd_transient(args: argparse.Namespace) -> int:
    from fpm_sim.cli.rollout import equilibrium_hint, stepping_kwargs
    from fpm_sim.linear.equilibrium import EquilibriumError
    from fpm_sim.model.options import resolve_segments, warn_if_coarse
    from fpm_sim.outputs import atomic_dir
    from fpm_sim.study.transient import STUDY_POSE, STUDY_THICKNESS_M, study_transient

    if args.out is not None:
        check_output_dir(args.out, "--out", overwrite=args.overwrite)
    manip = load_manipulator(args)
    thickness: float | None
    if args.study:
        if manip.motors.mode != "locked":
            raise CliError("--study needs motors.mode = 'locked' (the study's motors were locked); check --config")
        pose, thickness = STUDY_POSE, STUDY_THICKNESS_M
    else:
        pose, thickness = pose_of(args), mm(args.thickness_mm)  # validated once, by the description (schema)
    for name in ("force_n", "duration_s", "output_step_s"):
        if not getattr(args, name) > 0:
            raise CliError(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)!r}")
    opts = model_options(args)
    segments = resolve_segments(segments=opts.segments, link_model=opts.link_model)  # ModelOptions resolved it
    if segments < 2:
        raise CliError(f"--segments must be >= 2 for a flexible transient, got {segments}")
    warn_if_coarse(opts)
    stepping = stepping_kwargs(args, "--step-band-hz")
    try:
        res = study_transient(
            manip,
            pose=pose,
            thickness_m=thickness,
            force_n=args.force_n,
            duration_s=args.duration_s,
            output_step_s=args.output_step_s,
            segments=segments,
            axial=opts.axial,
            band_hz=None if args.modes else args.band_hz,
            n_modes=args.modes,
            progress=not args.json,
            integrator=stepping["integrator"],
            step_band_hz=stepping["band_hz"],
        )
    except EquilibriumError as exc:
        raise EquilibriumError(equilibrium_hint(exc, args)) from exc
    files = {}
    if args.out:
        with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
            files = {k: Path(args.out) / Path(v).name for k, v in res.save(tmp).items()}
    payload = with_resolution(res.summary(), opts)
    payload["files"] = {k: str(v) for k, v in files.items()}
    text = res.table() + "\n" + resolution_line(opts) + "".join(f"\nwrote {v}" for v in files.values())
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "transient",
        help="full nonlinear rollout vs reduced model under a constant end-effector force (the study's check)",
        description=(
            "Constant end-effector force in x, then in y, from the static equilibrium under gravity; the full "
            "nonlinear MuJoCo model (discrete integrator at the step of --step-band-hz, default 5 x f1; --integrator "
            "explicit: the reference) and the reduced modal model share one discretisation. --study: pose (0,0), "
            f"links 5 mm thick, motors locked, {STUDY_DURATION_S:g} s at a "
            f"{STUDY_OUTPUT_STEP_S * 1e3:g} ms output step, {STUDY_FORCE_N:g} N (assumed magnitude)."
        ),
    )
    p.add_argument(
        "--study",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="the study's setup (pose (0,0), 5 mm links, locked motors; default off)",
    )
    p.add_argument("--out", type=Path, help="write transient.csv, transient.png and summary.json/.txt to this folder")
    add_overwrite_arg(p)
    p.add_argument(
        "--force-n", type=float, default=STUDY_FORCE_N, help=f"force magnitude (N, default {STUDY_FORCE_N:g})"
    )
    p.add_argument("--duration-s", type=float, default=STUDY_DURATION_S, help="simulated time (s)")
    p.add_argument("--output-step-s", type=float, default=STUDY_OUTPUT_STEP_S, help="output step (s)")
    p.add_argument("--thickness-mm", type=float, help="link in-plane thickness override (mm; without --study)")
    add_resolution_args(p, axial=False)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--band-hz", type=float, default=DEFAULT_BAND_HZ, help="keep modes up to this frequency (Hz)")
    g.add_argument("--modes", type=count_arg("--modes"), help="keep this many modes instead of a band")
    add_stepping_args(p, band_flag="--step-band-hz")
    add_pose_args(p)
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_transient)
