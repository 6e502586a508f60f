"""Reading and setting one value of a description by its dotted name (``section.thickness_m``,
``hardware.platform.mass_kg``): what design studies vary and what gradients are taken with respect to."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

from fpm_sim.config.schema import Manipulator
from fpm_sim.errors import FpmSimError

__all__ = ["EXAMPLE_PARAMETERS", "parameter_value", "with_parameter"]

EXAMPLE_PARAMETERS = ("section.thickness_m", "material.young_pa", "hardware.platform.mass_kg")
"""Dotted names an unknown name's hint suggests."""


def parameter_value(config: Manipulator, name: str, *, examples: Sequence[str] = EXAMPLE_PARAMETERS) -> float:
    """The value (SI) of a dotted parameter name, e.g. ``section.thickness_m``.

    Raises
    ------
    FpmSimError
        ``name`` is not a settable numeric field; the hint lists the fields settable where it failed and
        ``examples`` of dotted names.
    """
    obj: Any = config
    for part in name.split("."):
        settable = [f.name for f in dataclasses.fields(obj)] if dataclasses.is_dataclass(obj) else []
        if part not in settable:
            what = "a derived value, not a settable field" if hasattr(obj, part) else "not a field"
            raise FpmSimError(
                f"unknown parameter: {part!r} is {what}",
                parameter=name,
                hint=f"settable here: {', '.join(settable) or 'none'}; e.g. {', '.join(examples)}",
            )
        obj = getattr(obj, part)
    if not isinstance(obj, (int, float)) or isinstance(obj, bool):
        raise FpmSimError("is not a number", parameter=name)
    return float(obj)


def with_parameter(config: Manipulator, name: str, value: float) -> Manipulator:
    """A copy of ``config`` with the dotted parameter ``name`` set to ``value`` (validated)."""
    parameter_value(config, name)
    parts = name.split(".")

    def rebuild(obj: Any, path: list[str]) -> Any:
        if len(path) == 1:
            return dataclasses.replace(obj, **{path[0]: value})
        return dataclasses.replace(obj, **{path[0]: rebuild(getattr(obj, path[0]), path[1:])})

    edited: Manipulator = rebuild(config, parts).replace()
    return edited
