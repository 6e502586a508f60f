"""Leave-one-out predictive checks of a calibration, by Pareto-smoothed importance sampling (PSIS-LOO).

How well does the posterior predict a measured pose it was not given? Refitting once per pose (twelve nested
sampling runs) answers it exactly; PSIS-LOO (Vehtari, Gelman & Gabry 2017) answers it from the one posterior:
the draws re-weighted by ``1 / p(y_i | y_-i, theta_s)`` are draws of the posterior without datum ``i``, and
the Pareto-smoothed weights say when that is reliable (``k < 0.7``; above it, refit). For a Gaussian-process
discrepancy the data are not independent given ``theta``, and the pointwise term is the exact conditional
``p(y_i | y_-i, theta)`` of the multivariate normal (Buerkner, Gabry & Vehtari 2021).

Per held-out datum ``i`` the leave-one-out predictive is the weighted mixture over draws ``s`` of
``N(f_is + m_is, v_is)``: the model's frequency, the discrepancy's conditional mean given the other data (zero
for an independent discrepancy) and the variance of a new measurement (discrepancy and measurement noise).
:func:`leave_one_out` returns its 5/25/50/75/95 % quantiles (exact: bisection of the mixture's CDF), whether
the measured value lies in the 50 % and 90 % bands, the median's error and the expected log predictive
density ``elpd_loo`` with its standard error (the quantity to compare models by, beside the evidence).

The inputs are one posterior's arrays (:class:`fpm_sim.study.posterior.Posterior` and ``fpm-sim calibrate``
hold them); this module needs NumPy, SciPy and ArviZ (its ``psislw``) only.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fpm_sim.errors import FpmSimError
from fpm_sim.figures import bands_against_measured
from fpm_sim.study.discrepancy import covariance, loo_conditionals

__all__ = [
    "LOO_QUANTILES",
    "PARETO_K_LIMIT",
    "LeaveOneOut",
    "leave_one_out",
    "loo_from_components",
    "mixture_quantiles",
]

LOO_QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
PARETO_K_LIMIT = 0.7
"""Above it the importance weights of a datum are unreliable (Vehtari et al. 2017: refit without the datum)."""


@dataclass
class LeaveOneOut:
    """PSIS-LOO predictive of every datum (:func:`leave_one_out`).

    Attributes
    ----------
    labels
        The data's names.
    measured_hz
        ``(n,)`` measured values.
    quantiles_hz
        ``(n, 5)`` the leave-one-out predictive's :data:`LOO_QUANTILES`.
    pointwise_elpd
        ``(n,)`` ``log p(y_i | y_-i)`` estimated by PSIS.
    pareto_k
        ``(n,)`` the Pareto shape of each datum's importance weights.
    """

    labels: list[str]
    measured_hz: np.ndarray
    quantiles_hz: np.ndarray
    pointwise_elpd: np.ndarray
    pareto_k: np.ndarray

    @property
    def n(self) -> int:
        return int(self.measured_hz.size)

    @property
    def median_hz(self) -> np.ndarray:
        return self.quantiles_hz[:, 2]

    def inside(self, level: float) -> np.ndarray:
        """Per datum: the measured value lies in the central ``level`` band (0.5 or 0.9)."""
        lo, hi = {0.5: (1, 3), 0.9: (0, 4)}[level]
        y = self.measured_hz
        out: np.ndarray = (y >= self.quantiles_hz[:, lo]) & (y <= self.quantiles_hz[:, hi])
        return out

    @property
    def relative_error(self) -> np.ndarray:
        """``(n,)`` (median - measured) / measured."""
        out: np.ndarray = (self.median_hz - self.measured_hz) / self.measured_hz
        return out

    @property
    def mean_abs_error(self) -> float:
        """Mean |relative error| of the leave-one-out median (the point prediction)."""
        return float(np.mean(np.abs(self.relative_error)))

    @property
    def half_width(self) -> np.ndarray:
        """``(n,)`` half the 90 % band over the median."""
        out: np.ndarray = 0.5 * (self.quantiles_hz[:, 4] - self.quantiles_hz[:, 0]) / self.median_hz
        return out

    @property
    def elpd(self) -> float:
        return float(np.sum(self.pointwise_elpd))

    @property
    def elpd_se(self) -> float:
        return float(math.sqrt(self.n * np.var(self.pointwise_elpd)))

    def to_dict(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "inside90": int(self.inside(0.9).sum()),
            "inside50": int(self.inside(0.5).sum()),
            "mean_abs_error": self.mean_abs_error,
            "median_half_width90": float(np.median(self.half_width)),
            "elpd_loo": self.elpd,
            "elpd_loo_se": self.elpd_se,
            "max_pareto_k": float(np.max(self.pareto_k)),
            "data": [
                {
                    "label": lab,
                    "measured_hz": float(y),
                    **{f"q{round(100 * q):02d}_hz": float(v) for q, v in zip(LOO_QUANTILES, qs)},
                    "pareto_k": float(k),
                }
                for lab, y, qs, k in zip(self.labels, self.measured_hz, self.quantiles_hz, self.pareto_k)
            ],
        }

    def summary_line(self) -> str:
        """One sentence with the headline numbers."""
        return (
            f"leave-one-out (PSIS): {self.inside(0.9).sum()}/{self.n} measured values inside their 90 % band "
            f"({self.inside(0.5).sum()}/{self.n} in the 50 %), median half-width of the 90 % band "
            f"{100 * np.median(self.half_width):.1f} %, mean error of the median {100 * self.mean_abs_error:.1f} %, "
            f"elpd_loo {self.elpd:.1f} +- {self.elpd_se:.1f}, max Pareto k {np.max(self.pareto_k):.2f}"
            + (" (above 0.7: unreliable there)" if np.max(self.pareto_k) > PARETO_K_LIMIT else "")
        )

    def table(self, *, summary: bool = True) -> str:
        """The per-datum table (pose, measured, 5/50/95 %, error, Pareto k), under :meth:`summary_line` unless
        ``summary`` is false (where the caller gives that line itself)."""
        lines = [
            *([self.summary_line()] if summary else []),
            f"{'datum':<34} {'measured':>9} {'5 %':>7} {'50 %':>7} {'95 %':>7} {'error':>7} {'k':>5}",
        ]
        for i, lab in enumerate(self.labels):
            lab = lab[lab.find("(") :] if "(" in lab else lab  # the pose, without the file name
            q = self.quantiles_hz[i]
            flag = "" if self.inside(0.9)[i] else "  outside 90 %"
            lines.append(
                f"{lab[:34]:<34} {self.measured_hz[i]:>9.1f} {q[0]:>7.1f} {q[2]:>7.1f} {q[4]:>7.1f} "
                f"{100 * self.relative_error[i]:>+6.1f}% {self.pareto_k[i]:>5.2f}{flag}"
            )
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Leave-one-out median and 50/90 % bands against the measured values."""
        import matplotlib.pyplot as plt

        fig = ax.figure if ax is not None else plt.figure(figsize=(6.5, 5.5))
        ax = ax if ax is not None else fig.add_subplot(111)
        bands_against_measured(
            ax,
            self.measured_hz,
            self.quantiles_hz.T,
            what="leave-one-out",
            colour="tab:green",
            ylabel="predicted without that datum (Hz)",
            title=f"leave-one-out predictions (PSIS; {self.inside(0.9).sum()}/{self.n} inside 90 %)",
        )
        return fig


def mixture_quantiles(mu: np.ndarray, sd: np.ndarray, w: np.ndarray, levels: Sequence[float]) -> np.ndarray:
    """``(len(levels), n_poses)`` quantiles, per pose, of the Gaussian mixture over the components ``(n_draws,
    n_poses, n_components)`` (means, sds, weights; NaN components left out, weights renormalised per pose), by
    bisection to round-off; NaN where a pose has no component."""
    from scipy.special import ndtr

    ok = np.isfinite(mu) & np.isfinite(sd) & np.isfinite(w) & (w > 0)
    ww = np.where(ok, w, 0.0)
    tot = ww.sum(axis=(0, 2))
    ww = ww / np.where(tot > 0, tot, 1.0)[None, :, None]
    m, s = np.where(ok, mu, 0.0), np.where(ok, sd, 1.0)
    lo = np.where(ok, m - 12 * s, np.inf).min(axis=(0, 2))
    hi = np.where(ok, m + 12 * s, -np.inf).max(axis=(0, 2))
    out = np.full((len(levels), mu.shape[1]), np.nan)
    has = tot > 0
    for j, q in enumerate(levels):
        a, b = np.where(has, lo, 0.0), np.where(has, hi, 0.0)  # poses without a component: left NaN below
        for _ in range(80):
            x = 0.5 * (a + b)
            p = np.sum(ww * ndtr((x[None, :, None] - m) / s), axis=(0, 2))
            below = p < q
            a = np.where(below, x, a)
            b = np.where(below, b, x)
        out[j, has] = 0.5 * (a + b)[has]
    return out


def leave_one_out(
    f_hz: np.ndarray,
    measured_hz: np.ndarray,
    sigma_hz: np.ndarray,
    discrepancy_rel: np.ndarray,
    *,
    features: np.ndarray | None = None,
    length_scale_m: np.ndarray | None = None,
    labels: list[str] | None = None,
) -> LeaveOneOut:
    """PSIS leave-one-out predictive of every datum of a posterior (module docstring).

    Parameters
    ----------
    f_hz
        ``(n_draws, n)`` each equal-weight draw's model frequency at each datum (Hz).
    measured_hz, sigma_hz
        ``(n,)`` the data and their measurement sd (Hz).
    discrepancy_rel
        ``(n_draws,)`` each draw's relative discrepancy sd ``d``.
    features, length_scale_m
        For a Gaussian-process discrepancy: the data's pose features ``(n, 3)``
        (:func:`fpm_sim.study.discrepancy.pose_features`) and each draw's correlation length ``(n_draws,)`` (m).
    labels
        The data's names.
    """
    f = np.asarray(f_hz, float)
    y = np.asarray(measured_hz, float)
    sig = np.asarray(sigma_hz, float)
    d = np.asarray(discrepancy_rel, float)
    n_draws, n = f.shape
    if y.shape != (n,) or sig.shape != (n,) or d.shape != (n_draws,):
        raise FpmSimError(
            f"shapes do not agree: f {f.shape}, measured {y.shape}, sigma {sig.shape}, discrepancy {d.shape}",
            parameter="f_hz",
        )
    if n_draws < 10 or not np.isfinite(f).all():
        raise FpmSimError(
            "needs at least 10 draws with a finite frequency at every datum",
            parameter="f_hz",
            value=f"{n_draws} draws",
        )
    mean = np.zeros_like(f)
    sd = np.sqrt(sig[None] ** 2 + (d[:, None] * f) ** 2)
    if length_scale_m is not None:
        if features is None:
            raise FpmSimError("a correlation length needs the data's pose features", parameter="features")
        ls = np.asarray(length_scale_m, float)
        for s in range(n_draws):
            cov = covariance(f[s], sig, features, float(d[s]), float(ls[s]))
            mean[s], sd[s] = loo_conditionals(y - f[s], cov)
    return loo_from_components((f + mean)[..., None], sd[..., None], np.ones((n_draws, n, 1)), y, labels=labels)


def loo_from_components(
    means_hz: np.ndarray,
    sds_hz: np.ndarray,
    weights: np.ndarray,
    measured_hz: np.ndarray,
    *,
    labels: list[str] | None = None,
) -> LeaveOneOut:
    """PSIS leave-one-out from each draw's leave-one-out predictive of every datum given as a Gaussian mixture.

    Parameters
    ----------
    means_hz, sds_hz, weights
        ``(n_draws, n, n_components)``: for draw ``s`` and datum ``i``, ``p(y_i | y_-i, theta_s) = sum_c
        w_sic N(y_i | mean_sic, sd_sic^2)`` (weights summing to 1 over ``c``).
    measured_hz
        ``(n,)`` the data.
    labels
        The data's names.
    """
    import arviz as az
    from scipy.stats import norm

    y = np.asarray(measured_hz, float)
    mu, sd, wc = (np.asarray(a, float) for a in (means_hz, sds_hz, weights))
    n = y.size
    with np.errstate(divide="ignore"):
        loglik = np.log(np.sum(wc * norm.pdf(y[None, :, None], mu, sd), axis=-1))  # (n_draws, n)
    psis = np.zeros_like(loglik)  # (n_draws, n): each datum's normalised importance weights
    elpd = np.zeros(n)
    kk = np.zeros(n)
    for i in range(n):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # arviz warns about k > 0.7: reported in pareto_k instead
            lw, k = az.psislw(-loglik[:, i])
        lw = np.asarray(lw, float)
        w = np.exp(lw - np.max(lw))
        w /= w.sum()
        kk[i] = float(k)
        top = float(np.max(loglik[:, i]))
        elpd[i] = float(np.log(np.sum(w * np.exp(loglik[:, i] - top))) + top)
        psis[:, i] = w
    q = mixture_quantiles(mu, sd, psis[:, :, None] * wc, LOO_QUANTILES)  # (5, n)
    return LeaveOneOut(
        labels=list(labels) if labels is not None else [f"datum {i}" for i in range(n)],
        measured_hz=y,
        quantiles_hz=q.T,
        pointwise_elpd=elpd,
        pareto_k=kk,
    )
