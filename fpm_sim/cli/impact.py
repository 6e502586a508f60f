"""``fpm-sim impact``: the virtual impact-hammer test (nonlinear rollouts, H1 over impacts, first peak)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import (
    CliError,
    add_config_args,
    add_joint_args,
    add_output_args,
    add_pose_args,
    add_resolution_args,
    build_machine,
    check_output_file,
    emit,
    is_imported,
    load_machine,
    model_options,
    resolution_line,
    with_resolution,
)
from fpm_sim.cli.frf import LinkPointDefault, add_point_args, point_of
from fpm_sim.cli.main import PLOT_SUFFIXES, save_figure
from fpm_sim.cli.rollout import add_stepping_args, stepping_kwargs

__all__ = ["register"]

STUDY_POINT = LinkPointDefault("distal_0", 0.5, "z")
"""The parser's default hammer point: :data:`fpm_sim.sim.impact.STUDY_IMPACT_POINT` (a test checks they agree)."""
PULSE_MS = 1.0
"""Default half-sine pulse (ms): :data:`fpm_sim.sim.impact.PULSE_S` (checked by a test)."""
PEAK_FORCE_N = 20.0
"""Default peak force (N): :data:`fpm_sim.sim.impact.PEAK_FORCE_N` (checked by a test)."""


def _check_uff(args: argparse.Namespace, machine: Any) -> None:
    """``--uff`` where its record cannot carry the pose: an imported model's (its joints), or one with z."""
    if args.uff and is_imported(args):
        raise CliError(
            "--uff: the UFF record carries a task pose in x, y and phi, and an imported model is posed by its joints; "
            "drop --uff (--csv writes the FRF)"
        )
    if args.uff and "z" in getattr(machine, "task", ()):
        raise CliError(
            f"--uff: the UFF record carries a pose in x, y and phi; {machine.name} sets z too; drop --uff (--csv "
            "writes the FRF)"
        )


def cmd_impact(args: argparse.Namespace) -> int:
    from fpm_sim.model.options import resolve_segments, warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.response import default_point
    from fpm_sim.sim.impact import ImpactSetup, virtual_impact_test

    check_output_file(args.csv, "--csv", (".csv",))
    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    check_output_file(args.uff, "--uff", (".uff", ".unv"))
    if not (math.isfinite(args.pulse_ms) and args.pulse_ms > 0):
        raise CliError(f"--pulse-ms: must be a positive pulse length (ms), got {args.pulse_ms:g}")
    if args.implicit_step_s is not None:
        top = min(ImpactSetup.sample_s, args.pulse_ms * 1e-4)  # the sampling interval; a tenth of the pulse
        if not 0.0 < args.implicit_step_s <= top:
            raise CliError(
                f"--implicit-step-s {args.implicit_step_s:g} must lie in (0, {top:g}] s: at most the "
                f"{ImpactSetup.sample_s * 1e3:g} ms sampling interval and a tenth of --pulse-ms"
            )
    stepping = stepping_kwargs(args)
    if args.integrator == "explicit" and args.implicit_step_s is not None:
        raise CliError("--implicit-step-s sets the discrete integrator's step; drop it with --integrator explicit")
    opts = model_options(args)
    segments = resolve_segments(segments=opts.segments, link_model=opts.link_model)  # ModelOptions resolved it
    if segments < 2:
        raise CliError(f"--segments must be >= 2 for flexible links, got {segments}")
    warn_if_coarse(opts)
    machine = load_machine(args, "impact")
    _check_uff(args, machine)
    built, pose_label = build_machine(args, machine, opts)
    hit = point_of(args, "impact", default_point(built))
    acc = point_of(args, "accel", hit)
    setup = ImpactSetup(
        impact=hit,
        accelerometer=acc,
        pulse_s=args.pulse_ms * 1e-3,
        peak_force_n=args.peak_force_n,
        n_impacts=args.impacts,
        record_s=args.record_s,
        noise_m_s2=args.noise_m_s2,
        seed=args.seed,
        f_max_hz=args.f_max_hz,
        timestep_s=args.implicit_step_s,
        integrator=stepping["integrator"],
        band_hz=stepping["band_hz"],
    )
    res = virtual_impact_test(built, setup, progress=not args.json)
    if args.csv:
        with atomic_file(args.csv) as tmp:
            res.frf.save_csv(tmp)
    if args.uff:
        from fpm_sim.sim.impact import write_uff58

        pose = built.parameters["pose"]
        with atomic_file(args.uff) as tmp:
            write_uff58(
                res.frf,
                tmp,
                pose_mm_rad=(pose["x_m"] * 1e3, pose["y_m"] * 1e3, pose["phi_rad"]),
                window_tau_s=res.window_tau_s,
                discrete_step_s=res.discrete_step_s,
            )
    if args.plot:
        save_figure(args.plot, res.plot)
    payload = with_resolution(res.to_dict(), opts)
    payload["csv"] = str(args.csv) if args.csv else None
    payload["plot"] = str(args.plot) if args.plot else None
    text = (
        f"pose {pose_label}, {opts.segments} segments, axial {opts.axial}, nv {built.model.nv}, "
        f"timestep {res.parameters['rollout_timestep_s']:.3g} s ({res.parameters['rollout_integrator']})\n"
        + res.table()
        + "\n"
        + resolution_line(opts)
        + "".join(f"\nwrote {f}" for f in (args.csv, args.uff, args.plot) if f)
    )
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "impact",
        help="virtual impact-hammer test: nonlinear rollouts, H1 FRF averaged over impacts, first peak vs modal f1",
        description=(
            f"Half-sine hammer pulses ({PULSE_MS:g} ms, {PEAK_FORCE_N:g} N peak by default) on the full nonlinear "
            "model from its static equilibrium; accelerometer signal with optional noise; H1 FRF averaged over the "
            "impacts (exponential window, zero padding); the first frequency by peak picking, compared with the "
            "modal f1 of the same model. Default point (assumed for the study): mid-span of chain 0's distal link, "
            "axis z (out of plane), hammer along the accelerometer axis; on a described architecture mid-span of "
            "the first chain's last flexible link, along the link frame's z; on an imported model (posed by --q "
            "and/or the pose options) mid-span of its first flexible body's beam, along its z."
        ),
    )
    add_point_args(p, "impact", "hammer", STUDY_POINT)
    add_point_args(p, "accel", "accelerometer (default: the hammer point and axis)", None)
    p.add_argument("--impacts", type=int, default=3, help="impacts averaged (default 3, as the study)")
    p.add_argument("--pulse-ms", type=float, default=PULSE_MS, help="half-sine pulse length (ms)")
    p.add_argument("--peak-force-n", type=float, default=PEAK_FORCE_N, help="peak hammer force (N)")
    p.add_argument("--record-s", type=float, default=0.5, help="record length per impact (s, default 0.5)")
    p.add_argument("--noise-m-s2", type=float, default=0.0, help="accelerometer noise standard deviation (m/s^2)")
    p.add_argument("--seed", type=int, default=0, help="random seed (force spread, noise)")
    p.add_argument("--f-max-hz", type=float, default=1000.0, help="top of the band searched for peaks (Hz)")
    p.add_argument(
        "--implicit-step-s",
        type=float,
        default=None,
        help="the discrete integrator's step (s) instead of the band's (--band-hz); it adds ~pi f h of damping to "
        "a mode at f, which the result and fpm-sim ema (from the UFF record) remove",
    )
    add_stepping_args(p)
    add_resolution_args(p, axial=False)
    p.add_argument(
        "--gravity", action=argparse.BooleanOptionalAction, default=True, help="gravity along the motor axes"
    )
    p.add_argument("--csv", type=Path, help="write the H1 FRF and coherence to this CSV")
    p.add_argument(
        "--uff",
        type=Path,
        help="write the H1 FRF as a Universal File type-58 record (for fpm-sim ema; it carries the pose, the "
        "exponential window's time constant and the discrete integrator's step, whose effects fpm-sim ema removes "
        "from the poles)",
    )
    p.add_argument("--plot", type=Path, help="H1 magnitude/phase/coherence plot (.png, .pdf, .svg)")
    add_pose_args(p)
    add_joint_args(p)
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_impact)
