"""The model discrepancy of the calibration's likelihood: independent, or a Gaussian process over the pose.

A measured frequency at pose ``p`` is modelled (Kennedy & O'Hagan 2001) as::

    y(p) = f(p, theta) (1 + delta(p)) + eps,     eps ~ N(0, sigma^2)   (the measurement)

- **independent** (``length_scale_m = None``): ``delta(p) ~ N(0, d^2)`` independently at every datum;
- **Gaussian process** (``length_scale_m = l``): ``delta ~ GP(0, d^2 k(p, p'))`` with the squared-exponential
  correlation ``k = exp(-|u - u'|^2 / (2 l^2))`` of the pose features ``u = (x, y, ARC_RADIUS_M * phi)`` (m):
  the model's relative error at two nearby poses is alike (the same missing compliance, the same joint), so a
  misfit at the measured poses says something about the poses between them. ``l -> 0`` is the independent
  model; ``l -> inf`` is one common relative error (a level offset).

With ``D = diag(f)`` and ``S = diag(sigma^2)`` the data's covariance is ``Sigma = S + d^2 D K D``
(:func:`covariance`). Given the data, the discrepancy at new poses is Gaussian (:func:`conditional`): on the
relative residuals ``r = (y - f) / f`` with ``C = d^2 K + diag(sigma^2 / f^2)``, the mean is
``d^2 k*' C^-1 r`` and the variance ``d^2 - d^4 k*' C^-1 k*``. That is how a Gaussian-process posterior
corrects a prediction between measured poses, and why its bands narrow there and widen away from the data.

Pure NumPy; every function works on one draw's arrays. Used by the likelihood
(:mod:`fpm_sim.study.calibrate.problem`), the predictive bands (:mod:`fpm_sim.study.posterior`) and the
leave-one-out checks (:mod:`fpm_sim.study.loo`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "ARC_RADIUS_M",
    "LENGTH_SCALE_PARAMETER",
    "conditional",
    "correlation",
    "covariance",
    "gaussian_log_likelihood",
    "loo_conditionals",
    "pose_features",
]

LENGTH_SCALE_PARAMETER = "likelihood.length_scale_m"
"""The Gaussian-process discrepancy's correlation length (m); absent: the independent discrepancy."""

ARC_RADIUS_M = 0.1
"""Lever (m) that turns a platform rotation into a distance of the correlation: ``ARC_RADIUS_M * phi``.
Assumed: a platform-sized radius (the study's poses turn by 0.2 rad, 20 mm at 0.1 m: less than the grid's
50 mm step, so a turned pose correlates with its unturned neighbours as a pose 20 mm away would)."""


def pose_features(x_m: np.ndarray, y_m: np.ndarray, phi_rad: np.ndarray) -> np.ndarray:
    """``(n, 3)`` the correlation's coordinates ``(x, y, ARC_RADIUS_M * phi)`` (m)."""
    return np.stack([np.asarray(x_m, float), np.asarray(y_m, float), ARC_RADIUS_M * np.asarray(phi_rad, float)], 1)


def correlation(u: np.ndarray, v: np.ndarray, length_scale_m: float) -> np.ndarray:
    """``(len(u), len(v))`` squared-exponential correlation of pose features (:func:`pose_features`)."""
    d2 = np.sum((u[:, None, :] - v[None, :, :]) ** 2, axis=-1)
    out: np.ndarray = np.exp(-0.5 * d2 / length_scale_m**2)
    return out


def covariance(
    f_hz: np.ndarray, sigma_hz: np.ndarray, features: np.ndarray, d: float, length_scale_m: float | None
) -> np.ndarray:
    """``Sigma = diag(sigma^2) + d^2 diag(f) K diag(f)`` (Hz^2) of the data (module docstring);
    ``length_scale_m=None``: ``K = I`` (independent)."""
    f = np.asarray(f_hz, float)
    if length_scale_m is None:
        k = np.eye(f.size)
    else:
        k = correlation(features, features, length_scale_m)
    out: np.ndarray = np.diag(np.asarray(sigma_hz, float) ** 2) + d**2 * (f[:, None] * k * f[None, :])
    return out


def gaussian_log_likelihood(residual: np.ndarray, cov: np.ndarray) -> float:
    """``log N(residual | 0, cov)``; ``-inf`` where ``cov`` is not positive definite."""
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return -math.inf
    z = np.linalg.solve(chol, residual)
    return float(-0.5 * z @ z - np.sum(np.log(np.diag(chol))) - 0.5 * residual.size * math.log(2 * math.pi))


def conditional(
    f_data_hz: np.ndarray,
    y_hz: np.ndarray,
    sigma_hz: np.ndarray,
    features: np.ndarray,
    new_features: np.ndarray,
    d: float,
    length_scale_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of the relative discrepancy ``delta`` at ``new_features`` given the data.

    Parameters
    ----------
    f_data_hz, y_hz, sigma_hz
        The draw's model frequencies at the data, the measured values and their sd (Hz), each ``(n,)``.
    features, new_features
        :func:`pose_features` of the data ``(n, 3)`` and of the new poses ``(m, 3)``.
    d, length_scale_m
        The draw's discrepancy sd (relative) and correlation length (m).

    Returns
    -------
    ``(mean, sd)``, each ``(m,)``, relative: the new pose's frequency is ``f (1 + delta)``.
    """
    f = np.asarray(f_data_hz, float)
    r = (np.asarray(y_hz, float) - f) / f
    c = d**2 * correlation(features, features, length_scale_m) + np.diag((np.asarray(sigma_hz, float) / f) ** 2)
    ks = d**2 * correlation(new_features, features, length_scale_m)  # (m, n)
    chol = np.linalg.cholesky(c)
    a = np.linalg.solve(chol, ks.T)  # (n, m)
    mean = a.T @ np.linalg.solve(chol, r)
    var = np.maximum(d**2 - np.sum(a * a, axis=0), 0.0)
    return mean, np.sqrt(var)


def loo_conditionals(residual: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out conditionals of a Gaussian vector: for each ``i``, the mean of ``residual_i`` given the
    others and its sd (exact, from the precision matrix: ``mean_i = r_i - [P r]_i / P_ii``,
    ``var_i = 1 / P_ii``; Sundararajan & Keerthi 2001)."""
    prec = np.linalg.inv(cov)
    diag = np.diag(prec)
    mean = residual - (prec @ residual) / diag
    return mean, np.sqrt(1.0 / diag)
