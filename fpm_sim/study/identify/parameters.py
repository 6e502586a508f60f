"""Named parameter groups that ``fpm-sim identify --free`` can free, and how each sets a description.

Every parameter is a scalar in SI units (angles in degrees, stiffnesses as ``log10`` of N m/rad) with
bounds. The mapping is data: a :class:`ParameterSpec` names the description field it edits by a dotted path
(``"geometry.base_radius_m"``, ``"rig.section.height_m"``) and how the scalar becomes that field's value
(its ``kind``); :func:`apply_parameters` is the one function that edits a description with them, and
:meth:`ParameterSet.apply` turns a vector into a validated :class:`Manipulator`. Specs and sets are plain
frozen data, so they pickle (a ``spawn`` worker receives them whole).

This module imports neither MuJoCo, SciPy, JAX nor (until a set is used) NumPy: the command line reads
:data:`GROUPS` from it while building its parser.

Groups (:data:`GROUPS`):

``geometry``
    Mean base radius, platform radius, proximal and distal lengths (m; chain-to-chain differences
    of the start kept), a rotation of the motor layout and one of the platform-joint layout (deg,
    about the start). Bounds: lengths 0.6-1.6 x the start, rotations +-60 deg.
``geometry-per-chain``
    Per chain: base radius, motor angle, proximal length, distal length, platform radius,
    platform-joint angle (18 parameters). Bounds: lengths 0.8-1.25 x the start, angles +-15 deg.
``as-built``
    Each chain's deviations from the other groups' symmetric layout, as built: its motor's and its platform
    joint's angle (deg, added to the layout's) and its proximal and distal link's length (relative, the length
    times ``1 + v``); 12 parameters, applied after every other group's whatever the order given. Bounds +-5 deg
    and +-5 %. For a calibration whose priors say how well the machine was built (the machine's joint positions
    and lengths known to about 1 deg and 1 %, not to the 0.1 deg a near-singular pose's frequency needs;
    docs/identification.md, "As-built deviations as unknowns").
``hubs``
    The rigid length at each link end, ``geometry.hub_length_m`` (m), 0 .. 0.3 x the shortest link.
``hardware``
    Platform mass (its inertia scaled with it), elbow-joint mass, platform-joint mass (kg; inertias
    scaled with the masses). Bounds 0.05-4 x the start (platform: 0.05-10 kg where the start is 0).
``section``
    The links' out-of-plane height and in-plane thickness (m), 0.5-2 x the start.
``section-height``
    The out-of-plane height only, 0.5-2 x the start: for a description whose in-plane thickness is known
    (the study states 30 mm links; freed, the study's data pull it to 56 mm, docs/identification.md).
``compliance``
    ``log10`` of the passive-joint tilt, locked-motor and motor-mount tilt rotational stiffnesses
    (N m/rad), 2 .. 7 (a rigid start, ``inf``, starts at 7: the stiff end).
``offsets``
    The stacked links' layer heights ``geometry.distal_offset_m`` (distal links above the proximal ones)
    and ``geometry.platform_offset_m`` (platform joints and platform above the distal links), m, 0 .. 0.06,
    from the start description's values (a per-chain start keeps its chain-to-chain differences). A
    coplanar start (0) begins at 0.03 instead: flipping every layer (z -> -z) leaves the frequencies as
    they are, so 0 is a stationary point where a local fit would never move (it stays there, tested).
``rig``
    The test pieces (only with ``--subsystems``): rig length, clamped length, the piece's height and
    the chain hinge's mass.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

from fpm_sim.config import ConfigError, LumpedMass, Manipulator
from fpm_sim.errors import FpmSimError

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "GEOMETRY_GROUPS",
    "GROUPS",
    "KINDS",
    "ParameterError",
    "ParameterSet",
    "ParameterSpec",
    "apply_parameters",
    "apply_parameters_batch",
    "parameter_set",
]

GROUPS = (
    "geometry",
    "geometry-per-chain",
    "as-built",
    "hubs",
    "hardware",
    "section",
    "section-height",
    "compliance",
    "offsets",
    "rig",
)
"""Groups ``--free`` accepts."""

GEOMETRY_GROUPS = ("geometry", "geometry-per-chain")
"""The groups that move the joint layout (and so the elbow-branch choice matters)."""

LOG_STIFF_BOUNDS = (2.0, 7.0)
OFFSET_BOUNDS_M = (0.0, 0.06)
"""Bounds of the ``offsets`` group's layer heights (m)."""

Kind = Literal["value", "log10", "chain_mean", "chain_item", "chain_scale", "angle_deg", "angle_add_deg", "lump_mass"]
KINDS: tuple[Kind, ...] = (
    "value", "log10", "chain_mean", "chain_item", "chain_scale", "angle_deg", "angle_add_deg", "lump_mass",
)  # fmt: skip
"""How a :class:`ParameterSpec` turns its scalar ``v`` into the value of the field at its ``path``:

``value``
    ``v`` itself.
``log10``
    ``10 ** v``.
``chain_mean``
    A per-chain length whose mean is ``v``: ``v`` where the start's chains (``reference``) agree, else each
    chain's start value shifted by ``v - mean(reference)``.
``chain_item``
    Chain ``index`` of a per-chain length set to ``v`` (the other chains as the description has them).
``chain_scale``
    Chain ``index`` of a per-chain length times ``1 + v`` (the length as the specs before it left it).
``angle_deg``
    A per-chain angle (rad): chains ``chains`` set to ``reference[i] + radians(v)``, the others kept.
``angle_add_deg``
    A per-chain angle (rad): ``radians(v)`` added to chains ``chains`` (the angles as the specs before it left them).
``lump_mass``
    A :class:`LumpedMass` of mass ``v``, its inertia scaled with the mass (a 15 mm radius of gyration where
    the description's mass is 0).
"""


class ParameterError(FpmSimError):
    """An unknown or unusable parameter group (``--free``)."""


@dataclass(frozen=True)
class ParameterSpec:
    """One free scalar, as data: its dotted name (unit in the name), the description field it edits, how,
    its start value and bounds.

    Attributes
    ----------
    name
        The parameter's name in results and priors, e.g. ``geometry.base_rotation_deg``.
    path
        Dotted path of the edited field of the :class:`Manipulator`, e.g. ``geometry.base_angles_rad``.
    kind
        How the scalar becomes the field's value (:data:`KINDS`).
    start, lower, upper
        Start value and bounds, in the parameter's unit.
    group
        The ``--free`` group it belongs to.
    subsystem
        True for parameters of the test pieces (they change only the rig frequencies).
    index
        ``chain_item``: the chain edited.
    chains
        ``angle_deg``: the chains turned.
    reference
        ``chain_mean``: the start's per-chain values; ``angle_deg``: the start's per-chain angles (rad).
    """

    name: str
    path: str
    kind: Kind
    start: float
    lower: float
    upper: float
    group: str
    subsystem: bool = False
    index: int | None = None
    chains: tuple[int, ...] = ()
    reference: tuple[float, ...] = ()


def _scaled_lump(lump: LumpedMass, mass: float) -> LumpedMass:
    if lump.mass_kg > 0:
        ratio = mass / lump.mass_kg
        i0, i1, i2 = lump.inertia_kg_m2
        return LumpedMass(mass, (i0 * ratio, i1 * ratio, i2 * ratio))
    r2 = 0.015**2  # no start inertia to scale: a 15 mm radius of gyration (joint hardware size)
    return LumpedMass(mass, (mass * r2, mass * r2, mass * r2))


def _chain_mean(per_chain: tuple[float, ...]) -> float:
    """The chains' common value, or their mean where they differ."""
    import numpy as np

    return per_chain[0] if len(set(per_chain)) == 1 else float(np.mean(per_chain))


def _field_value(spec: ParameterSpec, current: Any, owner: Any, leaf: str, v: float) -> Any:
    """The new value of field ``leaf`` of ``owner`` (now ``current``) for the scalar ``v`` (:data:`KINDS`).
    Any: the field's type depends on the path."""
    if spec.kind == "value":
        return v
    if spec.kind == "log10":
        return 10.0**v
    if spec.kind == "chain_mean":
        ref = spec.reference
        return v if len(set(ref)) == 1 else tuple(x + (v - _chain_mean(ref)) for x in ref)
    if spec.kind in ("chain_item", "chain_scale"):
        assert spec.index is not None
        vals = list(getattr(owner, f"{leaf[:-2]}_per_chain"))
        vals[spec.index] = v if spec.kind == "chain_item" else vals[spec.index] * (1.0 + v)
        return tuple(vals)
    if spec.kind in ("angle_deg", "angle_add_deg"):
        cur = list(current)
        for i in spec.chains:
            cur[i] = (spec.reference[i] if spec.kind == "angle_deg" else cur[i]) + math.radians(v)
        return tuple(cur)
    if spec.kind == "lump_mass":
        return _scaled_lump(current, v)
    raise ValueError(f"unknown parameter kind {spec.kind!r}")


def _set_path(obj: Any, path: Sequence[str], spec: ParameterSpec, v: float) -> Any:
    """``obj`` with the field at ``path`` (relative to it) set from ``v``: ``dataclasses.replace`` at every level
    (Any: the description's nested dataclasses)."""
    head, rest = path[0], path[1:]
    if obj is None:
        raise ConfigError(f"{spec.name}: the description has no {head!r} to set", parameter=spec.path)
    current = getattr(obj, head)
    new = _set_path(current, rest, spec, v) if rest else _field_value(spec, current, obj, head, v)
    return dataclasses.replace(obj, **{head: new})


def apply_parameters(
    config: Manipulator, specs: Sequence[ParameterSpec], x: Sequence[float] | np.ndarray
) -> Manipulator:
    """``config`` with each spec's field set from the matching value of ``x``, in order (not validated: see
    :meth:`ParameterSet.apply`).

    Parameters
    ----------
    config
        The description edited.
    specs
        The free parameters (:class:`ParameterSpec`), each editing the field at its dotted ``path``.
    x
        One value per spec, in its unit.

    Returns
    -------
    Manipulator
        The edited description.
    """
    for spec, v in zip(specs, x):
        config = _set_path(config, spec.path.split("."), spec, float(v))
    return config


def apply_parameters_batch(config: Manipulator, specs: Sequence[ParameterSpec], x: np.ndarray) -> dict[str, np.ndarray]:
    """The fields that ``specs`` edit, for every row of ``x`` (``(n, len(specs))``) at once: ``{path: array}``.

    A per-chain field comes as ``(n, 3)`` (per-chain lengths and angles), a lumped mass as ``(n, 4)`` (its mass,
    then its inertia's diagonal), any other field as ``(n,)``. Row ``i`` holds what :func:`apply_parameters` sets
    from ``x[i]`` (the same formulas, in the same order; tested), not validated. For the vectorised likelihoods of
    a sampler's particles (:func:`~fpm_sim.study.calibrate.vectorised.inplane_arrays`).
    """
    import numpy as np

    x = np.asarray(x, float)
    out: dict[str, np.ndarray] = {}
    for j, spec in enumerate(specs):
        current = out.get(spec.path)
        out[spec.path] = _batch_value(spec, _batch_start(config, spec, len(x)) if current is None else current, x[:, j])
    return out


def _batch_start(config: Manipulator, spec: ParameterSpec, n: int) -> np.ndarray:
    """The field of ``config`` that ``spec`` edits, repeated over ``n`` rows (:func:`apply_parameters_batch`)."""
    import numpy as np

    *owners, leaf = spec.path.split(".")
    owner: Any = config
    for name in owners:
        owner = getattr(owner, name)
    if spec.kind in ("chain_mean", "chain_item", "chain_scale"):
        value: Any = getattr(owner, f"{leaf[:-2]}_per_chain")
    elif spec.kind == "lump_mass":
        lump = getattr(owner, leaf)
        value = (lump.mass_kg, *lump.inertia_kg_m2)
    else:
        value = getattr(owner, leaf)
    row = np.asarray(value, float)
    return np.repeat(row[None], n, axis=0)


def _batch_value(spec: ParameterSpec, current: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`_field_value` for a column ``v`` of values, ``current`` the field's rows."""
    import numpy as np

    if spec.kind == "value":
        return v.copy()
    if spec.kind == "log10":
        out: np.ndarray = 10.0**v
        return out
    if spec.kind == "chain_mean":
        ref = spec.reference
        if len(set(ref)) == 1:
            return np.repeat(v[:, None], 3, axis=1)
        return np.asarray(ref, float)[None] + (v - _chain_mean(ref))[:, None]
    new = current.copy()
    if spec.kind in ("chain_item", "chain_scale"):
        assert spec.index is not None
        new[:, spec.index] = v if spec.kind == "chain_item" else current[:, spec.index] * (1.0 + v)
        return new
    if spec.kind in ("angle_deg", "angle_add_deg"):
        for i in spec.chains:
            new[:, i] = (spec.reference[i] if spec.kind == "angle_deg" else current[:, i]) + np.radians(v)
        return new
    if spec.kind == "lump_mass":
        m0 = current[:, 0]
        scaled = current[:, 1:] * (v / np.where(m0 > 0, m0, 1.0))[:, None]
        new[:, 0] = v
        new[:, 1:] = np.where((m0 > 0)[:, None], scaled, (v * 0.015**2)[:, None])  # as _scaled_lump
        return new
    raise ValueError(f"unknown parameter kind {spec.kind!r}")


def _geometry(cfg: Manipulator) -> list[ParameterSpec]:
    g = cfg.geometry
    out = []
    for f in ("base_radius_m", "platform_radius_m", "proximal_length_m", "distal_length_m"):
        per = tuple(getattr(g, f"{f[:-2]}_per_chain"))
        m = _chain_mean(per)
        out.append(
            ParameterSpec(
                f"geometry.{f}", f"geometry.{f}", "chain_mean", m, 0.6 * m, 1.6 * m, "geometry", reference=per
            )
        )
    for name, angles in (("base", g.base_angles_rad), ("platform", g.platform_angles_rad)):
        out.append(
            ParameterSpec(
                f"geometry.{name}_rotation_deg",
                f"geometry.{name}_angles_rad",
                "angle_deg",
                0.0,
                -60.0,
                60.0,
                "geometry",
                chains=(0, 1, 2),
                reference=tuple(angles),
            )
        )
    return out


def _geometry_per_chain(cfg: Manipulator) -> list[ParameterSpec]:
    g = cfg.geometry
    out = []
    group = "geometry-per-chain"
    for i in range(3):
        for f in ("base_radius_m", "proximal_length_m", "distal_length_m", "platform_radius_m"):
            v = getattr(g, f"{f[:-2]}_per_chain")[i]
            out.append(
                ParameterSpec(f"geometry.{f}[{i}]", f"geometry.{f}", "chain_item", v, 0.8 * v, 1.25 * v, group, index=i)
            )
        for name, angles in (("base", g.base_angles_rad), ("platform", g.platform_angles_rad)):
            out.append(
                ParameterSpec(
                    f"geometry.{name}_angle_deg[{i}]",
                    f"geometry.{name}_angles_rad",
                    "angle_deg",
                    0.0,
                    -15.0,
                    15.0,
                    group,
                    chains=(i,),
                    reference=tuple(angles),
                )
            )
    return out


AS_BUILT_BOUNDS = (5.0, 0.05)
"""The ``as-built`` group's bounds: +-5 deg, +-5 %."""


def _as_built(cfg: Manipulator) -> list[ParameterSpec]:
    """Per chain: its motor's and platform joint's angle deviation (deg), its links' relative length deviations."""
    deg, rel = AS_BUILT_BOUNDS
    out = []
    for i in range(3):
        for name in ("base", "platform"):
            out.append(
                ParameterSpec(
                    f"geometry.{name}_angle_dev_deg[{i}]", f"geometry.{name}_angles_rad", "angle_add_deg", 0.0,
                    -deg, deg, "as-built", chains=(i,),
                )
            )  # fmt: skip
        for f in ("proximal_length", "distal_length"):
            out.append(
                ParameterSpec(f"geometry.{f}_dev_rel[{i}]", f"geometry.{f}_m", "chain_scale", 0.0, -rel, rel,
                              "as-built", index=i)
            )  # fmt: skip
    return out


def _hubs(cfg: Manipulator) -> list[ParameterSpec]:
    g = cfg.geometry
    hi = 0.3 * min(g.proximal_length_per_chain + g.distal_length_per_chain)
    return [ParameterSpec("geometry.hub_length_m", "geometry.hub_length_m", "value", g.hub_length_m, 0.0, hi, "hubs")]


def _hardware(cfg: Manipulator) -> list[ParameterSpec]:
    out = []
    for name in ("platform", "elbow_joint", "platform_joint"):
        m = getattr(cfg.hardware, name).mass_kg
        lo, hi = (0.05 * m, 4.0 * m) if m > 0 else (0.0, 10.0 if name == "platform" else 2.0)
        start = m if m > 0 else 0.5 * hi
        out.append(
            ParameterSpec(f"hardware.{name}.mass_kg", f"hardware.{name}", "lump_mass", start, lo, hi, "hardware")
        )
    return out


def _section(cfg: Manipulator, fields: tuple[str, ...] = ("height_m", "thickness_m")) -> list[ParameterSpec]:
    out = []
    for f in fields:
        v = getattr(cfg.section, f)
        out.append(ParameterSpec(f"section.{f}", f"section.{f}", "value", v, 0.5 * v, 2.0 * v, "section"))
    return out


def _section_height(cfg: Manipulator) -> list[ParameterSpec]:
    return _section(cfg, ("height_m",))


def _compliance(cfg: Manipulator) -> list[ParameterSpec]:
    out = []
    for f in ("passive_joint_tilt_nm_per_rad", "motor_clamp_nm_per_rad", "motor_mount_tilt_nm_per_rad"):
        v = getattr(cfg.compliance, f)
        start = min(math.log10(v), LOG_STIFF_BOUNDS[1]) if math.isfinite(v) else LOG_STIFF_BOUNDS[1]
        out.append(
            ParameterSpec(f"compliance.log10_{f}", f"compliance.{f}", "log10", start, *LOG_STIFF_BOUNDS, "compliance")
        )
    return out


def _offsets(cfg: Manipulator) -> list[ParameterSpec]:
    g = cfg.geometry
    out = []
    for f in ("distal_offset_m", "platform_offset_m"):
        per = tuple(getattr(g, f"{f[:-2]}_per_chain"))
        # coplanar (all 0) is a stationary point of every frequency (the mirror z -> -z maps +offsets to -offsets
        # and leaves the frequencies), where a local fit cannot move: start such a description mid-range
        start = _chain_mean(per) if any(per) else 0.5 * (OFFSET_BOUNDS_M[0] + OFFSET_BOUNDS_M[1])
        out.append(
            ParameterSpec(
                f"geometry.{f}", f"geometry.{f}", "chain_mean", start, *OFFSET_BOUNDS_M, "offsets", reference=per
            )
        )
    return out


def _rig(cfg: Manipulator) -> list[ParameterSpec]:
    rig = cfg.rig
    if rig is None:
        raise ParameterError(
            "the group 'rig' needs a [rig] table in the start description", parameter="free", hint="add one to config"
        )
    L = rig.length_m
    h = rig.section.height_m
    hinge_m = rig.chain_hinge.mass_kg
    return [
        ParameterSpec("rig.length_m", "rig.length_m", "value", L, 0.5 * L, 2.0 * L, "rig", True),
        ParameterSpec(
            "rig.clamped_length_m",
            "rig.clamped_length_m",
            "value",
            max(rig.clamped_length_m, 0.05 * L),
            0.0,
            0.4 * L,
            "rig",
            True,
        ),
        ParameterSpec("rig.section.height_m", "rig.section.height_m", "value", h, 0.4 * h, 2.5 * h, "rig", True),
        ParameterSpec(
            "rig.chain_hinge.mass_kg",
            "rig.chain_hinge",
            "lump_mass",
            hinge_m if hinge_m > 0 else 0.2,
            0.0,
            2.0,
            "rig",
            True,
        ),
    ]


_BUILDERS: dict[str, Callable[[Manipulator], list[ParameterSpec]]] = {
    "geometry": _geometry,
    "geometry-per-chain": _geometry_per_chain,
    "as-built": _as_built,
    "hubs": _hubs,
    "hardware": _hardware,
    "section": _section,
    "section-height": _section_height,
    "compliance": _compliance,
    "offsets": _offsets,
    "rig": _rig,
}


@dataclass
class ParameterSet:
    """The free parameters of one identification, over a start description (plain data: picklable)."""

    start: Manipulator
    parameters: list[ParameterSpec] = field(default_factory=list)

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def lower(self) -> np.ndarray:
        import numpy as np

        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        import numpy as np

        return np.array([p.upper for p in self.parameters])

    @property
    def x0(self) -> np.ndarray:
        import numpy as np

        return np.clip(np.array([p.start for p in self.parameters]), self.lower, self.upper)

    @property
    def width(self) -> np.ndarray:
        """The bounds' widths (1 where a parameter's bounds coincide): the unit of the normalised ``z``."""
        import numpy as np

        lo, hi = self.lower, self.upper
        return np.where(hi > lo, hi - lo, 1.0)

    def from_unit(self, z: Sequence[float] | np.ndarray) -> np.ndarray:
        """Parameters (their units) at normalised ``z`` (clipped to [0, 1]: 0 the lower bound, 1 the upper)."""
        import numpy as np

        return self.lower + np.clip(z, 0.0, 1.0) * self.width

    def to_unit(self, x: Sequence[float] | np.ndarray) -> np.ndarray:
        """Normalised parameters of ``x`` (not clipped)."""
        import numpy as np

        return (np.asarray(x, float) - self.lower) / self.width

    def apply(self, x: Sequence[float] | np.ndarray, *, base: Manipulator | None = None) -> Manipulator:
        """The description with ``x`` set (validated). Raises :class:`ConfigError` for impossible values."""
        cfg = apply_parameters(base or self.start, self.parameters, x)
        cfg.replace()  # validate
        return cfg

    def subset(self, subsystem: bool) -> list[int]:
        return [i for i, p in enumerate(self.parameters) if p.subsystem == subsystem]


def parameter_set(start: Manipulator, groups: Sequence[str]) -> ParameterSet:
    """The free parameters of ``groups`` (see module docstring) over ``start``."""
    params: list[ParameterSpec] = []
    for g in groups:
        if g not in _BUILDERS:
            raise ParameterError(
                "unknown parameter group", parameter="free", value=g, hint=f"choose from {', '.join(GROUPS)}"
            )
        params += _BUILDERS[g](start)
    params = [p for p in params if p.group != "as-built"] + [p for p in params if p.group == "as-built"]
    for a, b in (GEOMETRY_GROUPS, ("section", "section-height"), ("geometry-per-chain", "as-built")):
        if a in groups and b in groups:
            raise ParameterError(f"{a} and {b} overlap", parameter="free", hint="choose one of them")
    if not params:
        raise ParameterError("no parameter group given", parameter="free")
    try:
        ParameterSet(start, params).apply([p.start for p in params])
    except ConfigError as exc:
        raise ParameterError(
            f"the start description is not valid with the free parameters at their start: {exc}"
        ) from exc
    return ParameterSet(start, params)
