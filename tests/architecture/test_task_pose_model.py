"""The described architectures' pose loop re-poses one compiled model (``fpm_sim.batch.task_pose_model``): the model
it re-poses must be the model compiled at the pose, and the sweep's warm-started inverse kinematics must land on the
cold solver's assembly."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import solve_task_pose, task_unknowns
from fpm_sim.batch.task_pose_model import TaskPoseModel
from fpm_sim.batch.task_sweep import sweep_task
from fpm_sim.linear.solvers import modes_constrained
from fpm_sim.model.general import build_general

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
MACHINES = ["five_bar", "delta", "three_prr", "serial_arm"]
FIELDS = ["body_pos", "body_quat", "jnt_pos", "jnt_axis", "eq_data", "body_ipos", "body_iquat", "body_mass"]
OPTIONS = fs.ModelOptions(segments=3, axial=False, gravity=False)


def _pose(desc, k: int) -> fs.TaskPose:
    p = desc.check_poses[k]
    return fs.TaskPose(p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0), p.get("phi", 0.0))


@pytest.mark.parametrize("name", MACHINES)
def test_the_re_posed_model_is_the_model_compiled_at_the_pose(name):
    desc = fs.load_description(EXAMPLES / f"{name}.toml")
    home, other = solve_task_pose(desc, _pose(desc, 0)), solve_task_pose(desc, _pose(desc, 1))
    pm = TaskPoseModel(desc, OPTIONS, home)
    freq, deficient = pm.solve(other, 6)
    compiled = build_general(desc, other.pose, OPTIONS, assembly=other)
    for field in FIELDS:
        # the same numbers through the same builder: equal but for the compiler's quaternion normalisation (1 ulp)
        np.testing.assert_allclose(getattr(pm.model, field), getattr(compiled.model, field), rtol=0, atol=1e-15)
    assert not deficient
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = modes_constrained(compiled, n_modes=6).frequencies_hz
    # the second method differentiates the passive forces (central differences, relative error ~1e-9 on K); the
    # loop takes the springs' exact diagonal: equal to far below the 1e-7 asked here
    np.testing.assert_allclose(freq, reference[:6], rtol=1e-7)


@pytest.mark.parametrize("name", ["five_bar", "delta"])
def test_a_warm_start_from_the_neighbour_finds_the_cold_solvers_assembly(name):
    desc = fs.load_description(EXAMPLES / f"{name}.toml")
    a, b = _pose(desc, 0), _pose(desc, 1)
    cold = solve_task_pose(desc, b)
    warm = solve_task_pose(desc, b, start=task_unknowns(desc, solve_task_pose(desc, a)))
    for chain, frames in cold.chains.items():
        # both converge below CLOSURE_TOL_M (1e-11 m) and polish once: the same assembly to far below 1e-9 m
        np.testing.assert_allclose(warm.chains[chain].positions_m, frames.positions_m, atol=1e-9)


def test_the_sweep_loop_equals_one_model_compiled_per_pose():
    """A row of poses through the re-posed, warm-started loop against each pose's own model and cold solve."""
    desc = fs.load_description(EXAMPLES / "five_bar.toml")
    poses = [fs.TaskPose(x, 0.25) for x in (-0.04, -0.02, 0.0, 0.02, 0.04)]
    sweep = sweep_task(desc, poses, options=OPTIONS, n_modes=4)
    assert sweep.status == ["ok"] * len(poses)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for pose, freq in zip(poses, sweep.freq_hz):
            ref = modes_constrained(build_general(desc, pose, OPTIONS), n_modes=4).frequencies_hz
            np.testing.assert_allclose(freq, ref, rtol=1e-7)  # as in the test above


def _check_poses(desc) -> list[fs.TaskPose]:
    return [_pose(desc, k) for k in range(3)]


def test_the_jax_backend_solves_a_described_machine_as_the_cpu_loop_does():
    desc = fs.load_description(EXAMPLES / "five_bar.toml")
    options = fs.ModelOptions(segments=2)
    cpu = sweep_task(desc, _check_poses(desc), options=options, n_modes=4)
    jax = sweep_task(desc, _check_poses(desc), options=options, n_modes=4, backend="jax")
    assert jax.status == cpu.status
    # the same discrete eigenproblem, MuJoCo's formulas in JAX against MuJoCo's own: equal to round-off, far
    # below 1e-9 (measured 3e-12)
    np.testing.assert_allclose(jax.freq_hz, cpu.freq_hz, rtol=1e-9)


@pytest.mark.slow  # MJX's compile of the Delta's tree: about a minute on a 2-core CPU
def test_the_mjx_backend_solves_the_delta_as_the_cpu_loop_does():
    desc = fs.load_description(EXAMPLES / "delta.toml")
    options = fs.ModelOptions(segments=2)
    cpu = sweep_task(desc, _check_poses(desc), options=options, n_modes=4)
    mjx = sweep_task(desc, _check_poses(desc), options=options, n_modes=4, backend="mjx")
    assert mjx.status == cpu.status
    np.testing.assert_allclose(mjx.freq_hz, cpu.freq_hz, rtol=1e-9)  # as above (measured 6e-13)


def test_the_jax_backend_refuses_a_spherical_loop_closure_by_its_path():
    desc = fs.load_description(EXAMPLES / "delta.toml")
    with pytest.raises(fs.FpmSimError, match=r"chains\[\d+\]\.path\[\d+\]\.type = 'spherical'.*mjx"):
        sweep_task(desc, _check_poses(desc), backend="jax")
