"""Mode filtering by physical criteria, instability detection and the constraint rank in consistent units."""

import dataclasses
import warnings

import mujoco
import numpy as np
import pytest

from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import NearSingularityWarning, Pose
from fpm_sim.linear import solvers
from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.linear.matrices import forward_at, mass_matrix
from fpm_sim.linear.mode_filter import ModeFilter, UnstableModelError, reference_frequency_hz
from fpm_sim.linear.nullspace import RedundantConstraintWarning, constraint_rank
from fpm_sim.linear.solvers import modes_constrained, modes_transition_fd
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.rigs import RigSetup, build_rig

NEAR_SINGULAR = Pose(0.083, 0.0045, 0.0)  # the pose: singularity measure 0.0028


@pytest.fixture(scope="module")
def near_singular(reference_manip):  # the geometry whose singular pose NEAR_SINGULAR is
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        return build_manipulator(reference_manip, NEAR_SINGULAR, ModelOptions(segments=6))


@pytest.mark.parametrize("method", [modes_transition_fd, modes_constrained], ids=["transition_fd", "constrained"])
def test_near_singular_first_mode_is_reported_with_a_warning(near_singular, method):
    with pytest.warns(NearSingularityWarning, match=r"mode 1 at 0\.\d+ Hz \(bend_in\)"):
        res = method(near_singular, n_modes=3)
    f = res.frequencies_hz
    # the in-plane motion that vanishes at the singularity: 0.51-0.53 Hz here (stiffness ~ measure^2), two
    # orders below the next mode (69 Hz), and nothing dropped as rigid-body
    assert 0.3 < f[0] < 1.0, f
    assert f[1] > 50.0
    assert res.modes[0].dominant == "bend_in"
    assert "rigid_body" not in res.dropped


def test_both_methods_agree_on_the_near_singular_mode(near_singular):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        a = modes_transition_fd(near_singular, n_modes=2).frequencies_hz
        b = modes_constrained(near_singular, n_modes=2).frequencies_hz
    # measured 3.8 % on mode 1 (its stiffness is 1e-5 of mode 2's, so the soft weld's compliance, time
    # constant 2h, and the step map show); 2e-6 on mode 2. 5 % and 1e-4 keep a margin over both.
    assert abs(a[0] / b[0] - 1) < 0.05
    assert abs(a[1] / b[1] - 1) < 1e-4


def test_cli_modes_reports_the_near_singular_first_mode(capsys):
    from conftest import REFERENCE_CONFIG  # the description whose singular pose this is

    from fpm_sim.cli.main import main

    argv = ["modes", "--x-mm", "83", "--y-mm", "4.5", "--phi-rad", "0", "--n-modes", "2", "--json"]
    rc = main([*argv, "--config", str(REFERENCE_CONFIG)])
    assert rc in (0, None)
    import json

    captured = capsys.readouterr()
    # the CLI prints warnings as one line each: the near-singularity one names mode 1
    assert any(ln.startswith("warning:") and "singular" in ln for ln in captured.err.splitlines()), captured.err
    out = json.loads(captured.out)
    f1 = out["modes"][0]["frequency_hz"]
    assert 0.3 < f1 < 1.0, f1  # was 68.9 Hz: the physical first mode had been dropped as "zero"
    assert "zero" not in out["dropped"]
    assert "rigid_body" not in out["dropped"]


def test_free_free_rig_drops_exactly_its_six_rigid_body_modes(steel_bar):
    built = build_rig(RigSetup("free-free"), steel_bar, ModelOptions(segments=6))
    res = modes_constrained(built, n_modes=4)
    assert res.dropped == {"rigid_body": 6}
    assert res.frequencies_hz[0] > 900.0  # the first bending mode, not a rigid motion


def test_reference_frequency_scales_with_the_model(steel_bar, default_manip):
    cant = build_rig(RigSetup("cantilever"), steel_bar, ModelOptions(segments=6))
    data = mujoco.MjData(cant.model)
    mujoco.mj_forward(cant.model, data)
    f_ref = reference_frequency_hz(cant.model, mass_matrix(cant.model, data))
    f1 = modes_constrained(cant, n_modes=1).frequencies_hz[0]
    # the model's own scale is of the order of its first mode (0.5..5x), so rigid_fraction * f_ref sits
    # far below any physical mode
    assert 0.2 * f1 < f_ref < 5 * f1


def _shifted(monkeypatch, shift_w2):
    """Make K softer by ``shift_w2 * M`` (every eigenvalue w^2 drops by shift_w2)."""
    original = solvers.stiffness_matrix

    def softer(model, data, qpos, eps=1e-7):
        k = original(model, data, qpos, eps=eps)
        forward_at(model, data, qpos)
        return k - shift_w2 * mass_matrix(model, data)

    monkeypatch.setattr(solvers, "stiffness_matrix", softer)


def test_mild_instability_is_an_error_not_a_zero_mode(monkeypatch, symmetric_manip):
    built = build_manipulator(symmetric_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, gravity=False))
    f1 = modes_constrained(built, n_modes=1).frequencies_hz[0]
    # push mode 1 to w^2 = -(2 pi 0.5 Hz)^2: far beyond round-off but 1e-9 of the largest w^2, which the
    # old relative test clipped to zero and reported as a dropped "zero" mode
    _shifted(monkeypatch, (2 * np.pi * f1) ** 2 + (2 * np.pi * 0.5) ** 2)
    with pytest.raises(UnstableModelError, match="negative stiffness eigenvalue"):
        modes_constrained(built, n_modes=1)


def test_growing_step_map_is_an_error(default_manip):
    # 30 m thick links: the step map grows (damping ratios down to -0.6 were reported silently)
    thick = default_manip.replace(section=dataclasses.replace(default_manip.section, thickness_m=30.0))
    built = build_manipulator(thick, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # MuJoCo's own instability warning
        with pytest.raises(UnstableModelError, match="grow"):
            modes_transition_fd(built, n_modes=3)


@pytest.mark.parametrize("n", [-2, 0, 10_000, 2.5, True])
def test_n_modes_is_checked(symmetric_manip, n):
    built = build_manipulator(symmetric_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, gravity=False))
    with pytest.raises(FpmSimError, match="n_modes"):
        modes_constrained(built, n_modes=n)


def test_fewer_physical_modes_than_asked_warns(steel_bar):
    built = build_rig(RigSetup("free-free"), steel_bar, ModelOptions(segments=2))
    with pytest.warns(UserWarning, match="only"):
        res = modes_constrained(built, n_modes=built.model.nv)
    assert len(res.modes) == built.model.nv - 6


def test_mode_filter_values_are_checked():
    with pytest.raises(FpmSimError, match="rigid_fraction"):
        ModeFilter(rigid_fraction=-1.0)
    with pytest.raises(FpmSimError, match="max_damping_ratio"):
        ModeFilter(max_damping_ratio=float("nan"))


def _rank_at(built):
    data = mujoco.MjData(built.model)
    mujoco.mj_forward(built.model, data)
    return constraint_rank(built.model, data), equality_jacobian(built.model, data)


@pytest.mark.parametrize("pose", [Pose(0.0, 0.0, 0.0), NEAR_SINGULAR, Pose(-0.1, 0.0, 0.2)], ids=str)
def test_manipulator_welds_have_full_rank_in_consistent_units(default_manip, pose):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        built = build_manipulator(default_manip, pose, ModelOptions(segments=3, gravity=False))
    rank, jac = _rank_at(built)
    assert rank.n_rows == 12
    assert rank.rank == 12
    assert not rank.deficient
    # measured 0.14..0.17: the scaled rows are well conditioned; the basis spans exactly null(J)
    assert rank.ratio > 0.05
    assert rank.basis.shape == (built.model.nv, built.model.nv - 12)
    assert np.allclose(rank.basis.T @ rank.basis, np.eye(rank.basis.shape[1]), atol=1e-10)
    assert np.max(np.abs(jac @ rank.basis)) < 1e-10 * np.max(np.abs(jac))


def test_rank_is_independent_of_the_length_unit(default_manip):
    """The decision must not change when the rotation rows are weighted differently (metres vs radians):
    the scaled singular values of J are invariant to a uniform change of the rotation rows' torquescale."""
    built = build_manipulator(default_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, gravity=False))
    base, _ = _rank_at(built)
    model = built.model
    model.eq_data[:, 10] = 1e3  # rotation rows 1000x larger in J (torquescale), same physics
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    scaled = constraint_rank(model, data)
    assert scaled.rank == base.rank
    assert np.allclose(scaled.singular_values, base.singular_values, rtol=1e-9)


def test_straight_inextensible_chain_drops_its_structural_redundancy_silently(steel_bar):
    built = build_rig(RigSetup("chain", angle_deg=180.0), steel_bar, ModelOptions(segments=4, axial=False))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RedundantConstraintWarning)
        rank, _ = _rank_at(built)
    # the axial row of a straight chain without axial springs: exactly redundant (ratio ~4e-17)
    assert rank.n_rows == 6
    assert rank.rank == 5
    assert rank.singular_values[-1] / rank.singular_values[0] < 1e-12


@pytest.mark.parametrize(("segments", "warns"), [(1, True), (6, True), (7, False), (12, False)])
def test_coarse_links_warn_about_resolution(segments, warns):
    # one resolution policy (model.options): the estimated f1 error 0.41 / n^2 passes 1 % below 7 segments
    from fpm_sim.model.options import ResolutionWarning, warn_if_coarse

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_if_coarse(ModelOptions(segments=segments))
    got = [w for w in caught if issubclass(w.category, ResolutionWarning)]
    assert bool(got) == warns
    if warns:  # names the parameter (the command line shows it as --segments)
        assert got[0].message.parameter == "segments"
        assert "use segments >= 7" in str(got[0].message)
