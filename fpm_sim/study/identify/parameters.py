"""Named parameter groups that ``fpm-sim identify --free`` can free, and how each sets a description.

Every parameter is a scalar in SI units (angles in degrees, stiffnesses as ``log10`` of N m/rad) with
bounds; :meth:`ParameterSet.apply` turns a vector into a validated :class:`Manipulator`.

Groups (:data:`GROUPS`):

``geometry``
    Mean base radius, platform radius, proximal and distal lengths (m; chain-to-chain differences
    of the start kept), a rotation of the motor layout and one of the platform-joint layout (deg,
    about the start). Bounds: lengths 0.6-1.6 x the start, rotations +-60 deg.
``geometry-per-chain``
    Per chain: base radius, motor angle, proximal length, distal length, platform radius,
    platform-joint angle (18 parameters). Bounds: lengths 0.8-1.25 x the start, angles +-15 deg.
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
from dataclasses import dataclass
from typing import Any

import numpy as np

from fpm_sim.config import ConfigError, LumpedMass, Manipulator, RigConfig
from fpm_sim.errors import FpmSimError

__all__ = ["GEOMETRY_GROUPS", "GROUPS", "FreeParameter", "ParameterError", "ParameterSet", "parameter_set"]

GROUPS = (
    "geometry",
    "geometry-per-chain",
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


class ParameterError(FpmSimError):
    """An unknown or unusable parameter group (``--free``)."""


@dataclass(frozen=True)
class FreeParameter:
    """One free scalar: dotted name (unit in the name), start value and bounds, and its setter."""

    name: str
    start: float
    lower: float
    upper: float
    setter: Callable[[Manipulator, float], Manipulator]
    group: str
    subsystem: bool = False
    """True for parameters of the test pieces (they change only the rig frequencies)."""


def _scaled_lump(lump: LumpedMass, mass: float) -> LumpedMass:
    if lump.mass_kg > 0:
        ratio = mass / lump.mass_kg
        i0, i1, i2 = lump.inertia_kg_m2
        return LumpedMass(mass, (i0 * ratio, i1 * ratio, i2 * ratio))
    r2 = 0.015**2  # no start inertia to scale: a 15 mm radius of gyration (joint hardware size)
    return LumpedMass(mass, (mass * r2, mass * r2, mass * r2))


def _set_geometry(cfg: Manipulator, **changes: Any) -> Manipulator:
    # Any: the field names are chosen at run time; dataclasses.replace checks them.
    return dataclasses.replace(cfg, geometry=dataclasses.replace(cfg.geometry, **changes))


def _chain_mean(per_chain: tuple[float, float, float]) -> float:
    """The chains' common value, or their mean where they differ."""
    return per_chain[0] if len(set(per_chain)) == 1 else float(np.mean(per_chain))


def _mean_setter(field_name: str, per_chain: tuple[float, float, float]) -> Callable[[Manipulator, float], Manipulator]:
    sym = len(set(per_chain)) == 1
    mean0 = _chain_mean(per_chain)

    def set_(cfg: Manipulator, v: float) -> Manipulator:
        value: float | tuple = v if sym else tuple(x + (v - mean0) for x in per_chain)
        return _set_geometry(cfg, **{field_name: value})

    return set_


def _chain_setter(field_name: str, i: int) -> Callable[[Manipulator, float], Manipulator]:
    def set_(cfg: Manipulator, v: float) -> Manipulator:
        vals = list(getattr(cfg.geometry, f"{field_name[:-2]}_per_chain"))
        vals[i] = v
        return _set_geometry(cfg, **{field_name: tuple(vals)})

    return set_


def _angle_setter(
    field_name: str, start: tuple[float, ...], chains: Sequence[int]
) -> Callable[[Manipulator, float], Manipulator]:
    def set_(cfg: Manipulator, v_deg: float) -> Manipulator:
        cur = list(getattr(cfg.geometry, field_name))
        for i in chains:
            cur[i] = start[i] + math.radians(v_deg)
        return _set_geometry(cfg, **{field_name: tuple(cur)})

    return set_


def _geometry(cfg: Manipulator) -> list[FreeParameter]:
    g = cfg.geometry
    out = []
    for f in ("base_radius_m", "platform_radius_m", "proximal_length_m", "distal_length_m"):
        per = getattr(g, f"{f[:-2]}_per_chain")
        m = _chain_mean(per)
        out.append(FreeParameter(f"geometry.{f}", m, 0.6 * m, 1.6 * m, _mean_setter(f, per), "geometry"))
    out.append(
        FreeParameter(
            "geometry.base_rotation_deg",
            0.0,
            -60.0,
            60.0,
            _angle_setter("base_angles_rad", g.base_angles_rad, range(3)),
            "geometry",
        )
    )
    out.append(
        FreeParameter(
            "geometry.platform_rotation_deg",
            0.0,
            -60.0,
            60.0,
            _angle_setter("platform_angles_rad", g.platform_angles_rad, range(3)),
            "geometry",
        )
    )
    return out


def _geometry_per_chain(cfg: Manipulator) -> list[FreeParameter]:
    g = cfg.geometry
    out = []
    for i in range(3):
        for f in ("base_radius_m", "proximal_length_m", "distal_length_m", "platform_radius_m"):
            v = getattr(g, f"{f[:-2]}_per_chain")[i]
            out.append(
                FreeParameter(f"geometry.{f}[{i}]", v, 0.8 * v, 1.25 * v, _chain_setter(f, i), "geometry-per-chain")
            )
        out.append(
            FreeParameter(
                f"geometry.base_angle_deg[{i}]",
                0.0,
                -15.0,
                15.0,
                _angle_setter("base_angles_rad", g.base_angles_rad, [i]),
                "geometry-per-chain",
            )
        )
        out.append(
            FreeParameter(
                f"geometry.platform_angle_deg[{i}]",
                0.0,
                -15.0,
                15.0,
                _angle_setter("platform_angles_rad", g.platform_angles_rad, [i]),
                "geometry-per-chain",
            )
        )
    return out


def _hubs(cfg: Manipulator) -> list[FreeParameter]:
    g = cfg.geometry
    hi = 0.3 * min(g.proximal_length_per_chain + g.distal_length_per_chain)

    def set_(c: Manipulator, v: float) -> Manipulator:
        return _set_geometry(c, hub_length_m=v)

    return [FreeParameter("geometry.hub_length_m", g.hub_length_m, 0.0, hi, set_, "hubs")]


def _lump_setter(name: str) -> Callable[[Manipulator, float], Manipulator]:
    def set_(cfg: Manipulator, v: float) -> Manipulator:
        hw = cfg.hardware
        return dataclasses.replace(cfg, hardware=dataclasses.replace(hw, **{name: _scaled_lump(getattr(hw, name), v)}))

    return set_


def _hardware(cfg: Manipulator) -> list[FreeParameter]:
    out = []
    for name in ("platform", "elbow_joint", "platform_joint"):
        m = getattr(cfg.hardware, name).mass_kg
        lo, hi = (0.05 * m, 4.0 * m) if m > 0 else (0.0, 10.0 if name == "platform" else 2.0)
        start = m if m > 0 else 0.5 * hi
        out.append(FreeParameter(f"hardware.{name}.mass_kg", start, lo, hi, _lump_setter(name), "hardware"))
    return out


def _section(cfg: Manipulator, fields: tuple[str, ...] = ("height_m", "thickness_m")) -> list[FreeParameter]:
    out = []
    for f in fields:
        v = getattr(cfg.section, f)

        def set_(c: Manipulator, x: float, f: str = f) -> Manipulator:
            return dataclasses.replace(c, section=dataclasses.replace(c.section, **{f: x}))

        out.append(FreeParameter(f"section.{f}", v, 0.5 * v, 2.0 * v, set_, "section"))
    return out


def _section_height(cfg: Manipulator) -> list[FreeParameter]:
    return _section(cfg, ("height_m",))


def _compliance(cfg: Manipulator) -> list[FreeParameter]:
    out = []
    for f in ("passive_joint_tilt_nm_per_rad", "motor_clamp_nm_per_rad", "motor_mount_tilt_nm_per_rad"):
        v = getattr(cfg.compliance, f)
        start = min(math.log10(v), LOG_STIFF_BOUNDS[1]) if math.isfinite(v) else LOG_STIFF_BOUNDS[1]

        def set_(c: Manipulator, x: float, f: str = f) -> Manipulator:
            return dataclasses.replace(c, compliance=dataclasses.replace(c.compliance, **{f: 10.0**x}))

        out.append(FreeParameter(f"compliance.log10_{f}", start, *LOG_STIFF_BOUNDS, set_, "compliance"))
    return out


def _offsets(cfg: Manipulator) -> list[FreeParameter]:
    g = cfg.geometry
    out = []
    for f in ("distal_offset_m", "platform_offset_m"):
        per = getattr(g, f"{f[:-2]}_per_chain")
        # coplanar (all 0) is a stationary point of every frequency (the mirror z -> -z maps +offsets to -offsets
        # and leaves the frequencies), where a local fit cannot move: start such a description mid-range
        start = _chain_mean(per) if any(per) else 0.5 * (OFFSET_BOUNDS_M[0] + OFFSET_BOUNDS_M[1])
        out.append(FreeParameter(f"geometry.{f}", start, *OFFSET_BOUNDS_M, _mean_setter(f, per), "offsets"))
    return out


def _rig(cfg: Manipulator) -> list[FreeParameter]:
    rig = cfg.rig
    if rig is None:
        raise ParameterError(
            "the group 'rig' needs a [rig] table in the start description", parameter="free", hint="add one to config"
        )

    # build(rig, value) -> the new value of the one RigConfig field named by the keyword (Any: its type
    # depends on that field).
    def setter(**kw_of_value: Callable[[RigConfig, float], Any]) -> Callable[[Manipulator, float], Manipulator]:
        ((attr, build),) = kw_of_value.items()

        def set_(c: Manipulator, v: float) -> Manipulator:
            assert c.rig is not None
            return dataclasses.replace(c, rig=dataclasses.replace(c.rig, **{attr: build(c.rig, v)}))

        return set_

    L = rig.length_m
    hinge_m = rig.chain_hinge.mass_kg
    return [
        FreeParameter("rig.length_m", L, 0.5 * L, 2.0 * L, setter(length_m=lambda r, v: v), "rig", True),
        FreeParameter(
            "rig.clamped_length_m",
            max(rig.clamped_length_m, 0.05 * L),
            0.0,
            0.4 * L,
            setter(clamped_length_m=lambda r, v: v),
            "rig",
            True,
        ),
        FreeParameter(
            "rig.section.height_m",
            rig.section.height_m,
            0.4 * rig.section.height_m,
            2.5 * rig.section.height_m,
            setter(section=lambda r, v: dataclasses.replace(r.section, height_m=v)),
            "rig",
            True,
        ),
        FreeParameter(
            "rig.chain_hinge.mass_kg",
            hinge_m if hinge_m > 0 else 0.2,
            0.0,
            2.0,
            setter(chain_hinge=lambda r, v: _scaled_lump(r.chain_hinge, v)),
            "rig",
            True,
        ),
    ]


_BUILDERS = {
    "geometry": _geometry,
    "geometry-per-chain": _geometry_per_chain,
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
    """The free parameters of one identification, over a start description."""

    start: Manipulator
    parameters: list[FreeParameter]

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    @property
    def x0(self) -> np.ndarray:
        return np.clip(np.array([p.start for p in self.parameters]), self.lower, self.upper)

    def apply(self, x: Sequence[float] | np.ndarray, *, base: Manipulator | None = None) -> Manipulator:
        """The description with ``x`` set (validated). Raises :class:`ConfigError` for impossible values."""
        cfg = base or self.start
        for p, v in zip(self.parameters, x):
            cfg = p.setter(cfg, float(v))
        cfg.replace()  # validate
        return cfg

    def subset(self, subsystem: bool) -> list[int]:
        return [i for i, p in enumerate(self.parameters) if p.subsystem == subsystem]


def parameter_set(start: Manipulator, groups: Sequence[str]) -> ParameterSet:
    """The free parameters of ``groups`` (see module docstring) over ``start``."""
    params: list[FreeParameter] = []
    for g in groups:
        if g not in _BUILDERS:
            raise ParameterError(
                "unknown parameter group", parameter="free", value=g, hint=f"choose from {', '.join(GROUPS)}"
            )
        params += _BUILDERS[g](start)
    for a, b in (GEOMETRY_GROUPS, ("section", "section-height")):
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
