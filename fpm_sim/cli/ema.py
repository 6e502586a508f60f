"""``fpm-sim ema``: natural frequencies and damping from measured FRFs (UFF 58 or CSV), for ``identify``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fpm_sim.cli.common import CliError, add_output_args, add_overwrite_arg, check_output_dir, emit

__all__ = ["cmd_ema", "register"]

MODE_LABELS = ("in_plane", "out_of_plane")
""":data:`fpm_sim.study.identify.data.MODE_LABELS`, listed here so that building the parser imports neither
MuJoCo nor SciPy (a test checks they agree)."""


def cmd_ema(args: argparse.Namespace) -> int:
    from fpm_sim.outputs import atomic_dir
    from fpm_sim.results import to_jsonable
    from fpm_sim.study.identify.ema import estimate_modes, read_frfs, write_modes_csv

    check_output_dir(args.out, "--out", overwrite=args.overwrite)
    if not 0 <= args.f_lower_hz < args.f_upper_hz:
        raise CliError(f"--f-lower-hz {args.f_lower_hz} must be >= 0 and below --f-upper-hz {args.f_upper_hz}")
    if args.n_modes < 1:
        raise CliError(f"--n-modes must be >= 1, got {args.n_modes}")
    if args.exp_window_tau_s is not None and not args.exp_window_tau_s > 0:
        raise CliError(f"--exp-window-tau-s must be > 0 s (inf: no window), got {args.exp_window_tau_s}")
    given = (args.x_mm, args.y_mm, args.phi_rad)
    estimates = []
    for path in args.files:
        for frf in read_frfs(path):
            if frf.pose_mm_rad is None:
                if None in given[:2]:
                    raise CliError(f"{frf.source}: the file does not say where it was measured; give --x-mm and --y-mm")
                frf.pose_mm_rad = (float(given[0]), float(given[1]), float(given[2] or 0.0))
            est = estimate_modes(
                frf,
                f_lower_hz=args.f_lower_hz,
                f_upper_hz=args.f_upper_hz,
                n_modes=args.n_modes,
                pol_order=args.pol_order,
                window_tau_s=args.exp_window_tau_s,
            )
            est.mode_label = args.mode_label
            estimates.append(est)
    taus = {f"{e.window_tau_s:.4g}" for e in estimates if e.window_tau_s is not None}
    header = (
        "Natural frequencies (Hz) and damping ratios estimated by fpm-sim ema (sdypy-EMA LSCF, stable poles "
        f"nearest the FRF peaks, {args.f_lower_hz:g}-{args.f_upper_hz:g} Hz, orders up to {args.pol_order}"
        + (f"; exponential window decay removed, tau {', '.join(sorted(taus))} s" if taus else "")
        + ").\n"
        "Columns as fpm-sim identify --measured reads them."
    )
    with atomic_dir(args.out, overwrite=True) as tmp:  # --out / --overwrite were checked before computing
        write_modes_csv(estimates, tmp / "modes.csv", header=header)
        (tmp / "ema.json").write_text(json.dumps(to_jsonable([e.to_dict() for e in estimates]), indent=1))
    lines = [
        f"{e.source} at {e.pose_mm_rad}: "
        + ", ".join(f"{f:.3f} Hz ({100 * z:.2f} %)" for f, z in zip(e.freq_hz, e.damping))
        + (f" (window tau {e.window_tau_s:.4g} s removed)" if e.window_tau_s is not None else "")
        + (f" (discrete integrator step {e.discrete_step_s:.4g} s removed)" if e.discrete_step_s is not None else "")
        for e in estimates
    ]
    lines.append(f"wrote {args.out / 'modes.csv'} (give it to fpm-sim identify --measured)")
    emit(args, {"estimates": [e.to_dict() for e in estimates], "csv": str(args.out / "modes.csv")}, "\n".join(lines))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ema",
        help="experimental modal analysis: natural frequencies and damping from FRFs (UFF 58 or CSV)",
        description="Reads FRFs (UFF type 58 via pyuff, or fpm-sim's FRF CSV), estimates poles with sdypy-EMA's LSCF "
        "and keeps the stable ones nearest the FRF peaks; writes OUT/modes.csv (the CSV fpm-sim identify reads) and "
        "OUT/ema.json.",
    )
    p.add_argument("files", nargs="+", type=Path, help="FRF files (.uff/.unv or .csv)")
    p.add_argument("--f-lower-hz", type=float, default=5.0, help="lower band edge (Hz, default 5)")
    p.add_argument("--f-upper-hz", type=float, default=500.0, help="upper band edge (Hz, default 500)")
    p.add_argument("--n-modes", type=int, default=3, help="modes per FRF, lowest peaks first (default 3)")
    p.add_argument("--pol-order", type=int, default=40, help="highest LSCF model order (default 40)")
    p.add_argument(
        "--mode-label",
        choices=MODE_LABELS,
        default=None,
        help="the kind of modes these FRFs see, written to the mode column (e.g. out_of_plane for a hammer and "
        "accelerometer along the motor axes): identify then matches the K-th estimate to the K-th model mode of "
        "that kind instead of the K-th lowest overall (default: unlabelled)",
    )
    p.add_argument(
        "--exp-window-tau-s",
        type=float,
        default=None,
        help="time constant (s) of the exponential response window the FRFs were computed with: its decay is "
        "removed from every pole, so damping and frequency are the structure's (default: what each UFF record says; "
        "fpm-sim impact --uff writes it; none when it says nothing; inf: no window)",
    )
    p.add_argument("--x-mm", type=float, default=None, help="pose of FRFs whose file does not carry one (mm)")
    p.add_argument("--y-mm", type=float, default=None, help="pose of FRFs whose file does not carry one (mm)")
    p.add_argument("--phi-rad", type=float, default=None, help="pose of FRFs whose file does not carry one (rad)")
    p.add_argument("--out", type=Path, required=True, help="output folder (written atomically)")
    add_overwrite_arg(p)
    add_output_args(p)
    p.set_defaults(func=cmd_ema)
