"""``fpm-sim`` command line. Each sub-command prints a table, or JSON with ``--json``.

Commands live in modules that expose ``register(subparsers)``; :data:`COMMAND_MODULES` lists them.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim import __version__
from fpm_sim.config import ConfigError, Manipulator, default_config, default_config_text, load_config
from fpm_sim.kinematics import Pose, SingularPoseError, UnreachablePoseError
from fpm_sim.linear.analysis import ModalComparison, analyse
from fpm_sim.linear.modal import ModalResult
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import BuiltModel, ModelOptions, TimestepError
from fpm_sim.model.parts import DEFAULT_RESOLUTION, LINK_MODELS, LinkModelError
from fpm_sim.model.rigs import RIGS, RigError, RigSetup, build_rig, rig_piece
from fpm_sim.results import to_jsonable

__all__ = ["main", "COMMAND_MODULES"]

COMMAND_MODULES: list[str] = [
    "fpm_sim.cli.reproduce",
    "fpm_sim.cli.sweep",
    "fpm_sim.cli.rollout",
    "fpm_sim.cli.reduce",
    "fpm_sim.cli.transient",
    "fpm_sim.cli.frf",
    "fpm_sim.cli.impact",
    "fpm_sim.cli.readability",
    "fpm_sim.cli.atlas",
    "fpm_sim.cli.identify",
    "fpm_sim.cli.ema",
]
"""Command modules beyond the core ones (each exposes ``register(subparsers)``)."""

_USER_ERRORS = (
    ConfigError,
    UnreachablePoseError,
    SingularPoseError,
    LinkModelError,
    RigError,
    TimestepError,
    FileNotFoundError,
)


# ---------------------------------------------------------------------------------------------
# shared option groups


def add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, help="manipulator TOML file (default: the embedded study prototype)")


def add_model_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("model")
    g.add_argument(
        "--link-model",
        default="segments",
        help=f"link model: {', '.join(LINK_MODELS)} (default segments; see docs/link_models.md)",
    )
    g.add_argument(
        "--segments",
        type=int,
        default=None,
        help=f"resolution per link: spring locations (segments), elastic joints (cable) or flex edges (flex); "
        f"default per model {DEFAULT_RESOLUTION}",
    )
    g.add_argument("--no-axial", action="store_true", help="inextensible links (no axial springs; faster)")
    g.add_argument("--rotary-inertia", action="store_true", help="include section rotary inertia (Rayleigh beam)")
    g.add_argument("--no-gravity", action="store_true", help="switch gravity (along the motor axes) off")
    g.add_argument("--timestep-s", type=float, default=None, help="simulation step (default: automatic)")


def add_pose_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("pose")
    g.add_argument("--x-mm", type=float, default=0.0, help="end-effector x (mm)")
    g.add_argument("--y-mm", type=float, default=0.0, help="end-effector y (mm)")
    g.add_argument("--phi-rad", type=float, default=0.0, help="end-effector rotation (rad)")


def add_output_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def load_manipulator(args: argparse.Namespace) -> Manipulator:
    return load_config(args.config) if getattr(args, "config", None) else default_config()


def model_options(args: argparse.Namespace) -> ModelOptions:
    return ModelOptions(
        link_model=args.link_model,
        segments=args.segments,
        axial=not args.no_axial,
        rotary_inertia=args.rotary_inertia,
        gravity=not args.no_gravity,
        timestep_s=args.timestep_s,
    )


def pose_of(args: argparse.Namespace) -> Pose:
    return Pose.from_mm(args.x_mm, args.y_mm, args.phi_rad)


def emit(args: argparse.Namespace, payload: dict[str, Any], text: str) -> None:
    if args.json:
        print(json.dumps(to_jsonable(payload), indent=2))
    else:
        print(text)


def _result_payload(result: ModalResult | ModalComparison, n_modes: int) -> tuple[dict[str, Any], str]:
    if isinstance(result, ModalComparison):
        a, b = result.transition_fd, result.constrained
        payload = a.to_dict(n_modes)
        payload["cross_check"] = {
            "method": "constrained",
            "modes": b.to_dict(n_modes)["modes"],
            "relative_difference": result.relative_differences(n_modes),
        }
        lines = [f"{'mode':>4}  {'transitionFD (Hz)':>17}  {'constrained (Hz)':>16}  {'diff':>8}  {'damping':>8}"]
        for i, d in enumerate(result.relative_differences(n_modes)):
            lines.append(
                f"{i + 1:>4}  {a.modes[i].frequency_hz:>17.3f}  {b.modes[i].frequency_hz:>16.3f}  {d:>8.2e}  "
                f"{a.modes[i].damping_ratio:>8.4f}"
            )
        return payload, "\n".join(lines)
    return result.to_dict(n_modes), result.table(n_modes)


def _header(built: BuiltModel, title: str) -> str:
    p = built.parameters
    return (
        f"{title}\n  nv = {p['nv']}, timestep = {p['timestep_s']:.3g} s, link model = {p['options']['link_model']}"
        + (f" ({p['options']['segments']} segments)" if p["options"]["link_model"] != "rigid" else "")
    )


# ---------------------------------------------------------------------------------------------
# commands


def _shapes_and_plot(args: argparse.Namespace, result: ModalResult | ModalComparison, payload: dict[str, Any]) -> str:
    """Add Cartesian mode shapes to the payload (``--shapes``) and save a figure (``--plot``)."""
    primary = result.transition_fd if isinstance(result, ModalComparison) else result
    note = ""
    if args.shapes:
        n = min(args.n_modes, len(primary.modes))
        for i, mode_payload in enumerate(payload["modes"][:n]):
            disp = primary.point_displacements(i)
            peak = max(float(np.max(np.linalg.norm(d, axis=1))) for d in disp.values()) or 1.0
            mode_payload["points_displacement"] = {k: (v / peak).tolist() for k, v in disp.items()}
        payload["points_position_m"] = {k: v.tolist() for k, v in primary.point_positions().items()}
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        n = min(args.n_modes, len(primary.modes), 6)
        fig = plt.figure(figsize=(4.5 * n, 4.5))
        for i in range(n):
            primary.plot(i, ax=fig.add_subplot(1, n, i + 1, projection="3d"))
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        plt.close(fig)
        note = f"\nmode shapes plotted to {args.plot}"
    return note


def cmd_modes(args: argparse.Namespace) -> int:
    manip = load_manipulator(args)
    pose = pose_of(args)
    built = build_manipulator(manip, pose, model_options(args))
    result = analyse(built, args.method, args.n_modes)
    payload, table = _result_payload(result, args.n_modes)
    payload["config"] = manip.name
    payload["manipulator"] = manip.to_dict()
    note = _shapes_and_plot(args, result, payload)
    text = _header(built, f"{manip.name}\n  pose {pose.label()}") + "\n" + table + note
    emit(args, payload, text)
    return 0


def _rig_setup(args: argparse.Namespace, manip: Manipulator) -> RigSetup:
    return RigSetup(args.rig, angle_deg=args.angle_deg, damping_beta_s=args.damping_beta_s)


def _rig_piece(args: argparse.Namespace, manip: Manipulator):  # noqa: ANN202
    return rig_piece(
        manip,
        length_m=args.length_m,
        thickness_m=args.thickness_m,
        height_m=args.height_m,
        young_pa=args.young_pa,
        poisson=args.poisson,
        density_kg_m3=args.density_kg_m3,
        clamped_length_m=args.clamped_length_m,
    )


def cmd_rig(args: argparse.Namespace) -> int:
    manip = load_manipulator(args)
    built = build_rig(
        _rig_setup(args, manip), _rig_piece(args, manip), model_options(args), compliance=manip.compliance
    )
    result = analyse(built, args.method, args.n_modes)
    payload, table = _result_payload(result, args.n_modes)
    title = f"rig {args.rig}" + (f" (hinge angle {args.angle_deg:g} deg)" if args.rig == "chain" else "")
    emit(args, payload, _header(built, title) + "\n" + table)
    return 0


def cmd_config(args: argparse.Namespace) -> int:
    """Print the embedded default description (a template), or a file's values with their provenance."""
    if args.json:
        emit(args, load_manipulator(args).to_dict(), "")
    elif args.config:
        manip = load_manipulator(args)
        width = max(len(k) for k in manip.provenance)
        print(manip.name)
        for key, source in sorted(manip.provenance.items()):
            print(f"  {key:<{width}}  {source}")
    else:
        print(default_config_text(), end="")
    return 0


def cmd_export_mjcf(args: argparse.Namespace) -> int:
    manip = load_manipulator(args)
    opts = model_options(args)
    if args.what == "manipulator":
        built = build_manipulator(manip, pose_of(args), opts)
    else:
        args.rig = args.what
        built = build_rig(_rig_setup(args, manip), _rig_piece(args, manip), opts, compliance=manip.compliance)
    xml = built.to_xml()
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(xml)
    payload = {"what": args.what, "out": str(args.out) if args.out else None, "parameters": built.parameters}
    if args.json:
        emit(args, payload, "")
    elif args.out:
        print(f"wrote {args.out} ({built.model.nv} dof, timestep {built.timestep_s:.3g} s)")
    else:
        sys.stdout.write(xml)
    return 0


def _add_rig_overrides(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("test piece overrides (default: the config's [rig] table)")
    g.add_argument("--length-m", type=float)
    g.add_argument("--thickness-m", type=float, help="in-plane thickness")
    g.add_argument("--height-m", type=float, help="out-of-plane height")
    g.add_argument("--young-pa", type=float)
    g.add_argument("--poisson", type=float)
    g.add_argument("--density-kg-m3", type=float)
    g.add_argument("--clamped-length-m", type=float, help="length held in each clamp")
    p.add_argument("--angle-deg", type=float, default=180.0, help="chain hinge interior angle (180 = straight)")
    p.add_argument(
        "--damping-beta-s",
        type=float,
        default=0.0,
        help="rig stiffness-proportional damping (s; default 0: the config's value is for the manipulator)",
    )


def _add_analysis_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n-modes", type=int, default=8, help="number of physical modes to report")
    p.add_argument(
        "--method",
        choices=("transition_fd", "constrained", "both"),
        default="transition_fd",
        help="linearisation: mjd_transitionFD, constrained eigen-solve, or both side by side",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fpm-sim",
        description="Natural frequencies, modes and reduced models of flexible planar 3RRR manipulators (MuJoCo).",
    )
    parser.add_argument("--version", action="version", version=f"fpm-sim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("modes", help="modal analysis of the manipulator at one pose")
    add_pose_args(p)
    add_config_args(p)
    add_model_args(p)
    _add_analysis_args(p)
    p.add_argument("--shapes", action="store_true", help="with --json: Cartesian mode shapes of points along each link")
    p.add_argument("--plot", type=Path, help="save the first mode shapes (base-plane view) to this image file")
    add_output_args(p)
    p.set_defaults(func=cmd_modes)

    p = sub.add_parser("rig", help="modal analysis of a subsystem test rig")
    p.add_argument("rig", choices=RIGS)
    _add_rig_overrides(p)
    add_config_args(p)
    add_model_args(p)
    _add_analysis_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_rig)

    p = sub.add_parser("config", help="print the default description (TOML template) or a file's provenance")
    add_config_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_config)

    p = sub.add_parser("export-mjcf", help="write the generated MJCF of the manipulator at a pose, or of a rig")
    p.add_argument("what", choices=("manipulator", *RIGS))
    p.add_argument("--out", type=Path, help="output file (default: stdout)")
    add_pose_args(p)
    _add_rig_overrides(p)
    add_config_args(p)
    add_model_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_export_mjcf)

    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            return int(args.func(args))
    except _USER_ERRORS as exc:
        print(f"fpm-sim: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
