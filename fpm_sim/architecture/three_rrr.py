"""The study's planar 3RRR (:class:`fpm_sim.config.Manipulator`) written as a general description.

The same machine in the form every architecture uses: chain ``i`` from its motor axis ``A_i`` (actuated, locked)
through the proximal link, the elbow (its hardware split half and half between the two links, as the 3RRR builder
assumes), the distal link, to the platform joint at ``C_i`` (its hardware on the pin after the joint); the platform
and payload are the end effector's lumps. ``elbow_branch = +1`` (elbow left of ``A_i -> C_i``) is a negative
relative elbow angle: ``branch_deg = [-180, 0]``.

Used to prove the general path on the 3RRR (``tests/architecture``: the same frequencies as
:func:`fpm_sim.model.manipulator.build_manipulator`). Stacked layers, rigid hubs, compliant joints and servo motors
are not in the general form yet and are refused by name.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable

from fpm_sim.architecture.description import ChainDesc, Description, EndEffectorDesc, JointDesc, LinkDesc, PlacedLump
from fpm_sim.config import LumpedMass, Manipulator
from fpm_sim.config.schema import ConfigError

__all__ = ["description_of_3rrr", "three_rrr_toml"]


def _half(lump: LumpedMass) -> LumpedMass:
    i = lump.inertia_kg_m2
    return LumpedMass(lump.mass_kg / 2.0, (i[0] / 2.0, i[1] / 2.0, i[2] / 2.0))


def _refuse_what_is_not_general(manip: Manipulator) -> None:
    g = manip.geometry
    checks = {
        "geometry.hub_length_m": g.hub_length_m != 0.0,
        "geometry.distal_offset_m": any(g.distal_offset_per_chain),
        "geometry.platform_offset_m": any(g.platform_offset_per_chain),
        "compliance": any(
            math.isfinite(v)
            for v in (
                manip.compliance.passive_joint_tilt_nm_per_rad,
                manip.compliance.motor_clamp_nm_per_rad,
                manip.compliance.motor_mount_tilt_nm_per_rad,
            )
        ),
        "motors.mode": manip.motors.mode != "locked",
    }
    for name, unsupported in checks.items():
        if unsupported:
            raise ConfigError(
                "not in the general description form yet",
                parameter=name,
                hint="use the 3RRR's own builder for this description",
            )


def description_of_3rrr(manip: Manipulator) -> Description:
    """The 3RRR ``manip`` as a :class:`Description` (module docstring); raises for what the form lacks."""
    _refuse_what_is_not_general(manip)
    g, hw = manip.geometry, manip.hardware
    chains, attachments = [], {}
    for i in range(3):
        rb, rp = g.base_radius_per_chain[i], g.platform_radius_per_chain[i]
        a, gam = g.base_angles_rad[i], g.platform_angles_rad[i]
        attachments[f"c{i}"] = (rp * math.cos(gam), rp * math.sin(gam), 0.0)
        branch = (-math.pi, 0.0) if g.elbow_branch[i] > 0 else (0.0, math.pi)
        path = (
            JointDesc("motor", "revolute", actuated=True, lump=hw.motor_flange),
            LinkDesc("proximal", g.proximal_length_per_chain[i], manip.section, manip.material),
            JointDesc("elbow", "revolute", lump=_half(hw.elbow_joint), lump_after=_half(hw.elbow_joint), branch=branch),
            LinkDesc("distal", g.distal_length_per_chain[i], manip.section, manip.material),
            JointDesc("platform_joint", "revolute", lump_after=hw.platform_joint, at=f"c{i}"),
        )
        chains.append(ChainDesc(str(i), path, base_position_m=(rb * math.cos(a), rb * math.sin(a), 0.0)))
    ee = EndEffectorDesc(attachments, (PlacedLump(hw.platform), PlacedLump(hw.payload)))
    return Description(
        name=manip.name,
        planar=True,
        task=("x", "y", "phi"),
        chains=tuple(chains),
        end_effector=ee,
        damping_beta_s=manip.damping.stiffness_proportional_s,
        check_poses=({"x": 0.0, "y": 0.0, "phi": 0.0},),
        provenance=dict(manip.provenance),
    )


def _v(value: object, source: str) -> str:
    text = repr(value) if not isinstance(value, (list, tuple)) else "[" + ", ".join(repr(x) for x in value) + "]"
    return f"{{ value = {text}, source = {json.dumps(source)} }}"


def three_rrr_toml(manip: Manipulator) -> str:
    """The 3RRR ``manip`` written as a general description file (``examples/architectures/three_rrr.toml``), every
    value with the provenance the 3RRR's own file gives it; :func:`fpm_sim.architecture.parse_description` reads it
    back to :func:`description_of_3rrr`'s description."""
    _refuse_what_is_not_general(manip)
    src = _sources(manip)
    lines = [
        "# The study's planar 3RRR in the general description form, written by fpm_sim.architecture.three_rrr",
        "# (three_rrr_toml) from the embedded default; every value keeps its provenance there. The general path gives",
        "# the 3RRR builder's frequencies (tests/architecture/test_modes.py).",
        f"name = {json.dumps(manip.name)}",
        'kind = "planar"',
        'task = ["x", "y", "phi"]',
        "check_poses = [{ x_mm = 0.0, y_mm = 0.0, phi_rad = 0.0 }]",
        "",
        "[materials.links]",
        *(
            f"{k} = {_v(getattr(manip.material, k), src(f'material.{k}'))}"
            for k in ("young_pa", "poisson", "density_kg_m3")
        ),
        "",
        "[sections.links]",
        'shape = "rect"',
        *(f"{k} = {_v(getattr(manip.section, k), src(f'section.{k}'))}" for k in ("thickness_m", "height_m")),
    ]
    lines += _lump_lines(manip, src) + _end_effector_lines(manip, src)
    beta = manip.damping.stiffness_proportional_s
    lines += ["", "[damping]", f"stiffness_proportional_s = {_v(beta, src('damping.stiffness_proportional_s'))}"]
    for i in range(3):
        lines += _chain_lines(manip, i, src)
    return "\n".join(lines) + "\n"


def _sources(manip: Manipulator) -> Callable[[str], str]:
    return lambda key: manip.provenance.get(key, "unknown")


def _lump_lines(manip: Manipulator, src: Callable[[str], str]) -> list[str]:
    hw = manip.hardware
    lumps = {
        "motor_flange": hw.motor_flange,
        "platform_joint": hw.platform_joint,
        "platform": hw.platform,
        "payload": hw.payload,
        "elbow_half": _half(hw.elbow_joint),
    }
    lines: list[str] = []
    for name, lump in lumps.items():
        key = "elbow_joint" if name == "elbow_half" else name
        note = " (half of it: the 3RRR builder's assumed split)" if name == "elbow_half" else ""
        lines += [
            "",
            f"[lumps.{name}]",
            f"mass_kg = {_v(lump.mass_kg, src(f'hardware.{key}.mass_kg') + note)}",
            f"inertia_kg_m2 = {_v(list(lump.inertia_kg_m2), src(f'hardware.{key}.inertia_kg_m2') + note)}",
        ]
    return lines


def _end_effector_lines(manip: Manipulator, src: Callable[[str], str]) -> list[str]:
    g = manip.geometry
    where = f"{src('geometry.platform_radius_m')} (with geometry.platform_angles_deg)"
    points = []
    for i in range(3):
        rp, gam = g.platform_radius_per_chain[i], g.platform_angles_rad[i]
        points.append(f"c{i} = {_v([rp * math.cos(gam), rp * math.sin(gam), 0.0], where)}")
    centre = _v([0.0, 0.0, 0.0], "assumed: at the platform's centre, as the 3RRR builder places it")
    placed = ", ".join(f'{{ lump = "{n}", position_m = {centre} }}' for n in ("platform", "payload"))
    return ["", "[end_effector.attachments_m]", *points, "", "[end_effector]", f"lumps = [{placed}]"]


def _chain_lines(manip: Manipulator, i: int, src: Callable[[str], str]) -> list[str]:
    g = manip.geometry
    rb, a = g.base_radius_per_chain[i], g.base_angles_rad[i]
    base = _v([rb * math.cos(a), rb * math.sin(a), 0.0], f"{src('geometry.base_radius_m')} (with base_angles_deg)")
    branch = _v([-180.0, 0.0] if g.elbow_branch[i] > 0 else [0.0, 180.0], src("geometry.elbow_branch"))
    proximal = _v(g.proximal_length_per_chain[i], src("geometry.proximal_length_m"))
    distal = _v(g.distal_length_per_chain[i], src("geometry.distal_length_m"))
    material = 'section = "links", material = "links"'
    elbow_lumps = 'lump = "elbow_half", lump_after = "elbow_half"'
    return [
        "",
        "[[chains]]",
        f'name = "{i}"',
        f"base_position_m = {base}",
        "path = [",
        '  { joint = "motor", type = "revolute", actuated = true, lump = "motor_flange" },',
        f'  {{ link = "proximal", length_m = {proximal}, {material} }},',
        f'  {{ joint = "elbow", type = "revolute", {elbow_lumps}, branch_deg = {branch} }},',
        f'  {{ link = "distal", length_m = {distal}, {material} }},',
        f'  {{ joint = "platform_joint", type = "revolute", lump_after = "platform_joint", at = "c{i}" }},',
        "]",
    ]
