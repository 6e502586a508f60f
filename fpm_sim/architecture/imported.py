"""An *imported description*: a MuJoCo model (MJCF or URDF) with some of its bodies made flexible links.

The file's form (``docs/import.md``)::

    kind = "imported"
    name = "acrobot"
    model = "acrobot.xml"            # relative to this file, or absolute; .xml (MJCF) or .urdf
    locked_joints = ["shoulder"]     # locked besides the actuated ones (those an <actuator> drives)
    servo_joints = ["left_motor"]    # motors without an <actuator>: locked for modal analysis like the actuated
                                     # ones, position servos in a move (optional)

    [servos]                         # optional: the motors' servo gains in a move, as a described architecture's
    stiffness_nm_per_rad = 500.0     # (fpm_sim.architecture.description.ServoGains; defaults SERVO_SOURCE)

    [materials.aluminium]            # as a described architecture's (fpm_sim.architecture.reader)
    [sections.tube]

    [[flexible]]
    body = "upper_arm"               # the body whose link becomes a flexible beam
    section = "tube"
    material = "aluminium"
    # optional: start_m / end_m ([x, y, z] in the body's frame), end_site (a site's name), z_axis (the section's
    # height_m direction, in the body's frame), replace_geoms (the geoms the beam replaces)

    [end_effector]                   # optional: pose the model in task space (fpm_sim.model.imported_pose)
    site = "tool"                    # a site of the model
    coordinates = ["x", "y", "phi"]  # its task coordinates: x, y, z (the site's position in the world, m) and phi
                                     # (its x axis' heading about the world z axis, rad)

The beam runs by default from the body's own joint to its child body's joint (or to ``end_site``). Errors name the
path in the file, as the architecture reader's.
"""

from __future__ import annotations

import copy
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fpm_sim.architecture.description import AnySection, ServoGains, raise_at
from fpm_sim.architecture.reader import ValueReader, read_material, read_section, read_servos, table_keys
from fpm_sim.config import Material
from fpm_sim.config.schema import read_toml_file

__all__ = [
    "TASK_COORDINATES",
    "EndEffector",
    "FlexibleBody",
    "ImportedDescription",
    "is_imported_file",
    "load_imported",
    "parse_imported",
]

_TOP = {
    "kind",
    "name",
    "model",
    "default_source",
    "materials",
    "sections",
    "flexible",
    "locked_joints",
    "servo_joints",
    "servos",
    "damping",
    "end_effector",
}
TASK_COORDINATES = ("x", "y", "z", "phi")
"""The task coordinates an imported model's end-effector site may be posed by, in this order."""
_FLEX = {"body", "section", "material", "start_m", "end_m", "end_site", "z_axis", "replace_geoms"}


@dataclass(frozen=True)
class FlexibleBody:
    """One body of the model made a flexible link (see the module docstring for the defaults)."""

    body: str
    section: AnySection
    material: Material
    start_m: tuple[float, float, float] | None = None
    end_m: tuple[float, float, float] | None = None
    end_site: str | None = None
    z_axis: tuple[float, float, float] | None = None
    replace_geoms: tuple[str, ...] | None = None


@dataclass(frozen=True)
class EndEffector:
    """The site an imported model is posed by in task space, and which of its coordinates the pose sets."""

    site: str
    coordinates: tuple[str, ...]
    """A subset of :data:`TASK_COORDINATES`, in that order."""


@dataclass(frozen=True)
class ImportedDescription:
    """A MuJoCo model and the bodies of it made flexible (:func:`fpm_sim.model.imported.build_imported`)."""

    name: str
    model_path: Path
    flexible: tuple[FlexibleBody, ...]
    locked_joints: tuple[str, ...] = ()
    damping_beta_s: float = 0.0
    provenance: dict[str, str] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)
    source: str = "user"
    end_effector: EndEffector | None = None
    servo_joints: tuple[str, ...] = ()
    """Motors the model drives without an ``<actuator>``: locked for modal analysis as the actuated joints are,
    position servos in a move (:func:`fpm_sim.model.imported.build_imported` with ``motors="servo"``)."""
    servos: ServoGains = field(default_factory=ServoGains)
    """The motors' servo gains in a move (``[servos]``, as a described architecture's)."""

    @property
    def task(self) -> tuple[str, ...]:
        """The task coordinates the model is posed by (empty without an ``[end_effector]``: joint space only)."""
        return self.end_effector.coordinates if self.end_effector else ()

    def to_dict(self) -> dict[str, Any]:
        """The description as read (JSON-ready)."""
        return {"kind": "imported", "name": self.name, "model": str(self.model_path), **copy.deepcopy(self.data)}


def _strings(v: Any, path: str) -> tuple[str, ...]:
    if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
        raise_at(path, "must be a list of names", v)
    return tuple(v)


def _flexible(r: ValueReader, t: Any, path: str, libs: dict[str, dict[str, Any]]) -> FlexibleBody:
    table_keys(t, path, _FLEX)
    body = t.get("body")
    if not isinstance(body, str) or not body:
        raise_at(f"{path}.body", "must name a body of the model")
    picked = {}
    for kind in ("section", "material"):
        name = t.get(kind)
        if not isinstance(name, str) or name not in libs[kind + "s"]:
            raise_at(f"{path}.{kind}", f"no {kind} of that name", name, hint=f"define it under [{kind}s]")
        picked[kind] = libs[kind + "s"][name]
    end_site = t.get("end_site")
    if end_site is not None and not isinstance(end_site, str):
        raise_at(f"{path}.end_site", "must name a site of the model", end_site)
    if end_site is not None and "end_m" in t:
        raise_at(f"{path}.end_site", "give end_site or end_m, not both")
    return FlexibleBody(
        body=body,
        section=picked["section"],
        material=picked["material"],
        start_m=r.vec3(t, path, "start_m") if "start_m" in t else None,
        end_m=r.vec3(t, path, "end_m") if "end_m" in t else None,
        end_site=end_site,
        z_axis=r.vec3(t, path, "z_axis") if "z_axis" in t else None,
        replace_geoms=_strings(t["replace_geoms"], f"{path}.replace_geoms") if "replace_geoms" in t else None,
    )


def _end_effector(t: Any) -> EndEffector:
    table_keys(t, "end_effector", {"site", "coordinates"})
    site = t.get("site")
    if not isinstance(site, str) or not site:
        raise_at("end_effector.site", "must name a site of the model", site)
    coords = t.get("coordinates")
    if (
        not isinstance(coords, list)
        or not coords
        or any(c not in TASK_COORDINATES for c in coords)
        or len(set(coords)) != len(coords)
    ):
        raise_at(
            "end_effector.coordinates",
            f"must be a list of distinct task coordinates out of {', '.join(TASK_COORDINATES)}",
            coords,
            hint='e.g. coordinates = ["x", "y", "phi"] for a planar machine',
        )
    return EndEffector(site, tuple(c for c in TASK_COORDINATES if c in coords))


def parse_imported(data: dict[str, Any], *, base_dir: Path, source: str = "user") -> ImportedDescription:
    """A validated :class:`ImportedDescription` from parsed TOML; ``model`` is resolved against ``base_dir``."""
    table_keys(data, "<top>", _TOP)
    if data.get("kind") != "imported":
        raise_at("kind", "must be 'imported'", data.get("kind"))
    r = ValueReader(str(data.get("default_source", source)))
    model = data.get("model")
    if not isinstance(model, str) or not model.lower().endswith((".xml", ".urdf", ".mjcf")):
        raise_at("model", "must name a MuJoCo model file (.xml MJCF or .urdf)", model)
    path = Path(model) if Path(model).is_absolute() else Path(os.path.normpath(base_dir / model))  # as relpath
    if not path.is_file():
        raise_at("model", f"file not found: {path}", model, hint="give the path relative to the description file")
    libs: dict[str, dict[str, Any]] = {
        "materials": {k: read_material(r, v, f"materials.{k}") for k, v in data.get("materials", {}).items()},
        "sections": {k: read_section(r, v, f"sections.{k}") for k, v in data.get("sections", {}).items()},
    }
    raw = data.get("flexible")
    if not isinstance(raw, list) or not raw:
        raise_at("flexible", "an imported description needs at least one [[flexible]] table")
    flexible = tuple(_flexible(r, t, f"flexible[{i}]", libs) for i, t in enumerate(raw))
    names = [f.body for f in flexible]
    if len(set(names)) != len(names):
        raise_at("flexible", "a body is named flexible twice", names)
    damping = table_keys(data.get("damping", {}), "damping", {"stiffness_proportional_s"})
    locked = _strings(data.get("locked_joints", []), "locked_joints")
    servo = _strings(data.get("servo_joints", []), "servo_joints")
    if set(locked) & set(servo):
        raise_at(
            "servo_joints",
            "a joint is both locked and a servo",
            sorted(set(locked) & set(servo)),
            hint="name each motor once: in servo_joints (locked for modal analysis, a servo in a move)",
        )
    return ImportedDescription(
        name=str(data.get("name", path.stem)),
        model_path=path.resolve(),
        flexible=flexible,
        locked_joints=locked,
        servo_joints=servo,
        servos=read_servos(r, data.get("servos", {})),
        damping_beta_s=r.number(damping, "damping", "stiffness_proportional_s", 0.0),
        provenance=r.provenance,
        data=copy.deepcopy(data),
        source=source,
        end_effector=_end_effector(data["end_effector"]) if "end_effector" in data else None,
    )


def load_imported(path: str | Path) -> ImportedDescription:
    """Read an imported description (module docstring) from a TOML file."""
    p = Path(path)
    return parse_imported(read_toml_file(p, what="imported description"), base_dir=p.resolve().parent, source=str(p))


def is_imported_file(path: str | Path) -> bool:
    """Whether a TOML file is an imported description (``kind = "imported"``)."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return data.get("kind") == "imported"
