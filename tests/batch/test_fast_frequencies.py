import numpy as np
import pytest

from fpm_sim.batch.frequencies import first_frequencies, pose_frequencies, register_backend
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.kinematics import Pose
from fpm_sim.linear.analysis import manipulator_modes
from fpm_sim.model.options import ModelOptions


def test_fast_path_matches_full_analysis_at_same_resolution(default_manip):
    # Same links (4 segments, axial springs): the fast path leaves out only gravity's prestress
    # (motor axes along gravity: the in-plane structure carries no gravity load to first order) and
    # uses the constrained eigen-solve instead of transitionFD (0.05 % apart, ENGINE_NOTES).
    pose = Pose.from_mm(30.0, -20.0, 0.1)
    fast = first_frequencies(default_manip, [pose], n_modes=3, options=fast_options(segments=4, axial=True))[0]
    full = manipulator_modes(pose, config=default_manip, options=ModelOptions(segments=4), n_modes=3).frequencies_hz
    assert fast == pytest.approx(full, rel=5e-3)


def test_status_marks_unreachable_and_singular(default_manip):
    poses = [Pose(0.0, 0.0, 0.0), Pose(0.9, 0.0, 0.0)]
    res = pose_frequencies(default_manip, poses, n_modes=2, options=fast_options(segments=2))
    assert res.status == ["ok", "unreachable"]
    assert np.isfinite(res.frequencies_hz[0]).all() and np.isnan(res.frequencies_hz[1]).all()


def test_workers_give_the_same_numbers(default_manip):
    poses = [Pose.from_mm(x, y, 0.0) for x in (-40, 0, 40) for y in (-40, 40)]
    opts = fast_options(segments=2)
    a = first_frequencies(default_manip, poses, options=opts, workers=1)
    b = first_frequencies(default_manip, poses, options=opts, workers=2)
    np.testing.assert_array_equal(a, b)


def test_backends_are_replaceable(default_manip, monkeypatch):
    from fpm_sim.batch import frequencies

    # a private copy of the registry for this test: the fake backend must not outlive it
    monkeypatch.setattr(frequencies, "BACKENDS", dict(frequencies.BACKENDS))
    calls = []

    def fake(config, poses, **kw):
        calls.append(kw["n_modes"])
        return pose_frequencies(config, poses, n_modes=kw["n_modes"], options=kw["options"])

    register_backend("fake-test", fake)
    out = first_frequencies(default_manip, [Pose(0, 0, 0)], backend="fake-test", options=fast_options(segments=2))
    assert calls == [1] and out.shape == (1, 1)
    with pytest.raises(ValueError, match="unknown backend"):
        first_frequencies(default_manip, [Pose(0, 0, 0)], backend="nope")
