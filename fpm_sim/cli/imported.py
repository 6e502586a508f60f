"""``fpm-sim import``: write an imported description (``kind = "imported"``, :mod:`fpm_sim.architecture.imported`)
for a MuJoCo model (MJCF or URDF) with some of its bodies made flexible links.

The output is proven creatable (and refused when it exists, without ``--overwrite``) before the model is read; the
description is checked by building the import report (:func:`fpm_sim.model.imported.import_report`) before it is
written, atomically. Every value written carries its provenance (``{ value = ..., source = "fpm-sim import ..." }``).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import tomllib
from pathlib import Path
from typing import Any

from fpm_sim.cli.common import CliError, add_output_args, add_overwrite_arg, check_output_file, emit

__all__ = ["MATERIAL_PRESETS", "cmd_import", "parse_section_spec", "register"]

MATERIAL_PRESETS: dict[str, dict[str, float]] = {
    "steel": {"young_pa": 200e9, "poisson": 0.3, "density_kg_m3": 7850.0},
    "aluminium": {"young_pa": 70e9, "poisson": 0.33, "density_kg_m3": 2700.0},
}
"""The named materials of ``--material`` (E in Pa, Poisson's ratio, density in kg/m^3: handbook values)."""

_SECTION = re.compile(r"^(rect|tube):([0-9.eE+-]+)x([0-9.eE+-]+)mm$")


def parse_section_spec(spec: str) -> dict[str, Any]:
    """``rect:HEIGHTxTHICKNESSmm`` (height along the section's z, the joint axis by default) or
    ``tube:OUTERxWALLmm`` (outer diameter, wall thickness) as a section table in SI units."""
    m = _SECTION.match(spec.strip())
    try:
        a_mm, b_mm = (float(m.group(2)), float(m.group(3))) if m else (math.nan, math.nan)
    except ValueError:
        a_mm = b_mm = math.nan
    a, b = a_mm * 1e-3, b_mm * 1e-3
    if not m or not (math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0):
        raise CliError(
            f"--section {spec}: give rect:HEIGHTxTHICKNESSmm (e.g. rect:25x6mm) or tube:OUTERxWALLmm "
            "(e.g. tube:100x5mm), positive sizes in mm"
        )
    if m.group(1) == "rect":
        return {"shape": "rect", "height_m": a, "thickness_m": b}
    if 2 * b >= a:
        raise CliError(f"--section {spec}: the wall ({b * 1e3:g} mm) must be less than half the outer diameter")
    return {"shape": "tube", "outer_diameter_m": a, "inner_diameter_m": (a_mm - 2 * b_mm) * 1e-3}


def _names(text: str | None, option: str) -> list[str]:
    names = [n.strip() for n in (text or "").split(",")]
    if text is not None and (not names or not all(names)):
        raise CliError(f"{option} {text}: give names separated by commas (e.g. upper_arm,lower_arm)")
    return [n for n in names if n]


def _value(v: float, source: str) -> str:
    return f'{{ value = {v!r}, source = "{source}" }}'


def description_text(args: argparse.Namespace, out: Path) -> str:
    """The TOML text of the imported description ``args`` ask for, ``model`` relative to ``out``'s folder."""
    flexible = _names(args.flexible, "--flexible")
    if not flexible:
        raise CliError("--flexible: name at least one body (e.g. --flexible upper_arm,lower_arm)")
    if args.material not in MATERIAL_PRESETS:
        raise CliError(f"--material {args.material}: choose {' or '.join(MATERIAL_PRESETS)}")
    section = parse_section_spec(args.section)
    model = Path(args.model)
    if not model.is_file():
        raise CliError(f"MODEL {model}: file not found; give the MuJoCo model (.xml MJCF or .urdf)")
    rel = os.path.relpath(model.resolve(), out.resolve().parent)
    lines = [
        f"# {getattr(args, 'command_line', 'fpm-sim import')}",
        'kind = "imported"',
        f'name = "{model.stem}"',
        f"model = {_quote(rel)}",
        'default_source = "fpm-sim import"',
        f"locked_joints = [{', '.join(_quote(n) for n in _names(args.lock, '--lock'))}]",
        *(
            [f"servo_joints = [{', '.join(_quote(n) for n in _names(args.servo, '--servo'))}]  # servos in a move"]
            if args.servo
            else []
        ),
        "",
        f"[materials.{args.material}]",
    ]
    src = f"fpm-sim import --material {args.material} (preset)"
    lines += [f"{k} = {_value(v, src)}" for k, v in MATERIAL_PRESETS[args.material].items()]
    lines += ["", "[sections.link]", f'shape = "{section.pop("shape")}"']
    lines += [f"{k} = {_value(v, f'fpm-sim import --section {args.section}')}" for k, v in section.items()]
    lines += _end_effector_lines(args)
    from fpm_sim.model.imported import end_sites

    ends = end_sites(model, flexible)
    for body in flexible:
        lines += ["", "[[flexible]]", f"body = {_quote(body)}", 'section = "link"', f'material = "{args.material}"']
        if body in ends:
            lines.append(f"end_site = {_quote(ends[body])}  # the body's site farthest from its joint (no child joint)")
    return "\n".join(lines) + "\n"


def _end_effector_lines(args: argparse.Namespace) -> list[str]:
    """The ``[end_effector]`` table of ``--end-site`` and ``--task`` (none without them)."""
    from fpm_sim.architecture.imported import TASK_COORDINATES

    if args.end_site is None and args.task is None:
        return []
    if args.end_site is None or args.task is None:
        given, missing = ("--end-site", "--task") if args.task is None else ("--task", "--end-site")
        raise CliError(f"{given}: give --end-site SITE and --task COORDINATES together (missing {missing})")
    task = _names(args.task, "--task")
    if not task or any(c not in TASK_COORDINATES for c in task) or len(set(task)) != len(task):
        raise CliError(
            f"--task {args.task}: distinct task coordinates out of {','.join(TASK_COORDINATES)} (e.g. x,y,phi)"
        )
    coordinates = ", ".join(_quote(c) for c in TASK_COORDINATES if c in task)
    return ["", "[end_effector]", f"site = {_quote(args.end_site)}", f"coordinates = [{coordinates}]"]


def _with_mechanisms_locked(text: str, locked: list[str], mechanisms: list[str]) -> str:
    """``text`` with its ``locked_joints`` line replaced by ``locked``, a comment naming the ``mechanisms``."""
    line = next(ln for ln in text.splitlines() if ln.startswith("locked_joints = "))
    new = (
        f"locked_joints = [{', '.join(_quote(n) for n in locked)}]  # {', '.join(mechanisms)}: locked by the import "
        "(passive, nothing holds them: a mechanism)"
    )
    return text.replace(line, new, 1)


def _quote(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _named_error(exc: Exception, args: argparse.Namespace) -> CliError | None:
    """A model-import error on a table the flags wrote, as one line naming the flag."""
    parameter = str(getattr(exc, "parameter", "") or "")
    option = {
        "flexible": "--flexible",
        "locked_joints": "--lock",
        "servo_joints": "--servo",
        "model": "MODEL",
        "end_effector.site": "--end-site",
    }.get(parameter.split("[")[0])
    if option is None:
        return None
    hint = getattr(exc, "hint", None)
    return CliError(f"{option}: {getattr(exc, 'message', exc)}" + (f" ({hint})" if hint else ""))


def cmd_import(args: argparse.Namespace) -> int:
    from fpm_sim.architecture.imported import parse_imported
    from fpm_sim.errors import FpmSimError
    from fpm_sim.model.imported import import_report, mechanism_joints
    from fpm_sim.outputs import atomic_file

    check_output_file(args.out, "--out", (".toml",), overwrite=args.overwrite)
    text = description_text(args, args.out)
    try:
        desc = parse_imported(tomllib.loads(text), base_dir=args.out.resolve().parent, source=str(args.out))
        mechanisms = mechanism_joints(desc)
        if mechanisms:  # passive joints nothing holds: locked, and said so in the file and the output
            text = _with_mechanisms_locked(text, [*desc.locked_joints, *mechanisms], mechanisms)
            desc = parse_imported(tomllib.loads(text), base_dir=args.out.resolve().parent, source=str(args.out))
        report = import_report(desc)
        if desc.end_effector is not None:
            from fpm_sim.model.imported_pose import ImportedKinematics

            ImportedKinematics(desc)  # the site exists
    except FpmSimError as exc:
        named = _named_error(exc, args)
        if named is None:
            raise
        raise named from exc
    with atomic_file(args.out) as tmp:
        tmp.write_text(text)
    payload = {"out": str(args.out), "description": desc.to_dict(), "report": report.__dict__, "mechanisms": mechanisms}
    said = (
        f"locked as mechanisms: {', '.join(mechanisms)} (passive joints that nothing holds: free, they would make the "
        "machine a mechanism; take them out of locked_joints to analyse them free)\n"
        if mechanisms
        else ""
    )
    emit(args, payload, f"{report.table()}\n{said}wrote {args.out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import",
        help="write an imported description: a MuJoCo model (MJCF or URDF) with bodies made flexible links",
        description="Writes a description (kind = 'imported', docs/import.md) naming MODEL, with one [[flexible]] "
        "table per body of --flexible at --section and --material, every value with its provenance; prints what "
        "the import keeps and replaces. Every other command then takes it with --config. With --end-site and --task "
        "the model is also posed in task space (--x-mm, --y-mm, --z-mm, --phi-rad, or a poses CSV of them).",
    )
    p.add_argument("model", type=Path, metavar="MODEL", help="the MuJoCo model: MJCF (.xml) or URDF (.urdf)")
    p.add_argument("--flexible", required=True, metavar="BODY,...", help="the bodies made flexible links")
    p.add_argument(
        "--section",
        required=True,
        metavar="SPEC",
        help="the links' section: rect:HEIGHTxTHICKNESSmm (e.g. rect:25x6mm) or tube:OUTERxWALLmm (tube:100x5mm)",
    )
    p.add_argument("--material", required=True, metavar="NAME", help="the links' material: steel or aluminium")
    p.add_argument("--lock", metavar="JOINT,...", help="joints locked besides the actuated ones")
    p.add_argument(
        "--servo",
        metavar="JOINT,...",
        help="motors without an <actuator> (servo_joints): locked for modal analysis like the actuated joints, "
        "position servos in a move",
    )
    p.add_argument(
        "--end-site",
        metavar="SITE",
        help="the end effector's site: the model is then posed in task space too (--x-mm ...; with --task)",
    )
    p.add_argument(
        "--task",
        metavar="COORDS",
        help="the end-effector site's task coordinates, out of x,y,z,phi (world position, heading about z; "
        "e.g. x,y,phi)",
    )
    p.add_argument("--out", type=Path, required=True, help="the description file to write (.toml)")
    add_overwrite_arg(p)
    add_output_args(p)
    p.set_defaults(func=cmd_import)
