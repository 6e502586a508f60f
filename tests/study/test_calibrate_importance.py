"""Importance sampling from a mixture fitted to a sampler's particles (:mod:`fpm_sim.study.calibrate.importance`), on
targets whose evidence and mode weights are known in closed form (the SMC tests' two-mode mixture)."""

import math

import numpy as np
import pytest
from scipy import stats

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate.importance import ProbitMixture, importance_diagnostics, importance_sample
from fpm_sim.study.calibrate.problem import CalibrationError
from fpm_sim.study.calibrate.smc import SmcSettings, emulated_two_stage, two_stage
from tests.study.test_calibrate_smc import CENTRES, SD, WEIGHTS, D, _cheap, _emulated, _full, _modes


def _draws_of_the_mixture(n: int, share: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` exact draws of the two-mode mixture with ``share`` of them in the first mode (0.3: the target's)."""
    first = rng.random(n) < share
    return np.where(first[:, None], CENTRES[0], CENTRES[1]) + SD * rng.standard_normal((n, D))


def test_the_mixtures_density_is_the_student_t_mixtures():
    rng = np.random.default_rng(0)
    q = ProbitMixture.fit(_draws_of_the_mixture(2000, 0.3, rng), rng)
    assert len(q.means) >= 2  # the two modes are apart in probit coordinates too
    z = q.sample(500, rng)
    want = np.logaddexp.reduce(
        [
            lw + stats.multivariate_t(loc=m, shape=c @ c.T, df=q.df).logpdf(z)
            for lw, m, c in zip(q.log_weights, q.means, q.chols)
        ],
        axis=0,
    )
    np.testing.assert_allclose(q.log_density(z), want, rtol=1e-10)  # the same arithmetic up to round-off


def test_importance_sampling_gives_the_evidence_with_an_honest_error_and_corrects_the_particles_shares():
    # the particles put 0.1 on the first mode where the target puts 0.3 (a tempering's resampling drift, exaggerated):
    # the importance weights restore 0.3; ln Z = 0 (the support u_0 < 0.9 holds both modes whole)
    z, s, shares = [], [], []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        imp = importance_sample(_draws_of_the_mixture(800, 0.1, rng), _full, 5000, rng)
        w = np.exp(imp.normalised_log_weights)
        ess, k = importance_diagnostics(imp.log_w)
        assert k < 0.7  # the Student-t tails keep the weights bounded: the error estimate is reliable
        z.append(imp.log_evidence)
        s.append(math.sqrt(imp.log_evidence_var))
        share = float(np.sum(w * _modes(imp.u)[1]))
        # the share's error from the effective draws (binomial, sqrt(0.21 / ESS)); 4 of those
        assert abs(share - WEIGHTS[0]) < 4 * math.sqrt(0.21 / ess), (share, ess)
        shares.append(share)
    z_arr, s_rms = np.array(z), math.sqrt(np.mean(np.square(s)))
    assert np.all(np.abs(z_arr) < 4 * np.array(s)), (z_arr, s)
    # the stated error against the 12 independent runs' spread: within the chi-square's 0.1 % .. 99.9 % points of
    # 11 degrees of freedom (sqrt(chi2 / 11): 0.41 .. 1.69)
    assert 0.41 < np.std(z_arr, ddof=1) / s_rms < 1.69, (z_arr, s_rms)


def test_a_mode_across_a_periodic_seam_is_one_component():
    # a Gaussian of sd 0.03 at u_0 = 0.01 on a whole-turn coordinate: half its particles near 1, half near 0; the
    # rotation puts them together, so the fit is one compact component and the weights nearly equal
    rng = np.random.default_rng(1)
    centre = np.array([0.01, 0.5])

    def wrapped(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.mod(u - centre + 0.5, 1.0) - 0.5
        return np.zeros(len(u)), stats.norm.logpdf(d, scale=0.03).sum(axis=1)

    pop = np.mod(centre + 0.03 * rng.standard_normal((1000, 2)), 1.0)
    imp = importance_sample(pop, wrapped, 4000, rng, periodic=(0,))
    ess, _ = importance_diagnostics(imp.log_w)
    assert ess > 0.4 * len(imp.u)  # a t fitted to a Gaussian, inflated 1.5: most draws count
    assert abs(imp.log_evidence) < 4 * math.sqrt(imp.log_evidence_var)  # the wrapped Gaussian's mass is 1
    assert np.all((imp.u >= 0) & (imp.u <= 1))


def test_an_emulated_data_stage_by_importance_sampling_gives_the_exact_evidence_and_shares():
    # the wrong emulator of the SMC tests (shifted, 1.5 times as wide, weighted 1 : 1, evidence 2): the importance
    # draws on it, then the exact weights at the resampled draws, give ln Z = 0 and the share 0.3
    one, two = SmcSettings(particles=500), SmcSettings(particles=1000, importance=8000)
    for seed in range(3):
        run = emulated_two_stage(_cheap, lambda u: _emulated, _full, D, one, two, np.random.default_rng(seed))
        assert run.importance is not None
        assert run.log_weights is not None
        assert abs(run.log_evidence) < 4 * run.log_evidence_err, (run.log_evidence, run.log_evidence_err)
        assert run.log_evidence_err < 0.2  # thousands of independent draws, not a few hundred correlated ones
        w = np.exp(run.log_weights)
        ess = 1.0 / float(np.sum(w**2))
        assert abs(float(np.sum(w * _modes(run.u)[1])) - WEIGHTS[0]) < 4 * math.sqrt(0.21 / ess)
        assert np.array_equal(run.log_b, _full(run.u)[1])  # the exact likelihood is reported
        assert len(run.u) <= two.particles  # the exact model runs once per distinct resampled draw
        assert run.n_calls >= two.importance + len(run.u)


def test_a_two_stage_run_by_importance_sampling_gives_the_evidence():
    one, two = SmcSettings(particles=500), SmcSettings(particles=800, importance=6000)
    run = two_stage(_cheap, _full, D, one, two, np.random.default_rng(4))
    assert run.importance is not None
    assert run.log_weights is not None
    assert abs(run.log_evidence) < 4 * run.log_evidence_err
    assert math.isclose(float(np.sum(np.exp(run.log_weights))), 1.0)


def test_too_few_importance_draws_are_refused_by_name():
    with pytest.raises(CalibrationError, match="importance"):
        SamplerOptions(sampler="smc", particles=400, importance=100).check()
