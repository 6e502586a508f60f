"""``fpm-sim plan-tests``: which measurements would narrow the posterior's bands most (:mod:`fpm_sim.study.plan`).

Ranks single candidate measurements (poses x quantities) and chooses ``--k`` of them greedily by the target's
expected spread after them; prints the plan's table (or ``--json``) and writes ``plan.csv``, ``candidates.csv``,
``plan.json`` and ``gain_map.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    CliError,
    add_engine_args,
    add_output_args,
    check_output_dir,
    count_arg,
    emit,
    engine_options,
    finish_store,
    resolution_line,
    with_resolution,
)

__all__ = ["cmd_plan_tests", "register"]


def _quantities(text: str, posterior: Any) -> list[str]:
    from fpm_sim.study.plan import QUANTITIES, PlanError
    from fpm_sim.study.planning import read_point, refuse_reads

    qs = [q.strip() for q in text.split(",") if q.strip()]
    bad = [q for q in qs if q not in QUANTITIES and not q.startswith("read:")]
    if bad or not qs:
        raise CliError(
            f"--quantities: unknown {', '.join(map(repr, bad)) or 'empty list'}; use {','.join(QUANTITIES)} or "
            "read:LINK@POS:AXIS (e.g. read:distal_0@0.5:z)"
        )
    try:
        for q in qs:
            read_point(q)
        refuse_reads(posterior, qs)
    except PlanError as err:
        raise CliError(err.render(parameter="--quantities")) from None
    return qs


def _candidates(args: argparse.Namespace, posterior: Any) -> list[Any]:
    from fpm_sim.study.planning import grid_candidates, pose_file_candidates, study_candidates

    qs = _quantities(args.quantities, posterior)
    which = args.candidates or ("grid" if posterior.described else "study")
    if which == "study":
        if posterior.described:
            raise CliError(
                f"--candidates study: the study's 25 cells are the 3RRR's; {posterior.base.name!r} has its own task "
                f"coordinates ({', '.join(posterior.base.task)}); use --candidates grid or a CSV of its task poses"
            )
        return study_candidates(qs)
    if which == "grid":
        return grid_candidates(posterior, qs, step_mm=args.candidate_step_mm)
    return pose_file_candidates(posterior, which, qs, parameter="--candidates")


def _target(args: argparse.Namespace, posterior: Any) -> Any:
    from fpm_sim.study.planning import Target, read_pose_file, requirement_target, workspace_target

    if args.target == "workspace":
        return workspace_target(posterior, step_mm=args.target_step_mm, mode=args.target_mode)
    path = Path(args.target)
    if path.suffix == ".toml":
        return requirement_target(posterior, path, args.requirement)
    poses = read_pose_file(posterior, path, parameter="--target")
    return Target(tuple(poses), args.target_mode, None, f"f{args.target_mode} at the poses of {path.name}")


def cmd_plan_tests(args: argparse.Namespace) -> int:
    from fpm_sim.cli.bands import band_options, load_posterior, posterior_line
    from fpm_sim.outputs import atomic_dir, atomic_file
    from fpm_sim.study.planning import plan_tests
    from fpm_sim.study.posterior import default_posterior_path

    out = args.out
    check_output_dir(out, "--out", overwrite=args.overwrite)
    if args.sigma_pct is not None and not args.sigma_pct > 0:
        raise CliError(
            f"--sigma-pct must be > 0 (the planned measurement's sd, % of the frequency), got {args.sigma_pct}"
        )
    path = args.posterior or default_posterior_path()
    if path is None:
        raise CliError("--posterior: no posterior given and none shipped; give posterior.nc from 'fpm-sim calibrate'")
    posterior = load_posterior(args, path)
    assert posterior is not None
    cands = _candidates(args, posterior)
    target = _target(args, posterior)
    if args.k > len(cands):
        raise CliError(f"--k {args.k}: only {len(cands)} candidate measurements; choose at most {len(cands)}")
    opts = band_options(args, posterior)
    plan = plan_tests(
        posterior,
        cands,
        target,
        k=args.k,
        sigma_rel=None if args.sigma_pct is None else args.sigma_pct / 100,
        n_draws=args.draws,
        outcomes=args.outcomes,
        seed=args.seed,
        ess_min=args.ess_min,
        options=opts,
        engine=engine_options(args, out),
    )
    payload = with_resolution(plan.to_dict(), opts)
    payload["posterior"] = str(path)
    with atomic_dir(out, overwrite=args.overwrite) as tmp:
        names = [p.name for p in plan.write(tmp)]
        with atomic_file(tmp / "plan.json") as f:
            f.write_text(json.dumps(payload, indent=1))
        names.append("plan.json")
    finish_store(out)
    paths = [str(Path(out) / n) for n in names]
    payload["files"] = paths
    text = "\n".join(
        [posterior_line(posterior, plan.n_draws), plan.table(), resolution_line(opts), "  wrote " + ", ".join(paths)]
    )
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan-tests",
        help="which measurements would narrow the posterior's bands most",
        description="Rank candidate measurements (poses x quantities) by how much each is expected to narrow the "
        "target's 90 % band (or the pass/fail uncertainty of a requirement) under the posterior, and choose --k of "
        "them greedily. The outcomes come from the posterior predictive; each update re-weights the draws "
        "(docs/identification.md, 'Planning the next tests').",
    )
    p.add_argument("--posterior", type=Path, default=None, help="posterior.nc (default: the embedded default's)")
    p.add_argument(
        "--candidates",
        default=None,
        help="candidate poses: 'study' (the study's 25 cells; the default for the 3RRR), 'grid' (the workspace every "
        "--candidate-step-mm, phi 0; the default for a described machine) or a CSV file with x_mm,y_mm,phi_rad (a "
        "described machine: its task coordinates, e.g. x_mm,y_mm)",
    )
    p.add_argument("--candidate-step-mm", type=float, default=50.0, help="grid step of --candidates grid (default 50)")
    p.add_argument(
        "--quantities",
        default="f1,f1+f2,f1..f3",
        help="what each candidate measures, comma-separated from f1, f1+f2, f1..f3 (labelled modes) and "
        "read:LINK@POS:AXIS (the first clear peak of a hammer test at that accelerometer point and axis, its mode "
        "unlabelled, e.g. read:distal_0@0.5:z; the 3RRR's) (default: f1,f1+f2,f1..f3)",
    )
    p.add_argument(
        "--sigma-pct",
        type=float,
        default=None,
        help="the planned measurement's sd, %% (default: the posterior's data's)",
    )
    p.add_argument(
        "--target",
        default="workspace",
        help="where predictions matter: 'workspace' (default: the median description's workspace every "
        "--target-step-mm), a CSV of poses, or a requirements TOML (its min_frequency requirement's poses and level)",
    )
    p.add_argument("--target-step-mm", type=float, default=50.0, help="grid step of --target workspace (default 50)")
    p.add_argument("--target-mode", type=int, choices=(1, 2, 3), default=1, help="the target's frequency (default 1)")
    p.add_argument("--requirement", default=None, help="with a requirements TOML: the requirement's name")
    p.add_argument("--k", type=count_arg("--k", high=100), default=3, help="measurements to choose (default 3)")
    p.add_argument(
        "--draws", type=count_arg("--draws", low=10, high=100_000), default=200, help="posterior draws (default 200)"
    )
    p.add_argument(
        "--outcomes",
        type=count_arg("--outcomes", low=2, high=10_000),
        default=64,
        help="simulated outcomes per set (default 64)",
    )
    p.add_argument(
        "--ess-min",
        type=float,
        default=20.0,
        help="effective sample size below which an update is Bayes-linear (default 20)",
    )
    p.add_argument(
        "--screen",
        type=count_arg("--screen", high=100_000),
        default=40,
        help="with more candidates than this, screen them all by the band's moments and score this many best with "
        "quantiles (default 40)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the draws and the outcomes (default 0)")
    p.add_argument("--segments", type=int, default=None, help="spring locations per link (default: the posterior's)")
    p.add_argument(
        "--out", type=Path, default=Path("out") / "plan_tests", help="output folder (default out/plan_tests)"
    )
    p.add_argument("--overwrite", action="store_true", help="replace --out if it holds results")
    add_engine_args(p, workers=True)
    add_output_args(p)
    p.set_defaults(func=cmd_plan_tests)
