"""``fpm-sim transient``: the study's full-vs-reduced transient (or a variant at any pose)."""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.cli.main import add_config_args, add_output_args, add_pose_args, emit, load_manipulator, pose_of
from fpm_sim.cli.rollout import user_errors
from fpm_sim.rom.reduction import ReductionError
from fpm_sim.study.transient import (
    DEFAULT_BAND_HZ,
    DEFAULT_SEGMENTS,
    STUDY_DURATION_S,
    STUDY_FORCE_N,
    STUDY_OUTPUT_STEP_S,
    STUDY_POSE,
    STUDY_THICKNESS_M,
    study_transient,
)

__all__ = ["register"]


@user_errors
def cmd_transient(args: argparse.Namespace) -> int:
    manip = load_manipulator(args)
    if args.study:
        if manip.motors.mode != "locked":
            raise ReductionError(
                "--study needs motors.mode = 'locked' (the study's motors were locked); check --config"
            )
        pose, thickness = STUDY_POSE, STUDY_THICKNESS_M
    else:
        pose, thickness = pose_of(args), args.thickness_m
    for name in ("force_n", "duration_s", "output_step_s"):
        if not getattr(args, name) > 0:
            raise ReductionError(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)!r}")
    if args.segments < 2:
        raise ReductionError(f"--segments must be >= 2 for a flexible transient, got {args.segments}")
    res = study_transient(
        manip,
        pose=pose,
        thickness_m=thickness,
        force_n=args.force_n,
        duration_s=args.duration_s,
        output_step_s=args.output_step_s,
        segments=args.segments,
        axial=args.axial,
        band_hz=None if args.modes else args.band_hz,
        n_modes=args.modes,
        progress=not args.json,
    )
    files = res.save(args.out) if args.out else {}
    payload = res.summary()
    payload["files"] = {k: str(v) for k, v in files.items()}
    text = res.table() + "".join(f"\nwrote {v}" for v in files.values())
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "transient",
        help="full nonlinear rollout vs reduced model under a constant end-effector force (the study's check)",
        description=(
            "Constant end-effector force in x, then in y, from the static equilibrium under gravity; the full "
            "nonlinear MuJoCo model and the reduced modal model share one discretisation. --study: pose (0,0), "
            f"links {STUDY_THICKNESS_M * 1e3:g} mm thick, motors locked, {STUDY_DURATION_S:g} s at a "
            f"{STUDY_OUTPUT_STEP_S * 1e3:g} ms output step, {STUDY_FORCE_N:g} N (assumed magnitude)."
        ),
    )
    p.add_argument("--study", action="store_true", help="the study's setup (pose (0,0), 5 mm links, locked motors)")
    p.add_argument("--out", type=Path, help="write transient.csv, transient.png and summary.json/.txt here")
    p.add_argument(
        "--force-n", type=float, default=STUDY_FORCE_N, help=f"force magnitude (N, default {STUDY_FORCE_N:g})"
    )
    p.add_argument("--duration-s", type=float, default=STUDY_DURATION_S, help="simulated time (s)")
    p.add_argument("--output-step-s", type=float, default=STUDY_OUTPUT_STEP_S, help="output step (s)")
    p.add_argument("--thickness-m", type=float, help="link in-plane thickness override (without --study)")
    p.add_argument(
        "--segments", type=int, default=DEFAULT_SEGMENTS, help=f"spring locations per link (default {DEFAULT_SEGMENTS})"
    )
    p.add_argument("--axial", action="store_true", help="add axial springs (much smaller timestep; slow)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--band-hz", type=float, default=DEFAULT_BAND_HZ, help="keep modes up to this frequency (Hz)")
    g.add_argument("--modes", type=int, help="keep this many modes instead of a band")
    add_pose_args(p)
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_transient)
