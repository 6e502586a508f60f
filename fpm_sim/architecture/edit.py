"""Reading and setting one value of a described architecture by a dotted path into its TOML file.

A path names a number the way the file writes it (``docs/architectures.md``, Dotted paths)::

    materials.steel.young_pa            [materials.steel] young_pa
    sections.bar.height_m               [sections.bar] height_m (every link of section "bar" changes)
    lumps.elbow.mass_kg                 [lumps.elbow] mass_kg (every joint carrying lump "elbow" changes)
    lumps.elbow.inertia_kg_m2[2]        one item of a list of numbers
    chains.left.proximal.length_m       the link (or joint) "proximal" of the chain named "left"
    chains.left.elbow.branch_deg[1]     a joint's working-mode interval
    chains.left.base_position_m[0]      the chain's own keys
    end_effector.attachments_m.p[1]     an attachment point
    end_effector.lumps[0].position_m[2] an item of a list of tables, by its index
    damping.stiffness_proportional_s

A list of tables is entered by an item's name (a chain's ``name``, a path entry's ``joint`` or ``link``) or its index
(``chains[0].path[1].length_m``, the form of the reader's error paths, is read too). Only numbers written in the file
are settable (a value left to its default is settable once written). An edit changes the parsed TOML mapping the
description keeps (:attr:`Description.data`) and reads it again, so the edited machine is validated exactly as the file
is (a negative height is the reader's error, naming the path) and its provenance says ``design study`` (or ``source``).

An imported description (:mod:`fpm_sim.architecture.imported`) is edited the same way:
``sections.tube.outer_diameter_m``, ``materials.aluminium.density_kg_m3``, ``flexible.upper_arm.end_m[0]`` (a
``[[flexible]]`` table by its ``body``),
``damping.stiffness_proportional_s``; it is read again by :func:`~fpm_sim.architecture.imported.parse_imported`, its
``model`` kept as the file writes it.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from pathlib import Path
from typing import Any, overload

from fpm_sim.architecture.description import Description
from fpm_sim.architecture.imported import ImportedDescription, parse_imported
from fpm_sim.architecture.reader import parse_description
from fpm_sim.config import Manipulator, parameter_value, with_parameter
from fpm_sim.config.schema import ConfigError

__all__ = [
    "DESIGN_SOURCE",
    "ParameterPathError",
    "description_value",
    "machine_parameter",
    "settable_paths",
    "with_description_value",
    "with_machine_parameter",
]

DESIGN_SOURCE = "design study"
"""The provenance of an edited value (:func:`with_description_value`'s default)."""
EXAMPLE_PATHS = ("sections.<name>.height_m", "materials.<name>.young_pa", "chains.<chain>.<link>.length_m")

_PART = re.compile(r"^([^\[\]\s]+)((?:\[\d+\])*)$")
Key = str | int


class ParameterPathError(ConfigError):
    """A dotted path names no settable number of the description (or the description has no file to edit)."""


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_wrapped(v: Any) -> bool:
    """``{ value = ..., source = "..." }``: a value with its provenance."""
    return isinstance(v, dict) and "value" in v and set(v) <= {"value", "source"}


def _parts(name: str) -> list[Key]:
    if not isinstance(name, str) or not name.strip():
        raise ParameterPathError("give a dotted path", parameter="parameter", value=name, hint=_examples())
    out: list[Key] = []
    for part in name.strip().split("."):
        m = _PART.match(part)
        if not m:
            raise ParameterPathError(
                f"cannot read {part!r}", parameter=name, hint="join names by dots, list items as [k]; " + _examples()
            )
        out.append(m.group(1))
        out.extend(int(k) for k in re.findall(r"\d+", m.group(2)))
    return out


def _examples() -> str:
    return "e.g. " + ", ".join(EXAMPLE_PATHS)


def _item_name(item: Any) -> str | None:
    if isinstance(item, dict):
        for key in ("name", "joint", "link", "body"):
            if isinstance(item.get(key), str):
                return str(item[key])
    return None


def _settable(node: Any, prefix: str) -> list[str]:
    """What can follow ``prefix`` at ``node`` (for the hint of an unknown path)."""
    pre = f"{prefix}." if prefix else ""
    if isinstance(node, list):
        names = [n for n in (_item_name(i) for i in node) if n]
        if names:
            return [f"{pre}{n}" for n in names]
        return [f"{prefix}[0..{len(node) - 1}]"] if node else []
    if not isinstance(node, dict):
        return []
    out = []
    for k, v in node.items():
        if k == "check_poses" or (k == "path" and isinstance(v, list)):  # a chain's path: its entries by name, below
            continue
        v = v["value"] if _is_wrapped(v) else v
        if _is_number(v):
            out.append(f"{pre}{k}")
        elif isinstance(v, list) and v and all(_is_number(x) for x in v):
            out.append(f"{pre}{k}[0..{len(v) - 1}]")
        elif isinstance(v, dict) and v:
            inner = [k2 for k2, v2 in v.items() if not isinstance(v2, (str, bool))]
            out.append(f"{pre}{k}.<{'|'.join(inner)}>")
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            names = [n for n in (_item_name(i) for i in v) if n]
            out.append(f"{pre}{k}.<{'|'.join(names)}>" if names else f"{pre}{k}[0..{len(v) - 1}]")
    if isinstance(node.get("path"), list):  # a chain: its joints and links by name
        out += [f"{pre}{n}" for n in (_item_name(i) for i in node["path"]) if n]
    return out


def _unknown(name: str, node: Any, done: str, why: str) -> ParameterPathError:
    here = _settable(node, done)
    return ParameterPathError(
        f"unknown parameter: {why}",
        parameter=name,
        hint=f"settable {'under ' + done if done else 'here'}: {', '.join(here) or 'nothing'}; {_examples()}",
    )


def _step(name: str, node: Any, part: Key, done: str) -> list[Key]:
    """The keys of the file that ``part`` names below ``node`` (a chain's path entry: ``path``, its index)."""
    if isinstance(part, int):
        if isinstance(node, list) and 0 <= part < len(node):
            return [part]
        size = f"a list of {len(node)}" if isinstance(node, list) else "not a list"
        raise _unknown(name, node, done, f"[{part}]: {done or 'this'} is {size}")
    if isinstance(node, dict):
        if part in node and not _is_wrapped(node):
            return [part]
        if isinstance(node.get("path"), list):
            for k, e in enumerate(node["path"]):
                if _item_name(e) == part:
                    return ["path", k]
    if isinstance(node, list):
        for k, e in enumerate(node):
            if _item_name(e) == part:
                return [k]
    raise _unknown(name, node, done, f"no {part!r} {'under ' + done if done else 'at the top'}")


def _resolve(data: dict[str, Any], name: str) -> tuple[list[Key], int]:
    """The keys of the number ``name`` names in ``data``, and how many of them lead to the file's value (the key
    whose value is the number, the list or its ``{ value, source }``: what the provenance is recorded for)."""
    node: Any = data
    keys: list[Key] = []
    value_at = 0
    done = ""
    parts = _parts(name)
    if parts[0] == "check_poses":
        raise ParameterPathError(
            "the check poses are where a machine is checked, not a design parameter", parameter=name, hint=_examples()
        )
    for part in parts:
        if _is_wrapped(node):
            keys.append("value")
            node = node["value"]
        for k in _step(name, node, part, done):
            keys.append(k)
            node = node[k]
        done = f"{done}[{part}]" if isinstance(part, int) else (f"{done}.{part}" if done else str(part))
        if not value_at and (_is_wrapped(node) or _is_number(node) or _is_number_list(node)):
            value_at = len(keys)
    if _is_wrapped(node):
        keys.append("value")
        node = node["value"]
    if not _is_number(node):
        if _is_number_list(node):
            raise ParameterPathError(
                f"is a list of {len(node)} numbers",
                parameter=name,
                hint=f"name one item: {name}[0] .. [{len(node) - 1}]",
            )
        if isinstance(node, (dict, list)):
            raise _unknown(name, node, done, f"{done} is a table, not a number")
        raise ParameterPathError("is not a number (a name or a choice of the file)", parameter=name, value=node)
    return keys, value_at


def _is_number_list(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(_is_number(x) for x in v)


def _data(desc: Description | ImportedDescription, name: str) -> dict[str, Any]:
    if desc.data is None:
        raise ParameterPathError(
            f"{desc.name} was built in code, not read from a file: it has no dotted paths",
            parameter=name,
            hint="load it with fpm_sim.architecture.load_description (or parse_description) to edit it by path",
        )
    return desc.data


def _get(data: Any, keys: list[Key]) -> Any:
    for k in keys:
        data = data[k]
    return data


def description_value(desc: Description | ImportedDescription, name: str) -> float:
    """The number (SI, as the file writes it) at the dotted path ``name`` (module docstring).

    Raises
    ------
    ParameterPathError
        ``name`` names no number of the file; the hint lists what is settable where it failed.
    """
    data = _data(desc, name)
    keys, _ = _resolve(data, name)
    return float(_get(data, keys))


def _file_path(keys: list[Key]) -> str:
    """The reader's name of the value at ``keys`` (``chains[0].path[1].length_m``)."""
    out = ""
    for k in keys:
        if k == "value":
            continue
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
    return out


@overload
def with_description_value(desc: Description, name: str, value: float, *, source: str = ...) -> Description: ...
@overload
def with_description_value(
    desc: ImportedDescription, name: str, value: float, *, source: str = ...
) -> ImportedDescription: ...
def with_description_value(
    desc: Description | ImportedDescription, name: str, value: float, *, source: str = DESIGN_SOURCE
) -> Description | ImportedDescription:
    """A copy of ``desc`` with the number at ``name`` set to ``value``, read again from the edited file (validated as
    the file is; its provenance ``source``). A section, material or lump shared by several links changes in all.

    Raises
    ------
    ParameterPathError
        ``name`` names no number of the file.
    ConfigError
        ``value`` is not a finite number, or the edited file is invalid (the reader's error, naming ``name``).
    """
    data = _data(desc, name)
    keys, value_at = _resolve(data, name)
    if not _is_number(value) or not math.isfinite(value):
        raise ConfigError("must be a finite number", parameter=name, value=value)
    new = copy.deepcopy(data)
    _get(new, keys[:-1])[keys[-1]] = float(value)
    holder, key = _get(new, keys[: value_at - 1]), keys[value_at - 1]
    if _is_wrapped(holder[key]):
        holder[key]["source"] = source
    else:
        holder[key] = {"value": holder[key], "source": source}
    try:
        if isinstance(desc, ImportedDescription):
            return _reparse_imported(desc, new)
        edited = parse_description(new, source=desc.source)
    except ConfigError as exc:
        here = _file_path(keys[:value_at])
        same = exc.parameter is not None and (here.startswith(exc.parameter) or exc.parameter.startswith(here))
        raise ConfigError(
            exc.message if same else f"{value:g} makes the file invalid: {exc.parameter}: {exc.message}",
            parameter=name,
            value=value,
            hint=exc.hint,
        ) from None
    return dataclasses.replace(edited, source_file=desc.source_file)


def _reparse_imported(desc: ImportedDescription, new: dict[str, Any]) -> ImportedDescription:
    """The edited file of an imported description, read again at its model (resolved already), the file's own
    ``model`` text kept."""
    edited = parse_imported({**new, "model": str(desc.model_path)}, base_dir=Path(desc.model_path).parent)
    return dataclasses.replace(edited, data=new, source=desc.source)


def settable_paths(desc: Description | ImportedDescription) -> list[str]:
    """Every dotted path of a number in ``desc``'s file (chains and path entries by name, other lists by index)."""
    out: list[str] = []

    def walk(node: Any, prefix: str) -> None:
        if _is_wrapped(node):
            node = node["value"]
        if _is_number(node):
            out.append(prefix)
        elif _is_number_list(node):
            out.extend(f"{prefix}[{k}]" for k in range(len(node)))
        elif isinstance(node, dict):
            for k, v in node.items():
                if k == "check_poses" and not prefix:
                    continue
                if k == "path" and isinstance(v, list):
                    for k2, e in enumerate(v):
                        walk(e, f"{prefix}.{_item_name(e) or f'path[{k2}]'}")
                else:
                    walk(v, f"{prefix}.{k}" if prefix else str(k))
        elif isinstance(node, list):
            for k, e in enumerate(node):
                n = _item_name(e)
                walk(e, f"{prefix}.{n}" if n else f"{prefix}[{k}]")

    walk(_data(desc, "parameter"), "")
    return out


def machine_parameter(machine: Manipulator | Description | ImportedDescription, name: str) -> float:
    """The value of a dotted name on any form: the 3RRR's (:func:`fpm_sim.config.parameter_value`,
    ``section.thickness_m``), a described architecture's or an imported model's (:func:`description_value`, a path
    into its file: ``sections.bar.height_m``)."""
    if isinstance(machine, (Description, ImportedDescription)):
        return description_value(machine, name)
    return parameter_value(machine, name)


@overload
def with_machine_parameter(machine: Manipulator, name: str, value: float) -> Manipulator: ...
@overload
def with_machine_parameter(machine: Description, name: str, value: float) -> Description: ...
@overload
def with_machine_parameter(machine: ImportedDescription, name: str, value: float) -> ImportedDescription: ...
def with_machine_parameter(
    machine: Manipulator | Description | ImportedDescription, name: str, value: float
) -> Manipulator | Description | ImportedDescription:
    """``machine`` with the dotted name set: :func:`with_description_value` (a described architecture or an imported
    model) or :func:`fpm_sim.config.with_parameter` (the 3RRR)."""
    if isinstance(machine, (Description, ImportedDescription)):
        return with_description_value(machine, name, value)
    return with_parameter(machine, name, value)
