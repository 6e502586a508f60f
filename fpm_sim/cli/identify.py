"""``fpm-sim identify``: model updating from measured natural frequencies (and rig tests)."""

from __future__ import annotations

import argparse
import json
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
    load_manipulator,
    workers_of,
)
from fpm_sim.study.identify.parameters import GROUPS

__all__ = [
    "add_data_args",
    "cmd_identify",
    "parse_measured_arg",
    "read_data_args",
    "read_described_measured",
    "register",
]

GLOBAL_METHODS = ("auto", "de", "hybrid", "multistart", "surrogate-de", "staged", "none")
""":data:`fpm_sim.study.identify.GLOBAL_METHODS` (checked by a test)."""
DEFAULT_SIGMA_PCT = 2.0
""":data:`fpm_sim.study.identify.DEFAULT_SIGMA_PCT` (checked by a test)."""


def parse_measured_arg(text: str) -> tuple[Path, dict[str, str]]:
    """``FILE[,sigma_pct=P][,reading=x+]`` -> path and options."""
    parts = text.split(",")
    opts: dict[str, str] = {}
    for kv in parts[1:]:
        if "=" not in kv:
            raise CliError(f"--measured {text!r}: options after the file are key=value (sigma_pct=P, reading=x+)")
        k, v = kv.split("=", 1)
        if k not in ("sigma_pct", "reading"):
            raise CliError(f"--measured {text!r}: unknown option {k!r}; use sigma_pct= or reading=")
        opts[k] = v
    return Path(parts[0]), opts


def add_data_args(p: argparse.ArgumentParser) -> None:
    """``--measured``, ``--subsystems``, ``--reading``, ``--sigma-pct`` (read by :func:`read_data_args`)."""
    p.add_argument(
        "--measured",
        action="append",
        metavar="FILE[,sigma_pct=P][,reading=R]",
        help="measured frequencies (repeatable); sigma_pct: relative std of its values where no sigma_hz column "
        "(default --sigma-pct); reading: for row_mm,col_mm files. A described architecture takes one file in its "
        "task coordinates, an imported model one with a column per joint, or in its [end_effector]'s task "
        "coordinates (docs/import.md)",
    )
    p.add_argument("--subsystems", type=Path, help="rig tests CSV (rig,setting,experimental_hz), frees the rig group")
    p.add_argument("--reading", default=None, help="how to read row_mm,col_mm files: x+, x-, y+ or y-")
    p.add_argument(
        "--sigma-pct",
        type=float,
        default=DEFAULT_SIGMA_PCT,
        help=f"default relative std (%%) of a measured frequency (default {DEFAULT_SIGMA_PCT:g})",
    )


def read_data_args(args: argparse.Namespace) -> tuple[list[str], list[Any], list[Any]]:
    """``--free``, ``--measured`` (with ``--reading``, ``--sigma-pct``) and ``--subsystems`` -> the free groups
    (``rig`` added with rig tests), the data sets and the rig tests; no data at all is refused."""
    from fpm_sim.study.identify import read_measured_csv, read_subsystems_csv
    from fpm_sim.study.poses import parse_reading

    groups = [g.strip() for g in args.free.split(",") if g.strip()]
    if args.subsystems and "rig" not in groups:
        groups.append("rig")
    datasets = []
    for m in args.measured or []:
        path, file_opts = parse_measured_arg(m)
        rd_text = file_opts.get("reading", args.reading)
        reading = parse_reading(rd_text) if rd_text else None
        sigma = float(file_opts.get("sigma_pct", args.sigma_pct))
        datasets.append(read_measured_csv(path, reading=reading, sigma_pct=sigma))
    tests = read_subsystems_csv(args.subsystems) if args.subsystems else []
    if not any(ds.observations for ds in datasets) and not tests:
        raise CliError("no data: give --measured FILE.csv (repeatable) and/or --subsystems FILE.csv")
    return groups, datasets, tests


_STUDY_ONLY = {
    "subsystems": None,
    "workspace": None,
    "reading": None,
    "folds": 0,
    "global_method": "auto",
    "timoshenko": False,
    "workers": None,
    "jacobian": "fd",
    "pairing": "order",
}
"""Options of the 3RRR's identification (their defaults): on a described architecture they are refused by name."""


def read_described_measured(args: argparse.Namespace, desc: Any) -> Any:
    """``--measured FILE[,sigma_pct=P]`` of a described architecture: one file in its task coordinates
    (:func:`fpm_sim.study.identify.described.read_task_measured_csv`); of an imported model, one column per joint or
    per task coordinate of its ``[end_effector]`` (:func:`fpm_sim.study.identify.described.read_joint_measured_csv`)."""
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.study.identify.described import read_joint_measured_csv, read_task_measured_csv

    imported = isinstance(desc, ImportedDescription)
    columns = "one column per joint (or task coordinate)" if imported else "its task coordinates' columns"
    if len(args.measured or []) != 1:
        raise CliError(f"--measured: give one measured file ({columns}, f1_hz, ...)")
    path, file_opts = parse_measured_arg(args.measured[0])
    if "reading" in file_opts:
        raise CliError(f"--measured ...,reading=: the study's table form is the 3RRR's; give {columns}")
    read = read_joint_measured_csv if imported else read_task_measured_csv
    return read(path, desc, sigma_pct=float(file_opts.get("sigma_pct", args.sigma_pct)))


def _identify_described(args: argparse.Namespace) -> int:
    """``fpm-sim identify --config machine.toml --free PATH[=lo:hi],...``: bounded least squares of dotted paths into
    its file (:mod:`fpm_sim.study.identify.described`; an imported model's too, posed in joint space); writes the
    fitted file, identify.json and a figure."""
    import matplotlib.pyplot as plt

    from fpm_sim.architecture import description_toml
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.outputs import atomic_dir
    from fpm_sim.results import to_jsonable
    from fpm_sim.study.identify.described import identify_description, parse_free_paths

    for key, default in _STUDY_ONLY.items():
        if getattr(args, key, default) != default:
            flag = {"global_method": "--global"}.get(key, "--" + key.replace("_", "-"))
            raise CliError(
                f"{flag}: an option of the 3RRR's identification; a described architecture's is bounded least "
                f"squares of dotted paths from its file's values (docs/architectures.md); drop {flag}"
            )
    groups = [g.strip() for g in args.free.split(",") if g.strip()]
    if any("." not in g.partition("=")[0] for g in groups):
        raise CliError(
            f"--free {args.free}: the 3RRR's parameter groups; on a described architecture give dotted paths into "
            "its file, e.g. --free sections.bar.height_m,materials.steel.young_pa=150e9:250e9"
        )
    from fpm_sim.config import Manipulator

    desc = load_machine(args, "identify")
    assert not isinstance(desc, Manipulator)  # _identify_described runs on a described or imported file only
    free = parse_free_paths(args.free, desc)
    data = read_described_measured(args, desc)
    if args.segments < 1 or args.max_nfev < 1:
        raise CliError("--segments and --max-nfev must be >= 1")
    opts = ModelOptions(segments=args.segments, gravity=False, axial=False)
    result = identify_description(desc, data, free, options=opts, max_nfev=args.max_nfev)
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        (tmp / "description.toml").write_text(
            description_toml(result.fitted, header=f"{desc.name}, fitted by: {args.command_line}")
        )
        (tmp / "identify.json").write_text(json.dumps(to_jsonable(result.to_dict()), indent=2))
        fig = result.plot()
        fig.savefig(tmp / "identify.png", dpi=110)
        plt.close(fig)
    names = ("description.toml", "identify.json", "identify.png")
    text = result.table() + f"\n  wrote {', '.join(str(args.out / n) for n in names)}"
    emit(args, {"result": result.to_dict(), "out": str(args.out)}, text)
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    from fpm_sim.study.identify import (
        IdentifyOptions,
        Problem,
        cross_validate,
        identify,
        parameter_set,
    )
    from fpm_sim.study.identify.report import summary, write_identification

    check_output_dir(args.out, "--out", overwrite=args.overwrite)
    if is_described(args) or is_imported(args):
        return _identify_described(args)
    start = load_manipulator(args)
    groups, datasets, tests = read_data_args(args)
    observations = [o for ds in datasets for o in ds.observations]
    ps = parameter_set(start, groups)
    if any(p.subsystem for p in ps.parameters) and not tests:
        raise CliError("--free rig needs --subsystems FILE.csv (the rig parameters are seen only by rig tests)")
    args.workers = workers_of(args)
    _check_counts(args)
    opts = IdentifyOptions(
        segments=args.segments,
        global_method=args.global_method,
        n_starts=args.starts,
        staged_starts=args.staged_starts,
        n_refine=args.refine,
        refine_per_class=args.refine_per_class,
        de_strategy=args.de_strategy,
        generations=args.generations,
        popsize=args.popsize,
        surrogate_seeds=args.surrogate_seeds,
        seed=args.seed,
        max_nfev=args.max_nfev,
        workers=args.workers,
        timoshenko=args.timoshenko,
        jacobian=args.jacobian,
        pairing=args.pairing,
    )
    workspace = []
    if args.workspace is not None:
        from fpm_sim.batch.pose_loop import read_poses_csv

        workspace = read_poses_csv(args.workspace, parameter="workspace")
    if not 0.0 < args.min_singularity < 1.0:
        raise CliError(f"--min-singularity must be in (0, 1), got {args.min_singularity}")
    problem = Problem(
        ps,
        observations,
        tests,
        subsystem_sigma_pct=args.subsystem_sigma_pct,
        workspace=workspace,
        min_singularity=args.min_singularity,
    )
    result = identify(problem, options=opts, progress=not args.quiet)
    cv = None
    if args.folds:
        cv = cross_validate(result, folds=args.folds, max_nfev=args.cv_max_nfev, progress=not args.quiet)
    files = [ds.source + f" (sigma {ds.sigma_pct:g} % where not given)" for ds in datasets]
    if tests:
        files.append(f"{Path(args.subsystems).name} (rig tests, sigma {args.subsystem_sigma_pct:g} %)")
    command = args.command_line  # set by main(argv): the command that ran, also when run from Python
    data_note = ", ".join([ds.source for ds in datasets] + ([Path(args.subsystems).name] if tests else []))
    write_identification(args.out, result, cv, command=command, data_files=files, data_note=data_note)
    summ = summary(result, cv)
    emit(args, {"summary": summ, "result": result.to_dict(), "out": str(args.out)}, _summary_text(args, result, summ))
    return 0


def _check_counts(args: argparse.Namespace) -> None:
    """The identification's counts must be >= 1 (``--surrogate-seeds`` >= 0)."""
    counts = (
        ("--workers", args.workers),
        ("--segments", args.segments),
        ("--generations", args.generations),
        ("--popsize", args.popsize),
        ("--refine", args.refine),
        ("--refine-per-class", args.refine_per_class),
        ("--staged-starts", args.staged_starts),
    )
    for flag, value in counts:
        if value < 1:
            raise CliError(f"{flag} must be >= 1, got {value}")
    if args.surrogate_seeds < 0:
        raise CliError(f"--surrogate-seeds must be >= 0, got {args.surrogate_seeds}")


def _summary_text(args: argparse.Namespace, result: Any, summ: dict[str, Any]) -> str:
    """The result's table, the in-sample (and cross-validated) mean error per data source, what was written."""
    lines = [result.table()]
    for src, st in summ.items():
        i, c = st["in_sample"], st.get("cross_validated")
        lines.append(
            f"  {src}: in-sample mean |err| {i.get('mean_abs_pct', float('nan')):.2f} %"
            + (f", {args.folds}-fold CV {c.get('mean_abs_pct', float('nan')):.2f} %" if c else "")
        )
    lines.append(f"  wrote {args.out}/config.toml, identify.json, report.md, figures")
    return "\n".join(lines)


def register(sub: argparse._SubParsersAction) -> None:
    """Declare ``fpm-sim identify`` and its options.

    Long because: the command's options, declared one after another in the order ``--help`` lists them.
    """
    p = sub.add_parser(
        "identify",
        help="identify the manipulator from measured natural frequencies (model updating)",
        description="Fits the free parameter groups of a description to measured natural frequencies (CSV "
        "x_mm,y_mm,phi_rad,f1_hz,...[,sigma_hz][,mode] or the study's row_mm,col_mm form with --reading) and rig "
        "tests; global search then bounded least squares; writes OUT/config.toml (usable with --config), "
        "OUT/identify.json, OUT/report.md and figures. Only the data named here is used.",
    )
    add_data_args(p)
    add_config_args(p)
    p.add_argument(
        "--free",
        default="geometry,hardware",
        help=f"comma-separated parameter groups: {', '.join(GROUPS)} (default geometry,hardware)",
    )
    p.add_argument(
        "--workspace",
        type=Path,
        metavar="POSES.csv",
        help="poses (x_mm,y_mm,phi_rad) the machine is known to work at with its motors locked: descriptions "
        "under which one is unreachable or nearer a singularity than --min-singularity are penalised (prior "
        "knowledge; no frequency is read there)",
    )
    p.add_argument(
        "--min-singularity",
        type=float,
        default=0.05,
        help="smallest singularity measure accepted at a --workspace pose (default 0.05, the near-singularity "
        "warning's threshold)",
    )
    p.add_argument("--subsystem-sigma-pct", type=float, default=1.0, help="relative std (%%) of a rig test (default 1)")
    p.add_argument(
        "--global",
        dest="global_method",
        default="auto",
        choices=GLOBAL_METHODS,
        help="global exploration before the local refinement (default auto: staged for rich data, at least 3 "
        "data per free parameter, else de; staged: least squares with exact derivatives freeing masses and "
        "sections, then the collective geometry, then each chain's, from the start and prior samples; de: "
        "differential evolution on the full model; see docs/identification.md)",
    )
    p.add_argument(
        "--staged-starts",
        type=int,
        default=4,
        help="staged: starts, the start description and prior samples (default 4)",
    )
    p.add_argument("--generations", type=int, default=200, help="de: generations (default 200)")
    p.add_argument("--popsize", type=int, default=8, help="de: population per free parameter (default 8)")
    p.add_argument(
        "--surrogate-seeds",
        type=int,
        default=2,
        help="de: first-population members per elbow-branch combination seeded with that branch's in-plane "
        "surrogate geometry (default 2; 0 = a Sobol population only)",
    )
    p.add_argument("--starts", type=int, default=24, help="multistart: Latin-hypercube points (default 24)")
    p.add_argument("--refine", type=int, default=4, help="best global candidates refined locally (default 4)")
    p.add_argument(
        "--de-strategy",
        default="best1bin",
        choices=("best1bin", "rand1bin"),
        help="de: mutation strategy (default best1bin: around the best member; rand1bin: around a random one, "
        "keeps more basins alive)",
    )
    p.add_argument(
        "--refine-per-class",
        type=int,
        default=1,
        help="de: final-population members per elbow-branch class that are refinement candidates, class "
        "leaders first (default 1)",
    )
    p.add_argument(
        "--max-nfev", type=int, default=30, help="local least squares: max residual evaluations (default 30)"
    )
    p.add_argument(
        "--jacobian",
        choices=("fd", "exact"),
        default="fd",
        help="local least squares' Jacobian: fd (finite differences of the frequencies, default) or exact (the "
        "eigen-solve's sensitivities, geometry included)",
    )
    p.add_argument(
        "--pairing",
        choices=("order", "frequency"),
        default="order",
        help="pair a pose's measured modes with the model's by order (fK = K-th lowest, default) or by frequency "
        "(the assignment problem: a model mode the file did not measure does not shift the others)",
    )
    p.add_argument("--folds", type=int, default=0, help="k-fold cross-validation over poses (0 = none)")
    p.add_argument("--cv-max-nfev", type=int, default=10, help="per-fold refit budget (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the global search and the folds (default 0)")
    p.add_argument("--segments", type=int, default=4, help="spring locations per link of the fitted model (default 4)")
    p.add_argument("--workers", type=int, default=None, help=WORKERS_HELP)
    p.add_argument(
        "--timoshenko",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="links as Timoshenko beams (shear + rotary inertia)",
    )
    p.add_argument("--out", type=Path, required=True, help="output folder (written atomically)")
    add_overwrite_arg(p)
    p.add_argument("--quiet", action=argparse.BooleanOptionalAction, default=False, help="no progress lines")
    add_output_args(p)
    p.set_defaults(func=cmd_identify)
