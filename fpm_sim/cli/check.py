"""``fpm-sim check``: evaluate a requirements file (``fpm-requirements.toml``) on a description.

Prints a table (requirement, worst pose, mode, margin, pass/fail), or JSON with ``--json``; writes JUnit XML
with ``--junit-xml`` (atomically) and a margin chart with ``--plot``. Exit 0 when every requirement passes,
1 when one fails, 2 for bad input (one ``error:`` line).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.cli.common import CliError, add_config_args, add_output_args, check_output_file, emit

__all__ = ["cmd_check", "register"]


def cmd_check(args: argparse.Namespace) -> int:
    from fpm_sim.cli.common import load_machine
    from fpm_sim.study.requirements import check_requirements, load_requirements

    check_output_file(args.junit_xml, "--junit-xml", (".xml",))
    check_output_file(args.plot, "--plot", (".png", ".pdf", ".svg"))
    if args.segments is not None and args.segments < 1:
        raise CliError(f"--segments must be >= 1, got {args.segments}")
    reqs = load_requirements(args.file)
    if args.config is None and reqs.config is not None:
        args.config = reqs.config
    machine = load_machine(args, "check")
    report = check_requirements(reqs, machine, segments=args.segments)
    notes = []
    if args.junit_xml:
        report.write_junit(args.junit_xml)
        notes.append(f"wrote {args.junit_xml}")
    if args.plot:
        from fpm_sim.cli.main import save_figure

        save_figure(args.plot, report.plot)
        notes.append(f"wrote {args.plot}")
    emit(args, report.to_dict(), report.table() + "".join(f"\n{n}" for n in notes))
    return 0 if report.passed else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="check frequency requirements (fpm-requirements.toml): exit 1 when one fails",
        description="Evaluates each requirement of FILE (min_frequency, band_exclusion, match_measurements; see "
        "docs/testing.md) on the description and prints the worst pose, mode and margin of each. Exit status: 0 "
        "all pass, 1 a requirement fails, 2 bad input. Requirements with the same poses, payload and resolution "
        "share one sweep.",
    )
    p.add_argument("file", type=Path, help="requirements file (TOML), e.g. fpm-requirements.toml")
    add_config_args(p)
    p.add_argument(
        "--segments",
        type=int,
        default=None,
        help="resolution per link for every requirement (overrides the file's settings.segments)",
    )
    p.add_argument("--junit-xml", type=Path, default=None, help="write a JUnit XML report (one test per requirement)")
    p.add_argument("--plot", type=Path, default=None, help="save a chart of the margins (.png, .pdf, .svg)")
    add_output_args(p)
    p.set_defaults(func=cmd_check)
