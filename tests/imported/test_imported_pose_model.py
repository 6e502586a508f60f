"""The imported models' pose loop (:class:`fpm_sim.batch.imported_pose_model.ImportedPoseModel`): one compiled model
posed by joint values, its locked joints locked by constraint rows, against models built at each pose and against
the native description's own pose loop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fpm_sim.architecture import TaskPose, load_description
from fpm_sim.architecture.imported import load_imported
from fpm_sim.batch.imported_pose_model import ImportedPoseModel
from fpm_sim.batch.joint_sweep import sweep_joints
from fpm_sim.batch.task_sweep import sweep_task
from fpm_sim.errors import FpmSimError
from fpm_sim.linear.analysis import analyse
from fpm_sim.model.imported import build_imported
from fpm_sim.model.imported_pose import joint_poses_of
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.poses import parse_reading, study_poses
from tests.helpers.imported_copy import imported_copy

ROOT = Path(__file__).resolve().parents[2]
POLICY = ModelOptions(segments=3, gravity=False, axial=False)
pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")


def test_3rrr_imported_sweep_is_the_native_pose_loop(tmp_path: Path) -> None:
    """The 3RRR exported once and imported, swept over the study's 25 poses in task space, has the native
    description's sweep frequencies (its own pose loop: closed-form kinematics, a compiled model re-posed by
    frames) within 1e-8: two assemblies of the same constrained eigenproblem, each kinematics solved to ~1e-12 m
    (the near-mechanism (-100, 50) mm included: measured 8.3e-9 there, 2e-11 elsewhere)."""
    desc = load_description(ROOT / "examples/architectures/three_rrr.toml")
    imp = load_imported(imported_copy(desc, tmp_path))
    poses = [TaskPose(p.pose.x_m, p.pose.y_m, 0.0, p.pose.phi_rad) for p in study_poses(parse_reading("x+"))]
    native = sweep_task(desc, poses, options=POLICY, n_modes=3).frequencies_hz
    imported = sweep_joints(imp, joint_poses_of(imp, poses), options=POLICY, n_modes=3).frequencies_hz
    np.testing.assert_allclose(imported, native, rtol=1e-8)


def test_posed_model_is_the_model_built_at_the_pose(tmp_path: Path) -> None:
    """At each of the five-bar's check poses the posed model's modes are those of the model built there (its
    locked joints deleted instead of locked by rows): the same eigenproblem, rtol 1e-9."""
    desc = load_description(ROOT / "examples/architectures/five_bar.toml")
    imp = load_imported(imported_copy(desc, tmp_path))
    loop = ImportedPoseModel(imp, POLICY)
    qs = joint_poses_of(imp, [TaskPose.from_coordinates(c) for c in desc.check_poses])
    for q in qs:
        built = analyse(build_imported(imp, q, POLICY), "constrained", 4).frequencies_hz
        np.testing.assert_allclose(loop.solve(q, 4)[0], built, rtol=1e-9)


def test_a_pose_whose_loop_does_not_close_is_refused_by_the_equality(tmp_path: Path) -> None:
    """Joint values that leave the five-bar's weld open: refused naming the equality, the pose and the fix."""
    desc = load_description(ROOT / "examples/architectures/five_bar.toml")
    imp = load_imported(imported_copy(desc, tmp_path))
    q = joint_poses_of(imp, [TaskPose.from_coordinates(desc.check_poses[1])])[0]
    q["left_elbow"] += 0.05
    with pytest.raises(FpmSimError, match=r"pose 1 \(.*\): the loop closure loop_right_tool does not close") as e:
        sweep_joints(imp, [q], options=POLICY)
    assert "task space" in (e.value.hint or "")
