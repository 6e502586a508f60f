"""The study's subsystem test rigs as MuJoCo models.

``free-free``
    One link floating freely (the study hung it on elastic bands): a free joint at its root, gravity
    off; its six rigid-body modes are dropped by the zero-frequency criterion.
``cantilever``
    One link with ``clamped_length_m`` of its length cast in the clamp; the free part is modelled,
    its root fixed to the world (or held by ``compliance.base_clamp_nm_per_rad`` springs).
``chain``
    Two links joined by a passive hinge (axis z) whose interior angle is ``angle_deg`` (180 = straight),
    both far ends clamped: the first link's root is fixed, the second link's end is welded to the world.
    Half the hinge hardware sits on each link end.

All lie in the base plane with x along the first link; gravity (if on) acts along -z.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass
from typing import Any

import mujoco
import numpy as np

from fpm_sim.config import Compliance, LumpedMass, Manipulator, Material, RigConfig, Section, default_config
from fpm_sim.errors import FpmSimError
from fpm_sim.model.links import add_link
from fpm_sim.model.manipulator import dof_kinds_of
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.parts import (
    LinkBuild,
    LinkSpec,
    add_compliance_springs,
    add_hinge,
    half_lump,
    lump_part,
    set_inertial,
)
from fpm_sim.model.spec import BuiltModel, add_weld, compile_model, new_spec

__all__ = ["RIGS", "RigError", "RigSetup", "build_rig", "rig_piece"]

RIGS = ("free-free", "cantilever", "chain")


class RigError(FpmSimError):
    """Impossible rig settings (unknown rig, angle out of range, clamp longer than the link)."""


@dataclass(frozen=True)
class RigSetup:
    """Which rig and its settings beyond the test piece itself."""

    rig: str
    angle_deg: float = 180.0
    damping_beta_s: float = 0.0

    def __post_init__(self) -> None:
        if self.rig not in RIGS:
            raise RigError(f"unknown rig {self.rig!r}; choose one of {', '.join(RIGS)}")
        if self.rig == "chain" and not (10.0 <= self.angle_deg <= 180.0):
            raise RigError(
                "the chain hinge angle must lie in [10, 180] degrees", parameter="rig.angle_deg", value=self.angle_deg
            )


def _clamp_springs(body: mujoco.MjsBody, prefix: str, k: float, beta: float, kinds: dict[str, str]) -> None:
    add_compliance_springs(body, f"{prefix}_clamp", "yz", k, beta, "clamp", kinds)


def build_rig(
    setup: RigSetup,
    piece: RigConfig,
    options: ModelOptions | None = None,
    *,
    compliance: Compliance | None = None,
) -> BuiltModel:
    """Generate and compile a subsystem rig (see module docstring)."""
    opts = options or ModelOptions()
    comp = compliance or Compliance()
    # the free-free bar hangs whole; only the clamped rigs lose clamped_length_m to each clamp
    free_len = piece.length_m if setup.rig == "free-free" else piece.length_m - piece.clamped_length_m
    if free_len <= 0:
        raise RigError(
            f"clamped_length_m ({piece.clamped_length_m} m) must be shorter than length_m ({piece.length_m} m)"
        )
    gravity = opts.gravity and setup.rig != "free-free"
    spec = new_spec(f"fpm_rig_{setup.rig.replace('-', '_')}", gravity=gravity)
    kinds: dict[str, str] = {}
    links: dict[str, list[str]] = {}
    kw: dict[str, Any] = dict(
        section=piece.section,
        material=piece.material,
        link_model=opts.link_model,
        segments=opts.segments,
        axial=opts.axial,
        rotary_inertia=opts.rotary_inertia,
        shear=opts.shear,
        damping_beta_s=setup.damping_beta_s,
    )
    hinge = piece.chain_hinge if setup.rig == "chain" else LumpedMass()
    first = add_link(
        spec,
        spec.worldbody,
        LinkSpec(
            name="link_0",
            pos_m=(0.0, 0.0, 0.0),
            angle_rad=0.0,
            length_m=free_len,
            end_lumps=(half_lump(hinge),) if hinge.mass_kg > 0 else (),
            free_start=setup.rig == "free-free",
            free_end=setup.rig != "chain",
            **kw,
        ),
    )
    links[first.name] = first.sites
    kinds.update(dict(first.joints))
    if setup.rig == "free-free":
        if opts.link_model != "flex":  # a flex link's vertices are free already
            first.first.add_freejoint(name="float")
    else:
        _clamp_springs(first.first, "root", comp.base_clamp_nm_per_rad, setup.damping_beta_s, kinds)
    if setup.rig == "chain":
        _add_second_link_and_far_clamp(spec, first, setup, comp, hinge, free_len, kw, kinds, links)
    model = compile_model(spec, timestep_s=opts.timestep_s)
    return BuiltModel(
        model=model,
        spec=spec,
        name=setup.rig,
        links=links,
        dof_kinds=dof_kinds_of(model, kinds),
        parameters={
            "rig": asdict(setup),
            "piece": asdict(piece),
            "free_length_m": free_len,
            "options": asdict(opts),
            "timestep_s": float(model.opt.timestep),
            "nv": int(model.nv),
        },
    )


def _add_second_link_and_far_clamp(
    spec: mujoco.MjSpec,
    first: LinkBuild,
    setup: RigSetup,
    comp: Compliance,
    hinge: LumpedMass,
    free_len: float,
    kw: dict[str, Any],
    kinds: dict[str, str],
    links: dict[str, list[str]],
) -> None:
    """The chain rig's second link on the hinge at ``first``'s end (turned by ``setup.angle_deg``), its tip
    clamped to the world."""
    turn = math.pi - math.radians(setup.angle_deg)
    second = add_link(
        spec,
        first.last,
        LinkSpec(
            name="link_1",
            pos_m=(first.last_length_m, 0.0, 0.0),
            angle_rad=turn,
            length_m=free_len,
            start_lumps=(half_lump(hinge),) if hinge.mass_kg > 0 else (),
            free_end=False,
            **kw,
        ),
    )
    add_hinge(second.first, "hinge", [0, 0, 1])
    kinds["hinge"] = "passive"
    if math.isfinite(comp.passive_joint_tilt_nm_per_rad):  # the same bearing compliance as the manipulator's
        k_t = comp.passive_joint_tilt_nm_per_rad
        for ax, axis in (("x", [1, 0, 0]), ("y", [0, 1, 0])):
            add_hinge(second.first, f"hinge_tilt{ax}", axis, k_t, setup.damping_beta_s * k_t)
            kinds[f"hinge_tilt{ax}"] = "tilt"
    links[second.name] = second.sites
    kinds.update(dict(second.joints))
    tip = second.last.add_body(name="tip", pos=[second.last_length_m, 0.0, 0.0])
    set_inertial(tip, [lump_part(LumpedMass(1e-4, (1e-9, 1e-9, 1e-9)), np.zeros(3))])
    _clamp_springs(tip, "tip", comp.base_clamp_nm_per_rad, setup.damping_beta_s, kinds)
    add_weld(spec, "clamp_far", "tip", "world")


def rig_piece(
    config: Manipulator | None = None,
    *,
    length_m: float | None = None,
    thickness_m: float | None = None,
    height_m: float | None = None,
    young_pa: float | None = None,
    poisson: float | None = None,
    density_kg_m3: float | None = None,
    clamped_length_m: float | None = None,
) -> RigConfig:
    """The test piece of ``config`` (default: the embedded one) with optional overrides."""
    cfg = config or default_config()
    if cfg.rig is None:
        raise RigError("the configuration has no [rig] table; add one or pass length/section/material overrides")
    base = cfg.rig
    sec = Section(
        thickness_m=base.section.thickness_m if thickness_m is None else thickness_m,
        height_m=base.section.height_m if height_m is None else height_m,
    )
    mat = Material(
        young_pa=base.material.young_pa if young_pa is None else young_pa,
        poisson=base.material.poisson if poisson is None else poisson,
        density_kg_m3=base.material.density_kg_m3 if density_kg_m3 is None else density_kg_m3,
    )
    piece = dataclasses.replace(
        base,
        length_m=base.length_m if length_m is None else length_m,
        section=sec,
        material=mat,
        clamped_length_m=base.clamped_length_m if clamped_length_m is None else clamped_length_m,
    )
    # validate through the manipulator validator (names the rig.* field)
    cfg.replace(rig=piece)
    return piece
