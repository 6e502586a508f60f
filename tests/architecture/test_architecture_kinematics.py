"""General kinematics of the described architectures, checked against each specification's own geometry.

The checks are independent of the solver: every closure is recomputed here from the specification's formulas
(issue 28, "The four machines") and the assembled frames, and the working modes are checked as the specification
states them (which side of a line an elbow lies, which root a slider takes).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.architecture import TaskPose, load_description, solve_task_pose
from fpm_sim.architecture.kinematics import UnreachableTaskPoseError
from fpm_sim.architecture.three_rrr import description_of_3rrr
from fpm_sim.config import default_config
from fpm_sim.kinematics import assemble_many

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
CLOSURE_TOL_M = 1e-9  # the bound; the solver stops at 1e-11


def _pose(p: dict[str, float]) -> TaskPose:
    return TaskPose(p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0), p.get("phi", 0.0))


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _points(desc_name: str) -> list:
    d = load_description(EXAMPLES / f"{desc_name}.toml")
    return [(d, p) for p in d.check_poses]


@pytest.mark.parametrize(("desc", "pose"), _points("five_bar"), ids=lambda v: str(v) if isinstance(v, dict) else "")
def test_five_bar_closes_in_its_working_mode(desc, pose):
    asm = solve_task_pose(desc, _pose(pose))
    p = np.array([pose["x"], pose["y"]])
    for name, a, side in (("left", (-0.08, 0.0), 1.0), ("right", (0.08, 0.0), -1.0)):
        f = asm.chains[name]
        a_pt, b_pt, end = f.positions_m[0][:2], f.positions_m[2][:2], f.positions_m[-1][:2]
        np.testing.assert_allclose(a_pt, a, atol=1e-15)
        assert abs(np.linalg.norm(b_pt - a_pt) - 0.18) < 1e-12
        assert abs(np.linalg.norm(end - b_pt) - 0.22) < 1e-12
        assert np.linalg.norm(end - p) < CLOSURE_TOL_M
        # elbows out: B1 left of the directed line A1 -> P, B2 right of A2 -> P
        assert side * _cross2(p - a_pt, b_pt - a_pt) > 0
    assert asm.closure_residual_m < CLOSURE_TOL_M


@pytest.mark.parametrize(("desc", "pose"), _points("delta"), ids=lambda v: str(v) if isinstance(v, dict) else "")
def test_delta_closes_with_parallelograms_and_elbows_out(desc, pose):
    asm = solve_task_pose(desc, _pose(pose))
    p = np.array([pose["x"], pose["y"], pose["z"]])
    np.testing.assert_allclose(asm.ee_rotation, np.eye(3), atol=1e-9)  # the parallelograms keep it level
    for i, t in enumerate((90.0, 210.0, 330.0)):
        c, s = math.cos(math.radians(t)), math.sin(math.radians(t))
        u = np.array([-s, c, 0.0])
        a_pt = 0.12 * np.array([c, s, 0.0])
        arm = asm.chains[f"arm{i + 1}"]
        b_pt = arm.positions_m[-1]
        assert abs(np.linalg.norm(b_pt - a_pt) - 0.16) < 1e-12
        assert abs(np.dot(b_pt - a_pt, u)) < 1e-12  # in the vertical plane through A_i and the z axis
        assert np.hypot(*b_pt[:2]) > np.hypot(*a_pt[:2])  # elbows out
        c_pt = p + 0.04 * np.array([c, s, 0.0])
        for sign, tag in ((1, "a"), (-1, "b")):
            rod = asm.chains[f"rod{i + 1}{tag}"]
            np.testing.assert_allclose(rod.positions_m[0], b_pt + sign * 0.03 * u, atol=1e-12)
            assert np.linalg.norm(rod.positions_m[-1] - (c_pt + sign * 0.03 * u)) < CLOSURE_TOL_M
            assert abs(np.linalg.norm(rod.positions_m[-1] - rod.positions_m[0]) - 0.35) < 1e-12


@pytest.mark.parametrize(("desc", "pose"), _points("three_prr"), ids=lambda v: str(v) if isinstance(v, dict) else "")
def test_three_prr_closes_on_its_rails_with_the_larger_root(desc, pose):
    asm = solve_task_pose(desc, _pose(pose))
    p, phi = np.array([pose["x"], pose["y"]]), pose["phi"]
    rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    for i, t in enumerate((90.0, 210.0, 330.0)):
        c, s = math.cos(math.radians(t)), math.sin(math.radians(t))
        r_pt, v = 0.25 * np.array([c, s]), np.array([-s, c])
        c_pt = p + rot @ (0.06 * np.array([c, s]))
        f = asm.chains[f"rail{i + 1}"]
        slider = f.positions_m[1][:2]
        assert abs(_cross2(slider - r_pt, v)) < 1e-12  # on the rail
        assert np.linalg.norm(f.positions_m[-1][:2] - c_pt) < CLOSURE_TOL_M
        # the two sliders that reach C_i at 250 mm: s = v.(C - R) +- sqrt(L^2 - dist^2); the larger one
        d = c_pt - r_pt
        along, across = float(np.dot(d, v)), _cross2(v, d)
        assert abs(float(np.dot(slider - r_pt, v)) - (along + math.sqrt(0.25**2 - across**2))) < 1e-12


@pytest.mark.parametrize(("desc", "pose"), _points("serial_arm"), ids=lambda v: str(v) if isinstance(v, dict) else "")
def test_serial_arm_reaches_its_tip_elbow_up(desc, pose):
    asm = solve_task_pose(desc, _pose(pose))
    f = asm.chains["arm"]
    assert np.linalg.norm(f.positions_m[-1][:2] - [pose["x"], pose["y"]]) < CLOSURE_TOL_M
    assert float(f.coordinates["elbow"][0]) > 0  # elbow up


def test_the_general_solver_equals_the_3rrr_closed_form_and_its_singularity_measures():
    """The 3RRR as a general description: the numerical inverse kinematics gives the closed form's motor angles and
    the constraint-Jacobian measures its serial and parallel measures. Both solve to round-off (1e-11 m), the
    measures come from central differences (h = 1e-7: error ~ eps / h = 1e-9 of the entries), hence 1e-6."""
    cfg = default_config()
    desc = description_of_3rrr(cfg)
    poses = [(0.0, 0.0, 0.0), (0.05, -0.05, 0.1), (-0.1, 0.05, 0.0), (0.12, 0.03, -0.3), (-0.06, -0.09, 0.25)]
    for x, y, phi in poses:
        asm = solve_task_pose(desc, TaskPose(x, y, 0.0, phi))
        many = assemble_many(cfg.geometry, x, y, phi)
        motors = [float(asm.chains[str(i)].coordinates["motor"][0]) for i in range(3)]
        wrapped = np.angle(np.exp(1j * (np.array(motors) - many.motor_angles_rad[0])))
        np.testing.assert_allclose(wrapped, 0.0, atol=1e-9)
        np.testing.assert_allclose(asm.singularity_type1, many.serial[0], rtol=1e-6)
        np.testing.assert_allclose(asm.singularity_type2, many.parallel[0], rtol=1e-6, atol=1e-9)


def test_the_working_mode_is_kept_under_round_off():
    """The branch decision (which inverse-kinematics root) must not flip with 1e-12 changes of the pose."""
    desc = load_description(EXAMPLES / "five_bar.toml")
    base = solve_task_pose(desc, TaskPose(0.04, 0.18))
    rng = np.random.default_rng(3)
    for _ in range(3):
        dx, dy = 1e-12 * rng.standard_normal(2)
        asm = solve_task_pose(desc, TaskPose(0.04 + dx, 0.18 + dy))
        for name in ("left", "right"):
            assert (
                abs(float(asm.chains[name].coordinates["elbow"][0] - base.chains[name].coordinates["elbow"][0])) < 1e-9
            )


def test_a_pose_out_of_reach_is_refused_naming_the_pose():
    desc = load_description(EXAMPLES / "five_bar.toml")
    with pytest.raises(UnreachableTaskPoseError, match=r"chain .left. cannot reach .* at \(x=0\.0 mm, y=500\.0 mm\)"):
        solve_task_pose(desc, TaskPose(0.0, 0.5))


@pytest.mark.parametrize("name", ["five_bar", "delta", "three_prr", "serial_arm"])
def test_the_geometric_jacobian_is_the_residual_s_derivative(name):
    """The closure Jacobian from the joints' twists against central differences of the residual, at random
    configurations away from any solution (every joint type, the end effector's free and given coordinates).
    Central differences at h = 1e-7 carry ~eps / h = 1e-9 of round-off: 1e-7 relative is far below any wrong term."""
    from fpm_sim.architecture import kinematics as kin

    desc = load_description(EXAMPLES / f"{name}.toml")
    rng = np.random.default_rng(0)
    ell = kin.characteristic_length_m(desc)
    for free in (None, kin._ee_coordinates(desc)):
        lay = kin._layout(desc, ee_free=free)
        z = rng.normal(0.0, 0.7, lay.size)
        pose = TaskPose(0.01, 0.2, -0.3, 0.1)
        exact, fd = kin._jacobian(desc, lay, pose, z, ell), kin._jacobian_fd(desc, lay, pose, z, ell)
        assert np.max(np.abs(exact - fd)) < 1e-7 * np.max(np.abs(fd))


def test_the_shipped_3rrr_description_is_the_embedded_default_in_the_general_form():
    """examples/architectures/three_rrr.toml is what three_rrr_toml writes from the embedded default (regenerate it
    with that function when the default changes), and it reads back to description_of_3rrr's description with every
    value's provenance."""
    from fpm_sim.architecture.three_rrr import three_rrr_toml

    cfg = default_config()
    assert (EXAMPLES / "three_rrr.toml").read_text() == three_rrr_toml(cfg)
    desc = load_description(EXAMPLES / "three_rrr.toml")
    assert desc == description_of_3rrr(cfg)
    assert not [k for k, v in desc.provenance.items() if v.startswith("user")]
