"""Options and helpers shared by every ``fpm-sim`` command: one name for one thing.

Conventions (see ``fpm-sim --help``):

- the description is ``--config`` (a TOML file; default: the embedded study prototype);
- the resolution is ``--fidelity {fast,standard,fine}`` or ``--segments N`` (overrides), defined once in
  :mod:`fpm_sim.model.options`; every command defaults to the same fidelity, hence the same model;
- lengths in millimetres with ``_mm`` names (SI inside), booleans as ``--x/--no-x`` pairs;
- ``--out`` is the output file or folder, ``--json`` prints JSON, ``--backend``/``--workers`` drive pose loops;
- every output path is checked before any computation starts (:func:`check_output_file`,
  :func:`check_output_dir`), and written atomically (:mod:`fpm_sim.outputs`).

Errors: raise :class:`fpm_sim.errors.FpmSimError` (or a subclass); ``fpm_sim.cli.main.main`` maps it to exit
code 2 with one ``error: ...`` line. No command catches errors itself.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fpm_sim.errors import FpmSimError
from fpm_sim.outputs import prove_creatable

if TYPE_CHECKING:
    from fpm_sim.architecture import Description, TaskPose
    from fpm_sim.architecture.imported import ImportedDescription
    from fpm_sim.config import Manipulator
    from fpm_sim.kinematics import Pose
    from fpm_sim.model.options import ModelOptions

__all__ = [
    "FIDELITY_CHOICES",
    "IMPORTED_COMMANDS",
    "LINK_MODEL_CHOICES",
    "MAX_MODES",
    "OPTION_NAMES",
    "WORKERS_HELP",
    "CliError",
    "add_config_args",
    "add_engine_args",
    "add_joint_args",
    "add_model_args",
    "add_output_args",
    "add_overwrite_arg",
    "add_pose_args",
    "add_resolution_args",
    "build_machine",
    "check_output_dir",
    "check_output_file",
    "count_arg",
    "emit",
    "engine_options",
    "error_line",
    "finish_store",
    "imported_pose_of",
    "is_described",
    "is_imported",
    "joint_values",
    "load_machine",
    "load_manipulator",
    "mm",
    "model_options",
    "pose_of",
    "read_input_file",
    "refuse_joint_values",
    "refuse_task_pose",
    "task_pose_of",
    "with_resolution",
    "workers_of",
]

FIDELITY_CHOICES = ("fast", "standard", "fine")
""":data:`fpm_sim.model.options.FIDELITIES` (a test checks they agree), listed here so that building the
parser imports neither MuJoCo nor SciPy (``fpm-sim --help`` starts in a tenth of a second)."""
DEFAULT_FIDELITY = "standard"
""":data:`fpm_sim.model.options.DEFAULT_FIDELITY` (checked by a test)."""
LINK_MODEL_CHOICES = ("segments", "rigid", "cable", "flex")
""":data:`fpm_sim.model.parts.LINK_MODELS` (checked by a test)."""

MAX_MODES = 200
"""Upper bound of ``--n-modes``/``--modes`` (the models have a few hundred degrees of freedom)."""


class CliError(FpmSimError):
    """A command-line value that cannot work (the message names the option and the fix)."""


OPTION_NAMES: dict[str, tuple[str, float]] = {
    # library parameter -> (option, factor from the parameter's SI unit to the option's unit).
    # "command:parameter" entries win over "parameter" for that command.
    "section.thickness_m": ("--thickness-mm", 1e3),
    "section.height_m": ("--height-mm", 1e3),
    "x_m": ("--x-mm", 1e3),
    "y_m": ("--y-mm", 1e3),
    "z_m": ("--z-mm", 1e3),
    "phi_rad": ("--phi-rad", 1.0),
    "pose.phi_rad": ("--phi-rad", 1.0),
    "link_model": ("--link-model", 1.0),
    "segments": ("--segments", 1.0),
    "fidelity": ("--fidelity", 1.0),
    "timestep_s": ("--timestep-s", 1.0),
    "method": ("--method", 1.0),
    "backend": ("--backend", 1.0),
    "workers": ("--workers", 1.0),
    "chunk": ("--chunk-poses", 1.0),
    "scheduler": ("--scheduler", 1.0),
    "resume": ("--resume", 1.0),
    "out": ("--out", 1.0),
    "overwrite": ("--overwrite", 1.0),
    "config": ("--config", 1.0),
    "n_modes": ("--n-modes", 1.0),
    "atlas:n_modes": ("--modes", 1.0),
    "reduce:n_modes": ("--modes", 1.0),
    "transient:n_modes": ("--modes", 1.0),
    "modes:mode": ("--mode", 1.0),
    "q": ("--q", 1.0),
    "n_extra": ("--extra", 1.0),
    "band_hz": ("--band-hz", 1.0),
    "error_bound": ("--error-bound", 1.0),
    "f_min_hz": ("--f-min-hz", 1.0),
    "f_max_hz": ("--f-max-hz", 1.0),
    "df_hz": ("--df-hz", 1.0),
    "input_fraction": ("--input-fraction", 1.0),
    "output_fraction": ("--output-fraction", 1.0),
    "t0_s": ("--load-start-s", 1.0),
    "freq_hz": ("--load-freq-hz", 1.0),
    "duration_s": ("--duration-s", 1.0),
    "ee_wrench": ("--force-x-n, --force-y-n, --moment-z-nm", 1.0),
    "rig.angle_deg": ("--angle-deg", 1.0),
    "rig.length_m": ("--length-mm", 1e3),
    "rig.clamped_length_m": ("--clamped-length-mm", 1e3),
    "rig.section.thickness_m": ("--thickness-mm", 1e3),
    "rig.section.height_m": ("--height-mm", 1e3),
    "rig.material.young_pa": ("--young-pa", 1.0),
    "rig.material.poisson": ("--poisson", 1.0),
    "rig.material.density_kg_m3": ("--density-kg-m3", 1.0),
    "vary": ("--vary", 1.0),
    "designs": ("--designs", 1.0),
    "grid": ("--grid", 1.0),
    "poses": ("--poses", 1.0),
    "workspace": ("--workspace", 1.0),
    "x_mm": ("--x-mm", 1.0),
    "y_mm": ("--y-mm", 1.0),
    "step_mm": ("--step-mm", 1.0),
    "free": ("--free", 1.0),
    "measured": ("--measured", 1.0),
    "subsystems": ("--subsystems", 1.0),
    "reading": ("--reading", 1.0),
    "global_method": ("--global", 1.0),
    "folds": ("--folds", 1.0),
    "window_tau_s": ("--exp-window-tau-s", 1.0),
    "posterior": ("--posterior", 1.0),
    # Bayesian calibration (fpm_sim.study.calibrate)
    "priors": ("--priors", 1.0),
    "live_points": ("--live-points", 1.0),
    "dlogz": ("--dlogz", 1.0),
    "walks": ("--walks", 1.0),
    "max_calls": ("--max-calls", 1.0),
    "calibrate:draws": ("--draws", 1.0),
    "calibrate:runs": ("--runs", 1.0),
    "calibrate:particles": ("--particles", 1.0),
    "cheap_particles": ("--cheap-particles", 1.0),
    "emulator": ("--emulator", 1.0),
    "ess_fraction": ("--ess-fraction", 1.0),
    "calibrate:moves": ("--moves", 1.0),
    "final_moves": ("--final-moves", 1.0),
    "jumps": ("--jumps", 1.0),
    "importance": ("--importance", 1.0),
    "islands": ("--islands", 1.0),
    "crossover": ("--crossover", 1.0),
    # time domain (fpm_sim.sim.stepping, fpm_sim.sim.trajectory)
    "integrator": ("--integrator", 1.0),
    "step_band_hz": ("--step-band-hz", 1.0),
    "rollout:step_s": ("--timestep-s", 1.0),
    "impact:step_s": ("--implicit-step-s", 1.0),
    "output_step_s": ("--output-step-s", 1.0),
    "move_s": ("--move-s", 1.0),
    "profile": ("--profile", 1.0),
    "shaper": ("--shaper", 1.0),
    "path_csv": ("--path-csv", 1.0),
    "settle_s": ("--settle-s", 1.0),
    "settle_tol_m": ("--settle-tol-mm", 1e3),
    "n_impacts": ("--impacts", 1.0),
    "record_s": ("--record-s", 1.0),
    "peak_force_n": ("--peak-force-n", 1.0),
    "noise_m_s2": ("--noise-m-s2", 1.0),
}
"""The one map from the library's parameter names (:attr:`FpmSimError.parameter`) to the command line's option
names, with the factor that converts a value to the option's unit. Only options the command has are used."""


def _option_for(parameter: str, command: str | None, options: set[str] | None) -> tuple[str, float] | None:
    hit = OPTION_NAMES.get(f"{command}:{parameter}") or OPTION_NAMES.get(parameter)
    if hit is None:
        return None
    if options is not None and not all(o in options for o in hit[0].split(", ")):
        return None  # the command has no such option: the value came from elsewhere (a file, --vary)
    return hit


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def error_line(exc: FpmSimError, command: str | None = None, options: set[str] | None = None) -> str:
    """The ``error: ...`` line of ``exc``: its parameter as the command's option name, the value in its unit.

    ``options`` are the option strings of the command (``None``: map every known parameter).
    """
    if exc.parameter is None or exc.file is not None:
        return f"error: {exc}"
    hit = _option_for(exc.parameter, command, options)
    if hit is None:
        return f"error: {exc}"
    option, factor = hit
    value = None
    if exc.has_value and factor != 1.0:
        unit = option.rsplit("-", 1)[-1]
        v = exc.value
        if _is_number(v):
            value = f"{v * factor:g} {unit}"
        elif isinstance(v, (list, tuple)) and all(_is_number(e) for e in v):
            value = f"[{', '.join(f'{e * factor:g}' for e in v)}] {unit}"
    return f"error: {exc.render(parameter=option, value=value)}"


def mm(value_mm: float | None) -> float | None:
    """Millimetres (command line) to metres (inside), keeping ``None``."""
    return None if value_mm is None else value_mm * 1e-3


def count_arg(name: str, *, low: int = 1, high: int = MAX_MODES) -> Any:
    """An ``argparse`` type for a bounded count: ``low <= N <= high``, with a message naming ``name``."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if not low <= n <= high:
            raise argparse.ArgumentTypeError(f"{name} must be in {low}..{high}, got {n}")
        return n

    return parse


# ---------------------------------------------------------------------------------------------
# option groups


def add_config_args(p: argparse.ArgumentParser) -> None:
    """``--config FILE``."""
    p.add_argument("--config", type=Path, help="manipulator TOML file (default: the embedded study prototype)")


def add_resolution_args(p: argparse.ArgumentParser | Any, *, axial: bool) -> None:
    """``--fidelity``, ``--segments`` and ``--axial/--no-axial`` (default ``axial``)."""
    p.add_argument(
        "--fidelity",
        choices=FIDELITY_CHOICES,
        default=None,
        help=f"model resolution preset: fast (8 segments per link), standard (12), fine (24); default "
        f"{DEFAULT_FIDELITY}, the same in every command",
    )
    p.add_argument(
        "--segments",
        type=int,
        default=None,
        help="resolution per link, overrides --fidelity: spring locations (segments), elastic joints (cable) or "
        "flex edges (flex)",
    )
    p.add_argument(
        "--axial",
        action=argparse.BooleanOptionalAction,
        default=axial,
        help="axial springs (extensible links); without them the links are inextensible: faster, in-plane "
        f"frequencies within 0.1 %% (default {'on' if axial else 'off'})",
    )


def add_model_args(p: argparse.ArgumentParser, *, axial: bool = True) -> None:
    """The model group: link model, resolution, axial springs, rotary inertia, gravity, timestep."""
    g = p.add_argument_group("model")
    g.add_argument(
        "--link-model",
        default="segments",
        help=f"link model: {', '.join(LINK_MODEL_CHOICES)} (default segments; see docs/link_models.md)",
    )
    add_resolution_args(g, axial=axial)
    g.add_argument(
        "--rotary-inertia",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="include section rotary inertia (Rayleigh beam; default off)",
    )
    g.add_argument(
        "--gravity",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="gravity along the motor axes (default on)",
    )
    g.add_argument("--timestep-s", type=float, default=None, help="simulation step (s; default: automatic)")


def add_pose_args(p: argparse.ArgumentParser) -> None:
    """``--x-mm``, ``--y-mm``, ``--z-mm``, ``--phi-rad``: the task coordinates (those the architecture has)."""
    g = p.add_argument_group("pose (the architecture's task coordinates; default: its first check pose, or 0)")
    g.add_argument("--x-mm", type=float, default=None, help="end-effector x (mm)")
    g.add_argument("--y-mm", type=float, default=None, help="end-effector y (mm)")
    g.add_argument("--z-mm", type=float, default=None, help="end-effector z (mm; spatial architectures: the Delta)")
    g.add_argument("--phi-rad", type=float, default=None, help="end-effector rotation (rad, within -pi..pi)")


def add_output_args(p: argparse.ArgumentParser) -> None:
    """``--json``."""
    p.add_argument("--json", action=argparse.BooleanOptionalAction, default=False, help="print JSON instead of a table")


def add_overwrite_arg(p: argparse.ArgumentParser) -> None:
    """``--overwrite``: replace an existing output folder of another run."""
    p.add_argument(
        "--overwrite",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="replace an existing output (default: refuse)",
    )


# ---------------------------------------------------------------------------------------------
# from arguments to library objects


def load_manipulator(args: argparse.Namespace) -> Manipulator:
    """The description of ``--config`` (checked to be a readable file), or the embedded default."""
    from fpm_sim.config import default_config, load_config

    path = getattr(args, "config", None)
    if not path:
        return default_config()
    path = Path(path)
    if path.is_dir():
        raise CliError(f"--config {path} is a folder, not a file; give a TOML description (see 'fpm-sim config')")
    if not path.exists():
        raise CliError(f"--config {path}: file not found; check the path (fpm-sim config prints a template)")
    from fpm_sim.architecture import is_description_file
    from fpm_sim.architecture.imported import is_imported_file

    if is_description_file(path):
        raise CliError(_not_yet(str(getattr(args, "command", None) or "this command"), path))
    if is_imported_file(path):
        raise CliError(_not_on_imported(str(getattr(args, "command", None) or "this command"), path))
    return load_config(path)


def model_options(args: argparse.Namespace, **overrides: Any) -> ModelOptions:
    """:class:`ModelOptions` from the model/resolution options present in ``args`` (``overrides`` win)."""
    from fpm_sim.model.options import ModelOptions

    kw: dict[str, Any] = {
        "link_model": getattr(args, "link_model", "segments"),
        "segments": getattr(args, "segments", None),
        "fidelity": getattr(args, "fidelity", None),
        "axial": getattr(args, "axial", True),
        "rotary_inertia": getattr(args, "rotary_inertia", False),
        "gravity": getattr(args, "gravity", True),
        "timestep_s": getattr(args, "timestep_s", None),
    }
    kw.update(overrides)
    if kw["segments"] is not None:
        kw["fidelity"] = None
    return ModelOptions(**kw)


def pose_of(args: argparse.Namespace) -> Pose:
    """The 3RRR's pose of ``--x-mm``, ``--y-mm``, ``--phi-rad`` (each 0 when not given); a rotation beyond pi is
    refused, not wrapped; ``--z-mm`` is refused (the 3RRR's task coordinates are x, y, phi)."""
    from fpm_sim.kinematics import checked_pose_mm

    if getattr(args, "z_mm", None) is not None:
        raise CliError("--z-mm: the 3RRR's task coordinates are x, y and phi; drop --z-mm")
    return checked_pose_mm(*(0.0 if v is None else v for v in (args.x_mm, args.y_mm, args.phi_rad)))


GENERAL_COMMANDS = (
    "modes",
    "export-mjcf",
    "sweep",
    "check",
    "design",
    "identify",
    "reduce",
    "frf",
    "impact",
    "atlas",
    "rollout",
    "move",
    "calibrate",
)
"""The commands that run on a described architecture (``[[chains]]``) so far; the others say so."""


def is_imported(args: argparse.Namespace) -> bool:
    """Whether ``--config`` names an imported model's file (``kind = "imported"``)."""
    from fpm_sim.architecture.imported import is_imported_file

    path = getattr(args, "config", None)
    return path is not None and Path(path).is_file() and is_imported_file(path)


def is_described(args: argparse.Namespace) -> bool:
    """Whether ``--config`` names a described architecture's file (``[[chains]]``)."""
    from fpm_sim.architecture import is_description_file

    path = getattr(args, "config", None)
    return path is not None and Path(path).is_file() and is_description_file(path)


def load_machine(args: argparse.Namespace, command: str) -> Manipulator | Description:
    """The 3RRR description of ``--config``, or a described architecture (``[[chains]]``, :mod:`fpm_sim.architecture`)
    for the commands of :data:`GENERAL_COMMANDS`."""
    from fpm_sim.architecture import is_description_file, load_description
    from fpm_sim.architecture.imported import is_imported_file, load_imported

    path = getattr(args, "config", None)
    if path and Path(path).is_file() and is_imported_file(path):
        if command not in IMPORTED_COMMANDS:
            raise CliError(_not_on_imported(command, Path(path)))
        return load_imported(path)  # type: ignore[return-value]
    if path and Path(path).is_file() and is_description_file(path):
        if command not in GENERAL_COMMANDS:
            raise CliError(_not_yet(command, Path(path)))
        return load_description(path)
    return load_manipulator(args)


IMPORTED_COMMANDS = (
    "modes",
    "sweep",
    "frf",
    "export-mjcf",
    "check",
    "identify",
    "calibrate",
    "move",
    "rollout",
    "reduce",
    "impact",
    "design",
    "atlas",
)
"""The commands that run on an imported model (``kind = "imported"``), posed by joint values (``--q``, ``--poses``) or,
where its description names an ``[end_effector]``, by task poses (``--x-mm`` ..., a poses CSV of task columns); ``move``
needs that ``[end_effector]`` and motors (the joints an ``<actuator>`` drives, ``servo_joints``), ``rollout`` the
``[end_effector]`` (and motors with ``--motors servo``)."""

_WHY_NOT_IMPORTED: dict[str, str] = {}


def _not_on_imported(command: str, path: Path) -> str:
    why = _WHY_NOT_IMPORTED.get(command, "it is the study's 3RRR's own command (docs/study.md)")
    return (
        f"--config {path} is an imported model (kind = 'imported'); '{command}' does not run on it: {why}. On an "
        f"imported model run: {', '.join(IMPORTED_COMMANDS)}"
    )


STUDY_COMMANDS = ("reproduce", "rig", "readability", "transient")
"""The study's own commands: its poses, test rigs, readings and transient, which are the 3RRR's by definition."""


def _not_yet(command: str, path: Path) -> str:
    if command in STUDY_COMMANDS:
        return (
            f"--config {path} describes an architecture of its own ([[chains]]); '{command}' is the study's own "
            "command (its 3RRR's poses, rigs and readings: docs/study.md) and has no meaning on another "
            f"machine. On a described architecture run: {', '.join(GENERAL_COMMANDS)}"
        )
    return (
        f"--config {path} describes an architecture of its own ([[chains]]); '{command}' runs on the study's 3RRR "
        f"form only so far. On a described architecture run: {', '.join(GENERAL_COMMANDS)}"
    )


def task_pose_of(args: argparse.Namespace, desc: Description) -> TaskPose:
    """The task pose of the pose options for a described architecture: an option the architecture has no task
    coordinate for is refused by name; a coordinate not given takes the description's first check pose (or 0)."""
    from fpm_sim.architecture import TaskPose

    given = {"x": args.x_mm, "y": args.y_mm, "z": getattr(args, "z_mm", None), "phi": args.phi_rad}
    flags = {"x": "--x-mm", "y": "--y-mm", "z": "--z-mm", "phi": "--phi-rad"}
    for c, v in given.items():
        if v is not None and c not in desc.task:
            raise CliError(
                f"{flags[c]}: {desc.name} has no task coordinate {c} (its task coordinates are "
                f"{', '.join(desc.task)}); drop {flags[c]}"
            )
        if v is not None and not math.isfinite(v):
            raise CliError(f"{flags[c]}: must be a finite number, got {v}")
    if given["phi"] is not None and abs(given["phi"]) > math.pi:
        raise CliError(f"--phi-rad {given['phi']:g} is outside -pi..pi; give it in radians within -pi..pi")
    home = desc.check_poses[0] if desc.check_poses else {}
    si = {c: (given[c] * (1.0 if c == "phi" else 1e-3) if given[c] is not None else home.get(c, 0.0)) for c in given}
    return TaskPose(x_m=si["x"], y_m=si["y"], z_m=si["z"], phi_rad=si["phi"])


def build_machine(args: argparse.Namespace, machine: Manipulator | Description, opts: ModelOptions) -> tuple[Any, str]:
    """The :class:`~fpm_sim.model.spec.BuiltModel` of the 3RRR (at :func:`pose_of`) or of a described architecture
    (at :func:`task_pose_of`), and the pose's label."""
    from fpm_sim.architecture import Description
    from fpm_sim.architecture.imported import ImportedDescription

    refuse_joint_values(args, machine)
    if isinstance(machine, ImportedDescription):
        from fpm_sim.model.imported import build_imported

        q, label = imported_pose_of(args, machine)
        return build_imported(machine, q, opts), label
    if isinstance(machine, Description):
        from fpm_sim.model.general import build_general

        task_pose = task_pose_of(args, machine)
        return build_general(machine, task_pose, opts), task_pose.label(machine.task)
    from fpm_sim.model.manipulator import build_manipulator

    pose = pose_of(args)
    return build_manipulator(machine, pose, opts), pose.label()


def refuse_joint_values(args: argparse.Namespace, machine: Any) -> None:
    """``--q`` on a machine that is not an imported model: refused by name (its poses are task poses)."""
    from fpm_sim.architecture.imported import ImportedDescription

    if getattr(args, "q", None) and not isinstance(machine, ImportedDescription):
        raise CliError(
            "--q: joint values pose an imported model (kind = 'imported'); pose this machine by its task coordinates "
            "(--x-mm, --y-mm, ...)"
        )


def add_joint_args(p: argparse.ArgumentParser) -> None:
    """``--q NAME=VALUE``: an imported model's joint values (:func:`joint_values`)."""
    p.add_argument(
        "--q",
        action="append",
        metavar="NAME=VALUE",
        help="an imported model's joint value (rad for a hinge, m for a slide; repeat per joint)",
    )


def _task_options(args: argparse.Namespace, *, phi_default_zero: bool = False) -> dict[str, float]:
    """The task-pose options given (``x``, ``y``, ``z`` in mm, ``phi`` in rad). ``phi_default_zero``: the command's
    ``--phi-rad`` defaults to 0 (``sweep``, ``design``: their dense grid's), so 0 counts as not given."""
    given = {c: getattr(args, f"{c}_mm" if c != "phi" else "phi_rad", None) for c in ("x", "y", "z", "phi")}
    return {
        c: float(v) for c, v in given.items() if v is not None and not (phi_default_zero and c == "phi" and v == 0.0)
    }


def refuse_task_pose(args: argparse.Namespace) -> None:
    """A task-pose option where the poses are given otherwise (``--poses``), or the model has no end effector:
    refused by name."""
    for c in _task_options(args, phi_default_zero=True):
        option = "--" + ("phi-rad" if c == "phi" else f"{c}-mm")
        raise CliError(
            f"{option}: a single task pose does not combine with --poses; give the poses in the file (joint "
            "columns, or task columns x_mm, y_mm, z_mm, phi_rad where the model names an [end_effector])"
        )


def imported_pose_of(args: argparse.Namespace, desc: ImportedDescription) -> tuple[dict[str, float], str]:
    """An imported model's joint values and the pose's label: ``--q`` values, and a task pose (``--x-mm`` ...)
    solved by :class:`~fpm_sim.model.imported_pose.ImportedKinematics` where the description names an
    ``[end_effector]`` (its coordinates not given keep the model's reference value; ``--q`` joints stay fixed)."""
    q = joint_values(getattr(args, "q", None) or [])
    given = _task_options(args)
    if not given:
        return q, ", ".join(f"{k} = {v:g}" for k, v in q.items()) or "as the model"
    option = "--" + ("phi-rad" if next(iter(given)) == "phi" else f"{next(iter(given))}-mm")
    if desc.end_effector is None:
        raise CliError(
            f"{option}: {desc.name} names no end effector, so it has no task coordinates; pose it by its joints' "
            'values (--q NAME=VALUE), or name its site in the description: [end_effector] site = "tool", '
            'coordinates = ["x", "y", "phi"] (docs/import.md)'
        )
    for c, v in given.items():
        flag = "--" + ("phi-rad" if c == "phi" else f"{c}-mm")
        if c not in desc.task:
            raise CliError(f"{flag}: {desc.name}'s task coordinates are {', '.join(desc.task)}; drop {flag}")
        if not math.isfinite(v):
            raise CliError(f"{flag}: must be a finite number, got {v}")
    from dataclasses import replace

    from fpm_sim.model.imported_pose import ImportedKinematics

    kin = ImportedKinematics(desc)
    pose = replace(
        kin.reference_pose(),
        **{("phi_rad" if c == "phi" else f"{c}_m"): (v if c == "phi" else v * 1e-3) for c, v in given.items()},
    )
    return kin.solve(pose, fixed=q), pose.label(desc.task)


def joint_values(items: list[str]) -> dict[str, float]:
    """``--q NAME=VALUE`` options as a mapping (rad for hinges, m for slides: MuJoCo's joint coordinates)."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            v = float(value)
        except ValueError:
            v = math.nan
        if not sep or not name or not math.isfinite(v):
            raise CliError(f"--q {item}: give a joint's value as NAME=VALUE (rad for a hinge, m for a slide)")
        out[name] = v
    return out


def held_task_coordinates(args: argparse.Namespace, desc: Description) -> dict[str, float]:
    """The task coordinates a dense grid holds: z (spatial; ``--z-mm``, default the first check pose's) and phi
    (``--phi-rad``, where the architecture sets it)."""
    if args.phi_rad and "phi" not in desc.task:
        raise CliError(f"--phi-rad: {desc.name} has no task coordinate phi; drop --phi-rad")
    if args.z_mm is not None and "z" not in desc.task:
        raise CliError(f"--z-mm: {desc.name} has no task coordinate z; drop --z-mm")
    home = desc.check_poses[0] if desc.check_poses else {}
    z = args.z_mm * 1e-3 if args.z_mm is not None else home.get("z", 0.0)
    return {"z": z, "phi": args.phi_rad}


def with_resolution(payload: dict[str, Any], options: ModelOptions) -> dict[str, Any]:
    """Add the ``resolution`` entry (segments, fidelity, f1 error estimate) to a JSON payload."""
    from fpm_sim.model.options import resolution_summary

    payload["resolution"] = resolution_summary(options)
    return payload


def resolution_line(options: ModelOptions) -> str:
    """The resolution line every table ends with."""
    from fpm_sim.model.options import resolution_label

    return "resolution: " + resolution_label(options)


def emit(args: argparse.Namespace, payload: dict[str, Any], text: str) -> None:
    """Print ``payload`` as JSON with ``--json``, else ``text``."""
    if getattr(args, "json", False):
        from fpm_sim.results import to_jsonable

        print(json.dumps(to_jsonable(payload), indent=2))
    else:
        print(text)


# ---------------------------------------------------------------------------------------------
# output paths, checked before any computation


def check_output_file(
    path: Path | None, option: str, suffixes: tuple[str, ...] = (), *, overwrite: bool | None = None
) -> None:
    """Check an output file path before computing: suffix, not a folder, creatable
    (:func:`fpm_sim.outputs.prove_creatable`) and, where the command has ``--overwrite`` (``overwrite`` not
    ``None``), not an existing file unless ``overwrite``.

    Raises :class:`CliError` (or :class:`fpm_sim.outputs.OutputError`) naming ``option``.
    """
    if path is None:
        return
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise CliError(f"{option} {path} must end in {' or '.join(suffixes)}; rename the file")
    if path.is_dir():
        ends = " or ".join(suffixes) or "a suffix"
        raise CliError(f"{option} {path} is a folder; give a file name (ending in {ends})")
    if overwrite is False and path.exists():
        raise CliError(f"{option} {path} already exists; pass --overwrite to replace it, or choose another file")
    prove_creatable(path, parameter=option)


def check_output_dir(path: Path, option: str, *, overwrite: bool, marker: str | None = None) -> None:
    """Check an output folder before computing: not a file, creatable, and not another run's folder.

    An existing non-empty folder is refused unless ``overwrite`` (it is then replaced atomically on success).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise CliError(f"{option} {path} is an existing file, not a folder; choose a folder name")
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise CliError(
            f"{option} {path} already holds another run's results; pass --overwrite to replace it, or choose "
            "another folder"
        )
    prove_creatable(path, parameter=option, folder=True)


def read_input_file(path: Path, option: str, loader: Any, what: str) -> Any:
    """``loader(path)``, with a missing, unreadable or malformed file reported as :class:`CliError` naming it.

    ``what`` says what the file should be (e.g. ``"an atlas written by 'fpm-sim atlas build'"``).
    """
    path = Path(path)
    if path.is_dir():
        raise CliError(f"{option} {path} is a folder; give {what}")
    if not path.exists():
        raise CliError(f"{option} {path}: file not found; give {what}")
    try:
        return loader(path)
    except FpmSimError:
        raise
    except Exception as exc:  # any reader failure (zip, MAT, missing key) is this file's problem: name it
        raise CliError(f"{option} {path} cannot be read ({type(exc).__name__}: {exc}); give {what}") from exc


# --------------------------------------------------------------------------------------------- the Dask engine


WORKERS_HELP = "processes for the pose loop (default: the CPU count, the same in every command)"
"""The one ``--workers`` default (``None`` on the command line: :func:`workers_of` gives the CPU count)."""


def workers_of(args: argparse.Namespace) -> int:
    """``--workers``, or the CPU count when it was not given (the one default of every command)."""
    import os

    w = getattr(args, "workers", None)
    return int(w) if w is not None else (os.cpu_count() or 1)


def add_engine_args(p: argparse.ArgumentParser, *, workers: bool = False) -> None:
    """``--scheduler``, ``--resume``, ``--chunk-poses`` (and ``--workers`` when the command has none yet)."""
    g = p.add_argument_group("engine (Dask)")
    g.add_argument(
        "--scheduler",
        default=None,
        help="where the pose loop runs: local (a Dask LocalCluster of --workers processes), serial (this process) "
        "or the address of a running scheduler, e.g. tcp://10.0.0.5:8786 (used unchanged); default: local for "
        "runs of 4000 poses or more, else serial",
    )
    g.add_argument(
        "--resume",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="continue a killed run with the same --out: reuse the chunks it finished (in OUT.partial/)",
    )
    g.add_argument(
        "--chunk-poses",
        type=int,
        default=None,
        help="poses per task (default: about four tasks per worker, 16-512; see docs/design.md, Scale on paper)",
    )
    if workers:
        g.add_argument("--workers", type=int, default=None, help=WORKERS_HELP)


def engine_options(args: argparse.Namespace, out: Path | None) -> Any:
    """The :class:`fpm_sim.batch.engine.EngineOptions` of ``--scheduler``, ``--workers``, ``--chunk-poses`` and
    ``--resume``; finished chunks stream to ``OUT.partial/`` (:func:`fpm_sim.batch.engine.chunk_store`)."""
    from fpm_sim.batch.engine import EngineOptions, chunk_store

    return EngineOptions(
        scheduler=getattr(args, "scheduler", None),
        workers=getattr(args, "workers", None),
        chunk=getattr(args, "chunk_poses", None),
        store=chunk_store(out) if out is not None else None,
        resume=bool(getattr(args, "resume", False)),
        progress=not getattr(args, "json", False),
    )


def finish_store(out: Path | None) -> None:
    """Remove the chunk folder of ``out`` after a complete run."""
    import shutil

    from fpm_sim.batch.engine import chunk_store

    if out is not None and chunk_store(out).exists():
        shutil.rmtree(chunk_store(out), ignore_errors=True)
