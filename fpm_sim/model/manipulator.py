"""Per-pose MuJoCo model of the whole flexible 3RRR, built with :class:`mujoco.MjSpec`.

Topology (all bodies placed at the assembled pose, so ``qpos0 = 0`` is the assembly at rest with
straight, unstressed links):

``world -> [motor] -> proximal_i -> elbow hinge -> distal_i -> platform-joint hinge -> pin_i``;
``pin_0 -> platform`` rigidly; ``pin_1``, ``pin_2`` are welded to the platform (loop closure).

- motors locked: the proximal link's root is part of the base; a finite
  ``compliance.motor_clamp_nm_per_rad`` or ``motors.mode = "servo"`` adds a z-hinge spring there;
- motor mounts: rigid; a finite ``compliance.motor_mount_tilt_nm_per_rad`` adds two tilt springs
  (x along the proximal link, y across it) at each proximal link's root, on the base side of the
  motor hinge (:func:`add_motor_mount`);
- passive joints: ideal z-hinges; a finite ``compliance.passive_joint_tilt_nm_per_rad`` adds two
  tilt springs (x, y) at each;
- hardware: half the elbow hardware sits at the proximal link's end and half at the distal link's
  start (assumed split), the platform-joint hardware is the ``pin_i`` body, the motor flange sits at
  the proximal root, platform and payload at the platform centre. A pin without hardware mass gets
  :data:`MIN_PIN_MASS_KG` (MuJoCo needs mass on every moving body).
- stacked links: ``geometry.distal_offset_m`` places ``distal_i`` that far above its proximal link's
  end (+z) and ``geometry.platform_offset_m`` places ``pin_i`` (and so the platform) that far above
  its distal link's end: the offset is the joint's child body's position along the joint axis, so the
  pin between the layers is rigid (and massless: its mass belongs to the joint's hardware lumps) and
  the hinge axis (z) is the same line; in-plane positions and the kinematics are those of the coplanar
  model. The platform's centre sits at chain 0's pin height.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import mujoco
import numpy as np

from fpm_sim.config import Compliance, LumpedMass, Manipulator
from fpm_sim.kinematics import Assembly, Pose, inverse_kinematics
from fpm_sim.model.links import add_link
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.parts import LinkSpec, add_compliance_springs, add_hinge, half_lump, lump_part, quat_z, set_inertial
from fpm_sim.model.spec import BuiltModel, add_weld, compile_model, new_spec

__all__ = ["MIN_PIN_MASS_KG", "add_motor_mount", "build_manipulator"]

MIN_PIN_MASS_KG = 1e-4


def _add_passive_joint(body: mujoco.MjsBody, name: str, manip: Manipulator, kinds: dict[str, str]) -> None:
    add_hinge(body, name, [0, 0, 1])
    kinds[name] = "passive"
    k_tilt = manip.compliance.passive_joint_tilt_nm_per_rad
    add_compliance_springs(body, f"{name}_tilt", "xy", k_tilt, manip.damping.stiffness_proportional_s, "tilt", kinds)


def add_motor_mount(
    body: mujoco.MjsBody, name: str, compliance: Compliance, beta_s: float, kinds: dict[str, str]
) -> None:
    """The motor's mounting on the base at the root ``body`` of a proximal link (x along the link).

    A finite ``compliance.motor_mount_tilt_nm_per_rad`` adds the rotational springs ``{name}_mount_tiltx``
    (about the link: twists its root) and ``{name}_mount_tilty`` (across it: bends the link out of the
    plane), damping ``beta_s * k``, kind ``tilt``; rigid (``inf``) adds nothing. Called before the motor's
    own z-hinge, so the motor axis tilts with its mount.
    """
    k = compliance.motor_mount_tilt_nm_per_rad
    add_compliance_springs(body, f"{name}_mount_tilt", "xy", k, beta_s, "tilt", kinds)


def build_manipulator(
    manip: Manipulator,
    pose: Pose,
    options: ModelOptions | None = None,
    *,
    assembly: Assembly | None = None,
) -> BuiltModel:
    """Generate and compile the flexible manipulator assembled at ``pose``.

    Raises
    ------
    fpm_sim.kinematics.UnreachablePoseError, fpm_sim.kinematics.SingularPoseError
        For poses without a usable assembly.
    """
    opts = options or ModelOptions()
    g = manip.geometry
    asm = assembly if assembly is not None else inverse_kinematics(g, pose)
    beta = manip.damping.stiffness_proportional_s
    spec = new_spec("fpm_3rrr", gravity=opts.gravity)
    kinds: dict[str, str] = {}
    links: dict[str, list[str]] = {}
    link_kw: dict[str, Any] = dict(
        section=manip.section,
        material=manip.material,
        link_model=opts.link_model,
        lump_bodies=opts.link_model == "rigid",
        segments=opts.segments,
        axial=opts.axial,
        rotary_inertia=opts.rotary_inertia,
        shear=opts.shear,
        hub_length_m=g.hub_length_m,
        damping_beta_s=beta,
    )
    pins = [_add_chain(spec, i, manip, pose, asm, link_kw, kinds, links) for i in range(3)]
    _add_platform(spec, pins, manip)

    model = compile_model(spec, timestep_s=opts.timestep_s)
    return BuiltModel(
        model=model,
        spec=spec,
        name="manipulator",
        links=links,
        dof_kinds=dof_kinds_of(model, kinds),
        parameters={
            "config": manip.name,
            "pose": asdict(pose),
            "options": asdict(opts),
            "timestep_s": float(model.opt.timestep),
            "nv": int(model.nv),
            "motor_angles_rad": asm.motor_angles_rad.tolist(),
            "singularity_measure": asm.singularity.value,
        },
        end_effector_site="platform_center",
        accelerometer_links=tuple(f"distal_{i}" for i in range(3)),
        test_point=("distal_0", 0.5, "z"),  # the study's impact point (fpm_sim.sim.impact.STUDY_IMPACT_POINT)
        planar=True,
    )


def _add_chain(
    spec: mujoco.MjSpec,
    i: int,
    manip: Manipulator,
    pose: Pose,
    asm: Assembly,
    link_kw: dict[str, Any],
    kinds: dict[str, str],
    links: dict[str, list[str]],
) -> mujoco.MjsBody:
    """Chain ``i``: the proximal link on its motor mount, the distal link on the elbow, the platform pin at its
    end; records joint kinds and link sites, returns the pin body."""
    g, hw = manip.geometry, manip.hardware
    beta = manip.damping.stiffness_proportional_s
    a, b, c = asm.a[i], asm.b[i], asm.c[i]
    ang_p = math.atan2(*(b - a)[::-1])
    ang_d = math.atan2(*(c - b)[::-1])
    prox_spec = LinkSpec(
        name=f"proximal_{i}",
        pos_m=(float(a[0]), float(a[1]), 0.0),
        angle_rad=ang_p,
        length_m=g.proximal_length_per_chain[i],
        start_lumps=(hw.motor_flange,),
        end_lumps=(half_lump(hw.elbow_joint),),
        rgba=(0.25, 0.45, 0.8, 1.0),
        **link_kw,
    )
    prox = add_link(spec, spec.worldbody, prox_spec)
    add_motor_mount(prox.first, f"motor_{i}", manip.compliance, beta, kinds)
    _add_motor_joint(prox.first, f"motor_{i}", manip, kinds)
    dist_spec = LinkSpec(
        name=f"distal_{i}",
        pos_m=(prox.last_length_m, 0.0, g.distal_offset_per_chain[i]),
        angle_rad=ang_d - ang_p,
        length_m=g.distal_length_per_chain[i],
        start_lumps=(half_lump(hw.elbow_joint),),
        rgba=(0.85, 0.45, 0.2, 1.0),
        **link_kw,
    )
    dist = add_link(spec, prox.last, dist_spec)
    _add_passive_joint(dist.first, f"elbow_{i}", manip, kinds)
    for lb in (prox, dist):
        kinds.update(dict(lb.joints))
        links[lb.name] = lb.sites
    pin = dist.last.add_body(
        name=f"pin_{i}",
        pos=[dist.last_length_m, 0.0, g.platform_offset_per_chain[i]],
        quat=quat_z(pose.phi_rad - ang_d),
    )
    pin_lump = hw.platform_joint
    if pin_lump.mass_kg <= 0.0:
        pin_lump = LumpedMass(MIN_PIN_MASS_KG, (1e-9, 1e-9, 1e-9))
    set_inertial(pin, [lump_part(pin_lump, np.zeros(3))])
    _add_passive_joint(pin, f"platform_joint_{i}", manip, kinds)
    pin.add_site(name=f"pin_{i}_site", pos=[0, 0, 0], size=[0.003, 0, 0])
    return pin


def _add_motor_joint(body: mujoco.MjsBody, name: str, manip: Manipulator, kinds: dict[str, str]) -> None:
    """The motor hinge: a servo (``motors.mode = 'servo'``), a finite clamp stiffness, or none (locked)."""
    if manip.motors.mode == "servo":
        k, c_damp = manip.motors.servo_stiffness_nm_per_rad, manip.motors.servo_damping_nms_per_rad
        add_hinge(body, name, [0, 0, 1], k, c_damp)
        kinds[name] = "motor"
    elif math.isfinite(manip.compliance.motor_clamp_nm_per_rad):
        k = manip.compliance.motor_clamp_nm_per_rad
        add_hinge(body, name, [0, 0, 1], k, manip.damping.stiffness_proportional_s * k)
        kinds[name] = "clamp"


def _add_platform(spec: mujoco.MjSpec, pins: list[mujoco.MjsBody], manip: Manipulator) -> None:
    """The platform on chain 0's pin, welded to the other two pins (the loop closures)."""
    g, hw = manip.geometry, manip.hardware
    ang0 = g.platform_angles_rad[0]
    r_p0 = g.platform_radius_per_chain[0]
    platform = pins[0].add_body(
        name="platform",
        pos=[-r_p0 * math.cos(ang0), -r_p0 * math.sin(ang0), 0.0],
    )
    set_inertial(platform, [lump_part(hw.platform, np.zeros(3)), lump_part(hw.payload, np.zeros(3))])
    platform.add_geom(
        name="platform_g",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[max(max(g.platform_radius_per_chain), 0.01), 0.005, 0],
        rgba=[0.3, 0.7, 0.3, 1.0],
        contype=0,
        conaffinity=0,
    )
    platform.add_site(name="platform_center", pos=[0, 0, 0], size=[0.004, 0, 0])
    for i in (1, 2):
        add_weld(spec, f"loop_{i}", f"pin_{i}", "platform")


def dof_kinds_of(model: mujoco.MjModel, kinds: dict[str, str]) -> list[str]:
    """Kind of each degree of freedom from the joint-name -> kind map (free joints: ``free``; the
    three dofs of a ``cable`` link's ball joint, in the link frame: ``twist``, ``bend_out``, ``bend_in``)."""
    out = ["free"] * model.nv
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        adr = model.jnt_dofadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            continue
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            out[adr : adr + 3] = ["twist", "bend_out", "bend_in"]
            continue
        out[adr] = kinds.get(name, "passive")
    return out
