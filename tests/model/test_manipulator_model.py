import mujoco
import numpy as np
import pytest

from fpm_sim.kinematics import Pose, UnreachablePoseError, inverse_kinematics
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions

POSE = Pose(0.04, -0.03, 0.1)


@pytest.fixture(scope="module")
def built(default_manip):
    return build_manipulator(default_manip, POSE, ModelOptions(segments=4))


def test_qpos0_is_the_assembled_pose(built, default_manip):
    m = built.model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    asm = inverse_kinematics(default_manip.geometry, POSE)
    for i in range(3):
        prox, dist = built.links[f"proximal_{i}"], built.links[f"distal_{i}"]
        assert np.allclose(d.site(prox[0]).xpos[:2], asm.a[i], atol=1e-12)
        assert np.allclose(d.site(prox[-1]).xpos[:2], asm.b[i], atol=1e-12)
        assert np.allclose(d.site(dist[0]).xpos[:2], asm.b[i], atol=1e-12)
        assert np.allclose(d.site(dist[-1]).xpos[:2], asm.c[i], atol=1e-12)
        assert np.allclose(d.site(f"pin_{i}_site").xpos[:2], asm.c[i], atol=1e-12)
    assert np.allclose(d.site("platform_center").xpos[:2], [POSE.x_m, POSE.y_m], atol=1e-12)
    # the loops close at qpos0: weld residuals vanish, springs are unstressed
    assert np.max(np.abs(d.efc_pos[: d.nefc])) < 1e-12
    assert np.allclose(d.qfrc_passive, 0.0)


def test_mass_adds_up(built, default_manip):
    hw, g, sec, mat = default_manip.hardware, default_manip.geometry, default_manip.section, default_manip.material
    links = 3 * (g.proximal_length_m + g.distal_length_m) * sec.area_m2 * mat.density_kg_m3
    lumps = 3 * (hw.elbow_joint.mass_kg + hw.platform_joint.mass_kg + hw.motor_flange.mass_kg)
    lumps += hw.platform.mass_kg + hw.payload.mass_kg
    assert built.model.body_mass.sum() == pytest.approx(links + lumps, rel=1e-12)


def test_dof_kinds(built):
    kinds = set(built.dof_kinds)
    assert {"bend_in", "bend_out", "twist", "axial", "passive"} <= kinds
    assert built.dof_kinds.count("passive") == 6  # three elbows, three platform joints
    assert built.model.neq == 2


def test_compliances_and_servo_add_joints(default_manip):
    from fpm_sim.config import Compliance, Motors

    stiff = default_manip.replace(compliance=Compliance(passive_joint_tilt_nm_per_rad=5e3, motor_clamp_nm_per_rad=1e4))
    b = build_manipulator(stiff, POSE, ModelOptions(segments=2))
    assert b.dof_kinds.count("tilt") == 12
    assert b.dof_kinds.count("clamp") == 3
    servo = default_manip.replace(motors=Motors(mode="servo", servo_stiffness_nm_per_rad=300.0))
    b = build_manipulator(servo, POSE, ModelOptions(segments=2))
    assert b.dof_kinds.count("motor") == 3


def test_unreachable_pose_is_an_error(default_manip):
    with pytest.raises(UnreachablePoseError, match="chain"):
        build_manipulator(default_manip, Pose(0.6, 0.0, 0.0))
