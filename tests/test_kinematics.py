import math
import warnings

import numpy as np
import pytest

from fpm_sim.kinematics import (
    NEAR_SINGULAR_WARN,
    NearSingularityWarning,
    Pose,
    SingularPoseError,
    UnreachablePoseError,
    forward_kinematics,
    inverse_kinematics,
    jacobians,
)
from tests.helpers.truths import REFERENCE_GEOMETRY  # the geometry these tests measured their numbers on

GRID = [Pose.from_mm(x, y, 0.2 if y == 0 else 0.0) for x in (-100, -50, 0, 50, 100) for y in (-100, -50, 0, 50, 100)]


def _ik_quiet(g, pose):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        return inverse_kinematics(g, pose)


@pytest.mark.parametrize("pose", GRID, ids=lambda p: p.label())
def test_ik_fk_round_trip(pose):
    g = REFERENCE_GEOMETRY  # the grid is away from this geometry's singularities
    asm = _ik_quiet(g, pose)
    # links have the right lengths
    assert np.allclose(np.linalg.norm(asm.b - asm.a, axis=1), g.proximal_length_m, atol=1e-12)
    assert np.allclose(np.linalg.norm(asm.c - asm.b, axis=1), g.distal_length_m, atol=1e-12)
    guess = Pose(pose.x_m + 0.01, pose.y_m - 0.01, pose.phi_rad + 0.05)
    back = forward_kinematics(g, asm.motor_angles_rad, guess=guess)
    assert abs(back.x_m - pose.x_m) < 1e-9
    assert abs(back.y_m - pose.y_m) < 1e-9
    assert abs(back.phi_rad - pose.phi_rad) * g.platform_radius_m < 1e-9


def test_jacobian_matches_finite_difference(default_manip):
    g = default_manip.geometry
    pose = Pose(0.03, -0.02, 0.1)
    asm = _ik_quiet(g, pose)
    jx, jq = jacobians(g, asm)
    # d q / d x from IK by central differences must equal Jq^-1 Jx
    eps = 1e-7
    num = np.zeros((3, 3))
    for k in range(3):
        dx = np.zeros(3)
        dx[k] = eps
        qp = _ik_quiet(g, Pose(*(pose.as_array() + dx))).motor_angles_rad
        qm = _ik_quiet(g, Pose(*(pose.as_array() - dx))).motor_angles_rad
        num[:, k] = (qp - qm) / (2 * eps)
    assert np.allclose(num, np.linalg.solve(jq, jx), rtol=1e-6, atol=1e-6)


def test_unreachable_pose_names_the_chain(default_manip):
    with pytest.raises(UnreachablePoseError, match=r"chain \d"):
        inverse_kinematics(default_manip.geometry, Pose(0.5, 0.0, 0.0))


def test_elbow_branch_changes_solution(default_manip):
    from dataclasses import replace

    g = default_manip.geometry
    a = inverse_kinematics(g, Pose(0, 0, 0))
    b = inverse_kinematics(replace(g, elbow_branch=(-g.elbow_branch[0], *g.elbow_branch[1:])), Pose(0, 0, 0))
    assert not np.allclose(a.b[0], b.b[0])
    assert np.allclose(a.b[1:], b.b[1:])


def _stretched_pose(g):
    """A pose where chain 0 is almost fully stretched (serial singularity)."""
    a0 = g.base_radius_m * np.array([math.cos(g.base_angles_rad[0]), math.sin(g.base_angles_rad[0])])
    c_local = g.platform_radius_m * np.array([math.cos(g.platform_angles_rad[0]), math.sin(g.platform_angles_rad[0])])
    direction = -a0 / np.linalg.norm(a0)
    reach = g.proximal_length_m + g.distal_length_m
    return a0, c_local, direction, reach


def test_singular_pose_refused_and_near_singular_warns():
    g = REFERENCE_GEOMETRY
    a0, c_local, direction, reach = _stretched_pose(g)
    # exactly stretched: singular
    p = a0 + direction * reach - c_local
    with pytest.raises(SingularPoseError, match="serial"):
        inverse_kinematics(g, Pose(p[0], p[1], 0.0))
    # slightly folded: sin(elbow) ~ 0.03 < NEAR_SINGULAR_WARN -> warning, still assembled
    fold = 1 - 1.2e-4
    p = a0 + direction * reach * fold - c_local
    with pytest.warns(NearSingularityWarning, match="near a serial"):
        asm = inverse_kinematics(g, Pose(p[0], p[1], 0.0))
    assert asm.singularity.value < NEAR_SINGULAR_WARN


def test_home_pose_is_well_conditioned(default_manip):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        asm = inverse_kinematics(default_manip.geometry, Pose(0, 0, 0))
    assert asm.singularity.value > NEAR_SINGULAR_WARN
