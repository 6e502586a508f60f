"""``fpm-sim`` command line. Each sub-command prints a table, or JSON with ``--json``.

Commands live in modules that expose ``register(subparsers)``; :data:`COMMAND_MODULES` lists them.
Options shared by every command are in :mod:`fpm_sim.cli.common`. Errors are handled in ONE place,
:func:`main`: :class:`fpm_sim.errors.FpmSimError` -> exit 2 with one ``error: ...`` line, Ctrl-C -> exit 130
with one line, a closed pipe -> quiet, anything else -> its traceback and a line saying it is a bug.
Warnings print as one ``warning: ...`` line.

Heavy modules (MuJoCo models, SciPy, matplotlib) are imported inside the commands, so that
``fpm-sim --help`` and ``fpm-sim config`` start quickly (``benchmarks/startup.py``, an asv benchmark).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import shlex
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from fpm_sim import __version__

try:  # Ctrl-C while the modules load (a second or so): one line and 130, as at any later moment
    from fpm_sim.cli.bands import add_posterior_args, bands_hint
    from fpm_sim.cli.common import (
        OPTION_NAMES,
        CliError,
        add_config_args,
        add_joint_args,
        add_model_args,
        add_output_args,
        add_overwrite_arg,
        add_pose_args,
        build_machine,
        check_output_file,
        count_arg,
        emit,
        error_line,
        load_machine,
        load_manipulator,
        mm,
        model_options,
        refuse_task_pose,
        with_resolution,
    )
    from fpm_sim.errors import FpmSimError, FpmSimWarning
except KeyboardInterrupt:
    sys.unraisablehook = lambda unraisable: None  # see _after_interrupt
    sys.stderr.write("interrupted (Ctrl-C)\n")
    raise SystemExit(130) from None

if TYPE_CHECKING:
    from fpm_sim.config import Manipulator
    from fpm_sim.linear.analysis import ModalComparison
    from fpm_sim.linear.modes import ModalResult
    from fpm_sim.model.spec import BuiltModel

__all__ = ["COMMAND_MODULES", "build_parser", "main", "save_figure"]

COMMAND_MODULES: list[str] = [
    "fpm_sim.cli.imported",
    "fpm_sim.cli.reproduce",
    "fpm_sim.cli.sweep",
    "fpm_sim.cli.rollout",
    "fpm_sim.cli.reduce",
    "fpm_sim.cli.transient",
    "fpm_sim.cli.move",
    "fpm_sim.cli.frf",
    "fpm_sim.cli.impact",
    "fpm_sim.cli.readability",
    "fpm_sim.cli.atlas",
    "fpm_sim.cli.design",
    "fpm_sim.cli.calibrate",
    "fpm_sim.cli.identify",
    "fpm_sim.cli.ema",
    "fpm_sim.cli.check",
    "fpm_sim.cli.plan_tests",
]
"""Command modules beyond the core ones (each exposes ``register(subparsers)``)."""

RIGS = ("free-free", "cantilever", "chain")
"""The subsystem rigs (checked against :data:`fpm_sim.model.rigs.RIGS` by the tests; listed here so that
building the parser does not import MuJoCo)."""

PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def save_figure(path: Path, draw: Callable[[], Any]) -> None:
    """Draw with the non-interactive Agg backend (selected here, in the CLI only) and save atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.figure import Figure

    from fpm_sim.outputs import atomic_file

    obj = draw()
    fig = obj if isinstance(obj, Figure) else np.atleast_1d(obj)[0].figure
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


def _header(built: BuiltModel, title: str) -> str:
    p = built.parameters
    o = p["options"]
    return f"{title}\n  nv = {p['nv']}, timestep = {p['timestep_s']:.3g} s, link model = {o['link_model']}" + (
        f" ({o['segments']} segments)" if o["link_model"] != "rigid" else ""
    )


def _primary(result: ModalResult | ModalComparison) -> ModalResult:
    """The transitionFD result of a comparison (``--method both``), else the result itself."""
    from fpm_sim.linear.analysis import ModalComparison

    return result.transition_fd if isinstance(result, ModalComparison) else result


def _n_modes_note(result: ModalResult | ModalComparison, n_modes: int) -> str:
    primary = _primary(result)
    n = len(primary.modes)
    return f"\nnote: {n} physical modes found, fewer than --n-modes {n_modes}" if n < n_modes else ""


# ---------------------------------------------------------------------------------------------
# commands


def _shapes_and_plot(args: argparse.Namespace, result: ModalResult | ModalComparison, payload: dict[str, Any]) -> str:
    """Add Cartesian mode shapes to the payload (``--shapes``), write the animated GIF of one mode (``--animate``,
    ``--mode``) and save a figure (``--plot``)."""
    import numpy as np

    primary = _primary(result)
    note = ""
    if args.shapes:
        n = min(args.n_modes, len(primary.modes))
        for i, mode_payload in enumerate(payload["modes"][:n]):
            disp = primary.point_displacements(i)
            peak = max(float(np.max(np.linalg.norm(d, axis=1))) for d in disp.values()) or 1.0
            mode_payload["points_displacement"] = {k: (v / peak).tolist() for k, v in disp.items()}
        payload["points_position_m"] = {k: v.tolist() for k, v in primary.point_positions().items()}
    if args.animate:  # first: a --mode beyond the modes found writes nothing
        primary.animate(args.animate, mode=args.mode or 1)  # matplotlib's Agg renderer and Pillow writer
        note += f"\nmode {args.mode or 1} animated to {args.animate}"
    if args.plot:
        save_figure(args.plot, lambda: primary.plot(n_modes=min(args.n_modes, 6)))
        note += f"\nmode shapes plotted to {args.plot}"
    return note


def cmd_modes(args: argparse.Namespace) -> int:
    from fpm_sim.linear.analysis import analyse
    from fpm_sim.model.options import warn_if_coarse

    check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    check_output_file(args.animate, "--animate", (".gif",))
    if args.mode is not None and args.animate is None:
        raise CliError("--mode picks the mode that --animate draws; add --animate FILE.gif")
    if args.posterior is not None:  # predictions with bands (fpm_sim.cli.bands)
        from fpm_sim.cli.bands import modes_bands

        if args.shapes or args.animate:
            option = "--shapes" if args.shapes else "--animate"
            raise CliError(f"{option} draws one description's mode shapes; drop it with --posterior (bands only)")

        bands, payload, text = modes_bands(args)
        if args.plot:
            save_figure(args.plot, bands.plot)
            text += f"\nbands plotted to {args.plot}"
        emit(args, payload, text)
        return 0
    machine = load_machine(args, "modes")
    opts = model_options(args)
    warn_if_coarse(opts)
    if args.poses is not None:
        return _modes_at_joint_poses(args, machine, opts)
    built, pose_label = build_machine(args, machine, opts)
    # --mode K beyond --n-modes: every physical mode (a K beyond them is then refused by name, as --mode)
    result = analyse(built, args.method, args.n_modes if (args.mode or 1) <= args.n_modes else None)
    payload, table = result.to_dict(args.n_modes), result.table(args.n_modes)
    payload["config"] = machine.name
    payload["manipulator"] = machine.to_dict()
    with_resolution(payload, opts)
    note = _shapes_and_plot(args, result, payload)
    text = (
        _header(built, f"{machine.name}\n  pose {pose_label}")
        + "\n"
        + table  # ends with the resolution line
        + _n_modes_note(result, args.n_modes)
        + note
    )
    hint = bands_hint(args, "modes")
    if hint:
        text += "\n" + hint
        payload["bands_available"] = hint.strip()
    emit(args, payload, text)
    return 0


def _modes_at_joint_poses(args: argparse.Namespace, machine: Any, opts: Any) -> int:
    """``fpm-sim modes --config imported.toml --poses poses.csv``: the modes at each joint-space pose."""
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.batch.joint_sweep import modes_at_joint_poses, read_joint_poses_csv

    if not isinstance(machine, ImportedDescription):
        raise CliError(
            "--poses: a CSV of joint values poses an imported model (kind = 'imported'); pose this machine "
            "with --x-mm/--y-mm/--phi-rad"
        )
    for option, given in (
        ("--q", args.q),
        ("--shapes", args.shapes),
        ("--plot", args.plot),
        ("--animate", args.animate),
    ):
        if given:
            raise CliError(f"{option}: one pose's option; drop it with --poses (or give that pose with --q)")
    refuse_task_pose(args)
    poses = read_joint_poses_csv(args.poses, machine)
    results = modes_at_joint_poses(machine, poses, options=opts, n_modes=args.n_modes, method=args.method)
    rows, blocks = [], [machine.name]
    for k, (q, result) in enumerate(zip(poses, results, strict=True)):
        label = ", ".join(f"{j} = {v:g}" for j, v in q.items())
        rows.append({"pose": k + 1, "q": q, **result.to_dict(args.n_modes)})
        blocks.append(f"\npose {k + 1}: {label}\n" + result.table(args.n_modes))
    payload = {"config": machine.name, "manipulator": machine.to_dict(), "poses": rows}
    emit(args, with_resolution(payload, opts), "\n".join(blocks))
    return 0


def _rig_setup(args: argparse.Namespace) -> Any:
    from fpm_sim.model.rigs import RigSetup

    return RigSetup(args.rig, angle_deg=args.angle_deg, damping_beta_s=args.damping_beta_s)


def _rig_piece(args: argparse.Namespace, manip: Manipulator) -> Any:
    from fpm_sim.model.rigs import rig_piece

    return rig_piece(
        manip,
        length_m=mm(args.length_mm),
        thickness_m=mm(args.thickness_mm),
        height_m=mm(args.height_mm),
        young_pa=args.young_pa,
        poisson=args.poisson,
        density_kg_m3=args.density_kg_m3,
        clamped_length_m=mm(args.clamped_length_mm),
    )


def _piece_line(args: argparse.Namespace, manip: Manipulator, piece: Any) -> str:
    """The test piece's dimensions and where each comes from (an option, or the description's provenance), and,
    when options change it, the description's own piece: the one ``reproduce``'s subsystem tests use."""
    base = manip.rig if manip.rig is not None else piece  # rig_piece refuses a description without one
    dims = (
        ("length", "length_mm", "rig.length_m", piece.length_m, base.length_m),
        ("clamped", "clamped_length_mm", "rig.clamped_length_m", piece.clamped_length_m, base.clamped_length_m),
        ("thickness", "thickness_mm", "rig.section.thickness_m", piece.section.thickness_m, base.section.thickness_m),
        ("height", "height_mm", "rig.section.height_m", piece.section.height_m, base.section.height_m),
    )
    own, changed = [], []
    for name, opt, key, value, described in dims:
        source = manip.provenance.get(key, "description").split(":")[0]
        if getattr(args, opt, None) is not None:
            own.append(f"{name} {value * 1e3:.4g} mm (--{opt.replace('_', '-')})")
            if value != described:
                changed.append(f"{name} {described * 1e3:.4g} mm ({source})")
        else:
            own.append(f"{name} {value * 1e3:.4g} mm ({source})")
    line = "  test piece: " + ", ".join(own)
    if changed:
        line += (
            "\n  (the description's piece, which reproduce's subsystem tests use, has " + ", ".join(changed) + ": "
            "its frequencies differ from these for that reason)"
        )
    return line


def cmd_rig(args: argparse.Namespace) -> int:
    from fpm_sim.linear.analysis import analyse
    from fpm_sim.model.options import warn_if_coarse
    from fpm_sim.model.rigs import build_rig

    manip = load_manipulator(args)
    opts = model_options(args)
    warn_if_coarse(opts)
    piece = _rig_piece(args, manip)
    built = build_rig(_rig_setup(args), piece, opts, compliance=manip.compliance)
    result = analyse(built, args.method, args.n_modes)
    payload, table = result.to_dict(args.n_modes), result.table(args.n_modes)
    with_resolution(payload, opts)
    title = f"rig {args.rig}" + (f" (hinge angle {args.angle_deg:g} deg)" if args.rig == "chain" else "")
    text = (
        _header(built, title)
        + "\n"
        + _piece_line(args, manip, piece)
        + "\n"
        + table  # ends with the resolution line
        + _n_modes_note(result, args.n_modes)
    )
    emit(args, payload, text)
    return 0


def cmd_config(args: argparse.Namespace) -> int:
    """Print the embedded default description (a template), or a file's values with their provenance."""
    from fpm_sim.config import default_config_text

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
    from fpm_sim.config import Manipulator
    from fpm_sim.model.rigs import build_rig
    from fpm_sim.outputs import atomic_file

    check_output_file(args.out, "--out", (".xml",), overwrite=args.overwrite)
    machine = load_machine(args, "export-mjcf")
    opts = model_options(args)
    if args.what == "manipulator":
        built, _ = build_machine(args, machine, opts)
    elif not isinstance(machine, Manipulator):
        raise CliError(
            f"export-mjcf {args.what}: the rigs are the study's own test pieces; on a described "
            "architecture export the manipulator"
        )
    else:
        manip = machine
        args.rig = args.what
        built = build_rig(_rig_setup(args), _rig_piece(args, manip), opts, compliance=manip.compliance)
    xml = built.to_xml()
    if args.out:
        with atomic_file(args.out) as tmp:
            tmp.write_text(xml)
    payload = {"what": args.what, "out": str(args.out) if args.out else None, "parameters": built.parameters}
    with_resolution(payload, opts)
    if args.json:
        emit(args, payload, "")
    elif args.out:
        print(f"wrote {args.out} ({built.model.nv} dof, timestep {built.timestep_s:.3g} s)")
    else:
        sys.stdout.write(xml)
    return 0


def _add_rig_overrides(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("test piece overrides (default: the config's [rig] table)")
    g.add_argument("--length-mm", type=float, help="test piece length (mm)")
    g.add_argument("--thickness-mm", type=float, help="in-plane thickness (mm)")
    g.add_argument("--height-mm", type=float, help="out-of-plane height (mm)")
    g.add_argument("--young-pa", type=float, help="Young's modulus (Pa)")
    g.add_argument("--poisson", type=float, help="Poisson's ratio")
    g.add_argument("--density-kg-m3", type=float, help="density (kg/m^3)")
    g.add_argument("--clamped-length-mm", type=float, help="length held in each clamp (mm)")
    p.add_argument("--angle-deg", type=float, default=180.0, help="chain hinge interior angle (180 = straight)")
    p.add_argument(
        "--damping-beta-s",
        type=float,
        default=0.0,
        help="rig stiffness-proportional damping (s; default 0: the config's value is for the manipulator)",
    )


def _add_analysis_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--n-modes", type=count_arg("--n-modes"), default=8, help="number of physical modes to report (1..200)"
    )
    p.add_argument(
        "--method",
        choices=("transition_fd", "constrained", "both"),
        default="transition_fd",
        help="linearisation: mjd_transitionFD, constrained eigen-solve, or both side by side",
    )


class _Parser(argparse.ArgumentParser):
    """Usage errors become :class:`CliError` (one ``error:`` line and exit 2 from :func:`main`, like every
    other user error) instead of argparse's own exit."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)  # --thickness-m must not be read as --thickness-mm
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        """Also record the option strings of the parsers used (``_cli_options``), for :func:`error_line`."""
        ns, rest = super().parse_known_args(args, namespace)
        ns._cli_options = set(getattr(ns, "_cli_options", ())) | set(self._option_string_actions)
        return ns, rest

    def error(self, message: str) -> NoReturn:
        raise CliError(f"{message} ({self.prog}); see '{self.prog} --help'")


def build_parser() -> argparse.ArgumentParser:
    """The ``fpm-sim`` parser with every sub-command."""
    parser = _Parser(
        prog="fpm-sim",
        description="Natural frequencies, modes and reduced models of flexible planar 3RRR manipulators (MuJoCo).",
        allow_abbrev=False,  # stated here too; every sub-command's parser is a _Parser, which defaults to it
    )
    parser.add_argument("--version", action="version", version=f"fpm-sim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("modes", help="modal analysis of the manipulator at one pose")
    add_pose_args(p)
    add_config_args(p)
    add_model_args(p)
    _add_analysis_args(p)
    p.add_argument(
        "--shapes",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="with --json: Cartesian mode shapes of points along each link",
    )
    p.add_argument("--plot", type=Path, help="save the first mode shapes (3D view) to this image (.png, .pdf, .svg)")
    p.add_argument(
        "--animate",
        type=Path,
        metavar="GIF",
        help="write an animated GIF of one mode shape (--mode) to this file (.gif): one period, looping",
    )
    p.add_argument(
        "--mode", type=count_arg("--mode"), metavar="K", help="the mode --animate draws, 1-based (default 1)"
    )
    add_joint_args(p)
    p.add_argument(
        "--poses",
        type=Path,
        help="an imported model's joint-space poses: CSV with one column per joint name (rad or m), modes at each",
    )
    add_posterior_args(p)
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
    p.add_argument("--out", type=Path, help="output file (.xml; default: stdout)")
    add_overwrite_arg(p)
    add_pose_args(p)
    add_joint_args(p)
    _add_rig_overrides(p)
    add_config_args(p)
    add_model_args(p)
    add_output_args(p)
    p.set_defaults(func=cmd_export_mjcf)

    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


# ---------------------------------------------------------------------------------------------
# the one error path


def _one_line_warning(
    message: Warning | str, category: type[Warning], filename: str, lineno: int, file: Any = None, line: Any = None
) -> None:
    text = str(message).replace("\n", " ")
    name = getattr(message, "parameter", None)
    if isinstance(message, FpmSimWarning) and name:
        text = f"{OPTION_NAMES.get(name, (name,))[0]}: {text}"
    try:
        print(f"warning: {text}", file=sys.stderr if file is None else file)
    except (OSError, ValueError):  # stderr closed: nothing to say it on
        pass


@contextlib.contextmanager
def _cli_warnings() -> Iterator[None]:
    """Warnings as one ``warning: ...`` line, without source lines; restored on exit (in-process callers)."""
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = _one_line_warning
        yield


def _after_interrupt() -> None:
    """After Ctrl-C: keep the "interrupted" line the only one, for the rest of the process.

    An interrupt can land inside a library object's ``__init__`` (h5netcdf's ``File`` while the posterior
    opens, for one); its ``__del__`` then fails on the half-built object when the interrupted frames are
    freed, and Python prints that as "Exception ignored in ... Traceback". Nothing is lost by silencing
    it: the command is abandoning its work, and outputs are written atomically. The hook stays replaced
    for the rest of the process (the CLI exits next; an in-process caller of :func:`main` gets the same).
    """
    sys.unraisablehook = lambda unraisable: None


def _quiet_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so that the interpreter's final flush stays quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (an in-process caller's capture)
        pass


def main(argv: list[str] | None = None) -> int:
    """Run ``fpm-sim`` with ``argv``; returns the exit status (0, 2 user error, 130 interrupted, 1 bug)."""
    args: argparse.Namespace | None = None
    with _cli_warnings():
        try:
            argv = sys.argv[1:] if argv is None else list(argv)
            args = build_parser().parse_args(argv)
            args.command_line = "fpm-sim " + shlex.join(argv)  # what was run, recorded by commands that write reports
            code = int(args.func(args))
            sys.stdout.flush()  # a closed pipe shows here, inside the handlers below
            return code
        except FpmSimError as exc:
            command, options = getattr(args, "command", None), getattr(args, "_cli_options", None)
            print(error_line(exc, command, options), file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            _after_interrupt()
            print("interrupted (Ctrl-C); unfinished outputs were not written", file=sys.stderr)
            return 130
        except BrokenPipeError:  # e.g. `fpm-sim config | head`: the reader has what it wanted
            _quiet_stdout()
            return 0
        except Exception:
            traceback.print_exc()
            print(
                "this is a bug in fpm-sim, not a problem with your input: please report it with the command line "
                "and the traceback above",
                file=sys.stderr,
            )
            return 1


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
