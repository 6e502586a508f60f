"""``fpm-sim readability``: mode-1 readability in a hammer test at the study's 25 poses."""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.cli.common import (
    add_config_args,
    add_output_args,
    add_resolution_args,
    check_output_file,
    emit,
    load_manipulator,
    model_options,
    with_resolution,
)
from fpm_sim.cli.frf import add_point_args, point_of
from fpm_sim.cli.impact import STUDY_POINT
from fpm_sim.cli.main import PLOT_SUFFIXES, save_figure

__all__ = ["register"]


def cmd_readability(args: argparse.Namespace) -> int:
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.study.readability import readability_table

    check_output_file(args.markdown, "--markdown", (".md",))
    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    # gravity off, as reproduce's pose loop and its readability tables: the same f1 at every study pose (with
    # gravity's prestress f1 differs near singularities, e.g. 0.81 instead of 0.68 Hz at (-100, 50))
    opts = model_options(args, gravity=False)
    warn_if_coarse(opts)
    manip = load_manipulator(args)
    tab = readability_table(
        manip,
        options=opts,
        point=point_of(args, "point", STUDY_POINT),
        row_is=args.row_is,
        phi_sign=1 if args.phi_sign == "+" else -1,
        f_max_hz=args.f_max_hz,
        damping_ratio=args.damping_ratio,
        progress=not args.json,
    )
    if args.plot:
        save_figure(args.plot, tab.plot)
    if args.markdown:
        with atomic_file(args.markdown) as tmp:
            tmp.write_text(tab.to_markdown() + "\n")
    payload = with_resolution(tab.to_dict(), opts)
    payload["markdown"] = str(args.markdown) if args.markdown else None
    payload["plot"] = str(args.plot) if args.plot else None
    wrote = "".join(f"\nwrote {f}" for f in (args.markdown, args.plot) if f)
    emit(args, payload, tab.table() + wrote)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "readability",
        help="how readable mode 1 is in a driving-point hammer test at the study's 25 poses (vs its 7 unreadable)",
        description=(
            "For each study pose: mode 1's frequency and character, its share of the driving-point modal constants, "
            "its FRF peak height and prominence (same point on each chain's distal link), a readable/unreadable "
            "prediction from assumed thresholds, and the agreement with the study's seven unreadable poses (AUC)."
        ),
    )
    add_point_args(p, "point", "hammer and accelerometer (driving point)", STUDY_POINT)
    p.add_argument("--row-is", choices=("x", "y"), default="x", help="the table's row label is x (default) or y")
    p.add_argument("--phi-sign", choices=("+", "-"), default="+", help="sign of the 0.2 rad rotation (default +)")
    p.add_argument("--f-max-hz", type=float, default=500.0, help="FRF band (Hz, default 500)")
    p.add_argument("--damping-ratio", type=float, help="modal damping ratio for every mode (default: the model's)")
    add_resolution_args(p, axial=False)
    p.add_argument("--markdown", type=Path, help="write the markdown table (.md) for the reproduce report")
    p.add_argument("--plot", type=Path, help="prominence map over the poses (.png, .pdf, .svg)")
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_readability)
