"""``fpm-sim reduce``: a reduced-order state-space model at one pose, exported to .mat or .npz."""

from __future__ import annotations

import argparse
from pathlib import Path

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
    is_described,
    is_imported,
    load_machine,
    model_options,
    with_resolution,
)
from fpm_sim.cli.rollout import add_motor_args, apply_motor_args

__all__ = ["register"]


def cmd_reduce(args: argparse.Namespace) -> int:
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.outputs import atomic_file
    from fpm_sim.rom.reduction import reduce_model

    check_output_file(args.out, "--out", (".mat", ".npz"))
    if args.accel_fraction is not None and not 0.0 <= args.accel_fraction <= 1.0:
        raise CliError(f"--accel-fraction must be in 0..1 (from the link's start), got {args.accel_fraction}")
    if args.motors == "servo" and (is_described(args) or is_imported(args)):
        raise CliError(
            "--motors servo: a described architecture's actuated joints and an imported model's motors are locked in "
            "its reduced model (the motor-torque inputs are the 3RRR's motor hinges); drop --motors"
        )
    opts = model_options(args)
    warn_if_coarse(opts)
    machine = load_machine(args, "reduce")
    built, pose_label = build_machine(args, apply_motor_args(machine, args), opts)
    rom = reduce_model(
        built,
        n_modes=args.modes,
        band_hz=args.band_hz,
        error_bound=args.error_bound,
        static_correction=args.static_correction,
        accel_fraction=args.accel_fraction,
    )
    if args.out:
        with atomic_file(args.out) as tmp:
            rom.save(tmp)
    payload = with_resolution(rom.to_dict(), opts)
    payload["out"] = str(args.out) if args.out else None
    control_note = ""
    try:
        sys_ = rom.to_control()
        payload["python_control"] = type(sys_).__name__
        control_note = (
            f"\npython-control StateSpace: {sys_.nstates} states, {sys_.ninputs} inputs, {sys_.noutputs} outputs"
        )
    except ImportError:
        payload["python_control"] = None
        control_note = "\npython-control not installed (pip install 'fpm-sim[control]' for a StateSpace)"
    text = (
        f"reduced model at pose {pose_label}: {rom.n_modes} modes of "
        f"{rom.parameters['reduction']['n_modes_full']}, "
        f"static correction {rom.static_correction}, uncorrected static truncation error "
        f"{rom.parameters['reduction']['static_truncation_error']:.2e}\n"
        f"inputs:  {', '.join(f'{n} ({u})' for n, u in zip(rom.input_names, rom.input_units))}\n"
        f"outputs: {', '.join(f'{n} ({u})' for n, u in zip(rom.output_names, rom.output_units))}\n"
        + rom.table()
        + control_note
        + (f"\nwrote {args.out}" if args.out else "")
    )
    emit(args, payload, text)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reduce",
        help="reduced-order state-space model (modal truncation) at one pose; export .mat/.npz",
        description=(
            "Modal truncation in physical modal coordinates at the static equilibrium: A, B, C, D with inputs "
            "force_x, force_y (N), moment_z (N m) at the end effector and motor_torque_i (N m, servo motors only); "
            "outputs disp_x, disp_y (m), rot_z (rad) and acc_<link> (m/s^2) on each accelerometer link (the 3RRR's "
            "distal links; a described architecture's last flexible link of each chain; a spatial one has all six "
            "wrench and displacement components). An imported model (kind = 'imported', posed by --q and/or the "
            "pose options): all six at its [end_effector] site (else its last flexible body's beam end), an "
            "accelerometer on each flexible body's beam. Choose modes by --modes, --band-hz or --error-bound."
        ),
    )
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--modes", type=count_arg("--modes"), help="number of modes kept (1..200)")
    g.add_argument("--band-hz", type=float, help="keep every mode up to this frequency (Hz)")
    g.add_argument("--error-bound", type=float, help="fewest modes with relative static truncation error <= this")
    p.add_argument("--out", type=Path, help="output file, .mat (MATLAB) or .npz")
    p.add_argument(
        "--static-correction",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="feedthrough for the truncated modes (default on)",
    )
    p.add_argument(
        "--accel-fraction",
        type=float,
        default=0.5,
        help="accelerometer position on each accelerometer link (0..1 from its start: the 3RRR's elbow)",
    )
    add_motor_args(p)
    add_pose_args(p)
    add_joint_args(p)
    add_config_args(p)
    add_model_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_reduce)
