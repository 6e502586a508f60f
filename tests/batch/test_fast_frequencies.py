import numpy as np
import pytest

from fpm_sim.batch.frequencies import first_frequencies, pose_frequencies, register_backend
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.kinematics import Pose
from fpm_sim.linear.analysis import manipulator_modes
from fpm_sim.model.options import ModelOptions
from tests.helpers.jitter import JITTER_SEEDS, jitter, jitter_symmetric


def test_fast_path_matches_full_analysis_at_same_resolution(reference_manip):
    # Same links (4 segments, axial springs): the fast path leaves out only gravity's prestress
    # (motor axes along gravity: the in-plane structure carries no gravity load to first order) and
    # uses the constrained eigen-solve instead of transitionFD (0.05 % apart, ENGINE_NOTES).
    pose = Pose.from_mm(30.0, -20.0, 0.1)
    fast = first_frequencies(reference_manip, [pose], n_modes=3, options=fast_options(segments=4, axial=True))[0]
    full = manipulator_modes(reference_manip, pose, options=ModelOptions(segments=4), n_modes=3).frequencies_hz
    assert fast == pytest.approx(full, rel=5e-3)


def test_status_marks_unreachable_and_singular(reference_manip):
    poses = [Pose(0.0, 0.0, 0.0), Pose(0.9, 0.0, 0.0)]
    res = pose_frequencies(reference_manip, poses, n_modes=2, options=fast_options(segments=2))
    assert res.status == ["ok", "unreachable"]
    assert np.isfinite(res.frequencies_hz[0]).all()
    assert np.isnan(res.frequencies_hz[1]).all()


def test_workers_give_the_same_numbers(reference_manip):
    poses = [Pose.from_mm(x, y, 0.0) for x in (-40, 0, 40) for y in (-40, 40)]
    opts = fast_options(segments=2)
    a = first_frequencies(reference_manip, poses, options=opts, workers=1)
    b = first_frequencies(reference_manip, poses, options=opts, workers=2)
    np.testing.assert_array_equal(a, b)


def test_backends_are_replaceable(reference_manip, monkeypatch):
    from fpm_sim.batch import frequencies

    # a private copy of the registry for this test: the fake backend must not outlive it
    monkeypatch.setattr(frequencies, "BACKENDS", dict(frequencies.BACKENDS))
    calls = []

    def fake(config, poses, **kw):
        calls.append(kw["n_modes"])
        return pose_frequencies(config, poses, n_modes=kw["n_modes"], options=kw["options"])

    register_backend("fake-test", fake)
    out = first_frequencies(reference_manip, [Pose(0, 0, 0)], backend="fake-test", options=fast_options(segments=2))
    assert calls == [1]
    assert out.shape == (1, 1)
    with pytest.raises(ValueError, match="unknown backend"):
        first_frequencies(reference_manip, [Pose(0, 0, 0)], backend="nope")


HANDFUL = [
    Pose.from_mm(0.0, 0.0, 0.0),
    Pose.from_mm(-60.0, -50.0, 0.0),
    Pose.from_mm(50.0, 70.0, 0.2),
    Pose.from_mm(0.0, 70.0, 0.2),  # near-singular (measure 0.003): the most sensitive to round-off
    Pose.from_mm(90.0, -100.0, -0.1),
    Pose(0.9, 0.0, 0.0),  # unreachable
]


@pytest.mark.parametrize("thickness_m", [0.005, 0.03])
def test_reposed_model_equals_the_per_pose_compile(reference_manip, thickness_m):
    # One compiled model re-posed in place must give what compiling a model per pose gives. The weld
    # relative poses are set with mj_setConst's own operations, so the two agree bit for bit here; 1e-9
    # relative leaves room for BLAS/LAPACK builds that round differently, far below any modelling effect.
    from fpm_sim.batch.pose_loop import solve_poses

    manip = reference_manip.with_section(thickness_m=thickness_m)
    opts = fast_options(segments=3, axial=True)
    fast = solve_poses(manip, HANDFUL, n_modes=4, options=opts)
    ref = solve_poses(manip, HANDFUL, n_modes=4, options=opts, recompile=True)
    assert fast.status == ref.status
    assert fast.status[-1] == "unreachable"
    assert "near_singular" in fast.status
    np.testing.assert_allclose(fast.frequencies_hz, ref.frequencies_hz, rtol=1e-9, equal_nan=True)
    np.testing.assert_allclose(fast.in_plane, ref.in_plane, rtol=1e-9, atol=1e-12, equal_nan=True)
    np.testing.assert_array_equal(fast.singularity, ref.singularity)


@pytest.mark.parametrize("jitter_seed", [None, *JITTER_SEEDS])
def test_plane_split_equals_the_whole_eigenproblem(reference_manip, jitter_seed):
    # The in-plane / out-of-plane split is exact when M and the weld Jacobian are block-diagonal; the
    # frequencies must match one reduced_eigenproblem on the whole matrices to the eigen-solver's round-off, and the
    # mode-1 character must come out pure (share 0 or 1). Also with M and the springs jittered at 1e-12
    # (tests.helpers.jitter, entrywise: the blocks stay decoupled), so that the agreement is not one machine's rounding.
    from fpm_sim.batch.pose_loop import PlaneSplit, PoseModel, plane_blocks, pose_assembly
    from fpm_sim.linear.equilibrium import equality_jacobian
    from fpm_sim.linear.matrices import mass_matrix
    from fpm_sim.linear.nullspace import constraint_rank
    from fpm_sim.linear.solvers import reduced_eigenproblem

    opts = fast_options(segments=4)
    for pose in HANDFUL[:3]:
        asm, _, _ = pose_assembly(reference_manip, pose)
        pm = PoseModel(reference_manip, opts, asm)
        freq, share, deficient = pm.solve(asm, 6)
        m, j, k = mass_matrix(pm.model, pm.data), equality_jacobian(pm.model, pm.data), pm.stiffness
        if jitter_seed is not None:
            m, k = jitter_symmetric(m, jitter_seed), jitter(k, jitter_seed)
            freq, share, deficient = PlaneSplit(pm.in_plane, k).modes(m, j, 6, scales=pm.scales)
        assert not deficient
        assert plane_blocks(m, j, pm.in_plane) is not None
        basis = constraint_rank(pm.model, pm.data).basis
        _, kr, mr, w2, _ = reduced_eigenproblem(m, np.diag(k), basis)
        # What a backward-stable symmetric-definite eigen-solver promises: each w_k^2 within about
        # n eps ||Kr|| ||Mr^-1|| of the exact one, so the whole and the split solves' w_k^2 differ by up to twice
        # that and their frequencies (square roots) by that relative to w_k^2: 5e-10 to 3e-8 here by mode and pose,
        # mode 1 the loosest. Measured at most 0.5 % of it, also under the jitter. The 1e-9 this replaces was one
        # machine's reading, below the bound for mode 1 at all three poses. A split that dropped a coupling of
        # relative size delta moves frequencies by about delta, far above 3e-8.
        bound = w2.size * np.finfo(float).eps * np.linalg.norm(kr, 2) * np.linalg.norm(np.linalg.inv(mr), 2) / w2[:6]
        err = np.abs(freq / (np.sqrt(w2[:6]) / (2 * np.pi)) - 1)
        assert np.all(err <= bound), (pose, err, bound)
        assert np.all((np.abs(share) < 1e-12) | (np.abs(share - 1) < 1e-12))
