"""The emulator of the segment model (:mod:`fpm_sim.study.calibrate.emulator`) on a synthetic pair of models whose
high-fidelity one switches mode families where the low-fidelity one does not: its stated per-pose error must be the
error it makes on fresh draws, and it must refuse too few runs."""

import numpy as np
import pytest

from fpm_sim.study.calibrate.emulator import train_emulator
from fpm_sim.study.calibrate.problem import CalibrationError

N_FREE, N_OBS = 3, 4


def _models(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(f_high, f_low)`` (Hz): the low-fidelity model's frequency rises with ``u0`` (and ``u1`` more at higher
    poses); the high-fidelity one is 20 % below it until another family (60-80 Hz, set by ``u2``) becomes the lowest,
    joined smoothly (a soft minimum over ~2 Hz), as the segment model's out-of-plane-like first mode takes over."""
    j = np.arange(N_OBS)[None, :]
    low = 60.0 * (1.0 + u[:, [0]] + 0.5 * j * u[:, [1]] / N_OBS)
    other = 60.0 + 20.0 * u[:, [2]]
    high = -2.0 * np.logaddexp(-0.8 * low / 2.0, -other / 2.0)
    return high, low


def test_the_emulators_stated_error_per_pose_is_its_error_on_fresh_draws():
    rng = np.random.default_rng(0)
    u = rng.random((600, N_FREE))
    emu = train_emulator(u, *_models(u), n_free=N_FREE, rng=rng)
    fresh = rng.random((4000, N_FREE))
    high, low = _models(fresh)
    err = np.log(emu.frequencies(fresh, low) / high)
    rms = np.sqrt(np.mean(err**2, axis=0))
    # the held-out estimate is a sample of 120 runs' errors (its relative sd ~ 1 / sqrt(2 x 120) = 6 % for Gaussian
    # errors, more for the heavier tails at the families' junction): within a factor of 2 of the fresh error
    assert np.all(rms < 2.0 * emu.held_out_rms_per_obs), (rms, emu.held_out_rms_per_obs)
    assert np.all(rms > 0.5 * emu.held_out_rms_per_obs), (rms, emu.held_out_rms_per_obs)
    assert np.array_equal(emu.model_error_rel, emu.held_out_rms_per_obs)  # EMULATOR_ERROR_FACTOR = 1
    # it learned the junction: its error is a small part of the log ratio's own spread
    spread = np.std(np.log(high / low), axis=0)
    assert np.all(rms < 0.25 * spread), (rms, spread)
    assert emu.held_out_max >= float(np.max(emu.held_out_rms_per_obs))


def test_the_emulator_is_nan_where_the_surrogate_fails_and_refuses_too_few_runs():
    rng = np.random.default_rng(1)
    u = rng.random((200, N_FREE))
    high, low = _models(u)
    emu = train_emulator(u, high, low, n_free=N_FREE, rng=rng)
    bad = low[:3].copy()
    bad[1, 2] = np.nan
    out = emu.frequencies(u[:3], bad)
    assert np.all(np.isnan(out[1]))
    assert np.all(np.isfinite(out[[0, 2]]))
    with pytest.raises(CalibrationError, match="too few usable segment-model runs"):
        train_emulator(u[:12], high[:12], low[:12], n_free=N_FREE, rng=rng)


def test_a_whole_turn_angle_is_read_on_a_circle():
    """With ``u0`` a whole-turn angle the high-fidelity model's correction is periodic in it; read on a circle, the
    emulator joins its two ends (to well within its stated error) and keeps its error honest."""
    rng = np.random.default_rng(2)

    def models(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        low = 60.0 * (1.0 + u[:, [1]] + 0.1 * np.arange(N_OBS)[None, :])
        return low * np.exp(0.3 * np.cos(2 * np.pi * u[:, [0]]) * (0.5 + u[:, [2]])), low

    u = rng.random((500, N_FREE))
    emu = train_emulator(u, *models(u), n_free=N_FREE, rng=rng, periodic=(0,))
    ends = rng.random((200, N_FREE))
    lo, hi = ends.copy(), ends.copy()
    lo[:, 0], hi[:, 0] = 1e-4, 1.0 - 1e-4
    gap = np.abs(np.log(emu.frequencies(lo, models(lo)[1]) / emu.frequencies(hi, models(hi)[1])))
    assert np.all(gap < 0.2 * emu.held_out_rms_per_obs), (gap.max(), emu.held_out_rms_per_obs)
    fresh = rng.random((3000, N_FREE))
    high, low = models(fresh)
    rms = np.sqrt(np.mean(np.log(emu.frequencies(fresh, low) / high) ** 2, axis=0))
    assert np.all(rms < 2.0 * emu.held_out_rms_per_obs), (rms, emu.held_out_rms_per_obs)


def _two_families(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(f_high, f_low)`` ``(n, 2, N_OBS)`` (Hz) of two mode families, each high-fidelity one a smooth multiple of
    its low-fidelity one (the in-plane family's 20 % below, the out-of-plane-like one's set by ``u2``, 5 % below):
    the frequency is the lower family, whose switch the families' corrections need not follow."""
    j = np.arange(N_OBS)[None, :]
    low_in = 60.0 * (1.0 + u[:, [0]] + 0.5 * j * u[:, [1]] / N_OBS)
    low_out = np.broadcast_to(60.0 + 30.0 * u[:, [2]], low_in.shape)
    high_in = 0.8 * low_in * np.exp(0.05 * np.sin(3.0 * u[:, [1]]))
    high_out = 0.95 * low_out * np.exp(0.02 * u[:, [0]])
    return np.stack([high_in, high_out], axis=1), np.stack([low_in, low_out], axis=1)


def test_an_emulator_of_two_families_follows_the_switch_that_one_correction_cannot():
    # The same runs, emulated as one family (the lower high-fidelity frequency over the in-plane low-fidelity one:
    # the correction must bend where the families cross) and as two (each family's smooth correction, then the
    # lower): the second's error on fresh draws is what it states, and a fraction of the first's.
    rng = np.random.default_rng(5)
    u = rng.random((400, N_FREE))
    high, low = _two_families(u)
    two = train_emulator(u, high, low, n_free=N_FREE, rng=rng)
    one = train_emulator(u, high.min(axis=1), low[:, 0], n_free=N_FREE, rng=rng)
    fresh = rng.random((4000, N_FREE))
    f_high, f_low = _two_families(fresh)
    truth = f_high.min(axis=1)
    rms_two = np.sqrt(np.mean(np.log(two.frequencies(fresh, f_low) / truth) ** 2, axis=0))
    rms_one = np.sqrt(np.mean(np.log(one.frequencies(fresh, f_low[:, 0]) / truth) ** 2, axis=0))
    assert np.all(rms_two < 0.25 * rms_one), (rms_two, rms_one)
    assert np.all(rms_two < 2.0 * two.held_out_rms_per_obs), (rms_two, two.held_out_rms_per_obs)
    assert np.all(rms_two > 0.5 * two.held_out_rms_per_obs), (rms_two, two.held_out_rms_per_obs)


def test_a_family_missing_from_a_run_leaves_only_that_familys_fit():
    # A run whose segment model has no in-plane mode among those computed (NaN) still trains the other family, and
    # its frequency (the lower family) is still used for the stated error.
    rng = np.random.default_rng(6)
    u = rng.random((400, N_FREE))
    high, low = _two_families(u)
    high[:20, 0] = np.nan
    emu = train_emulator(u, high, low, n_free=N_FREE, rng=rng)
    assert emu.n_train == 400
    assert np.all(np.isfinite(emu.frequencies(u[:20], low[:20])))


@pytest.mark.slow
def test_on_the_study_the_two_families_emulator_is_a_fraction_of_one_corrections_error():
    # The study's problem (the dominant orbit's class), prior draws that reach every measured pose, the segment model
    # run at each: fitted to 400, checked on 150 more. Where the lowest mode changes family between draws and poses,
    # one correction of the in-plane surrogate is a few % off; the two families' corrections are each smooth.
    # Headline of issue 31 (fifth session; measured at stage 1's particles: 2-8 % against 0.4-1.3 % per pose).
    from fpm_sim.study.calibrate.problem import study_problem
    from fpm_sim.study.calibrate.vectorised import family_frequencies_batch

    p = study_problem(model="segments", branch=(-1, -1, 1))
    rng = np.random.default_rng(7)
    u = rng.random((6000, p.ndim))
    theta = p.prior_transform(u)
    f_sur, cheap = family_frequencies_batch(p, theta)
    ok = np.flatnonzero(np.isfinite(cheap))[:550]
    u, theta, f_sur = u[ok], theta[ok], f_sur[ok]
    f_seg = np.array([p.predict_families(t) for t in theta])
    low = np.fmin(f_seg[:, 0], f_seg[:, 1])  # NaN where the segment model cannot give a pose (a few near singularities)
    fit, check = slice(0, 400), slice(400, None)
    n_free, per = len(p.priors.parameters), p.priors.periodic
    two = train_emulator(u[fit], f_seg[fit], f_sur[fit], n_free=n_free, rng=rng, periodic=per)
    one = train_emulator(u[fit], low[fit], f_sur[fit, 0], n_free=n_free, rng=rng, periodic=per)
    rms_two = np.sqrt(np.nanmean(np.log(two.frequencies(u[check], f_sur[check]) / low[check]) ** 2, axis=0))
    rms_one = np.sqrt(np.nanmean(np.log(one.frequencies(u[check], f_sur[check, 0]) / low[check]) ** 2, axis=0))
    assert np.all(rms_two < 0.5 * rms_one), (rms_two, rms_one)
    # its stated error is its error on fresh draws (150 of them: the rms itself is uncertain by ~10-20 %)
    assert np.all(rms_two < 2.0 * two.held_out_rms_per_obs), (rms_two, two.held_out_rms_per_obs)
