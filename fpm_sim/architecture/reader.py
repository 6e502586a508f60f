"""Reading a manipulator description (:mod:`fpm_sim.architecture.description`) from TOML.

The file's form (``examples/architectures/*.toml`` are complete examples; ``docs/architectures.md`` explains it)::

    name = "five-bar"
    kind = "planar"                  # or "spatial"
    task = ["x", "y"]                # the end effector's coordinates a pose sets
    default_source = "example specification"   # provenance of every bare number below

    [materials.steel]                # E (Pa), Poisson's ratio, density (kg/m^3)
    [sections.bar]                   # shape = "rect" (thickness_m along the link's y, height_m along z),
                                     # "tube" (outer_diameter_m, inner_diameter_m) or "general"
                                     # (area_m2, i_inplane_m4, i_outofplane_m4, torsion_constant_m4)
    [lumps.elbow]                    # mass_kg, inertia_kg_m2 (principal, about its own centre)

    [end_effector]
    attachments_m = { p = [0.0, 0.0, 0.0] }
    lumps = [{ lump = "tool", position_m = [0.0, 0.0, 0.0] }]

    [[chains]]
    name = "left"
    base_position_m = [-0.08, 0.0, 0.0]
    base_rotation_deg = 0.0          # about base_rotation_axis (default z)
    path = [
      { joint = "motor", type = "revolute", axis = [0, 0, 1], actuated = true },
      { link = "proximal", length_m = 0.18, section = "bar", material = "steel" },
      { joint = "elbow", type = "revolute", lump = "elbow", branch_deg = [-180, 0] },
      { link = "distal", length_m = 0.22, section = "bar", material = "steel" },
      { joint = "ee", type = "fixed", at = "p" },
    ]
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture.description import (
    JOINT_TYPES,
    PLANAR_TASK,
    SPATIAL_TASK,
    AnySection,
    ChainDesc,
    Description,
    EndEffectorDesc,
    GeneralSection,
    JointDesc,
    LinkDesc,
    PlacedLump,
    ServoGains,
    TubeSection,
    raise_at,
)
from fpm_sim.config import LumpedMass, Material, Section
from fpm_sim.config.schema import ConfigError, read_toml_file

__all__ = ["is_description_file", "load_description", "parse_description"]

_TOP = {
    "name",
    "kind",
    "task",
    "default_source",
    "materials",
    "sections",
    "lumps",
    "end_effector",
    "chains",
    "damping",
    "check_poses",
    "servos",
}
_TASK_KEYS = {"x": "x_mm", "y": "y_mm", "z": "z_mm", "phi": "phi_rad"}


class _Values:
    """Reads numbers out of tables, recording provenance under the value's path in the file."""

    def __init__(self, default_source: str) -> None:
        self.default_source = default_source
        self.provenance: dict[str, str] = {}

    def raw(self, table: dict[str, Any], path: str, key: str, default: Any = ...) -> Any:
        full = f"{path}.{key}"
        if key not in table:
            if default is ...:
                raise_at(full, "missing")
            return default
        v = table[key]
        if isinstance(v, dict) and "value" in v:
            if set(v) - {"value", "source"}:
                raise_at(full, f"unknown keys {sorted(set(v) - {'value', 'source'})}", hint="use 'value' and 'source'")
            src = v.get("source", self.default_source)
            if not isinstance(src, str) or not src:
                raise_at(f"{full}.source", "must be a non-empty string")
            self.provenance[full] = src
            return v["value"]
        self.provenance[full] = self.default_source
        return v

    def number(
        self, table: dict[str, Any], path: str, key: str, default: Any = ..., *, positive: bool = False
    ) -> float:
        v = self.raw(table, path, key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise_at(f"{path}.{key}", "must be a finite number", v)
        if positive and v <= 0:
            raise_at(f"{path}.{key}", "must be > 0", v)
        return float(v)

    def vector(
        self, table: dict[str, Any], path: str, key: str, default: Any = ..., *, n: int = 3
    ) -> tuple[float, ...]:
        v = self.raw(table, path, key, default)
        ok = isinstance(v, (list, tuple)) and len(v) == n
        if not ok or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in v):
            raise_at(f"{path}.{key}", f"must be a list of {n} finite numbers", v)
        return tuple(float(x) for x in v)

    def vec3(self, table: dict[str, Any], path: str, key: str, default: Any = ...) -> tuple[float, float, float]:
        x, y, z = self.vector(table, path, key, default, n=3)
        return (x, y, z)


def _keys(table: Any, path: str, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise_at(path, "must be a table")
    unknown = set(table) - allowed
    if unknown:
        raise_at(path, f"unknown field(s) {sorted(unknown)}", hint=f"allowed: {', '.join(sorted(allowed))}")
    return table


def _material(r: _Values, t: Any, path: str) -> Material:
    _keys(t, path, {"young_pa", "poisson", "density_kg_m3"})
    nu = r.number(t, path, "poisson")
    if not -1.0 < nu < 0.5:
        raise_at(f"{path}.poisson", "must lie in (-1, 0.5)", nu)
    return Material(r.number(t, path, "young_pa", positive=True), nu, r.number(t, path, "density_kg_m3", positive=True))


def _section(r: _Values, t: Any, path: str) -> AnySection:
    shape = _keys(
        t,
        path,
        {
            "shape",
            "thickness_m",
            "height_m",
            "outer_diameter_m",
            "inner_diameter_m",
            "area_m2",
            "i_inplane_m4",
            "i_outofplane_m4",
            "torsion_constant_m4",
        },
    ).get("shape", "rect")
    if shape == "rect":
        _keys(t, path, {"shape", "thickness_m", "height_m"})
        return Section(r.number(t, path, "thickness_m", positive=True), r.number(t, path, "height_m", positive=True))
    if shape == "tube":
        _keys(t, path, {"shape", "outer_diameter_m", "inner_diameter_m"})
        outer = r.number(t, path, "outer_diameter_m", positive=True)
        inner = r.number(t, path, "inner_diameter_m", 0.0)
        if not 0.0 <= inner < outer:
            raise_at(f"{path}.inner_diameter_m", f"must lie in [0, outer_diameter_m = {outer}) m", inner)
        return TubeSection(outer, inner)
    if shape == "general":
        _keys(t, path, {"shape", "area_m2", "i_inplane_m4", "i_outofplane_m4", "torsion_constant_m4"})
        names = ("area_m2", "i_inplane_m4", "i_outofplane_m4", "torsion_constant_m4")
        return GeneralSection(*(r.number(t, path, k, positive=True) for k in names))
    raise_at(f"{path}.shape", "unknown section shape", shape, hint="choose rect, tube or general")


def _lump(r: _Values, t: Any, path: str) -> LumpedMass:
    _keys(t, path, {"mass_kg", "inertia_kg_m2"})
    mass = r.number(t, path, "mass_kg")
    inertia = r.vector(t, path, "inertia_kg_m2", (0.0, 0.0, 0.0))
    if mass < 0 or min(inertia) < 0:
        raise_at(path, "mass and inertia must be >= 0", (mass, inertia))
    a, b, c = inertia
    if a + b < c * (1 - 1e-9) or b + c < a * (1 - 1e-9) or a + c < b * (1 - 1e-9):
        raise_at(f"{path}.inertia_kg_m2", "violates the triangle inequality of principal inertias", inertia)
    return LumpedMass(mass, (a, b, c))


def _named(kind: str, table: dict[str, Any], name: Any, path: str) -> Any:
    if not isinstance(name, str) or name not in table:
        raise_at(
            path, f"no {kind} of that name", name, hint=f"define it under [{kind}s] ({', '.join(table) or 'none'})"
        )
    return table[name]


def _unit(v: tuple[float, ...], path: str) -> tuple[float, float, float]:
    n = math.sqrt(sum(x * x for x in v))
    if n < 1e-12:
        raise_at(path, "must be a non-zero vector", v)
    return (v[0] / n, v[1] / n, v[2] / n)


def _joint(r: _Values, e: dict[str, Any], path: str, lumps: dict[str, LumpedMass]) -> JointDesc:
    _keys(e, path, {"joint", "type", "axis", "axis2", "actuated", "lump", "lump_after", "branch_deg", "branch_m", "at"})
    jtype = str(e.get("type"))
    if jtype not in JOINT_TYPES:
        raise_at(f"{path}.type", "unknown joint type", jtype, hint=f"choose one of {', '.join(JOINT_TYPES)}")
    actuated = e.get("actuated", False)
    if not isinstance(actuated, bool):
        raise_at(f"{path}.actuated", "must be true or false", actuated)
    branch: tuple[float, float] | None = None
    key = "branch_deg" if jtype == "revolute" else "branch_m"
    wrong = "branch_m" if jtype == "revolute" else "branch_deg"
    if wrong in e:
        raise_at(f"{path}.{wrong}", f"a {jtype} joint's working mode is given by {key}")
    if key in e:
        lo, hi = r.vector(e, path, key, n=2)
        if not lo < hi:
            raise_at(f"{path}.{key}", "must be an interval [low, high] with low < high", [lo, hi])
        branch = (math.radians(lo), math.radians(hi)) if jtype == "revolute" else (lo, hi)
    at = e.get("at")
    if at is not None and not isinstance(at, str):
        raise_at(f"{path}.at", "must name an attachment point of [end_effector]", at)
    return JointDesc(
        name=str(e["joint"]),
        type=jtype,
        axis=_unit(r.vector(e, path, "axis", (0.0, 0.0, 1.0)), f"{path}.axis"),
        axis2=_unit(r.vector(e, path, "axis2", (0.0, 1.0, 0.0)), f"{path}.axis2"),
        actuated=actuated,
        lump=_named("lump", lumps, e["lump"], f"{path}.lump") if "lump" in e else LumpedMass(),
        lump_after=_named("lump", lumps, e["lump_after"], f"{path}.lump_after") if "lump_after" in e else LumpedMass(),
        branch=branch,
        at=at,
    )


def _link(r: _Values, e: dict[str, Any], path: str, libs: dict[str, dict[str, Any]]) -> LinkDesc:
    _keys(e, path, {"link", "length_m", "section", "material", "flexible", "end_lump"})
    flexible = e.get("flexible", True)
    if not isinstance(flexible, bool):
        raise_at(f"{path}.flexible", "must be true or false", flexible)
    return LinkDesc(
        name=str(e["link"]),
        length_m=r.number(e, path, "length_m", positive=True),
        section=_named("section", libs["sections"], e.get("section"), f"{path}.section"),
        material=_named("material", libs["materials"], e.get("material"), f"{path}.material"),
        flexible=flexible,
        end_lump=_named("lump", libs["lumps"], e["end_lump"], f"{path}.end_lump") if "end_lump" in e else LumpedMass(),
    )


def _rotation(r: _Values, t: dict[str, Any], path: str) -> tuple[tuple[float, float, float], ...]:
    angle = math.radians(r.number(t, path, "base_rotation_deg", 0.0))
    axis = np.array(_unit(r.vector(t, path, "base_rotation_axis", (0.0, 0.0, 1.0)), f"{path}.base_rotation_axis"))
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)
    return tuple((float(row[0]), float(row[1]), float(row[2])) for row in rot)


def _chain(r: _Values, t: Any, path: str, libs: dict[str, dict[str, Any]]) -> ChainDesc:
    _keys(t, path, {"name", "parent", "base_position_m", "base_rotation_deg", "base_rotation_axis", "path"})
    name = t.get("name")
    if not isinstance(name, str) or not name:
        raise_at(f"{path}.name", "every chain needs a name")
    items = t.get("path")
    if not isinstance(items, list) or not items:
        raise_at(f"{path}.path", "must be a non-empty list of joints and links")
    elements: list[JointDesc | LinkDesc] = []
    for k, e in enumerate(items):
        epath = f"{path}.path[{k}]"
        if not isinstance(e, dict) or ("joint" in e) == ("link" in e):
            raise_at(epath, "each entry is a joint ({ joint = ... }) or a link ({ link = ... })")
        elements.append(_joint(r, e, epath, libs["lumps"]) if "joint" in e else _link(r, e, epath, libs))
    parent = t.get("parent")
    if parent is not None and not isinstance(parent, str):
        raise_at(f"{path}.parent", "must name another chain", parent)
    return ChainDesc(
        name=name,
        path=tuple(elements),
        base_position_m=r.vec3(t, path, "base_position_m", (0.0, 0.0, 0.0)),
        base_rotation=_rotation(r, t, path),
        parent=parent,
    )


def _end_effector(r: _Values, t: Any, lumps: dict[str, LumpedMass]) -> EndEffectorDesc:
    _keys(t, "end_effector", {"attachments_m", "lumps"})
    att = t.get("attachments_m")
    if not isinstance(att, dict) or not att:
        raise_at("end_effector.attachments_m", "must name at least one attachment point: { name = [x, y, z] }")
    points = {k: r.vec3(att, "end_effector.attachments_m", k) for k in att}
    placed: list[PlacedLump] = []
    raw_lumps = t.get("lumps", [])
    if not isinstance(raw_lumps, list):
        raise_at("end_effector.lumps", "must be a list of { lump = .., position_m = [..] }")
    for k, e in enumerate(raw_lumps):
        p = f"end_effector.lumps[{k}]"
        _keys(e, p, {"lump", "position_m"})
        placed.append(
            PlacedLump(_named("lump", lumps, e.get("lump"), f"{p}.lump"), r.vec3(e, p, "position_m", (0.0, 0.0, 0.0)))
        )
    return EndEffectorDesc(attachments_m=points, lumps=tuple(placed))


def parse_description(data: dict[str, Any], *, source: str = "user") -> Description:
    """A validated :class:`Description` from parsed TOML (module docstring); errors name the path in the file."""
    _keys(data, "<top>", _TOP)
    default_source = data.get("default_source", source)
    if not isinstance(default_source, str) or not default_source:
        raise_at("default_source", "must be a non-empty string")
    r = _Values(default_source)
    kind = data.get("kind", "planar")
    if kind not in ("planar", "spatial"):
        raise_at("kind", "must be 'planar' or 'spatial'", kind)
    libs: dict[str, dict[str, Any]] = {
        "materials": {
            k: _material(r, v, f"materials.{k}")
            for k, v in _keys(data.get("materials", {}), "materials", set(data.get("materials", {}))).items()
        },
        "sections": {k: _section(r, v, f"sections.{k}") for k, v in data.get("sections", {}).items()},
        "lumps": {k: _lump(r, v, f"lumps.{k}") for k, v in data.get("lumps", {}).items()},
    }
    chains_raw = data.get("chains")
    if not isinstance(chains_raw, list) or not chains_raw:
        raise_at("chains", "a description needs at least one [[chains]] table")
    chains = tuple(_chain(r, t, f"chains[{i}]", libs) for i, t in enumerate(chains_raw))
    ee = _end_effector(r, data["end_effector"], libs["lumps"]) if "end_effector" in data else None
    if ee is None:
        raise_at("end_effector", "missing", hint="the end effector carries the task coordinates and its lumps")
    task = _task(data.get("task"), planar=kind == "planar")
    damping = _keys(data.get("damping", {}), "damping", {"stiffness_proportional_s"})
    desc = Description(
        name=str(data.get("name", "unnamed manipulator")),
        planar=kind == "planar",
        task=task,
        chains=chains,
        end_effector=ee,
        damping_beta_s=r.number(damping, "damping", "stiffness_proportional_s", 0.0),
        check_poses=_check_poses(data.get("check_poses", []), task),
        servos=_servos(r, data.get("servos", {})),
        provenance=r.provenance,
        data=copy.deepcopy(data),
        source=source,
    )
    _check_structure(desc)
    return desc


def _servos(r: _Values, t: Any) -> ServoGains:
    """``[servos]``: the actuated joints' servo gains, each optional (its default:
    :data:`~fpm_sim.architecture.description.SERVO_SOURCE`)."""
    keys = ("stiffness_nm_per_rad", "damping_nms_per_rad", "stiffness_n_per_m", "damping_ns_per_m")
    table = _keys(t, "servos", set(keys))
    d = ServoGains()
    values = {}
    for k in keys:
        if k in table:
            v = r.number(table, "servos", k)
            if v < 0 or (k.startswith("stiffness") and v == 0):
                raise_at(f"servos.{k}", "must be > 0 (a stiffness) or >= 0 (a damping)", v)
            values[k] = v
        else:
            values[k] = getattr(d, k)  # its provenance: SERVO_SOURCE (ServoGains.to_dict)
    return ServoGains(**values)


def _task(task: Any, *, planar: bool) -> tuple[str, ...]:
    allowed = PLANAR_TASK if planar else SPATIAL_TASK
    if not isinstance(task, list) or not task or any(c not in allowed for c in task) or len(set(task)) != len(task):
        raise_at(
            "task",
            f"must be a list of distinct task coordinates of a {'planar' if planar else 'spatial'} "
            f"machine ({', '.join(allowed)})",
            task,
        )
    return tuple(c for c in allowed if c in task)


def _check_poses(raw: Any, task: tuple[str, ...]) -> tuple[dict[str, float], ...]:
    """``check_poses = [{ x_mm = .., y_mm = .. }, ...]``: every task coordinate given, in mm (phi in rad)."""
    if not isinstance(raw, list):
        raise_at("check_poses", "must be a list of poses { x_mm = .., y_mm = .. }")
    out = []
    for k, pose in enumerate(raw):
        keys = {_TASK_KEYS[c] for c in task}
        if not isinstance(pose, dict) or set(pose) != keys:
            raise_at(f"check_poses[{k}]", f"must give exactly {', '.join(sorted(keys))}", pose)
        vals = {}
        for c in task:
            v = pose[_TASK_KEYS[c]]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise_at(f"check_poses[{k}].{_TASK_KEYS[c]}", "must be a finite number", v)
            vals[c] = float(v) * (1.0 if c == "phi" else 1e-3)
        out.append(vals)
    return tuple(out)


def _check_structure(desc: Description) -> None:
    """Names unique, parents known and earlier, end joints onto existing attachment points, joints before links."""
    seen: dict[str, int] = {}
    for i, c in enumerate(desc.chains):
        if c.name in seen:
            raise_at(f"chains[{i}].name", f"two chains are named {c.name!r} (chains[{seen[c.name]}] too)", c.name)
        seen[c.name] = i
        if c.parent is not None and (c.parent not in seen or c.parent == c.name):
            raise_at(f"chains[{i}].parent", "must name a chain defined before this one", c.parent)
        names = [e.name for e in c.path]
        for k, e in enumerate(c.path):
            if names.count(e.name) > 1:
                raise_at(f"chains[{i}].path[{k}]", f"two entries of chain {c.name!r} are named {e.name!r}")
            if isinstance(e, JointDesc) and e.at is not None:
                if k != len(c.path) - 1:
                    raise_at(f"chains[{i}].path[{k}].at", "only a chain's last joint attaches to the end effector")
                if e.at not in desc.end_effector.attachments_m:
                    raise_at(
                        f"chains[{i}].path[{k}].at",
                        "no attachment point of that name in [end_effector]",
                        e.at,
                        hint=f"the end effector has {', '.join(desc.end_effector.attachments_m)}",
                    )
                if e.type in ("prismatic", "universal"):
                    raise_at(
                        f"chains[{i}].path[{k}].type",
                        f"a {e.type} end joint is not supported yet",
                        hint="end joints are revolute, spherical or fixed",
                    )
            if desc.planar and isinstance(e, JointDesc) and e.type in ("universal", "spherical"):
                raise_at(
                    f"chains[{i}].path[{k}].type",
                    f"a planar machine has no {e.type} joints",
                    e.type,
                    hint="set kind = 'spatial'",
                )
    attached = {c.end_joint.at for c in desc.chains if c.end_joint is not None}
    if not attached:
        raise_at("chains", "no chain ends on the end effector (an end joint with at = '<attachment point>')")
    if (
        len(desc.chains) > 1
        and len([c for c in desc.chains if c.end_joint is not None]) < 2
        and not any(c.parent for c in desc.chains)
    ):
        raise_at("end_effector.attachments_m", "a parallel machine needs its chains to end on the end effector")


def load_description(path: str | Path) -> Description:
    """Load a description file (see the module docstring); :class:`fpm_sim.config.ConfigError` names the path."""
    p = Path(path)
    data = read_toml_file(p, what="description")
    if data.get("kind") == "imported":
        raise ConfigError(
            f"{p} is an imported model (kind = 'imported'), not a described architecture",
            parameter="kind",
            file=str(p),
            hint="read it with fs.load_imported",
        )
    try:
        desc = parse_description(data, source=f"user: {p.name}")
    except ConfigError as exc:
        exc.file = exc.file or str(p)
        raise
    return Description(**{**desc.__dict__, "source_file": str(p)})


def is_description_file(path: str | Path) -> bool:
    """Whether a TOML file is a general description (it has ``[[chains]]``) rather than the 3RRR's own form."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return isinstance(data.get("chains"), list)


# The readers shared with the imported description (fpm_sim.architecture.imported): same validation, same paths.
ValueReader = _Values
read_material = _material
read_section = _section
table_keys = _keys
read_servos = _servos
