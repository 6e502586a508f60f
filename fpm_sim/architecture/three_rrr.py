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

import math

from fpm_sim.architecture.description import ChainDesc, Description, EndEffectorDesc, JointDesc, LinkDesc, PlacedLump
from fpm_sim.config import LumpedMass, Manipulator
from fpm_sim.config.schema import ConfigError

__all__ = ["description_of_3rrr"]


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
