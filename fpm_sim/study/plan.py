"""Test planning: which measurements would narrow the posterior's bands most, before the lab day (issue 30).

The posterior's equal-weight draws ``theta_s`` (``s = 1..S``) are pushed through the pose loop once, at every
candidate pose and every target pose. A candidate measurement (a pose and the modes it reads: f1, f1 and f2
(``f1+f2``), or f1..f3) has, under draw ``s``, the calibration's own likelihood: each measured frequency is
``N(f_s (1 + shift_s), sigma^2 + (d_s f_s)^2)`` with ``d_s`` the draw's model discrepancy and ``sigma`` the
measurement's sd (:meth:`fpm_sim.study.calibrate.CalibrationProblem.noise_sd`); a draw that cannot reach the
pose has likelihood 0 there.

A candidate may instead *read* a mode it does not label (the readout model, :mod:`fpm_sim.study.readout`): the
first clear peak of a hammer test at one accelerometer point and axis is mode ``k`` with probability
``p_{s,k}`` under draw ``s`` (:attr:`Ensemble.cand_read_weight`), so its one measured value has the mixture
likelihood ``sum_k p_{s,k} N(y; f_{s,k} (1 + shift_s), sigma^2 + (d_s f_{s,k})^2)``, and an outcome picks the
draw, then the mode with ``p_{s,k}``, then the noise.

The value of a set of measurements is the expected spread of the target after them (Lindley's expected
utility of an experiment, estimated by Monte Carlo over the posterior predictive):

1. an outcome ``m`` picks a draw ``s_m`` uniformly (the posterior predictive: the outcome is what the machine of
   draw ``s_m`` would give) and simulates every measurement of the set from it with fixed standard-normal numbers
   (common random numbers: every set is scored on the same outcomes, so the ranking does not depend on noise
   between candidates);
2. the posterior after the outcome is the draws re-weighted by the outcome's likelihood (importance
   re-weighting); its Kish effective sample size ``(sum w)^2 / sum w^2`` is reported;
3. the target's spread is evaluated under the weights, and averaged over the outcomes.

Targets:

- ``band``: the relative half-width of the 90 % predictive band of frequency ``mode`` at each target pose
  (``(q95 - q05) / (2 q50)`` of the mixture over draws of ``f_s (1 + shift_s + d_s z)``, ``z`` at
  :data:`Z_POINTS` stratified normal quantiles per draw), its median over the target poses;
- ``requirement``: the binary entropy (bits) of the probability that frequency ``mode`` is at least ``f_min_hz``
  at each target pose, its mean over the poses (how undecided pass/fail is).

Where re-weighting collapses (an outcome's effective sample size below ``ess_min``: the measurement would
select fewer draws than can carry a band), that outcome's update falls back to the Bayes-linear update of the
draws' ensemble (the ensemble Kalman update: the target's mean and variance after a linear-Gaussian update by
the measurements' covariance with it, the band then the Gaussian's), and the plan counts and states every such
outcome. Re-sampling with new model solves per outcome would be exact and costs a pose loop per outcome. A read
enters that update as one value with its mixture's mean and variance under each draw.

A set of ``k`` measurements is chosen greedily: at each step the candidate that lowers the set's expected target
spread most is added (the greedy choice is within ``1 - 1/e`` of the best set for submodular gains, and is the
standard sequential design of the field).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import ndtr, ndtri

from fpm_sim.errors import FpmSimError

__all__ = [
    "BAND_Z",
    "QUANTITIES",
    "Z_POINTS",
    "Ensemble",
    "Greedy",
    "PlanError",
    "PlanStep",
    "Score",
    "band_half_widths",
    "greedy_plan",
    "score_set",
    "target_spread",
]

QUANTITIES: dict[str, tuple[int, ...]] = {"f1": (1,), "f1+f2": (1, 2), "f1..f3": (1, 2, 3)}
"""The quantities a candidate measurement can read at its pose, by name: the modes an experimental modal analysis
labels there (sorted order)."""

Z_POINTS = 16
"""Stratified standard-normal points per draw for the target's band (the midpoints of 16 equal-probability
strata): the mixture's 5 % and 95 % points move by well under 1 % of the band between 16 and 64 points when
there are 100+ draws (each quantile is then a mixture of hundreds of points)."""

LEVELS = (0.05, 0.5, 0.95)
BAND_Z = float(ndtri(0.95))  # the 90 % band's half-width in sd of a Gaussian (Bayes-linear fallback)


class PlanError(FpmSimError):
    """Bad planning input: candidates, target, sigma or the number of measurements."""


@dataclass(frozen=True)
class Ensemble:
    """The draws' predictions the plan needs (SI units; ``S`` draws, ``C`` candidates, ``T`` target poses).

    Attributes
    ----------
    cand_hz
        ``(S, C, J)`` each draw's model frequency of the measured modes at each candidate (its ``J`` slots; NaN
        where the draw cannot reach the pose; unused slots of a candidate reading fewer modes are ignored).
    cand_used
        ``(C, J)`` which slots each candidate measures.
    cand_shift, cand_disc
        ``(S, C)`` the discrepancy's relative shift and sd at each candidate pose under each draw.
    sigma_rel
        The measurement's sd, relative to the frequency.
    target_hz, target_shift, target_disc
        ``(S, T)`` each draw's target frequency, and the discrepancy's shift and relative sd there.
    f_min_hz
        ``(T,)`` the requirement's level at each target pose (the ``requirement`` target), else ``None``.
    cand_read_weight
        ``(S, C, J)`` for a candidate that reads the first clear peak (one value, its mode unlabelled): the
        probability that the peak is each used slot's mode under each draw (summing to 1 over the used slots);
        NaN for a candidate that labels its modes. ``None``: no candidate reads.
    """

    cand_hz: np.ndarray
    cand_used: np.ndarray
    cand_shift: np.ndarray
    cand_disc: np.ndarray
    sigma_rel: float
    target_hz: np.ndarray
    target_shift: np.ndarray
    target_disc: np.ndarray
    f_min_hz: np.ndarray | None = None
    cand_read_weight: np.ndarray | None = None
    _sorted: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_rel) and self.sigma_rel > 0):
            raise PlanError("must be > 0", parameter="sigma_rel", value=self.sigma_rel, hint="the measurement's sd")
        if self.target_hz.shape[1] == 0:
            raise PlanError("no target poses", parameter="target", hint="give at least one pose to predict at")
        if self.cand_hz.shape[1] == 0:
            raise PlanError("no candidate measurements", parameter="candidates", hint="give at least one pose")

    @property
    def n_draws(self) -> int:
        return int(self.cand_hz.shape[0])

    @property
    def n_candidates(self) -> int:
        return int(self.cand_hz.shape[1])

    def is_read(self, c: int) -> bool:
        """Whether candidate ``c`` reads the first clear peak (:attr:`cand_read_weight`)."""
        return self.cand_read_weight is not None and bool(np.isfinite(self.cand_read_weight[:, c]).any())

    def means(self) -> np.ndarray:
        """``(S, C, J)`` the measured frequencies' means under each draw."""
        out: np.ndarray = self.cand_hz * (1.0 + self.cand_shift[:, :, None])
        return out

    def sds(self) -> np.ndarray:
        """``(S, C, J)`` the measured frequencies' sd under each draw (measurement and discrepancy)."""
        f = self.cand_hz
        out: np.ndarray = np.sqrt((self.sigma_rel * f) ** 2 + (self.cand_disc[:, :, None] * f) ** 2)
        return out

    def target_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The band target's predictive points sorted per target pose: ``(values (T, S*Q), draw (T, S*Q))``
        (NaN values of unreachable draws sorted last)."""
        if self._sorted is None:
            q = (np.arange(Z_POINTS) + 0.5) / Z_POINTS
            z = ndtri(q)
            g = self.target_hz[:, :, None] * (1.0 + self.target_shift[:, :, None] + self.target_disc[:, :, None] * z)
            s, t = self.target_hz.shape
            vals = np.transpose(g, (1, 0, 2)).reshape(t, s * Z_POINTS)
            order = np.argsort(vals, axis=1, kind="stable")  # NaN last
            draw = np.repeat(np.arange(s), Z_POINTS)[order]
            object.__setattr__(self, "_sorted", (np.take_along_axis(vals, order, axis=1), draw))
        assert self._sorted is not None
        return self._sorted


def target_spread(ens: Ensemble, weights: np.ndarray, mode: str = "band") -> np.ndarray:
    """The target's spread under each row of ``weights`` (``(M, S)``, >= 0): for ``band`` the median over target
    poses of the 90 % band's relative half-width, for ``requirement`` the mean binary entropy (bits) of the
    pass probability. Returns ``(M,)``."""
    w = np.atleast_2d(np.asarray(weights, float))
    if mode == "requirement":
        return _entropy_spread(ens, w)
    out: np.ndarray = np.nanmedian(band_half_widths(ens, w), axis=1)
    return out


def band_half_widths(ens: Ensemble, w: np.ndarray) -> np.ndarray:
    """``(M, T)`` the 90 % band's relative half-width ``(q95 - q05) / (2 q50)`` at each target pose under each row
    of weights ``w`` (``(M, S)``): the weighted quantiles of the draws' predictive points (NaN where no draw with
    weight reaches the pose)."""
    vals, draw = ens.target_samples()
    wt = w[:, draw]  # (M, T, S*Q): each point carries its draw's weight
    wt = np.where(np.isfinite(vals)[None], wt, 0.0)
    cw = np.cumsum(wt, axis=2)
    tot = cw[:, :, -1:]
    qs = []
    for lev in LEVELS:
        idx = np.minimum((cw < lev * tot).sum(axis=2), vals.shape[1] - 1)
        qs.append(np.take_along_axis(np.broadcast_to(vals, wt.shape), idx[:, :, None], axis=2)[:, :, 0])
    q05, q50, q95 = qs
    with np.errstate(invalid="ignore", divide="ignore"):
        half: np.ndarray = np.where(tot[:, :, 0] > 0, (q95 - q05) / (2.0 * q50), np.nan)
    return half


def _entropy_spread(ens: Ensemble, w: np.ndarray) -> np.ndarray:
    if ens.f_min_hz is None:
        raise PlanError("the requirement target needs its level", parameter="f_min_hz", hint="give f_min_hz")
    f, sh, d = ens.target_hz, ens.target_shift, ens.target_disc
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = f * (1.0 + sh)
        z = (centre - ens.f_min_hz[None]) / (np.abs(f) * d)
        above = np.where(d > 0, ndtr(z), (centre >= ens.f_min_hz[None]).astype(float))
    ok = np.isfinite(f)
    p = (w @ np.where(ok, above, 0.0)) / np.maximum(w @ ok.astype(float), 1e-300)
    return np.mean(_bits(p), axis=1)


def _bits(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 1e-15, 1 - 1e-15)
    out: np.ndarray = -(p * np.log2(p) + (1 - p) * np.log2(1 - p))
    return out


@dataclass(frozen=True)
class Outcomes:
    """The simulated outcomes shared by every set: the draw each outcome comes from, and its normal numbers."""

    draw: np.ndarray
    """``(M,)`` the draw of each outcome."""
    z: np.ndarray
    """``(M, C, J)`` standard-normal numbers, one per outcome, candidate and slot."""
    pick: np.ndarray | None = None
    """``(M, C)`` uniform numbers that pick the mode a read candidate's peak is (``None``: no candidate reads)."""

    @classmethod
    def make(cls, ens: Ensemble, n: int, seed: int) -> Outcomes:
        if n < 2:
            raise PlanError("must be >= 2", parameter="outcomes", value=n, hint="64 outcomes are typical")
        rng = np.random.default_rng(seed)
        draw = rng.integers(0, ens.n_draws, size=n)
        z = rng.standard_normal((n, *ens.cand_hz.shape[1:]))
        pick = None if ens.cand_read_weight is None else rng.random((n, ens.n_candidates))  # after z: same z
        return cls(draw, z, pick)


@dataclass(frozen=True)
class Score:
    """The expected outcome of measuring a set: the target's spread after it, and the re-weighting's health."""

    spread: float
    """The expected target spread after the set (mean over outcomes; NaN when no outcome is possible)."""
    spread_sd: float
    """The Monte Carlo sd of that mean (over outcomes)."""
    ess_median: float
    ess_min: float
    collapsed: int
    """Outcomes whose re-weighting collapsed (effective sample size below the threshold): Bayes-linear update."""
    n_outcomes: int


def _log_terms(ens: Ensemble, c: int, out: Outcomes, mu: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """``(M, S)`` the log-likelihood of every draw for candidate ``c``'s simulated outcomes (``-inf`` for a draw
    that cannot reach the pose, or whose outcome draw cannot: such outcomes get no weight at all)."""
    if ens.is_read(c):
        return _read_log_terms(ens, c, out, mu, sd)
    used = ens.cand_used[c]
    m_s, sd_s = mu[:, c, used], sd[:, c, used]  # (S, j)
    y = m_s[out.draw] + sd_s[out.draw] * out.z[:, c, used]  # (M, j)
    r = (y[:, None, :] - m_s[None]) / sd_s[None]
    ll = -0.5 * r**2 - np.log(sd_s[None])
    ll = np.where(np.isfinite(ll), ll, -np.inf).sum(axis=2)
    out_ll: np.ndarray = np.where(np.isfinite(y).all(axis=1)[:, None], ll, np.nan)  # unreachable outcome: NaN row
    return out_ll


def _read_values(ens: Ensemble, c: int, out: Outcomes, mu: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """``(M,)`` read candidate ``c``'s simulated values: the outcome's draw, then the mode its peak is (by the
    draw's read probabilities and the outcome's uniform number), then the noise (that slot's normal number)."""
    assert ens.cand_read_weight is not None
    assert out.pick is not None
    used = np.flatnonzero(ens.cand_used[c])
    p = np.nan_to_num(ens.cand_read_weight[out.draw][:, c, used])  # (M, j)
    k = np.minimum((np.cumsum(p, axis=1) < out.pick[:, c, None]).sum(axis=1), len(used) - 1)
    slot = used[k]
    rows = np.arange(len(out.draw))
    y: np.ndarray = mu[out.draw, c, slot] + sd[out.draw, c, slot] * out.z[rows, c, slot]
    return y


def _read_log_terms(ens: Ensemble, c: int, out: Outcomes, mu: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """:func:`_log_terms` of a read candidate: ``log sum_k p_{s,k} N(y; mu_{s,k}, sd_{s,k})`` (the same
    normalisation as a labelled slot's, so a read certain of one mode scores exactly as that mode labelled)."""
    assert ens.cand_read_weight is not None
    used = ens.cand_used[c]
    y = _read_values(ens, c, out, mu, sd)  # (M,)
    m_s, sd_s = mu[:, c, used], sd[:, c, used]  # (S, j)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (y[:, None, None] - m_s[None]) / sd_s[None]
        lp = np.log(ens.cand_read_weight[:, c, used])[None] - 0.5 * r**2 - np.log(sd_s[None])  # (M, S, j)
    lp = np.where(np.isfinite(lp), lp, -np.inf)
    top = lp.max(axis=2)
    safe = np.where(np.isfinite(top), top, 0.0)
    ll = np.where(np.isfinite(top), safe + np.log(np.exp(lp - safe[:, :, None]).sum(axis=2)), -np.inf)
    out_ll: np.ndarray = np.where(np.isfinite(y)[:, None], ll, np.nan)
    return out_ll


def _columns(
    ens: Ensemble, c: int, out: Outcomes, mu: np.ndarray, sd: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Candidate ``c``'s measured values for the Bayes-linear update: per value its draws' means ``(S,)`` and
    sds ``(S,)`` and the outcomes' simulated values ``(M,)``. A read is one value, its moments the mixture's
    (mean ``sum_k p_k mu_k``, variance ``sum_k p_k (sd_k^2 + (mu_k - mean)^2)``: a read certain of one mode is
    exactly that mode's value)."""
    if not ens.is_read(c):
        return [(mu[:, c, j], sd[:, c, j], mu[out.draw, c, j] + sd[out.draw, c, j] * out.z[:, c, j])
                for j in np.flatnonzero(ens.cand_used[c])]  # fmt: skip
    assert ens.cand_read_weight is not None
    used = ens.cand_used[c]
    p, m, s = ens.cand_read_weight[:, c, used], mu[:, c, used], sd[:, c, used]
    mean = (p * m).sum(axis=1)
    var = (p * (s**2 + (m - mean[:, None]) ** 2)).sum(axis=1)
    return [(mean, np.sqrt(var), _read_values(ens, c, out, mu, sd))]


def score_set(
    ens: Ensemble,
    log_w: np.ndarray,
    out: Outcomes,
    *,
    mode: str = "band",
    ess_min: float = 20.0,
    members: Sequence[int] = (),
) -> Score:
    """Score the set whose outcomes' summed log-likelihoods are ``log_w`` (``(M, S)``; NaN rows: outcomes the
    set cannot produce, left out). ``members``: its candidates (for the Bayes-linear fallback)."""
    keep = np.isfinite(log_w).any(axis=1) & ~np.isnan(log_w).any(axis=1)
    if not keep.any():
        return Score(math.nan, math.nan, 0.0, 0.0, 0, 0)
    lw = log_w[keep]
    w = np.exp(lw - lw.max(axis=1, keepdims=True))
    ess = w.sum(axis=1) ** 2 / (w**2).sum(axis=1)
    spread = target_spread(ens, w, mode)
    bad = ess < ess_min
    if bad.any():
        spread[bad] = _bayes_linear(ens, members, out.draw[keep][bad], out, keep, bad, mode)
    m = len(spread)
    sd = float(np.std(spread, ddof=1) / math.sqrt(m)) if m > 1 else math.nan
    return Score(float(np.mean(spread)), sd, float(np.median(ess)), float(ess.min()), int(bad.sum()), m)


def _bayes_linear(
    ens: Ensemble,
    members: Sequence[int],
    draws: np.ndarray,
    out: Outcomes,
    keep: np.ndarray,
    bad: np.ndarray,
    mode: str,
) -> np.ndarray:
    """The target spread after a linear-Gaussian (ensemble Kalman) update of the draws' ensemble by the set's
    measurements, for the collapsed outcomes (their measured values enter through the updated mean).

    Per target pose, over the draws that reach it and every measured pose: the update's variance and mean
    (``var - C_gy C_yy^-1 C_yg``, ``mean + C_gy C_yy^-1 (y - E y)``). A band target keeps its quantile band and
    scales it by the update (half-width times ``sqrt(var_after / var_now) mean_now / mean_after``), so that a
    collapsed outcome is scored on the same footing as a re-weighted one; a requirement target takes the
    Gaussian's pass probability."""
    mu, sd = ens.means(), ens.sds()
    cols = [col for c in members for col in _columns(ens, c, out, mu, sd)]
    y_s = np.stack([col[0] for col in cols], axis=1)  # (S, n)
    noise = np.stack([col[1] for col in cols], axis=1)
    ok_y = np.isfinite(y_s).all(axis=1)
    g = ens.target_hz * (1.0 + ens.target_shift)  # (S, T) the draws' target means
    valid = ok_y[:, None] & np.isfinite(g)  # (S, T)
    n_t = np.maximum(valid.sum(axis=0), 2)
    gz = np.where(valid, g, 0.0)
    g_mean = gz.sum(axis=0) / n_t
    y_mean = y_s[ok_y].mean(axis=0)
    dy = np.where(ok_y[:, None], y_s - y_mean, 0.0)
    dg = np.where(valid, g - g_mean, 0.0)
    var_in = np.where(valid, (ens.target_hz * ens.target_disc) ** 2, 0.0).sum(axis=0) / n_t
    var_now = (dg**2).sum(axis=0) / (n_t - 1) + var_in
    cy = np.atleast_2d(np.cov(y_s[ok_y], rowvar=False)) + np.diag(np.mean(noise[ok_y] ** 2, axis=0))
    cgy = dg.T @ dy / (n_t - 1)[:, None]  # (T, n)
    gain = np.linalg.solve(cy, cgy.T)  # (n, T)
    var = np.maximum(var_now - np.einsum("tn,nt->t", cgy, gain), 0.0)
    idx = np.flatnonzero(keep)[bad]
    y_obs = np.stack([col[2][idx] for col in cols], axis=1)  # (B, n) the collapsed outcomes' simulated values
    mean = g_mean[None] + (y_obs - y_mean[None]) @ gain  # (B, T)
    if mode == "requirement":
        assert ens.f_min_hz is not None
        p = ndtr((mean - ens.f_min_hz[None]) / np.sqrt(np.maximum(var, 1e-300))[None])
        result: np.ndarray = np.mean(_bits(p), axis=1)
        return result
    half_now = band_half_widths(ens, np.ones((1, ens.n_draws)))[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        half = half_now[None] * np.sqrt(var / var_now)[None] * (g_mean[None] / mean)
    result = np.nanmedian(half, axis=1)
    return result


@dataclass(frozen=True)
class PlanStep:
    """One step of the greedy plan: the candidate added and the set's score after it."""

    candidate: int
    score: Score


@dataclass(frozen=True)
class Greedy:
    """What :func:`greedy_plan` found."""

    before: Score
    """The target's spread now."""
    singles: list[Score]
    """Every candidate's score alone (spread NaN for a candidate the screening left out)."""
    steps: list[PlanStep]
    """The greedy set, in order, each with the set's score up to it."""
    screening: np.ndarray | None
    """``(C + 1,)`` every candidate's screening estimate of its spread alone (the band's moments), and last the
    estimate with no measurement, when the candidates were screened (more than ``screen`` of them, band target);
    else ``None``."""


def greedy_plan(
    ens: Ensemble,
    k: int,
    *,
    outcomes: int = 64,
    seed: int = 0,
    mode: str = "band",
    ess_min: float = 20.0,
    screen: int = 40,
) -> Greedy:
    """The target's spread now, every single candidate's score, and the greedy set of ``k`` measurements (a
    candidate is chosen at most once). The same simulated outcomes score every set.

    ``screen``: with more candidates than this and a band target, every candidate is first scored by the band's
    moments under its weights (the predictive mean and sd, two matrix products per candidate: a dense grid's
    thousands of candidates in seconds), and the ``screen`` best (at least ``k``) are scored and chosen from with
    the quantile band."""
    if not 1 <= k <= ens.n_candidates:
        raise PlanError(f"must be 1..{ens.n_candidates} (the number of candidate measurements)", parameter="k", value=k)
    if not ess_min >= 1:
        raise PlanError("must be >= 1", parameter="ess_min", value=ess_min)
    if screen < 1:
        raise PlanError("must be >= 1", parameter="screen", value=screen)
    out = Outcomes.make(ens, outcomes, seed)
    mu, sd = ens.means(), ens.sds()
    now = target_spread(ens, np.ones((1, ens.n_draws)), mode)[0]
    before = Score(float(now), 0.0, float(ens.n_draws), float(ens.n_draws), 0, 1)
    screening = None
    shortlist = list(range(ens.n_candidates))
    if mode == "band" and ens.n_candidates > max(screen, k):
        screening = _screening(ens, out, mu, sd)
        order = np.argsort(np.where(np.isnan(screening[:-1]), np.inf, screening[:-1]), kind="stable")
        shortlist = sorted(int(c) for c in order[: max(screen, k)])
    terms = {c: _log_terms(ens, c, out, mu, sd) for c in shortlist}
    nan = Score(math.nan, math.nan, 0.0, 0.0, 0, 0)
    singles = [nan] * ens.n_candidates
    for c in shortlist:
        singles[c] = score_set(ens, terms[c], out, mode=mode, ess_min=ess_min, members=[c])
    chosen: list[PlanStep] = []
    acc = np.zeros((outcomes, ens.n_draws))
    for step in range(k):
        picked = {p.candidate for p in chosen}
        scores = {
            c: singles[c]
            if step == 0
            else score_set(
                ens, acc + terms[c], out, mode=mode, ess_min=ess_min, members=[p.candidate for p in chosen] + [c]
            )
            for c in shortlist
            if c not in picked
        }
        best = min(scores, key=lambda c: (math.inf if math.isnan(scores[c].spread) else scores[c].spread, c))
        chosen.append(PlanStep(best, scores[best]))
        acc = acc + terms[best]
    return Greedy(before, singles, chosen, screening)


def _screening(ens: Ensemble, out: Outcomes, mu: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """``(C + 1,)`` each candidate's expected band half-width alone from the weighted moments of the target's
    predictive (``1.645 sd / mean`` per target pose, the median over poses, the mean over outcomes), and last the
    same with no measurement (the baseline its gains are taken from)."""
    first, second, count = _moment_parts(ens)
    res = np.full(ens.n_candidates + 1, np.nan)
    res[-1] = _moment_spread(np.ones((1, ens.n_draws)), first, second, count)
    for c in range(ens.n_candidates):
        lw = _log_terms(ens, c, out, mu, sd)
        lw = lw[np.isfinite(lw).any(axis=1) & ~np.isnan(lw).any(axis=1)]
        if len(lw):
            res[c] = _moment_spread(np.exp(lw - lw.max(axis=1, keepdims=True)), first, second, count)
    return res


def _moment_parts(ens: Ensemble) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(S, T)`` each draw's predictive first and second moments at each target pose (0 where it has none), and
    where it has one."""
    g = ens.target_hz * (1.0 + ens.target_shift)
    ok = np.isfinite(g)
    first = np.where(ok, g, 0.0)
    second = np.where(ok, g**2 + (ens.target_hz * ens.target_disc) ** 2, 0.0)
    return first, second, ok.astype(float)


def _moment_spread(w: np.ndarray, first: np.ndarray, second: np.ndarray, count: np.ndarray) -> float:
    """The mean over the rows of weights ``w`` of the median over target poses of ``1.645 sd / mean``."""
    n = w @ count
    with np.errstate(invalid="ignore", divide="ignore"):
        m1 = (w @ first) / n
        var = np.maximum((w @ second) / n - m1**2, 0.0)
        return float(np.mean(np.nanmedian(BAND_Z * np.sqrt(var) / m1, axis=1)))


def describe_candidates(modes: Sequence[tuple[int, ...]]) -> np.ndarray:
    """``(C, J)`` the slots each candidate uses, from each candidate's modes (1-based)."""
    j = max(max(m) for m in modes)
    used = np.zeros((len(modes), j), bool)
    for c, m in enumerate(modes):
        used[c, [k - 1 for k in m]] = True
    return used


def jsonable_score(s: Score) -> dict[str, Any]:
    """A score as JSON-ready values."""
    return {
        "expected_spread": s.spread,
        "expected_spread_mc_sd": s.spread_sd,
        "ess_median": s.ess_median,
        "ess_min": s.ess_min,
        "collapsed_outcomes": s.collapsed,
        "outcomes": s.n_outcomes,
    }
