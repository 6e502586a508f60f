"""Manipulator and test-rig descriptions: typed dataclasses, TOML loading, validation, provenance.

Every physical value lives in SI units inside the dataclasses. In a TOML file a value is either a
bare number (its provenance then reads ``"user: <file>"``) or an inline table carrying its source::

    proximal_length_m = { value = 0.228, source = "assumed: length of the study's test link" }

A source starts with ``study``, ``assumed: <why>`` or ``identified: <from what>`` in the shipped
default. Angles are written in degrees in TOML (keys ending in ``_deg``) and held in radians.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from fpm_sim.errors import FpmSimError, read_text_input

__all__ = [
    "DEFAULT_CONFIG_NAME",
    "Compliance",
    "ConfigError",
    "Damping",
    "Geometry",
    "Hardware",
    "LumpedMass",
    "Manipulator",
    "Material",
    "Motors",
    "RigConfig",
    "Section",
    "config_to_toml",
    "default_config",
    "load_config",
    "rectangle_torsion_constant_m4",
]

DEFAULT_CONFIG_NAME = "default_3rrr.toml"


class ConfigError(FpmSimError):
    """A manipulator description is invalid; the message names the offending field."""


@dataclass(frozen=True)
class Geometry:
    """Planar 3RRR geometry in the base plane (z = 0), SI units.

    The links lie in the base plane unless ``distal_offset_m`` / ``platform_offset_m`` stack them in
    layers along the joint axes (z); the in-plane kinematics does not depend on the layers.

    Chain ``i`` runs from the motor axis ``A_i`` on the base circle through the elbow ``B_i`` to the
    platform joint ``C_i``. ``elbow_branch[i]`` (+1 or -1) selects which of the two inverse-kinematics
    solutions the chain takes: +1 puts the elbow to the left of the line ``A_i -> C_i``.

    Per-chain geometry: each of the radii and link lengths is either one number (all three chains)
    or a tuple of three (chain 0, 1, 2). Code that needs the per-chain values reads the ``*_per_chain``
    properties (always three floats); :meth:`is_symmetric_in_lengths` says whether all chains agree.
    """

    base_radius_m: float | tuple[float, float, float]
    base_angles_rad: tuple[float, float, float]
    proximal_length_m: float | tuple[float, float, float]
    distal_length_m: float | tuple[float, float, float]
    platform_radius_m: float | tuple[float, float, float]
    platform_angles_rad: tuple[float, float, float]
    elbow_branch: tuple[int, int, int] = (1, 1, 1)
    hub_length_m: float = 0.0
    """Rigid length at each end of every link (joint hardware, clamped bosses): the flexible span is the
    joint-to-joint length minus twice this. 0 (default): flexible from joint to joint."""
    distal_offset_m: float | tuple[float, float, float] = 0.0
    """Stacked links: height (along the joint axes, +z) of the distal-link layer above the proximal one;
    the elbow between the layers is a rigid pin of this length. 0 (default): coplanar links."""
    platform_offset_m: float | tuple[float, float, float] = 0.0
    """Stacked links: height of the platform-joint/platform layer above the distal-link layer (a rigid
    pin at each platform joint). 0 (default): the platform in the distal links' plane. Per chain, the
    platform's centre (its mass, ``platform_center``) sits at chain 0's height."""

    @staticmethod
    def _three(v: float | tuple[float, ...]) -> tuple[float, float, float]:
        if isinstance(v, (tuple, list)):
            return (float(v[0]), float(v[1]), float(v[2]))
        return (float(v), float(v), float(v))

    @property
    def base_radius_per_chain(self) -> tuple[float, float, float]:
        """Motor-axis radius of each chain (m)."""
        return self._three(self.base_radius_m)

    @property
    def platform_radius_per_chain(self) -> tuple[float, float, float]:
        """Platform-joint radius of each chain on the platform (m)."""
        return self._three(self.platform_radius_m)

    @property
    def proximal_length_per_chain(self) -> tuple[float, float, float]:
        """Joint-to-joint length of each proximal link (m)."""
        return self._three(self.proximal_length_m)

    @property
    def distal_length_per_chain(self) -> tuple[float, float, float]:
        """Joint-to-joint length of each distal link (m)."""
        return self._three(self.distal_length_m)

    @property
    def distal_offset_per_chain(self) -> tuple[float, float, float]:
        """Height of each distal link above its proximal link (m)."""
        return self._three(self.distal_offset_m)

    @property
    def platform_offset_per_chain(self) -> tuple[float, float, float]:
        """Height of each platform joint (and the platform) above its distal link (m)."""
        return self._three(self.platform_offset_m)

    def is_symmetric_in_lengths(self) -> bool:
        """True when every radius and link length is the same for the three chains."""
        return all(
            len(set(t)) == 1
            for t in (
                self.base_radius_per_chain,
                self.platform_radius_per_chain,
                self.proximal_length_per_chain,
                self.distal_length_per_chain,
            )
        )


_Length = TypeVar("_Length")


def rectangle_torsion_constant_m4(long_m: _Length, short_m: _Length) -> _Length:
    """Saint-Venant torsion constant of solid rectangles of sides ``long_m >= short_m`` (m; Roark, series
    approximation, <0.5 %): plain arithmetic, so numbers or NumPy arrays of them (the calibration's particles)."""
    r = short_m / long_m  # type: ignore[operator]
    out: _Length = long_m * short_m**3 * (1.0 / 3.0 - 0.21 * r * (1.0 - r**4 / 12.0))  # type: ignore[operator]
    return out


@dataclass(frozen=True)
class Section:
    """Rectangular link cross-section: ``thickness_m`` in the base plane, ``height_m`` out of it."""

    thickness_m: float
    height_m: float

    @property
    def area_m2(self) -> float:
        return self.thickness_m * self.height_m

    @property
    def i_inplane_m4(self) -> float:
        """Second moment for bending in the base plane (deflection along the thickness)."""
        return self.height_m * self.thickness_m**3 / 12.0

    @property
    def i_outofplane_m4(self) -> float:
        """Second moment for bending out of the base plane (deflection along the height)."""
        return self.thickness_m * self.height_m**3 / 12.0

    @property
    def torsion_constant_m4(self) -> float:
        """Saint-Venant torsion constant of a solid rectangle (:func:`rectangle_torsion_constant_m4`)."""
        t, h = self.thickness_m, self.height_m
        return rectangle_torsion_constant_m4(max(t, h), min(t, h))


@dataclass(frozen=True)
class Material:
    """Linear elastic isotropic material."""

    young_pa: float
    poisson: float
    density_kg_m3: float

    @property
    def shear_pa(self) -> float:
        return self.young_pa / (2.0 * (1.0 + self.poisson))


@dataclass(frozen=True)
class LumpedMass:
    """A rigid lump: mass and principal inertia about its own centre, axes of the link frame
    (x along the link, z along the joint axis)."""

    mass_kg: float = 0.0
    inertia_kg_m2: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Hardware:
    """Lumped joint hardware, platform and payload."""

    elbow_joint: LumpedMass = field(default_factory=LumpedMass)
    platform_joint: LumpedMass = field(default_factory=LumpedMass)
    motor_flange: LumpedMass = field(default_factory=LumpedMass)
    platform: LumpedMass = field(default_factory=lambda: LumpedMass(0.1, (1e-4, 1e-4, 2e-4)))
    payload: LumpedMass = field(default_factory=LumpedMass)


@dataclass(frozen=True)
class Compliance:
    """Optional joint compliances as rotational stiffness; ``math.inf`` means rigid.

    ``passive_joint_tilt_nm_per_rad``: bearing stiffness of each passive hinge about the two axes
    normal to its own (out-of-plane tilt). ``motor_clamp_nm_per_rad``: stiffness of each locked motor
    about its axis. ``motor_mount_tilt_nm_per_rad``: stiffness of each motor's mounting on the base
    about the two axes normal to the motor axis (out-of-plane tilt of the proximal link's root: about
    the link, twisting it, and across it, bending it out of the plane). ``base_clamp_nm_per_rad``:
    rotational stiffness of the rigs' clamps (the study's concrete cylinders) about both bending axes.
    """

    passive_joint_tilt_nm_per_rad: float = math.inf
    motor_clamp_nm_per_rad: float = math.inf
    base_clamp_nm_per_rad: float = math.inf
    motor_mount_tilt_nm_per_rad: float = math.inf


@dataclass(frozen=True)
class Motors:
    """Motor state: ``"locked"`` (rigid, or ``Compliance.motor_clamp_nm_per_rad``) or ``"servo"``."""

    mode: str = "locked"
    servo_stiffness_nm_per_rad: float = 0.0
    servo_damping_nms_per_rad: float = 0.0


@dataclass(frozen=True)
class Damping:
    """Structural damping, stiffness-proportional: each link spring gets damping ``beta * k``.

    A mode dominated by link bending at angular frequency w then has damping ratio ``beta * w / 2``.
    """

    stiffness_proportional_s: float = 0.0


@dataclass(frozen=True)
class RigConfig:
    """The study's subsystem test pieces (single link, two-link chain)."""

    length_m: float
    section: Section
    material: Material
    clamped_length_m: float = 0.0
    chain_hinge: LumpedMass = field(default_factory=LumpedMass)


@dataclass(frozen=True)
class Manipulator:
    """A whole planar 3RRR description. ``provenance`` maps dotted field paths to their source."""

    name: str
    geometry: Geometry
    section: Section
    material: Material
    hardware: Hardware = field(default_factory=Hardware)
    compliance: Compliance = field(default_factory=Compliance)
    motors: Motors = field(default_factory=Motors)
    damping: Damping = field(default_factory=Damping)
    rig: RigConfig | None = None
    provenance: dict[str, str] = field(default_factory=dict, compare=False)

    def replace(self, **changes: Any) -> Manipulator:
        """A copy with top-level fields replaced, validated."""
        new = dataclasses.replace(self, **changes)
        validate(new)
        return new

    def with_section(self, *, thickness_m: float | None = None, height_m: float | None = None) -> Manipulator:
        """A copy with the link section changed (provenance marked as a user override)."""
        sec = Section(
            thickness_m=self.section.thickness_m if thickness_m is None else thickness_m,
            height_m=self.section.height_m if height_m is None else height_m,
        )
        prov = dict(self.provenance)
        if thickness_m is not None:
            prov["section.thickness_m"] = "user: override"
        if height_m is not None:
            prov["section.height_m"] = "user: override"
        return dataclasses.replace(self, section=sec, provenance=prov).replace()

    def to_dict(self) -> dict[str, Any]:
        """Plain-data view (for JSON), SI units, with provenance."""
        d = dataclasses.asdict(self)
        return d


# ---------------------------------------------------------------------------------------------
# loading


class _Reader:
    """Reads values out of a TOML table, recording provenance and naming fields in errors."""

    def __init__(self, default_source: str) -> None:
        self.default_source = default_source
        self.provenance: dict[str, str] = {}

    def get(self, table: dict[str, Any], path: str, key: str, default: Any = dataclasses.MISSING) -> Any:
        full = f"{path}.{key}" if path else key
        if key not in table:
            if default is dataclasses.MISSING:
                raise ConfigError("missing field", parameter=full)
            return default
        raw = table[key]
        if isinstance(raw, dict) and "value" in raw:
            unknown = set(raw) - {"value", "source"}
            if unknown:
                raise ConfigError(f"field '{full}': unknown keys {sorted(unknown)} (expected 'value', 'source')")
            source = raw.get("source", self.default_source)
            if not isinstance(source, str) or not source:
                raise ConfigError(f"field '{full}': 'source' must be a non-empty string")
            self.provenance[full] = source
            return raw["value"]
        self.provenance[full] = self.default_source
        return raw

    def number(self, table: dict[str, Any], path: str, key: str, default: Any = dataclasses.MISSING) -> float:
        v = self.get(table, path, key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError("must be a number", parameter=f"{path}.{key}", value=v)
        return float(v)

    def number_or_triple(
        self, table: dict[str, Any], path: str, key: str, default: Any = dataclasses.MISSING
    ) -> float | tuple[float, float, float]:
        """One number (all chains) or a list of three (one per chain)."""
        v = self.get(table, path, key, default)
        if isinstance(v, (list, tuple)):
            if len(v) != 3 or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v):
                raise ConfigError(
                    "must be a number or a list of 3 numbers (per chain)", parameter=f"{path}.{key}", value=v
                )
            return (float(v[0]), float(v[1]), float(v[2]))
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError("must be a number or a list of 3 numbers (per chain)", parameter=f"{path}.{key}", value=v)
        return float(v)

    def triple(
        self, table: dict[str, Any], path: str, key: str, default: Any = dataclasses.MISSING
    ) -> tuple[float, float, float]:
        v = self.get(table, path, key, default)
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise ConfigError("must be a list of 3 numbers", parameter=f"{path}.{key}", value=v)
        for x in v:
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise ConfigError("must be a list of 3 numbers", parameter=f"{path}.{key}", value=v)
        return (float(v[0]), float(v[1]), float(v[2]))

    def table(self, parent: dict[str, Any], path: str, key: str, required: bool = True) -> dict[str, Any]:
        full = f"{path}.{key}" if path else key
        if key not in parent:
            if required:
                raise ConfigError(f"missing table '[{full}]'")
            return {}
        t = parent[key]
        if not isinstance(t, dict):
            raise ConfigError(f"'{full}' must be a table")
        return t


def _check_keys(table: dict[str, Any], path: str, allowed: set[str]) -> None:
    unknown = set(table) - allowed
    if unknown:
        raise ConfigError(f"unknown field(s) in '[{path}]': {sorted(unknown)}; allowed: {sorted(allowed)}")


def _radians3(deg: tuple[float, float, float]) -> tuple[float, float, float]:
    return (math.radians(deg[0]), math.radians(deg[1]), math.radians(deg[2]))


def _lump(r: _Reader, t: dict[str, Any], path: str) -> LumpedMass:
    _check_keys(t, path, {"mass_kg", "inertia_kg_m2"})
    return LumpedMass(
        mass_kg=r.number(t, path, "mass_kg", 0.0),
        inertia_kg_m2=r.triple(t, path, "inertia_kg_m2", (0.0, 0.0, 0.0)),
    )


def _section(r: _Reader, t: dict[str, Any], path: str) -> Section:
    return Section(thickness_m=r.number(t, path, "thickness_m"), height_m=r.number(t, path, "height_m"))


def _material(r: _Reader, t: dict[str, Any], path: str) -> Material:
    return Material(
        young_pa=r.number(t, path, "young_pa"),
        poisson=r.number(t, path, "poisson"),
        density_kg_m3=r.number(t, path, "density_kg_m3"),
    )


def _geometry(r: _Reader, g: dict[str, Any]) -> Geometry:
    """The ``[geometry]`` table (angles in degrees, lengths in metres, one value or one per chain)."""
    _check_keys(
        g,
        "geometry",
        {
            "base_radius_m",
            "base_angles_deg",
            "proximal_length_m",
            "distal_length_m",
            "platform_radius_m",
            "platform_angles_deg",
            "elbow_branch",
            "hub_length_m",
            "distal_offset_m",
            "platform_offset_m",
        },
    )
    branch = r.get(g, "geometry", "elbow_branch", [1, 1, 1])
    if not isinstance(branch, (list, tuple)) or len(branch) != 3 or any(b not in (1, -1) for b in branch):
        raise ConfigError("must be three values each +1 or -1", parameter="geometry.elbow_branch", value=branch)
    return Geometry(
        base_radius_m=r.number_or_triple(g, "geometry", "base_radius_m"),
        base_angles_rad=_radians3(r.triple(g, "geometry", "base_angles_deg")),
        proximal_length_m=r.number_or_triple(g, "geometry", "proximal_length_m"),
        distal_length_m=r.number_or_triple(g, "geometry", "distal_length_m"),
        platform_radius_m=r.number_or_triple(g, "geometry", "platform_radius_m"),
        platform_angles_rad=_radians3(r.triple(g, "geometry", "platform_angles_deg")),
        elbow_branch=(int(branch[0]), int(branch[1]), int(branch[2])),
        hub_length_m=r.number(g, "geometry", "hub_length_m", 0.0),
        distal_offset_m=r.number_or_triple(g, "geometry", "distal_offset_m", 0.0),
        platform_offset_m=r.number_or_triple(g, "geometry", "platform_offset_m", 0.0),
    )


def _rig(r: _Reader, rt: dict[str, Any], material: Material) -> RigConfig:
    """The ``[rig]`` table: the test piece (its material defaults to the links' ``material``)."""
    _check_keys(rt, "rig", {"length_m", "clamped_length_m", "section", "material", "chain_hinge"})
    return RigConfig(
        length_m=r.number(rt, "rig", "length_m"),
        section=_section(r, r.table(rt, "rig", "section"), "rig.section"),
        material=_material(r, r.table(rt, "rig", "material"), "rig.material") if "material" in rt else material,
        clamped_length_m=r.number(rt, "rig", "clamped_length_m", 0.0),
        chain_hinge=_lump(r, r.table(rt, "rig", "chain_hinge"), "rig.chain_hinge")
        if "chain_hinge" in rt
        else LumpedMass(),
    )


def parse_config(data: dict[str, Any], *, source: str = "user") -> Manipulator:
    """Build a validated :class:`Manipulator` from parsed TOML data."""
    r = _Reader(default_source=source)
    _check_keys(
        data,
        "<top>",
        {"name", "geometry", "section", "material", "hardware", "compliance", "motors", "damping", "rig"},
    )
    geometry = _geometry(r, r.table(data, "", "geometry"))
    s = r.table(data, "", "section")
    _check_keys(s, "section", {"thickness_m", "height_m"})
    m = r.table(data, "", "material")
    _check_keys(m, "material", {"young_pa", "poisson", "density_kg_m3"})
    hw = r.table(data, "", "hardware", required=False)
    _check_keys(hw, "hardware", {f.name for f in dataclasses.fields(Hardware)})
    hardware = Hardware(**{k: _lump(r, r.table(hw, "hardware", k), f"hardware.{k}") for k in hw})
    c = r.table(data, "", "compliance", required=False)
    _check_keys(c, "compliance", {f.name for f in dataclasses.fields(Compliance)})
    compliance = Compliance(**{k: r.number(c, "compliance", k) for k in c})
    mo = r.table(data, "", "motors", required=False)
    _check_keys(mo, "motors", {f.name for f in dataclasses.fields(Motors)})
    motors = Motors(
        mode=str(r.get(mo, "motors", "mode", "locked")),
        servo_stiffness_nm_per_rad=r.number(mo, "motors", "servo_stiffness_nm_per_rad", 0.0),
        servo_damping_nms_per_rad=r.number(mo, "motors", "servo_damping_nms_per_rad", 0.0),
    )
    dmp = r.table(data, "", "damping", required=False)
    _check_keys(dmp, "damping", {"stiffness_proportional_s"})
    damping = Damping(stiffness_proportional_s=r.number(dmp, "damping", "stiffness_proportional_s", 0.0))
    material = _material(r, m, "material")
    rig = _rig(r, r.table(data, "", "rig"), material) if "rig" in data else None
    manip = Manipulator(
        name=str(data.get("name", "unnamed 3RRR")),
        geometry=geometry,
        section=_section(r, s, "section"),
        material=material,
        hardware=hardware,
        compliance=compliance,
        motors=motors,
        damping=damping,
        rig=rig,
        provenance=r.provenance,
    )
    validate(manip)
    return manip


def load_config(path: str | Path) -> Manipulator:
    """Load and validate a manipulator description from a TOML file.

    Raises
    ------
    ConfigError
        With the dotted name of the offending field.
    """
    p = Path(path)
    data = read_toml_file(p, what="config")
    try:
        return parse_config(data, source=f"user: {p.name}")
    except ConfigError as exc:
        exc.file = exc.file or str(p)  # the value came from this file, not from an option
        raise


def read_toml_file(path: Path, *, what: str) -> dict[str, Any]:
    """The parsed TOML of a description file (the 3RRR's or a described architecture's): one
    :class:`ConfigError` naming ``config`` for a missing file, a folder, text that is not UTF-8 and invalid TOML;
    ``what`` names the file in the missing-file message (``config``, ``description``)."""
    hint = "give the description's .toml file"
    try:
        text = read_text_input(path, error=ConfigError, parameter="config", kind="a TOML file", hint=hint)
        return tomllib.loads(text)
    except FileNotFoundError as exc:
        raise ConfigError(f"{what} file not found: {path}", parameter="config", hint=hint) from exc
    except IsADirectoryError as exc:
        raise ConfigError(f"{path} is a folder, not a TOML file", parameter="config", hint=hint) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}", parameter="config") from exc


def default_config() -> Manipulator:
    """The embedded default: the study's prototype, every value with its provenance."""
    text = resources.files("fpm_sim.data").joinpath(DEFAULT_CONFIG_NAME).read_text()
    return parse_config(tomllib.loads(text), source="default")


def default_config_text() -> str:
    """The embedded default TOML, as text (a template for users)."""
    return resources.files("fpm_sim.data").joinpath(DEFAULT_CONFIG_NAME).read_text()


# ---------------------------------------------------------------------------------------------
# writing


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if math.isnan(v):
            return "nan"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to TOML")


def _compact(v: Any) -> Any:
    """A per-chain triple whose entries agree is written as one number."""
    if isinstance(v, tuple) and len(v) == 3 and not isinstance(v[0], int) and len(set(v)) == 1:
        return v[0]
    return v


def config_to_toml(m: Manipulator, *, header: str = "", default_source: str = "unknown") -> str:
    """The description as TOML text that :func:`load_config` reads back to an equal :class:`Manipulator`.

    Every value is written as ``{ value = ..., source = ... }`` with its provenance
    (``m.provenance``; ``default_source`` where none is recorded). Angles in degrees, rounded to
    1e-9 deg; other floats written exactly (``repr``).
    """
    prov = m.provenance
    lines: list[str] = [f"# {ln}" if ln else "#" for ln in header.splitlines()] if header else []
    lines.append(f"name = {_toml_value(m.name)}")

    def entry(path: str, key: str, value: Any) -> str:
        src = prov.get(f"{path}.{key}", default_source)
        return f"{key} = {{ value = {_toml_value(value)}, source = {_toml_value(src)} }}"

    def deg(t: tuple[float, ...]) -> list[float]:
        return [round(math.degrees(a), 9) for a in t]

    g = m.geometry
    lines += ["", "[geometry]"]
    lines.append(entry("geometry", "base_radius_m", _compact(g.base_radius_m)))
    lines.append(entry("geometry", "base_angles_deg", deg(g.base_angles_rad)))
    lines.append(entry("geometry", "proximal_length_m", _compact(g.proximal_length_m)))
    lines.append(entry("geometry", "distal_length_m", _compact(g.distal_length_m)))
    lines.append(entry("geometry", "platform_radius_m", _compact(g.platform_radius_m)))
    lines.append(entry("geometry", "platform_angles_deg", deg(g.platform_angles_rad)))
    lines.append(entry("geometry", "elbow_branch", list(g.elbow_branch)))
    if g.hub_length_m:
        lines.append(entry("geometry", "hub_length_m", g.hub_length_m))
    for key in ("distal_offset_m", "platform_offset_m"):  # written only when stacked (0 = coplanar)
        if any(getattr(g, f"{key[:-2]}_per_chain")):
            lines.append(entry("geometry", key, _compact(getattr(g, key))))

    def section(path: str, sec: Section) -> None:
        lines.extend(
            ["", f"[{path}]", entry(path, "thickness_m", sec.thickness_m), entry(path, "height_m", sec.height_m)]
        )

    def material(path: str, mat: Material) -> None:
        lines.extend(["", f"[{path}]"])
        for f in dataclasses.fields(Material):
            lines.append(entry(path, f.name, getattr(mat, f.name)))

    def lump(path: str, lm: LumpedMass) -> None:
        lines.extend(
            ["", f"[{path}]", entry(path, "mass_kg", lm.mass_kg), entry(path, "inertia_kg_m2", list(lm.inertia_kg_m2))]
        )

    section("section", m.section)
    material("material", m.material)
    for f in dataclasses.fields(Hardware):
        lump(f"hardware.{f.name}", getattr(m.hardware, f.name))
    for tname, obj in (("compliance", m.compliance), ("motors", m.motors), ("damping", m.damping)):
        lines.extend(["", f"[{tname}]"])
        for f in dataclasses.fields(obj):
            lines.append(entry(tname, f.name, getattr(obj, f.name)))
    if m.rig is not None:
        lines.extend(["", "[rig]", entry("rig", "length_m", m.rig.length_m)])
        lines.append(entry("rig", "clamped_length_m", m.rig.clamped_length_m))
        section("rig.section", m.rig.section)
        if m.rig.material != m.material:
            material("rig.material", m.rig.material)
        lump("rig.chain_hinge", m.rig.chain_hinge)
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# validation


def _positive(value: float, name: str) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ConfigError("must be a positive finite number", parameter=name, value=value)


def _nonneg(value: float, name: str, allow_inf: bool = False) -> None:
    ok = value >= 0.0 and (allow_inf or math.isfinite(value))
    if not ok or math.isnan(value):
        raise ConfigError(f"must be >= 0{' (inf = rigid)' if allow_inf else ''}", parameter=name, value=value)


def _validate_lump(lump: LumpedMass, name: str) -> None:
    _nonneg(lump.mass_kg, f"{name}.mass_kg")
    for k, v in zip("xyz", lump.inertia_kg_m2):
        _nonneg(v, f"{name}.inertia_kg_m2[{k}]")
    a, b, c = lump.inertia_kg_m2
    if a + b < c * (1 - 1e-9) or b + c < a * (1 - 1e-9) or a + c < b * (1 - 1e-9):
        raise ConfigError(f"field '{name}.inertia_kg_m2' violates the triangle inequality: {lump.inertia_kg_m2}")


def _validate_section_material(sec: Section, mat: Material, prefix: str) -> None:
    _positive(sec.thickness_m, f"{prefix}section.thickness_m")
    _positive(sec.height_m, f"{prefix}section.height_m")
    _positive(mat.young_pa, f"{prefix}material.young_pa")
    _positive(mat.density_kg_m3, f"{prefix}material.density_kg_m3")
    if not (-1.0 < mat.poisson < 0.5):
        raise ConfigError("must lie in (-1, 0.5)", parameter=f"{prefix}material.poisson", value=mat.poisson)


def validate(m: Manipulator) -> None:
    """Check a description for values no physical manipulator can have. Raises :class:`ConfigError`."""
    g = m.geometry
    for i in range(3):
        sfx = f"[{i}]" if isinstance(g.base_radius_m, tuple) else ""
        _positive(g.base_radius_per_chain[i], f"geometry.base_radius_m{sfx}")
        sfx = f"[{i}]" if isinstance(g.proximal_length_m, tuple) else ""
        _positive(g.proximal_length_per_chain[i], f"geometry.proximal_length_m{sfx}")
        sfx = f"[{i}]" if isinstance(g.distal_length_m, tuple) else ""
        _positive(g.distal_length_per_chain[i], f"geometry.distal_length_m{sfx}")
        sfx = f"[{i}]" if isinstance(g.platform_radius_m, tuple) else ""
        _nonneg(g.platform_radius_per_chain[i], f"geometry.platform_radius_m{sfx}")
    for name, angles in (("base_angles_deg", g.base_angles_rad), ("platform_angles_deg", g.platform_angles_rad)):
        pts = [(math.cos(a), math.sin(a)) for a in angles]
        for i in range(3):
            for j in range(i + 1, 3):
                if math.dist(pts[i], pts[j]) < 1e-6:
                    raise ConfigError(f"field 'geometry.{name}': chains {i} and {j} share an angle")
    _nonneg(g.hub_length_m, "geometry.hub_length_m")
    for key in ("distal_offset_m", "platform_offset_m"):
        raw = getattr(g, key)
        for i, v in enumerate(getattr(g, f"{key[:-2]}_per_chain")):
            if not math.isfinite(v):
                sfx = f"[{i}]" if isinstance(raw, tuple) else ""
                raise ConfigError(
                    "must be a finite height in m (0 = coplanar layers)", parameter=f"geometry.{key}{sfx}", value=v
                )
    shortest = min(g.proximal_length_per_chain + g.distal_length_per_chain)
    if 2.0 * g.hub_length_m >= shortest:
        raise ConfigError(
            f"field 'geometry.hub_length_m' ({g.hub_length_m} m) leaves no flexible span: twice it must be shorter "
            f"than the shortest link ({shortest} m)"
        )
    if max(g.platform_radius_per_chain) >= min(g.base_radius_per_chain):
        raise ConfigError(
            f"field 'geometry.platform_radius_m' ({g.platform_radius_m} m) must be smaller than "
            f"'geometry.base_radius_m' ({g.base_radius_m} m)"
        )
    _validate_section_material(m.section, m.material, "")
    for f in dataclasses.fields(Hardware):
        _validate_lump(getattr(m.hardware, f.name), f"hardware.{f.name}")
    for f in dataclasses.fields(Compliance):
        _nonneg(getattr(m.compliance, f.name), f"compliance.{f.name}", allow_inf=True)
        if getattr(m.compliance, f.name) == 0.0:
            raise ConfigError(
                f"field 'compliance.{f.name}' is 0: that is a free joint, not a compliance; use inf for rigid"
            )
    if m.motors.mode not in ("locked", "servo"):
        raise ConfigError(f"field 'motors.mode' must be 'locked' or 'servo', got {m.motors.mode!r}")
    _nonneg(m.motors.servo_stiffness_nm_per_rad, "motors.servo_stiffness_nm_per_rad")
    _nonneg(m.motors.servo_damping_nms_per_rad, "motors.servo_damping_nms_per_rad")
    if m.motors.mode == "servo" and m.motors.servo_stiffness_nm_per_rad <= 0.0:
        raise ConfigError("field 'motors.servo_stiffness_nm_per_rad' must be > 0 when motors.mode = 'servo'")
    _nonneg(m.damping.stiffness_proportional_s, "damping.stiffness_proportional_s")
    if m.hardware.platform.mass_kg + m.hardware.payload.mass_kg <= 0.0:
        raise ConfigError("field 'hardware.platform.mass_kg' must be > 0 (the platform is a rigid body)")
    if m.rig is not None:
        _positive(m.rig.length_m, "rig.length_m")
        _validate_section_material(m.rig.section, m.rig.material, "rig.")
        _nonneg(m.rig.clamped_length_m, "rig.clamped_length_m")
        if m.rig.clamped_length_m >= m.rig.length_m:
            raise ConfigError(
                f"must be shorter than rig.length_m ({m.rig.length_m:.4g} m)",
                parameter="rig.clamped_length_m",
                value=m.rig.clamped_length_m,
            )
        _validate_lump(m.rig.chain_hinge, "rig.chain_hinge")
