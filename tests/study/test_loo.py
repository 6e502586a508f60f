"""PSIS leave-one-out and the Gaussian-process discrepancy, against truths computed another way."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from fpm_sim.errors import FpmSimError
from fpm_sim.study.discrepancy import (
    conditional,
    correlation,
    covariance,
    gaussian_log_likelihood,
    loo_conditionals,
    pose_features,
)
from fpm_sim.study.loo import leave_one_out


def test_psis_loo_matches_the_conjugate_normal_models_exact_leave_one_out() -> None:
    """y_i = mu + e_i, e ~ N(0, s^2), mu ~ N(0, t^2): the posterior without datum i is normal in closed form, so
    is the predictive of y_i. PSIS-LOO from 4000 exact posterior draws must match it."""
    rng = np.random.default_rng(3)
    s, t, n = 2.0, 10.0, 8
    y = 50.0 + s * rng.standard_normal(n)
    prec = 1 / t**2 + n / s**2
    mu = rng.normal((y.sum() / s**2) / prec, np.sqrt(1 / prec), size=4000)
    f = np.repeat(mu[:, None], n, axis=1)  # every datum's "model frequency" is mu
    loo = leave_one_out(f, y, np.full(n, s), np.zeros(4000))
    for i in range(n):
        rest = np.delete(y, i)
        p_i = 1 / t**2 + (n - 1) / s**2
        m_i = (rest.sum() / s**2) / p_i
        exact = stats.norm(m_i, np.sqrt(1 / p_i + s**2))
        # tolerance: the Monte Carlo error of 4000 importance-weighted draws on a quantile of sd ~2.1 (~0.05)
        np.testing.assert_allclose(loo.quantiles_hz[i], exact.ppf([0.05, 0.25, 0.5, 0.75, 0.95]), atol=0.12)
        assert loo.pointwise_elpd[i] == pytest.approx(exact.logpdf(y[i]), abs=0.02)
    assert np.all(loo.pareto_k < 0.5)


def test_loo_conditionals_equal_the_schur_complement() -> None:
    rng = np.random.default_rng(0)
    a = rng.standard_normal((6, 6))
    cov = a @ a.T + 0.5 * np.eye(6)
    r = rng.standard_normal(6)
    mean, sd = loo_conditionals(r, cov)
    for i in range(6):
        o = np.delete(np.arange(6), i)
        k = cov[i, o]
        m = k @ np.linalg.solve(cov[np.ix_(o, o)], r[o])
        v = cov[i, i] - k @ np.linalg.solve(cov[np.ix_(o, o)], k)
        assert mean[i] == pytest.approx(m, rel=1e-10)
        assert sd[i] == pytest.approx(np.sqrt(v), rel=1e-10)


def test_gp_conditional_equals_conditioning_the_joint_gaussian() -> None:
    """The relative discrepancy at new poses given the data, against the joint normal of (y, delta*) conditioned
    directly (the data's covariance from covariance(), the cross-covariance d^2 f k*)."""
    rng = np.random.default_rng(1)
    u = pose_features(rng.uniform(-0.1, 0.1, 7), rng.uniform(-0.1, 0.1, 7), rng.choice([0.0, 0.2], 7))
    v = pose_features(np.array([0.0, 0.05]), np.array([0.02, -0.08]), np.array([0.0, 0.2]))
    f = rng.uniform(35, 70, 7)
    sig = 0.02 * f
    y = f * (1 + 0.1 * rng.standard_normal(7))
    d, ell = 0.12, 0.07
    cov = covariance(f, sig, u, d, ell)
    cross = d**2 * correlation(v, u, ell) * f[None, :]  # cov(delta*, y)
    mean_direct = cross @ np.linalg.solve(cov, y - f)
    var_direct = d**2 - np.sum(cross * np.linalg.solve(cov, cross.T).T, axis=1)
    mean, sd = conditional(f, y, sig, u, v, d, ell)
    np.testing.assert_allclose(mean, mean_direct, rtol=1e-9)
    np.testing.assert_allclose(sd, np.sqrt(var_direct), rtol=1e-9)


def test_gaussian_log_likelihood_is_scipys_multivariate_normal() -> None:
    rng = np.random.default_rng(2)
    u = pose_features(rng.uniform(-0.1, 0.1, 5), rng.uniform(-0.1, 0.1, 5), np.zeros(5))
    f = rng.uniform(35, 70, 5)
    cov = covariance(f, 0.02 * f, u, 0.1, 0.05)
    r = rng.standard_normal(5)
    assert gaussian_log_likelihood(r, cov) == pytest.approx(stats.multivariate_normal(np.zeros(5), cov).logpdf(r))
    # the short-correlation limit is the independent model
    ind = covariance(f, 0.02 * f, u, 0.1, None)
    np.testing.assert_allclose(covariance(f, 0.02 * f, u, 0.1, 1e-6), ind, rtol=1e-12)


def test_leave_one_out_refuses_mismatched_or_too_few_draws() -> None:
    with pytest.raises(FpmSimError, match="shapes"):
        leave_one_out(np.ones((20, 3)), np.ones(4), np.ones(4), np.zeros(20))
    with pytest.raises(FpmSimError, match="at least 10 draws"):
        leave_one_out(np.ones((5, 3)), np.ones(3), np.ones(3), np.zeros(5))
