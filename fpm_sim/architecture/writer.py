"""Writing a described architecture back as TOML: the parsed mapping it keeps (:attr:`Description.data`), edits and
provenance included, in a form :func:`fpm_sim.architecture.load_description` reads to the same machine."""

from __future__ import annotations

import json
import math
import re
from typing import Any

from fpm_sim.architecture.description import Description
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.config.schema import ConfigError

__all__ = ["description_toml"]

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else json.dumps(k)


def _value(v: Any) -> str:
    """One TOML value, inline (tables as ``{ k = v }``)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ConfigError("a description holds only finite numbers", value=v)
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise ConfigError(f"cannot write a {type(v).__name__} as TOML", value=v)


def description_toml(desc: Description | ImportedDescription, *, header: str = "") -> str:
    """``desc``'s file as TOML text: top-level values first, each table under its header, each chain as a
    ``[[chains]]`` table with its path one entry a line; ``header`` lines become ``#`` comments. An imported
    description's ``model`` is written as its absolute path (the text is read from anywhere), its ``[[flexible]]``
    tables inline."""
    if desc.data is None:
        raise ConfigError(
            f"{desc.name} was built in code, not read from a file: nothing to write",
            hint="fpm_sim.architecture.three_rrr.three_rrr_toml writes the 3RRR",
        )
    data = desc.data
    if isinstance(desc, ImportedDescription):
        data = {**data, "model": str(desc.model_path)}
    lines = [f"# {ln}" for ln in header.splitlines()]
    tables = {k: v for k, v in data.items() if isinstance(v, dict) and k != "chains"}
    for k, v in data.items():
        if k not in tables and k != "chains":
            lines.append(f"{_key(k)} = {_value(v)}")
    for name, table in tables.items():
        inner = {k: v for k, v in table.items() if isinstance(v, dict) and not set(v) <= {"value", "source"}}
        plain = {k: v for k, v in table.items() if k not in inner}
        if plain or not inner:
            lines += ["", f"[{_key(name)}]"] + [f"{_key(k)} = {_value(v)}" for k, v in plain.items()]
        for k, v in inner.items():
            lines += ["", f"[{_key(name)}.{_key(k)}]"] + [f"{_key(k2)} = {_value(v2)}" for k2, v2 in v.items()]
    for chain in data.get("chains", []):
        lines += ["", "[[chains]]"]
        for k, v in chain.items():
            if k == "path" and isinstance(v, list):
                lines += ["path = ["] + [f"  {_value(e)}," for e in v] + ["]"]
            else:
                lines.append(f"{_key(k)} = {_value(v)}")
    return "\n".join(lines) + "\n"
