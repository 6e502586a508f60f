"""Subsystem rigs against Euler-Bernoulli theory, refinement, and the second linearisation method."""

import numpy as np
import pytest

from fpm_sim.beam_theory import euler_bernoulli_hz, rotary_inertia_shift
from fpm_sim.config import LumpedMass
from fpm_sim.linear import solvers
from fpm_sim.linear.analysis import compare_methods
from fpm_sim.linear.solvers import TimestepWarning, modes_transition_fd
from fpm_sim.model.options import DEFAULT_SEGMENTS, ModelOptions
from fpm_sim.model.rigs import RigError, RigSetup, build_rig
from tests.helpers.jitter import JITTER_SEEDS, jitter_dense


def _bending_pairs(built, n_pairs=3):
    """The square bar bends alike in and out of plane: modes come in degenerate pairs. Return the
    in-plane member of each of the first ``n_pairs`` pairs, and check the pairs are degenerate."""
    f = modes_transition_fd(built, n_modes=2 * n_pairs).frequencies_hz
    assert np.allclose(f[0::2], f[1::2], rtol=1e-6), f
    return f[0::2]


@pytest.mark.parametrize("boundary", ["cantilever", "free-free"])
def test_bar_matches_euler_bernoulli_at_default_resolution(steel_bar, boundary):
    eb = euler_bernoulli_hz(
        boundary, length_m=steel_bar.length_m, section=steel_bar.section, material=steel_bar.material
    )
    f = _bending_pairs(build_rig(RigSetup(boundary), steel_bar, ModelOptions(segments=DEFAULT_SEGMENTS)))
    # 1 %: the accuracy target for the discretisation (measured: <= 0.91 %, cantilever mode 3)
    assert np.all(np.abs(f / eb - 1) < 0.01), f / eb - 1


@pytest.mark.parametrize("boundary", ["cantilever", "free-free"])
def test_bar_error_falls_with_refinement(steel_bar, boundary):
    eb = euler_bernoulli_hz(
        boundary, length_m=steel_bar.length_m, section=steel_bar.section, material=steel_bar.material
    )
    errs = []
    for n in (4, 8, 16):
        f = _bending_pairs(build_rig(RigSetup(boundary), steel_bar, ModelOptions(segments=n)))
        errs.append(np.abs(f / eb - 1))
    errs = np.array(errs)
    assert np.all(np.diff(errs, axis=0) < 0), errs
    # at least second-order convergence: doubling n divides the error by more than 3
    assert np.all(errs[1] / errs[2] > 3.0), errs[1] / errs[2]


@pytest.mark.parametrize("boundary", ["cantilever", "free-free"])
def test_rotary_inertia_shift_matches_rayleigh_quotient(steel_bar, boundary):
    """With section rotary inertia the chain must shift each mode as Rayleigh's quotient predicts."""
    opts = dict(segments=20)
    base = _bending_pairs(build_rig(RigSetup(boundary), steel_bar, ModelOptions(**opts)))
    rot = _bending_pairs(build_rig(RigSetup(boundary), steel_bar, ModelOptions(rotary_inertia=True, **opts)))
    r = steel_bar.section.thickness_m / np.sqrt(12.0)
    predicted = np.array([rotary_inertia_shift(boundary, n, length_m=0.228, radius_of_gyration_m=r) for n in (1, 2, 3)])
    measured = rot / base - 1
    # first-order perturbation: its neglected second-order terms are ~(shift)^2, far below 5 % of it
    assert measured == pytest.approx(predicted, rel=0.05)


@pytest.mark.parametrize("angle", [60.0, 90.0, 180.0])
def test_chain_methods_agree(steel_bar, angle):
    piece = steel_bar.__class__(**{**steel_bar.__dict__, "chain_hinge": LumpedMass(0.15, (3e-5, 3e-5, 3e-5))})
    built = build_rig(RigSetup("chain", angle_deg=angle, damping_beta_s=5e-5), piece, ModelOptions(segments=8))
    cmp = compare_methods(built, n_modes=6)
    assert len(cmp.transition_fd.modes) == 6
    assert len(cmp.constrained.modes) == 6
    diffs = np.abs(cmp.relative_differences(6))
    # 0.5 %: the agreement target; the two differ only by the weld's softness and the
    # discrete map's (omega h)^2 error: measured <= 7e-4 below 1 kHz, 2.7e-3 at the 1.9 kHz sixth mode
    assert np.all(diffs < 0.005), diffs


@pytest.mark.parametrize("jitter_seed", [None, *JITTER_SEEDS])
def test_free_free_drops_exactly_six_rigid_body_modes(steel_bar, monkeypatch, jitter_seed):
    """Also on the step map jittered densely at 1e-12 (tests.helpers.jitter: another kernel's rounding)."""
    if jitter_seed is not None:
        step_map_modes = solvers._step_map_modes
        monkeypatch.setattr(
            solvers, "_step_map_modes", lambda b, a, *rest: step_map_modes(b, jitter_dense(a, jitter_seed), *rest)
        )
    built = build_rig(RigSetup("free-free"), steel_bar, ModelOptions(segments=6))
    with pytest.warns(TimestepWarning):  # all modes are asked for, up to omega h ~ 0.5
        res = modes_transition_fd(built, n_modes=None)
    # 6 rigid-body motions = 12 eigenvalues of the discrete map at lambda = 1, in 2 x 2 Jordan blocks (x+ = x + h v).
    # Exact here, they come out real (non_oscillatory, each eigenvalue counted); a defective eigenvalue perturbed by
    # delta splits by sqrt(delta), into two reals or a complex pair below the rigid-body threshold (rigid_body, one
    # count per pair), which one depends on the rounding: 1e-14 of dense jitter already gives both. All 12 dropped:
    assert res.dropped.get("non_oscillatory", 0) + 2 * res.dropped.get("rigid_body", 0) == 12, res.dropped
    assert res.frequencies_hz[0] > 900.0


def test_clamped_length_shortens_the_cantilever(steel_bar):
    short = steel_bar.__class__(**{**steel_bar.__dict__, "clamped_length_m": 0.028})
    f_full = modes_transition_fd(build_rig(RigSetup("cantilever"), steel_bar, ModelOptions(segments=8)), n_modes=1)
    f_short = modes_transition_fd(build_rig(RigSetup("cantilever"), short, ModelOptions(segments=8)), n_modes=1)
    # f ~ 1 / L_free^2
    assert f_short.frequencies_hz[0] / f_full.frequencies_hz[0] == pytest.approx((0.228 / 0.2) ** 2, rel=2e-3)


def test_bad_rig_settings():
    with pytest.raises(RigError, match="unknown rig"):
        RigSetup("trampoline")
    with pytest.raises(RigError, match="chain hinge angle") as exc:
        RigSetup("chain", angle_deg=200)
    assert (exc.value.parameter, exc.value.value) == ("rig.angle_deg", 200)
