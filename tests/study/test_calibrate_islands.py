"""Independent islands within an SMC run (:attr:`fpm_sim.study.calibrate.SamplerOptions.islands`): the evidence's
error and the quantiles' Monte Carlo error from their spread, on cases whose answer is known."""

import math

import numpy as np
import pytest

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate.problem import CalibrationError
from fpm_sim.study.calibrate.runs import ClassResult, islands_cdf_var
from fpm_sim.study.calibrate.sampler import _init_worker, sample_classes
from fpm_sim.study.calibrate.smc import merge_smc, smc_results
from tests.study.test_calibrate_runs import AMPLITUDE, HALF, Toy


def _island(log_z: float, err: float, samples: np.ndarray) -> dict:
    return smc_results(samples, np.zeros(len(samples)), log_z, err, len(samples), 1)


def test_islands_state_the_larger_of_their_spread_and_their_own_errors():
    rng = np.random.default_rng(0)
    lz = np.array([0.0, math.log(2.0), math.log(0.5), -math.inf])
    islands = [_island(z, 0.01, rng.standard_normal((10, 2))) for z in lz]
    out = merge_smc(islands, islands=True)
    z = np.exp(np.where(np.isfinite(lz), lz, -np.inf))
    # Z_bar the mean of the four (an island without support counts 0), its relative error the sample sd of the Z_i
    # over sqrt(K) and Z_bar: the textbook standard error of a mean of K independent unbiased estimates (larger here
    # than the lognormal one of the three finite logs, sqrt((exp(var) - 1) / K): 0.49 against 0.39)
    assert float(out["logz"][-1]) == pytest.approx(math.log(z.mean()))
    assert float(out["logzerr"][-1]) == pytest.approx(np.std(z, ddof=1) / math.sqrt(4) / z.mean())
    # islands a nat or more apart: the lognormal error, from the logs' sample variance (the study's class (1, 1, 1),
    # one run: the Z_i's own sample sd says 0.47)
    far = np.array([-76.58, -74.29, -72.87, -73.47])
    wide = merge_smc([_island(v, 0.05, rng.standard_normal((10, 2))) for v in far], islands=True)
    assert float(wide["logzerr"][-1]) == pytest.approx(math.sqrt(math.expm1(np.var(far, ddof=1)) / 4))
    assert float(wide["logzerr"][-1]) > 1.5
    np.testing.assert_array_equal(out["island"], np.repeat(np.arange(4), 10))
    # the islands' own errors where they are the larger: equal islands of error 0.2 each
    same = merge_smc([_island(0.0, 0.2, rng.standard_normal((10, 2))) for _ in range(4)], islands=True)
    assert float(same["logzerr"][-1]) == pytest.approx(0.2 / 2)  # sqrt(4 * (1/4)^2 * 0.2^2)
    # runs merged (not islands) keep each run's labels apart, offset past the ones before
    runs = merge_smc([out, out])
    assert np.unique(runs["island"]).tolist() == list(range(8))


def _class(samples: np.ndarray, island: np.ndarray) -> ClassResult:
    return ClassResult(None, samples, np.zeros(len(samples)), np.zeros(len(samples)), 0.0, 0.1, island)


def test_the_islands_cdf_error_is_the_binomials_for_independent_draws_and_counts_copies():
    rng = np.random.default_rng(1)
    k, n = 8, 500
    at = np.zeros((1, 3))  # the median of N(0, 1), in each of the three quantile slots
    # independent draws: the islands' estimate of var F(0) scatters about the binomial 0.25 / (k n), within the
    # chi-square's spread for k - 1 = 7 degrees of freedom (0.1 % .. 99.9 % points of chi2 / 7: 0.085 .. 3.4)
    ratios = []
    for _ in range(20):
        var = islands_cdf_var([_class(rng.standard_normal((k * n, 1)), np.repeat(np.arange(k), n))], np.ones(1), at)
        assert var is not None
        ratios.append(float(var[0, 0]) / (0.25 / (k * n)))
    assert all(0.085 < r < 3.4 for r in ratios), ratios
    assert 0.6 < np.mean(ratios) < 1.4  # the mean of 20 such ratios: sd sqrt(2 / 7 / 20) = 0.12
    # each island n copies of one draw (particles that never decorrelated): the pooled draws' q (1 - q) / ESS would
    # say 0.25 / 4000; the islands see k independent draws, 0.25 / k on average
    copies = np.repeat(rng.standard_normal((k, 1)), n, axis=0)
    var = islands_cdf_var([_class(copies, np.repeat(np.arange(k), n))], np.ones(1), at)
    assert var is not None
    assert float(var[0, 0]) > 100 * 0.25 / (k * n)
    # no labels, or one island: not known from islands
    assert islands_cdf_var([_class(copies, np.zeros(k * n, int))], np.ones(1), at) is None


def test_a_calibration_of_islands_states_an_evidence_error_that_covers_the_truth_and_passes_the_check():
    toy = Toy()
    _init_worker(toy)
    opts = SamplerOptions(sampler="smc", particles=100, cheap_particles=100, runs=3, seed=1, draws=2000,
                          probe_draws=200, islands=4)  # fmt: skip
    _, check, summaries, _ = sample_classes(toy, opts, None, checkpoint=None, resume=False, print_func=None)
    z = np.array(AMPLITUDE[:2]) / (2 * HALF) ** 2
    for k in (0, 1):
        assert abs(summaries[k].log_evidence - math.log(z[k])) < 4 * summaries[k].log_evidence_err + 1e-9
    assert check is not None
    assert check.passed, check.failures


def test_islands_are_the_smc_samplers_and_at_least_one():
    with pytest.raises(CalibrationError, match="islands"):
        SamplerOptions(sampler="dynesty", islands=3).check()
    with pytest.raises(CalibrationError, match="islands"):
        SamplerOptions(sampler="smc", islands=0).check()
