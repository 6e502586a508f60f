"""``fpm-sim calibrate``: Bayesian model updating (nested sampling) from measured natural frequencies."""

from __future__ import annotations

import argparse
import dataclasses
import math
import warnings
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    WORKERS_HELP,
    CliError,
    add_config_args,
    add_output_args,
    add_overwrite_arg,
    check_output_dir,
    emit,
    is_described,
    is_imported,
    load_machine,
    workers_of,
)
from fpm_sim.cli.identify import GROUPS, add_data_args, read_data_args, read_described_measured

__all__ = ["cmd_calibrate", "register"]

CHECKPOINT = "checkpoint.dynesty"
DEFAULT_FREE = "geometry,hardware,section-height"
"""The 3RRR's free groups when --free is not given."""
RUN_FILE = "calibration.pkl"


def cmd_calibrate(args: argparse.Namespace) -> int:
    import pickle

    from fpm_sim.outputs import atomic_file
    from fpm_sim.study.calibrate import SamplerOptions, run_calibration
    from fpm_sim.study.calibrate.posterior import thin, write_config, write_posterior
    from fpm_sim.study.calibrate.report import write_report

    out = Path(args.out)
    if args.resume:
        if not (out / (CHECKPOINT + ".digest")).exists() and not (out / RUN_FILE).exists():
            raise CliError(f"--resume: {out} holds no checkpoint ({CHECKPOINT}); run without --resume first")
    else:
        check_output_dir(out, "--out", overwrite=args.overwrite)
    described = is_described(args) or is_imported(args)
    problem, data_note = _described_problem(args) if described else _study_problem(args)
    opts = SamplerOptions(
        live_points=args.live_points,
        dlogz=args.dlogz,
        seed=args.seed,
        workers=workers_of(args),
        sample=args.sample,
        walks=args.walks,
        max_calls=args.max_calls,
        draws=args.draws,
        runs=args.runs,
        sampler=args.sampler,
        particles=args.particles,
        cheap_particles=args.cheap_particles,
        emulator=args.emulator,
        ess_fraction=args.ess_fraction,
        moves=args.moves,
        final_moves=args.final_moves,
        jumps=args.jumps,
        importance=args.importance,
        islands=args.islands,
        crossover=args.crossover,
    )
    opts.check()
    out.mkdir(parents=True, exist_ok=True)
    if args.overwrite and not args.resume:
        for f in [out / RUN_FILE, *out.glob(CHECKPOINT + "*")]:
            f.unlink(missing_ok=True)
    run_file = out / RUN_FILE
    cal = _saved_calibration(run_file, problem) if args.resume and run_file.exists() else None
    command = args.command_line  # set by main(argv): the command that ran, also when run from Python
    if cal is None:
        cal = run_calibration(problem, opts, checkpoint=out / CHECKPOINT, resume=args.resume, progress=not args.quiet)
        cal.extra["command"] = command  # the sampling run's command, kept when --resume rewrites the outputs
        with atomic_file(run_file) as tmp:
            tmp.write_bytes(pickle.dumps(cal, protocol=4))
    command = cal.extra.get("command", command)
    _warn_if_runs_disagree(cal)
    write_posterior(cal, out / "posterior.nc", command=command)
    if args.thin:
        write_posterior(cal, out / "posterior_thin.nc", command=command, idx=thin(cal, args.thin, seed=args.seed))
    median = "description.toml" if described else "config.toml"
    write_config(cal, out / median, data_note=data_note, command=command)
    write_report(cal, out, command=command, data_note=data_note)
    emit(
        args,
        {"result": cal.to_dict(), "out": str(out)},
        cal.table() + f"\nwrote {out}/posterior.nc, {median}, report.md, figures",
    )
    return 0


def _study_problem(args: argparse.Namespace) -> tuple[Any, str]:
    """The 3RRR's problem of the options (free groups, the study's data forms, rig tests) and its data note."""
    from fpm_sim.config import Manipulator
    from fpm_sim.errors import FpmSimWarning
    from fpm_sim.study.calibrate import CalibrationProblem, read_priors
    from fpm_sim.study.identify import parameter_set

    if args.priors is None:
        raise CliError("--priors: give the priors TOML file (e.g. fpm_sim/data/study_priors.toml)")
    args.free = args.free or DEFAULT_FREE
    start = load_machine(args, "calibrate")  # the 3RRR's form; an imported model is refused by name
    assert isinstance(start, Manipulator)
    groups, datasets, tests = read_data_args(args)
    observations = [o for ds in datasets for o in ds.observations]
    ps = parameter_set(start, groups)
    priors = read_priors(args.priors, ps.names)
    problem = CalibrationProblem(
        start, tuple(groups), priors, tuple(observations), tuple(tests), segments=args.segments
    )
    if problem.n_data < len(ps.names):
        warnings.warn(
            f"{problem.n_data} data for {len(ps.names)} free parameters: the data cannot determine them all; the "
            "posterior of the undetermined combinations is their prior (read report.md's marginals against the "
            "priors before using any value)",
            FpmSimWarning,
            stacklevel=1,
        )
    data_note = ", ".join([ds.source for ds in datasets] + ([Path(args.subsystems).name] if tests else []))
    return problem, data_note


def _described_problem(args: argparse.Namespace) -> tuple[Any, str]:
    """A described machine's problem (:mod:`fpm_sim.study.calibrate.described`): priors on dotted paths (the priors
    file and/or ``--free PATH=lo:hi``), its measured file, the row of a pose the file's machine cannot reach named."""
    from fpm_sim.config import Manipulator
    from fpm_sim.study.calibrate.described import described_problem

    for flag, given in (("--subsystems", args.subsystems), ("--reading", args.reading)):
        if given:
            raise CliError(
                f"{flag}: the 3RRR's (its rig tests, its table's reading); drop {flag} on a described machine"
            )
    if args.free and any("." not in g.partition("=")[0] for g in args.free.split(",") if g.strip()):
        raise CliError(
            f"--free {args.free}: the 3RRR's parameter groups; on a described architecture give dotted paths into "
            "its file (PATH with a prior in --priors, or PATH=lo:hi for a uniform prior), e.g. --free "
            "lumps.end_effector.mass_kg=0.05:1.0"
        )
    if args.priors is None and not args.free:
        raise CliError("--priors or --free: give the priors of the free dotted paths (a file, or PATH=lo:hi)")
    desc = load_machine(args, "calibrate")  # a described architecture or an imported model
    assert not isinstance(desc, Manipulator)
    data = read_described_measured(args, desc)
    problem = described_problem(desc, data, priors=args.priors, free=args.free, segments=args.segments)
    return problem, data.source


def _saved_calibration(run_file: Path, problem: Any) -> Any:
    """A finished calibration saved in ``run_file`` (refused for another problem), brought up to date."""
    import pickle

    from fpm_sim.study.calibrate.sampler import problem_digest

    with run_file.open("rb") as fh:
        cal = pickle.load(fh)
    if problem_digest(cal.problem) != problem_digest(problem):
        raise CliError(f"--resume: {run_file} belongs to another problem; run without --resume (and --overwrite)")
    if math.isnan(cal.start_log_likelihood):  # saved before the start check existed
        cal.start_log_likelihood = problem.start_log_likelihood()
    if "sampler" not in vars(cal.options):  # saved before the sampler could be chosen: nested sampling
        cal.options = dataclasses.replace(cal.options, sampler="dynesty")
    if "classes" not in vars(cal):  # saved before the classes were enumerated: one run, the class sampled
        cal.classes = []
        cal.options = dataclasses.replace(cal.options, runs=1)
    return cal


def _warn_if_runs_disagree(cal: object) -> None:
    """A loud warning naming what disagrees when the independent runs do not pass the between-run check."""
    from fpm_sim.errors import FpmSimWarning

    check = getattr(cal, "runs_check", None)
    if check is None or check.passed:
        return
    names = ", ".join(check.bad_parameters) if check.bad_parameters else "none (the evidences or classes differ)"
    warnings.warn(
        f"the {len(check.seeds)} independent runs DISAGREE: this posterior depends on the run ("
        + "; ".join(check.failures)
        + f"). Parameters whose quantiles disagree: {names}. Use "
        + (
            "more particles (--particles, --cheap-particles)"
            if getattr(getattr(cal, "options", None), "sampler", "dynesty") == "smc"
            else "more live points (--live-points)"
        )
        + " or more runs (--runs) before trusting it",
        FpmSimWarning,
        stacklevel=1,
    )


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="Bayesian calibration: a posterior over the unknowns from measured frequencies (nested sampling)",
        description="Samples the posterior of the free parameter groups of a description given measured natural "
        "frequencies (and rig tests), priors from a TOML file (one distribution per free parameter, each with its "
        "reason; the study's statements as soft likelihood terms) and a Gaussian likelihood with a relative "
        "model-discrepancy term (independent, or a Gaussian process over the pose with [likelihood.length_scale_m]; "
        "with [likelihood.mode_read] the mode behind each measured first frequency is latent), by nested sampling "
        "(dynesty). Writes OUT/posterior.nc (ArviZ), OUT/report.md (diagnostics, evidence, leave-one-out checks), "
        "OUT/config.toml (the posterior median) and figures; checkpoints to OUT/checkpoint.dynesty.* (--resume). "
        "The elbow-branch classes, when free, are each sampled on their own and weighted by their evidences; "
        "each is sampled --runs times and the runs are checked against each other "
        "(printed, in report.md and --json; a warning names what disagrees). On a described architecture "
        "(--config machine.toml with [[chains]]): priors on dotted paths into its file, one measured file in its "
        "task coordinates (x_mm, y_mm, z_mm, phi_rad as it has them; f1_hz, f2_hz, ...; sigma_hz), each fK_hz "
        "compared with its K-th lowest elastic mode (actuators locked), one class (its working modes are fixed); "
        "writes OUT/description.toml (the posterior median) in place of config.toml (docs/architectures.md). On an "
        "imported model (kind = 'imported'): the same, its measured file with one column per joint or per task "
        "coordinate of its [end_effector] (docs/import.md).",
    )
    add_data_args(p)
    p.add_argument(
        "--priors",
        type=Path,
        default=None,
        help="priors TOML (e.g. fpm_sim/data/study_priors.toml; required on the 3RRR); on a described architecture "
        'its [parameters."PATH"] tables name dotted paths into its file',
    )
    add_config_args(p)
    p.add_argument(
        "--free",
        default=None,
        help=f"comma-separated parameter groups: {', '.join(GROUPS)} (default {DEFAULT_FREE}); on a described "
        "architecture or an imported model dotted paths into its file, PATH (its prior in --priors) or PATH=lo:hi "
        "(uniform between them; default: every path --priors names)",
    )
    _add_sampler_args(p)
    p.add_argument("--draws", type=int, default=1000, help="equal-weight draws written to posterior.nc (default 1000)")
    p.add_argument("--thin", type=int, default=0, help="also write posterior_thin.nc with this many draws (0: no)")
    p.add_argument("--segments", type=int, default=4, help="spring locations per link of the model (default 4)")
    likelihood_workers = WORKERS_HELP.replace("for the pose loop", "evaluating the likelihood")
    p.add_argument("--workers", type=int, default=None, help=likelihood_workers)
    p.add_argument("--seed", type=int, default=0, help="seed of the first run; run r has seed + r (default 0)")
    p.add_argument(
        "--runs",
        type=int,
        default=3,
        help="independent runs per elbow-branch class (seeds SEED, SEED+1, ...), merged and checked against each "
        "other: ln Z within 3 sigma, each parameter's 5/50/95 %% quantiles within 0.5 posterior sd (or "
        "3 sigma of their Monte Carlo error where larger), every class a "
        "run weights above 1 %% present in the merged posterior (default 3; 1: no check)",
    )
    p.add_argument(
        "--resume",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="continue from OUT/checkpoint.dynesty (or rewrite the outputs of a finished run)",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder")
    add_overwrite_arg(p)
    p.add_argument("--quiet", action=argparse.BooleanOptionalAction, default=False, help="no progress line")
    add_output_args(p)
    p.set_defaults(func=cmd_calibrate)


def _add_sampler_args(p: argparse.ArgumentParser) -> None:
    """The sampler and its settings (nested sampling's and the SMC's)."""
    p.add_argument(
        "--sampler",
        default="dynesty",
        choices=("dynesty", "smc"),
        help="dynesty (default): nested sampling (--live-points, --dlogz, --sample, --walks, --max-calls). smc: "
        "two-stage tempered sequential Monte Carlo, first the prior times the study's statements (cheap: "
        "--cheap-particles), then the data (--particles); every run reaches the statements' region, but its runs "
        "still disagree on the study (docs/identification.md)",
    )
    p.add_argument(
        "--particles", type=int, default=400, help="smc: particles of the data stage of each run (default 400)"
    )
    p.add_argument(
        "--cheap-particles",
        type=int,
        default=2000,
        help="smc: particles of the first stage (the prior times the statements; default 2000)",
    )
    p.add_argument(
        "--emulator",
        type=int,
        default=0,
        help="smc: the data stage on an emulator of the segment model trained on this many segment-model runs at "
        "the first stage's particles and as many at the data stage's (500 measured), then importance-weighted to "
        'the segment model, exact (docs/identification.md, "An emulator of '
        "the segment model\"); each run prints its weights' effective sample size and Pareto k. 0 (default): the "
        "segment model throughout. A run whose weights are heavy (Pareto k >= 0.7) samples its data stage once "
        "more on a refit with every segment-model run so far",
    )
    p.add_argument(
        "--ess-fraction",
        type=float,
        default=0.5,
        help="smc: each tempering step keeps this fraction of the particles as effective sample size (default 0.5; "
        "0.9 with --moves 10: runs that agree better on the study, at about 4 times the time: "
        "docs/identification.md)",
    )
    p.add_argument(
        "--moves",
        type=float,
        default=3.0,
        help="smc: accepted Metropolis moves per particle after each tempering step of the data stage (default 3)",
    )
    _add_smc_move_args(p)
    p.add_argument(
        "--live-points", type=int, default=250, help="dynesty: nested sampling live points of each run (default 250)"
    )
    p.add_argument(
        "--dlogz", type=float, default=0.5, help="stop when the remaining evidence is below this (default 0.5)"
    )
    p.add_argument(
        "--sample",
        default="rwalk",
        choices=("rwalk", "rslice", "unif"),
        help="dynesty's proposal (default rwalk: random walks, robust in 10-20 dimensions)",
    )
    p.add_argument(
        "--walks", type=int, default=None, help="rwalk: steps per random walk (default: dynesty's, 20 + dimensions)"
    )
    p.add_argument(
        "--max-calls", type=int, default=None, help="stop each run after this many likelihood calls (not converged)"
    )


def _add_smc_move_args(p: argparse.ArgumentParser) -> None:
    """The SMC's moves beyond the tempering's, its islands and its importance sampling."""
    p.add_argument(
        "--jumps",
        type=float,
        default=0.0,
        help="smc: the fraction of the data stage's sweeps whose proposals are draws of a Gaussian mixture fitted to "
        "the particles, so that they move between modes in proportion to the posterior's mass (default 0: none)",
    )
    p.add_argument(
        "--crossover",
        action="store_true",
        help="smc: each Metropolis move of the data stage in a random subspace of the parameters (DREAM's crossover), "
        "so that loose parameters travel at their own width (default: all parameters at once)",
    )
    p.add_argument(
        "--islands",
        type=int,
        default=1,
        help="smc: independent islands of each run, each of --particles and --cheap-particles; the run's ln Z error "
        "and its quantiles' Monte Carlo errors are read from their spread (default 1: the particles' genealogy's; "
        "docs/identification.md)",
    )
    p.add_argument(
        "--importance",
        type=int,
        default=0,
        help="smc: independent draws of a mixture fitted to the data stage's particles, whose importance weights give "
        "each run's evidence and posterior with an error of their own (default 0: the tempering's; on the study's 23 "
        "parameters 20000 draws gave an ESS of tens: docs/identification.md)",
    )
    p.add_argument(
        "--final-moves",
        type=float,
        default=0.0,
        help="smc: accepted Metropolis moves per particle on the posterior after the data stage's last tempering "
        "step, letting the particles travel along a ridge (default 0: none)",
    )
