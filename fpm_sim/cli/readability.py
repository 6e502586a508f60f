"""``fpm-sim readability``: mode-1 readability in a hammer test at the study's 25 poses."""

from __future__ import annotations

import argparse
from pathlib import Path

from fpm_sim.cli.frf import add_point_args, frf_user_errors, point_of, save_figure
from fpm_sim.cli.main import add_config_args, add_output_args, emit, load_manipulator
from fpm_sim.frf import FrfError
from fpm_sim.model.options import ModelOptions
from fpm_sim.sim.impact import STUDY_IMPACT_POINT
from fpm_sim.study.readability import readability_table

__all__ = ["register"]


@frf_user_errors
def cmd_readability(args: argparse.Namespace) -> int:
    if args.markdown is not None and args.markdown.suffix != ".md":
        raise FrfError(f"--markdown {args.markdown} must end in .md")
    manip = load_manipulator(args)
    tab = readability_table(
        manip,
        options=ModelOptions(segments=args.segments, axial=args.axial),
        point=point_of(args, "point", STUDY_IMPACT_POINT),
        row_is=args.row_is,
        phi_sign=1 if args.phi_sign == "+" else -1,
        f_max_hz=args.f_max_hz,
        damping_ratio=args.damping_ratio,
        progress=not args.json,
    )
    if args.plot:
        save_figure(args.plot, lambda: tab.plot())
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(tab.to_markdown() + "\n")
    payload = tab.to_dict()
    payload["markdown"] = str(args.markdown) if args.markdown else None
    payload["plot"] = str(args.plot) if args.plot else None
    emit(args, payload, tab.table() + "".join(f"\nwrote {f}" for f in (args.markdown, args.plot) if f))
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
    add_point_args(p, "point", "hammer and accelerometer (driving point)", STUDY_IMPACT_POINT)
    p.add_argument("--row-is", choices=("x", "y"), default="x", help="the table's row label is x (default) or y")
    p.add_argument("--phi-sign", choices=("+", "-"), default="+", help="sign of the 0.2 rad rotation (default +)")
    p.add_argument("--f-max-hz", type=float, default=500.0, help="FRF band (Hz, default 500)")
    p.add_argument("--damping-ratio", type=float, help="modal damping ratio for every mode (default: the model's)")
    p.add_argument("--segments", type=int, default=6, help="spring locations per link (default 6)")
    p.add_argument("--axial", action="store_true", help="axial springs")
    p.add_argument("--markdown", type=Path, help="write the markdown table (.md) for the reproduce report")
    p.add_argument("--plot", type=Path, help="prominence map over the poses (.png, .pdf, .svg)")
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_readability)
