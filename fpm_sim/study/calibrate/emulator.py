"""An emulator of the segment model's first frequencies for the calibration's data stage, and the importance weights
that make a posterior sampled on it the segment model's.

The segment model costs about 36 ms a description (its 12 measured poses); a data stage of tempered SMC needs some
20 000 calls a run, so 8 elbow-branch classes times 3 runs are about 2.4 hours on 2 cores. The in-plane surrogate
(:mod:`fpm_sim.study.inplane_surrogate`) costs microseconds, but it is biased: on the first stage's particles (the
prior times the study's statements) the segment model's f1 is about 17 % below it on average (the log ratio -0.17
to -0.20 over three such populations), with a spread of 0.17-0.21 in the log (widest at thin sections); on the
surrogate's own posterior the segment model's log-likelihood is 14 nats lower at the median
(docs/identification.md, "An emulator of the segment model"). So the surrogate alone gives another posterior.

The emulator corrects it multiplicatively (Kennedy & O'Hagan's 2000 autoregressive form, on a log scale):

    f_emulated(theta)_j = f_surrogate(theta)_j * exp(g_j(u)),

``g`` a thin-plate-spline radial-basis fit (:class:`scipy.interpolate.RBFInterpolator`, smoothing 0.01, a linear
tail) of ``log(f_segments / f_surrogate)`` at each measured pose ``j`` over the free parameters' unit-cube
coordinates ``u`` (the discrepancy's left out: it does not change a frequency), trained on segment-model runs at the
first stage's particles, which cover where the posterior can be. A fifth of them is held out, and the held-out rms of
the log ratio is added to the emulated likelihood as a relative model error (``s^2 = sigma^2 + (d f)^2 + (e f)^2``):
the emulator's error is never silent, and it widens the emulated posterior, which keeps it a proposal that covers
the segment model's.

The emulated posterior is then made the segment model's by importance weights (multifidelity importance sampling,
Peherstorfer, Willcox & Gunzburger 2016): each particle of the emulated data stage is weighted by
``L_segments / L_emulated``, and the evidence multiplied by their mean. That is exact whatever the emulator's error;
its error shows only as fewer effective draws, measured by the weights' effective sample size and their Pareto
shape ``k`` (Vehtari et al. 2024: the weighted estimates are reliable for ``k < 0.7``), both reported per run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fpm_sim.study.calibrate.problem import CalibrationError

__all__ = ["EMULATOR_ERROR_FACTOR", "EMULATOR_HELD_OUT", "Emulator", "importance_diagnostics", "train_emulator"]

EMULATOR_ERROR_FACTOR = 1.0
"""The emulated likelihood's relative model error, in held-out rms errors of the emulator."""
EMULATOR_HELD_OUT = 0.2
"""The fraction of the training runs held out to measure the emulator's error."""
EMULATOR_SMOOTHING = 0.01
"""The radial-basis fit's smoothing: the segment model's log ratio is smooth in the parameters except where the
lowest mode changes family; an exact interpolant rings there (held-out rms 0.056 at smoothing 1e-3, 0.055 at 0.01,
0.059 at 0.1, fitted on 640 runs of the study's problem at stage-1 particles; measured)."""


@dataclass(frozen=True)
class Emulator:
    """The fitted correction ``g`` (module docstring) and its measured error."""

    fit: Any
    """The :class:`scipy.interpolate.RBFInterpolator` of ``(n, n_free) -> (n, n_obs)`` log ratios."""
    n_free: int
    """The unit-cube coordinates it reads (the free parameters', the discrepancy's excluded)."""
    n_train: int
    held_out_rms: float
    """The held-out rms of ``log(f_segments / f_emulated)``: the relative error added to the emulated likelihood."""
    held_out_max: float

    @property
    def model_error_rel(self) -> float:
        """The relative error the emulated likelihood adds (:data:`EMULATOR_ERROR_FACTOR` held-out rms errors)."""
        return EMULATOR_ERROR_FACTOR * self.held_out_rms

    def log_scale(self, u: np.ndarray) -> np.ndarray:
        """``(n, n_obs)`` the correction ``g(u)`` at unit-cube rows ``u`` (its first :attr:`n_free` columns read)."""
        out: np.ndarray = self.fit(np.atleast_2d(u)[:, : self.n_free])
        return out


def train_emulator(
    u: np.ndarray, f_segments: np.ndarray, f_surrogate: np.ndarray, *, n_free: int, rng: np.random.Generator
) -> Emulator:
    """The emulator fitted to the log ratios at unit-cube rows ``u`` (``(n, >= n_free)``; ``f_*``: ``(n, n_obs)``
    in Hz, rows with a non-finite or non-positive frequency left out): its error measured on
    :data:`EMULATOR_HELD_OUT` of the rows held out, then refitted on all of them."""
    from scipy.interpolate import RBFInterpolator

    with np.errstate(divide="ignore", invalid="ignore"):
        y = np.log(f_segments / f_surrogate)
    ok = np.all(np.isfinite(y), axis=1)
    x, y = np.asarray(u, float)[ok, :n_free], y[ok]
    n = len(x)
    n_out = round(EMULATOR_HELD_OUT * n)
    if n - n_out < 2 * (n_free + 1) or n_out < 1:
        raise CalibrationError(
            f"too few usable segment-model runs to fit the emulator: {n} of {len(u)}", parameter="emulator",
            value=len(u), hint="train it on more segment-model runs, or leave it 0",
        )  # fmt: skip
    order = rng.permutation(n)
    fit_on, held = order[n_out:], order[:n_out]

    def fitted(rows: np.ndarray) -> Any:
        return RBFInterpolator(x[rows], y[rows], kernel="thin_plate_spline", smoothing=EMULATOR_SMOOTHING, degree=1)

    res = y[held] - fitted(fit_on)(x[held])
    return Emulator(
        fit=fitted(np.arange(n)), n_free=n_free, n_train=n, held_out_rms=float(np.sqrt(np.mean(res**2))),
        held_out_max=float(np.max(np.abs(res))),
    )  # fmt: skip


def importance_diagnostics(log_w: np.ndarray) -> tuple[float, float]:
    """``(effective sample size, Pareto k)`` of importance weights given as ``log_w`` (``-inf``: weight 0; ``k``
    from ArviZ's Pareto-smoothed importance sampling: reliable below 0.7)."""
    import arviz as az

    ok = np.isfinite(log_w)
    if ok.sum() < 2:
        return float(ok.sum()), float("inf")
    w = np.exp(log_w[ok] - np.max(log_w[ok]))
    _, k = az.psislw(log_w[ok].copy())
    return float(w.sum() ** 2 / np.sum(w**2)), float(k)
