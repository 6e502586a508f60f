"""``fpm-sim reproduce``: the study's subsystem tests and 25 poses, with a report and figures."""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.batch.frequencies import BACKENDS
from fpm_sim.batch.pose_loop import FAST_SEGMENTS, fast_options
from fpm_sim.cli.design import add_engine_args, engine_options, finish_store
from fpm_sim.cli.main import add_config_args, add_output_args, emit, load_manipulator
from fpm_sim.study.poses import parse_reading
from fpm_sim.study.reproduce import reproduce_study

__all__ = ["register", "cmd_reproduce", "add_study_args", "study_manipulator"]


def add_study_args(p: argparse.ArgumentParser) -> None:
    """Options shared by ``reproduce`` and ``sweep``."""
    p.add_argument(
        "--reading",
        default="x+",
        help="how to read the study's table: x+, x-, y+ or y- (rows are x or y; sign of the 0.2 rad turn); default x+",
    )
    p.add_argument("--thickness-mm", type=float, help="in-plane link thickness (mm); the study: 30, 10, 5")
    p.add_argument(
        "--segments", type=int, default=FAST_SEGMENTS, help=f"spring locations per link (default {FAST_SEGMENTS})"
    )
    p.add_argument("--axial", action="store_true", help="add axial springs (extensible links; slower)")
    p.add_argument("--workers", type=int, default=2, help="processes for the pose loop (default 2)")
    p.add_argument(
        "--backend",
        default="cpu",
        help="pose-loop backend: cpu (scipy per pose, --workers processes) or mjx (all poses in one batched JAX "
        "computation; compiles once, seconds); default cpu",
    )


def study_manipulator(args: argparse.Namespace):  # noqa: ANN201
    """The manipulator of ``--config`` with ``--thickness-mm`` applied; raises ValueError on bad values."""
    manip = load_manipulator(args)
    if args.thickness_mm is not None:
        if not args.thickness_mm > 0:
            raise ValueError(f"--thickness-mm must be > 0, got {args.thickness_mm}")
        manip = manip.with_section(thickness_m=args.thickness_mm * 1e-3)
        manip = manip.replace(name=f"{manip.name} [links {args.thickness_mm:g} mm in-plane]")
    return manip


def cmd_reproduce(args: argparse.Namespace) -> int:
    import sys

    try:
        reading = parse_reading(args.reading)
        manip = study_manipulator(args)
        opts = fast_options(segments=args.segments, axial=args.axial)
        if args.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {args.workers}")
        if args.backend not in BACKENDS:
            raise ValueError(f"unknown --backend {args.backend!r}; available: {', '.join(sorted(BACKENDS))}")
    except ValueError as exc:
        print(f"fpm-sim: error: {exc}", file=sys.stderr)
        return 2
    rep = reproduce_study(
        manip,
        reading=reading,
        options=opts,
        backend=args.backend,
        workers=args.workers,
        progress=True,
        engine=engine_options(args, args.out) if args.backend == "cpu" else None,
    )
    paths = rep.write(args.out)
    finish_store(args.out)
    st = rep.stats()
    lines = [rep.config.name, f"reading {reading.name}", ""]
    lines.append(f"{'test':<22}{'measured':>10}{'COMSOL':>10}{'fpm-sim':>10}{'err %':>8}")
    for s in rep.subsystems:
        lines.append(
            f"{s.test.label:<22}{s.test.experimental_hz:>10g}{s.test.comsol_hz:>10g}{s.ours_hz:>10.2f}{s.error_pct:>+8.2f}"
        )
    lines.append("")
    lines.append(f"{'row':>5}{'col':>6}{'x':>7}{'y':>7}{'phi':>6}{'f1 Hz':>9}{'COMSOL':>9}{'diff %':>8}")
    for row in rep.rows():
        c = row["comsol_hz"]
        d = f"{100 * (row['f1_hz'] / c - 1):+8.1f}" if c == c else f"{'-':>8}"
        cs = f"{c:9.2f}" if c == c else f"{'-':>9}"
        lines.append(
            f"{row['row_mm']:>5g}{row['col_mm']:>6g}{row['x_mm']:>7g}{row['y_mm']:>7g}{row['phi_rad']:>6.1f}"
            f"{row['f1_hz']:>9.2f}{cs}{d}"
        )
    if st.get("n"):
        lines.append(
            f"\nvs COMSOL ({st['n']} poses): mean |err| {st['mean_abs_pct']:.2f} %, "
            f"median {st['median_abs_pct']:.2f} %, "
            f"max {st['max_abs_pct']:.2f} %, Spearman {st['spearman']:.3f}"
        )
    lines.append("wrote " + ", ".join(str(p) for p in paths))
    payload = rep.to_dict()
    payload["files"] = [str(p) for p in paths]
    emit(args, payload, "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce the study: subsystem tests, the 25 poses vs COMSOL, report and figures",
        description="Runs the study's single-link and chain tests and its 25 poses on a manipulator description "
        "and writes OUT/poses.csv, OUT/report.md and figures.",
    )
    add_config_args(p)
    add_study_args(p)
    add_engine_args(p)
    p.add_argument("--out", type=Path, default=Path("out/reproduce"), help="output folder (default out/reproduce)")
    add_output_args(p)
    p.set_defaults(func=cmd_reproduce)
