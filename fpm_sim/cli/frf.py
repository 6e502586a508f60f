"""``fpm-sim frf``: FRF of the linearised manipulator between two link points (table, CSV, plot)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_joint_args,
    add_model_args,
    add_output_args,
    add_pose_args,
    build_machine,
    check_output_file,
    count_arg,
    emit,
    load_machine,
    model_options,
    resolution_line,
    with_resolution,
)
from fpm_sim.cli.main import PLOT_SUFFIXES, save_figure

__all__ = ["LinkPointDefault", "add_point_args", "point_of", "register", "save_figure"]

AXES = ("normal", "along", "z", "x", "y")
"""Directions of a link point (checked against :data:`fpm_sim.response.AXES` by the tests; listed here so that
building the parser stays light)."""
QUANTITIES = ("receptance", "mobility", "accelerance")
"""FRF kinds (checked against :data:`fpm_sim.response.QUANTITIES` by the tests)."""


class LinkPointDefault:
    """A link point's defaults for the parser (link, fraction 0..1, axis), without importing :mod:`fpm_sim.response`."""

    def __init__(self, link: str = "distal_0", fraction: float = 0.5, axis: str = "z") -> None:
        self.link, self.fraction, self.axis = link, fraction, axis


def add_point_args(p: argparse.ArgumentParser, prefix: str, what: str, default: Any) -> None:
    """``--PREFIX-link``, ``--PREFIX-fraction``, ``--PREFIX-axis``; each not given is ``None`` and takes
    :func:`point_of`'s fallback (``default``: the 3RRR's, named in the help; ``None``: another point's)."""
    g = p.add_argument_group(what)
    d = default or LinkPointDefault()
    same = default is None
    g.add_argument(
        f"--{prefix}-link",
        default=None,
        help="the 3RRR's proximal_i, distal_i; a described architecture's <chain>_<link>; or platform (the end "
        "effector)" + (" (default: as the excitation)" if same else f" (default {d.link} on the 3RRR)"),
    )
    g.add_argument(
        f"--{prefix}-fraction",
        type=float,
        default=None,
        help="position along the link from its start, 0..1" + ("" if same else f" (default {d.fraction:g})"),
    )
    g.add_argument(
        f"--{prefix}-axis",
        choices=AXES,
        default=None,
        help="normal (in-plane, normal to the link), along, z (out of plane: the link frame's z), x, y"
        + ("" if same else f" (default {d.axis})"),
    )


def point_of(args: argparse.Namespace, prefix: str, fallback: Any = None) -> Any:
    from fpm_sim.response import LinkPoint

    key = prefix.replace("-", "_")
    fb = fallback or LinkPoint()
    link = getattr(args, f"{key}_link")
    frac = getattr(args, f"{key}_fraction")
    axis = getattr(args, f"{key}_axis")
    return LinkPoint(
        link=fb.link if link is None else link,
        fraction=fb.fraction if frac is None else frac,
        axis=fb.axis if axis is None else axis,
    )


def cmd_frf(args: argparse.Namespace) -> int:
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.response import default_point, frf_grid, modal_frf
    from fpm_sim.rom.reduction import modal_system

    frf_grid(args.f_min_hz, args.f_max_hz, args.df_hz, [])  # checks the band before any computation
    check_output_file(args.csv, "--csv", (".csv",))
    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    if args.link_model == "rigid":
        raise CliError(
            "an FRF needs flexible links: with rigid links and locked motors nothing moves; use --link-model segments"
        )
    machine = load_machine(args, "frf")
    opts = model_options(args)
    warn_if_coarse(opts)
    built, pose_label = build_machine(args, machine, opts)
    exc = point_of(args, "input", default_point(built))
    resp = point_of(args, "output", exc)
    exc.check(built, "input")
    resp.check(built, "output")
    system = modal_system(built)
    if args.damping_ratio is None and not (abs(system.xi.diagonal()) > 0.0).any():
        raise CliError(
            "--damping-ratio: the model has no damping (its FRF peaks would be infinite); give --damping-ratio "
            "(e.g. 0.01) or damping in the description"
        )
    freq = frf_grid(args.f_min_hz, args.f_max_hz, args.df_hz, system.frequencies_hz)
    frf = modal_frf(
        system,
        excitation=exc,
        response=resp,
        freq_hz=freq,
        quantity=args.quantity,
        damping_ratio=args.damping_ratio,
        n_modes=args.n_modes,
    )
    if args.csv:
        with atomic_file(args.csv) as tmp:
            frf.save_csv(tmp)
    if args.plot:
        save_figure(args.plot, frf.plot)
    payload = with_resolution(frf.to_dict(), opts)
    payload["damping"] = "model" if args.damping_ratio is None else args.damping_ratio
    payload["parameters"] = built.parameters
    payload["csv"] = str(args.csv) if args.csv else None
    payload["plot"] = str(args.plot) if args.plot else None
    lines = [
        f"pose {pose_label}, damping "
        + ("model" if args.damping_ratio is None else f"{args.damping_ratio:g} (all modes)"),
        frf.table(),
    ]
    lines.append(resolution_line(opts))
    lines += [f"wrote {f}" for f in (args.csv, args.plot) if f]
    emit(args, payload, "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "frf",
        help="frequency response function of the linearised model between two link points (CSV, plot)",
        description=(
            "Modal-superposition FRF (all constrained modes) at the static equilibrium from a unit force at a link "
            "point/direction to the response of a link point along an axis. Damping: the model's modal damping, or "
            "--damping-ratio for every mode (e.g. a value identified from a measured FRF)."
        ),
    )
    add_point_args(
        p,
        "input",
        "force input (default: the machine's test point: on the 3RRR distal_0 mid-span, z; on a described "
        "architecture mid-span of the first chain's last flexible link, z; on an imported model mid-span of its "
        "first flexible body's beam, z)",
        LinkPointDefault("distal_0", 0.5, "z"),
    )
    add_point_args(p, "output", "response (default: the input point and axis, a driving-point FRF)", None)
    p.add_argument(
        "--quantity", choices=tuple(QUANTITIES), default="accelerance", help="FRF kind (default accelerance)"
    )
    p.add_argument("--f-min-hz", type=float, default=1.0, help="lowest frequency (Hz, default 1)")
    p.add_argument("--f-max-hz", type=float, default=500.0, help="highest frequency (Hz, default 500)")
    p.add_argument("--df-hz", type=float, default=0.1, help="frequency step (Hz, default 0.1)")
    p.add_argument("--damping-ratio", type=float, help="modal damping ratio for every mode (default: the model's)")
    p.add_argument("--n-modes", type=count_arg("--n-modes"), help="sum over the lowest N modes only (default all)")
    p.add_argument("--csv", type=Path, help="write the FRF (re, im, magnitude, dB, phase) to this CSV")
    p.add_argument("--plot", type=Path, help="magnitude/phase plot (.png, .pdf, .svg)")
    add_pose_args(p)
    add_joint_args(p)
    add_config_args(p)
    add_model_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_frf)
