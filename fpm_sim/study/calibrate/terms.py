"""The calibration likelihood's terms as array functions, shared by the one-at-a-time problem
(:mod:`~fpm_sim.study.calibrate.problem`) and the vectorised one (:mod:`~fpm_sim.study.calibrate.vectorised`):
the Gaussian data term, the soft threshold of a statement, and the study's statements over many geometries."""

from __future__ import annotations

import math

import numpy as np

from fpm_sim.kinematics import GeometryArrays, assemble_batch
from fpm_sim.study.calibrate.priors import Priors

__all__ = ["independent_log_likelihood", "log_sigmoid_soft", "statements_batch"]


def log_sigmoid_soft(z: np.ndarray, eps: float) -> np.ndarray:
    """``log(eps + (1 - eps) sigmoid(z))`` elementwise (NaN counts as ``sigmoid = 0``)."""
    z = np.where(np.isfinite(z), z, -np.inf)
    with np.errstate(over="ignore"):
        s = 1.0 / (1.0 + np.exp(-z))
    out: np.ndarray = np.log(eps + (1.0 - eps) * s)
    return out


def statements_batch(priors: Priors, ga: GeometryArrays, measured_measure: np.ndarray | None) -> np.ndarray:
    """``(G,)`` the enabled study statements' soft terms (:mod:`~fpm_sim.study.calibrate.priors`) of ``G``
    geometries; ``measured_measure``: ``(G, P)`` their singularity measures at the distinct measured poses (the
    caller has them from its reachability check), ``None`` without data.
    :meth:`~fpm_sim.study.calibrate.problem.CalibrationProblem.statements_log_likelihood` is ``G = 1``."""
    total = np.zeros(len(ga.proximal_m))
    a = priors.singular_at_phi0
    if a is not None:
        xy = np.asarray(a.poses_mm, float) * 1e-3
        at0 = assemble_batch(ga, xy[:, 0], xy[:, 1], 0.0)
        turned = assemble_batch(ga, xy[:, 0], xy[:, 1], a.turn_rad)
        z = np.minimum((a.near - at0.parallel) / a.width, (turned.singularity - a.near) / a.width)
        # the product of two sigmoids, bounded by the smaller: the min keeps one soft threshold per pose
        total += np.sum(log_sigmoid_soft(z, a.eps), axis=1)
    b = priors.measured_poses_clear
    if b is not None and measured_measure is not None:
        m = measured_measure
        total += np.sum(log_sigmoid_soft((m - b.min_measure) / b.width, b.eps), axis=1)
    return total


def independent_log_likelihood(residual: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """``sum_i log N(residual_i | 0, sd_i^2)`` over the last axis."""
    r = residual / sd
    out: np.ndarray = -0.5 * np.sum(r**2, axis=-1) - np.sum(np.log(sd), axis=-1)
    out -= 0.5 * r.shape[-1] * math.log(2 * math.pi)
    return out
