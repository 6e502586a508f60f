"""The ``mjx`` backend (MJX's own pipeline) against the ``jax`` and ``cpu`` backends.

Three independent routes to the same constrained eigenproblem: C MuJoCo (``mj_fullM``, ``efc_J``, the joint
springs) with SciPy; MuJoCo's formulas rewritten in JAX; MJX's ``fwd_position`` (mass matrix, constraint
rows) and ``jax.jacfwd`` of its smooth forces. Two segments per link keep MJX's compile short.
"""

import numpy as np
import pytest

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.poses import study_poses


def test_mjx_backend_matches_jax_and_cpu_backends_at_the_25_study_poses(reference_manip):
    config = reference_manip  # the geometry the tolerance was measured on (conftest)
    poses = [p.pose for p in study_poses()]
    opts = fast_options(segments=2)
    cpu = pose_frequencies(config, poses, backend="cpu", n_modes=6, options=opts)
    jax_ = pose_frequencies(config, poses, backend="jax", n_modes=6, options=opts)
    mjx = pose_frequencies(config, poses, backend="mjx", n_modes=6, options=opts)
    assert mjx.status == cpu.status == jax_.status
    ok = np.isfinite(cpu.frequencies_hz[:, 0])
    assert ok.sum() >= 24
    assert np.array_equal(np.isfinite(mjx.frequencies_hz), np.isfinite(cpu.frequencies_hz))
    # The bound is 1e-6 relative. All three solve the same discrete eigenproblem and differ in
    # round-off only: measured at 2 segments, max relative difference 5.6e-12 (mjx vs cpu) and 7.7e-12
    # (mjx vs jax); at 6 segments 5.6e-10 (benchmarks/backends.py). 1e-8 keeps the test sharp.
    np.testing.assert_allclose(mjx.frequencies_hz[ok], cpu.frequencies_hz[ok], rtol=1e-8)
    np.testing.assert_allclose(mjx.frequencies_hz[ok], jax_.frequencies_hz[ok], rtol=1e-8)
    np.testing.assert_allclose(mjx.in_plane[ok], cpu.in_plane[ok], rtol=0, atol=1e-8)
    assert mjx.timings.poses == ok.sum()
    assert mjx.timings.compile_s > 0


def test_mjx_pipeline_refuses_the_chain_rig_and_mixed_structures():
    from fpm_sim.batch.jax_backend import x64
    from fpm_sim.batch.mjx_backend import MjxModelError, check_mjx_model, mjx_linearisation, stack_models
    from fpm_sim.errors import FpmSimError
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.rigs import RigSetup, build_rig, rig_piece

    rig = build_rig(RigSetup("chain", angle_deg=90), rig_piece(), ModelOptions(segments=2))
    with pytest.raises(MjxModelError, match="chain rig"):
        check_mjx_model(rig)
    with pytest.raises(FpmSimError, match="chain rig"):
        mjx_linearisation(rig)
    free = build_rig(RigSetup("free-free"), rig_piece(), ModelOptions(segments=2))
    with pytest.raises(MjxModelError, match="tangent space"):
        check_mjx_model(free)
    two = build_manipulator(config := default_config(), Pose(0, 0, 0), fast_options(segments=2))
    three = build_manipulator(config, Pose(0, 0, 0), fast_options(segments=3))
    with x64(), pytest.raises(MjxModelError, match="structure"):
        stack_models([two.model, three.model])
    with pytest.raises(FpmSimError, match="gravity"):
        pose_frequencies(config, [Pose(0, 0, 0)], backend="mjx", options=ModelOptions(segments=2))
