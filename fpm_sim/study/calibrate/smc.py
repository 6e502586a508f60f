"""Adaptive tempered sequential Monte Carlo (Del Moral, Doucet & Jasra 2006) on the unit cube, and the calibration's
two-stage use of it.

A target ``pi(u) L_a(u) L_b(u)^beta`` over the unit cube (the prior is uniform there: a calibration problem's prior
transform maps it to the parameters) is reached from ``pi(u) L_a(u)`` by raising ``beta`` from 0 to 1 in steps
chosen so that the incremental weights ``L_b^{d beta}`` keep an effective sample size of ``ess_fraction`` of the
particles (Jasra et al. 2011); after each step the particles are resampled (systematic) and moved by Metropolis
steps that leave the current tempered target invariant. The moves are differential-evolution proposals (ter Braak
2006): ``u' = u + gamma (u_a - u_b)`` with ``a, b`` two other particles of the population frozen at the start of the
sweep (symmetric, so the Metropolis ratio is the targets'), folded back into the cube (a symmetric reflection);
``gamma = 2.38 / sqrt(2 d)`` scaled to keep the acceptance near a quarter. Sweeps continue until each particle
has had ``moves`` accepted moves on average (at most ``max_sweeps``). The modes' weights are carried by the
importance weights of the tempering, not by moves between modes: ter Braak's mode-jumping ``gamma = 1`` moves,
with the population just resampled (copies of the moved particle among ``a, b``), biased ln Z upwards by about
0.015 per tempering step on a two-mode mixture (measured; ``tests/study/test_calibrate_smc.py``), so they are not
used.

The evidence is the product of the mean incremental weights, ``Z_b = prod_t mean_i L_b(u_i)^{d beta_t}``
(unbiased for a fixed schedule); its stated error is Lee & Whiteley's (2018) estimate of ``var(Z_hat) / Z^2`` from
the particles' genealogy (each particle's ancestor at the start, multinomial resampling), which counts the
correlation the resampling and the moves leave, unlike a sum of the steps' importance-sampling variances
(measured against the spread of independent runs in the tests and in docs/identification.md).

The calibration (:func:`two_stage`) runs it twice per elbow-branch class: stage 1 from the prior to the prior times
the cheap part of the likelihood (the support, and the study's statements: closed-form kinematics, many particles),
stage 2 from there to the posterior on the data's likelihood (expensive, fewer particles subsampled from stage
1's). ``Z = Z_1 Z_2``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import logsumexp

from fpm_sim.study.calibrate.importance import importance_sample, kmeans_clusters

__all__ = [
    "ModeProposal", "SmcRun", "SmcSettings", "emulated_two_stage", "mean_evidence", "merge_smc", "metropolis",
    "smc_results", "spread_over_mode", "temper", "two_stage",
]  # fmt: skip

Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``U (n, d) -> (log L_a, log L_b)`` at the rows of ``U`` (``-inf`` outside the support)."""


@dataclass(frozen=True)
class SmcSettings:
    """One tempering's settings (module docstring)."""

    particles: int = 1000
    ess_fraction: float = 0.5
    moves: float = 3.0
    """Accepted Metropolis moves per particle (on average) after each tempering step."""
    max_sweeps: int = 40
    min_sweeps: int = 2
    final_moves: float = 0.0
    """Accepted moves per particle (on average) at ``beta = 1``, after the last tempering step: a rejuvenation that
    lets the particles travel along a posterior ridge the tempering's few moves per step left unevenly covered (the
    evidence is the tempering's, unchanged; the particles stay draws of the target, now less tied to where the
    tempering put them). 0: none."""
    jumps: float = 0.0
    """The fraction of the sweeps (every ``1 / jumps``-th) whose proposals are independent draws of a Gaussian mixture
    fitted to the population at the sweep's start (:func:`_population_mixture`) instead of differential-evolution
    steps: Metropolis-Hastings with the density's ratio, so the target stays invariant, and a particle can jump to a
    separate mode or a far stretch of a ridge in proportion to its posterior mass there, which the local moves never
    do (without them the modes' shares are those the tempering's resampling happened to leave). 0: none."""
    crossover: bool = False
    """Each move in a random subspace of the coordinates (:func:`_sweep`, DREAM's crossover); ``False``: all of them."""
    importance: int = 0
    """Independent draws of a mixture fitted to the particles at ``beta = 1``
    (:mod:`~fpm_sim.study.calibrate.importance`) whose importance weights give the evidence and the posterior instead
    of the tempering's (whose stated error misses the correlation the moves leave along a ridge); the data stage's
    setting. 0: none, the tempering's."""
    periodic: tuple[int, ...] = ()
    """Unit-cube coordinates whose two ends are one point (an angle over a whole turn): moves wrap around them, and
    the differential-evolution differences there are the shorter way round, so a mode across the seam is one mode."""


@dataclass
class SmcRun:
    """The particles at ``beta = 1`` (equal weights) and the run's evidence, as a calibration run reports it."""

    u: np.ndarray
    """``(n, d)`` unit-cube positions."""
    log_a: np.ndarray
    log_b: np.ndarray
    log_evidence: float
    log_evidence_var: float
    n_calls: int
    betas: list[float] = field(default_factory=list)
    acceptance: list[float] = field(default_factory=list)
    log_weights: np.ndarray | None = None
    """``(n,)`` the particles' normalised log importance weights (:func:`emulated_two_stage`); ``None``: equal."""
    importance: dict[str, float] | None = None
    """Where the evidence and the particles are importance sampling's (:attr:`SmcSettings.importance`): its draws,
    their effective sample size, Pareto ``k`` and the stated error of ``ln Z_emulated``."""

    @property
    def log_evidence_err(self) -> float:
        return math.sqrt(max(self.log_evidence_var, 0.0))


@dataclass(frozen=True)
class ModeProposal:
    """A mixture of Gaussians on the unit cube: around the modes a search found, equally weighted, the part of the
    data stage's starting population that is drawn near them (:func:`two_stage`, ``modes``); or fitted to a
    population, weighted by its clusters' sizes, a jump's proposal (:func:`_population_mixture`)."""

    means: np.ndarray
    """``(k, d)`` the modes."""
    covs: np.ndarray
    """``(k, d, d)`` each Gaussian's covariance."""
    log_weights: np.ndarray | None = None
    """``(k,)`` the Gaussians' normalised log weights; ``None``: equal."""

    @classmethod
    def around(cls, populations: list[np.ndarray], *, floor: float = 0.005) -> ModeProposal:
        """Kernels at the particles of each population (``(n_i, d)`` each, spread over one mode:
        :func:`spread_over_mode`): a Gaussian at each particle, of its population's covariance times Silverman's
        factor squared, plus ``floor`` squared per coordinate (a population that sits at one point still gives
        kernels of that width)."""
        means: list[np.ndarray] = []
        covs: list[np.ndarray] = []
        for pop in populations:
            n, d = pop.shape
            h2 = n ** (-2.0 / (d + 4))  # Silverman's rule, squared
            means.extend(pop)
            covs.extend([h2 * np.atleast_2d(np.cov(pop.T)) + floor**2 * np.eye(d)] * n)
        return cls(np.array(means), np.array(covs))

    @functools.cached_property
    def _chol(self) -> np.ndarray:
        """The covariances' Cholesky factors (once: :meth:`log_density` runs at every move of the data stage)."""
        out: np.ndarray = np.linalg.cholesky(self.covs)
        return out

    @functools.cached_property
    def _whiten(self) -> tuple[np.ndarray, np.ndarray]:
        """The inverse Cholesky factors ``(k, d, d)`` and each Gaussian's log-normaliser ``(k,)``."""
        chol = self._chol
        inv = np.linalg.inv(chol)
        d = self.means.shape[1]
        log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
        return inv, -0.5 * log_det - 0.5 * d * math.log(2.0 * math.pi)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, d)`` draws (the mixture's; those outside the cube are kept: the stage's density is 0 there)."""
        if self.log_weights is None:
            k = rng.integers(0, len(self.means), n)
        else:
            k = rng.choice(len(self.means), size=n, p=np.exp(self.log_weights))
        chol = self._chol
        z = rng.standard_normal((n, self.means.shape[1]))
        out: np.ndarray = self.means[k] + np.einsum("nij,nj->ni", chol[k], z)
        return out

    def log_density(self, u: np.ndarray, *, block: int = 256) -> np.ndarray:
        """``(n,)`` the mixture's log-density at the rows of ``u`` (``block`` rows at a time: ``n x k x d`` work
        arrays stay small with many Gaussians)."""
        inv, norm = self._whiten
        if self.log_weights is not None:
            norm = norm + self.log_weights
        out = np.empty(len(u))
        for i in range(0, len(u), block):
            diff = u[i : i + block, None, :] - self.means[None]  # (b, k, d)
            z = np.einsum("kij,bkj->bki", inv, diff)
            out[i : i + block] = logsumexp(-0.5 * np.sum(z**2, axis=-1) + norm[None], axis=1)
        return out if self.log_weights is not None else out - math.log(len(self.means))


def _fold(u: np.ndarray, periodic: tuple[int, ...] = ()) -> np.ndarray:
    """Reflect into [0, 1], or wrap around on the ``periodic`` coordinates (either a symmetric map of a symmetric
    proposal)."""
    v = np.mod(u, 2.0)
    out: np.ndarray = np.where(v > 1.0, 2.0 - v, v)
    if periodic:
        p = list(periodic)
        out[..., p] = np.mod(u[..., p], 1.0)
    return out


def _ess(logw: np.ndarray) -> float:
    if not np.any(np.isfinite(logw)):
        return 0.0
    w = np.exp(logw - np.max(logw))
    return float(w.sum() ** 2 / np.sum(w**2))


def _next_beta(beta: float, log_b: np.ndarray, target: float) -> float:
    """The largest step ``beta -> beta'`` (bisection, <= 1) whose incremental weights keep ``ESS >= target``."""
    if _ess((1.0 - beta) * log_b) >= target:
        return 1.0
    lo, hi = 0.0, 1.0 - beta
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _ess(mid * log_b) >= target:
            lo = mid
        else:
            hi = mid
    return beta + max(lo, 1e-12)


def _systematic(logw: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    w = np.exp(logw - np.max(logw))
    c = np.cumsum(w / w.sum())
    c[-1] = 1.0
    idx: np.ndarray = np.searchsorted(c, (rng.random() + np.arange(n)) / n)
    return idx


CROSSOVER = (1.0 / 3.0, 2.0 / 3.0, 1.0)
"""The crossover probabilities a subspace sweep draws from, one per particle (DREAM's ``n_CR = 3``)."""


def _sweep(
    u: np.ndarray, la: np.ndarray, lb: np.ndarray, beta: float, gamma: float, evaluate: Evaluate,
    rng: np.random.Generator, periodic: tuple[int, ...] = (), *, crossover: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """One differential-evolution Metropolis sweep of every particle (the population frozen at its start; on the
    ``periodic`` coordinates the differences the shorter way round, still symmetric in ``a, b``). ``crossover``:
    each particle moves in a random subspace (DREAM's randomised subspace sampling, Vrugt et al. 2009): every
    coordinate is in it with a probability drawn from :data:`CROSSOVER` (at least one is), and its step is ``gamma
    sqrt(d / d')`` for ``d'`` coordinates moved (``2.38 / sqrt(2 d')`` at ``scale`` 1). The subspace is drawn
    independently of the state, so the proposal stays symmetric; a coordinate the data leave loose then takes steps
    of its own width instead of the tight directions' (the as-built deviations, whose posteriors are their priors,
    yet whose medians three runs of the study placed 0.5-0.8 of their sd apart)."""
    n, d = u.shape
    a = rng.integers(0, n - 1, n)
    a = a + (a >= np.arange(n))  # a != i
    b = rng.integers(0, n - 2, n)
    lo, hi = np.minimum(a, np.arange(n)), np.maximum(a, np.arange(n))
    b = b + (b >= lo)
    b = b + (b >= hi)  # b != i, b != a
    jitter = 1e-6 * rng.standard_normal((n, d))
    diff = u[a] - u[b]
    if periodic:
        p = list(periodic)
        diff[:, p] = np.mod(diff[:, p] + 0.5, 1.0) - 0.5
    step = np.full((n, 1), gamma)
    if crossover:
        mask = rng.random((n, d)) < rng.choice(CROSSOVER, n)[:, None]
        empty = ~mask.any(axis=1)
        mask[empty, rng.integers(0, d, int(empty.sum()))] = True
        diff, jitter = diff * mask, jitter * mask
        step = gamma * np.sqrt(d / mask.sum(axis=1, keepdims=True))
    return metropolis(u, la, lb, beta, _fold(u + step * diff + jitter, periodic), evaluate, rng)


def metropolis(
    u: np.ndarray, la: np.ndarray, lb: np.ndarray, beta: float, prop: np.ndarray, evaluate: Evaluate,
    rng: np.random.Generator, *, log_q_ratio: np.ndarray | float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Each row's proposal ``prop`` accepted or not against ``pi L_a L_b^beta``: ``(u, log L_a, log L_b,
    accepted)``. ``log_q_ratio``: ``log q(u) - log q(prop)`` of an asymmetric proposal (Metropolis-Hastings); 0 for a
    symmetric one."""
    pa, pb = evaluate(prop)
    with np.errstate(invalid="ignore"):
        cur = la + beta * lb if beta > 0 else la
        new = pa + beta * pb if beta > 0 else pa
        log_r = np.where(np.isfinite(new), new - cur + log_q_ratio, -np.inf)
    acc = np.log(rng.random(len(u))) < log_r
    u, la, lb = u.copy(), la.copy(), lb.copy()
    u[acc], la[acc], lb[acc] = prop[acc], pa[acc], pb[acc]
    return u, la, lb, acc


def _jump(
    u: np.ndarray, la: np.ndarray, lb: np.ndarray, beta: float, evaluate: Evaluate, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """One independence Metropolis-Hastings sweep (:attr:`SmcSettings.jumps`): each particle proposes a draw of a
    Gaussian mixture ``q`` fitted to the population at the sweep's start (:func:`_population_mixture`, fixed during
    it) and accepts it with ``min(1, pi(u') q(u) / (pi(u) q(u')))``. A draw outside the cube has target 0 and is
    refused without a call."""
    q = _population_mixture(u, rng)
    prop = q.sample(len(u), rng)

    def inside_only(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        inside = np.all((x >= 0.0) & (x <= 1.0), axis=1)
        pa, pb = np.full(len(x), -math.inf), np.full(len(x), -math.inf)
        if inside.any():
            pa[inside], pb[inside] = evaluate(x[inside])
        return pa, pb

    return metropolis(u, la, lb, beta, prop, inside_only, rng, log_q_ratio=q.log_density(u) - q.log_density(prop))


JUMP_COMPONENTS = 8
"""The most Gaussians of a jump's mixture (:func:`_population_mixture`)."""
JUMP_INFLATE = 1.5
"""A jump component's covariance is its cluster's times this (squared scale): heavier than the cluster, so the
proposal covers the target's tails, where a ratio ``q(u) / q(u')`` of a too-narrow proposal would trap particles."""


def _population_mixture(pop: np.ndarray, rng: np.random.Generator, *, floor: float = 0.005) -> ModeProposal:
    """A Gaussian mixture fitted to the population ``pop``: k-means clusters (at most :data:`JUMP_COMPONENTS`, each
    of at least ``2 d`` particles) weighted by their sizes, each Gaussian its cluster's mean and covariance times
    :data:`JUMP_INFLATE` plus ``floor`` squared per coordinate. A few parameters estimated from the whole population,
    so the proposal hardly depends on any one particle (a kernel density estimate centred on the particles themselves
    does: its own kernel makes ``q(u)`` at a particle many times the density elsewhere in 20 dimensions, and the sweep
    then accepts moves the target refuses, which biased the first stage's ln Z of the study by -0.37; measured)."""
    d = pop.shape[1]
    labels, sizes, keep = kmeans_clusters(pop, JUMP_COMPONENTS, rng, scale_floor=floor, min_size=2 * d)
    return ModeProposal(
        means=np.array([pop[labels == j].mean(axis=0) for j in keep]),
        covs=np.array([JUMP_INFLATE * np.cov(pop[labels == j].T) + floor**2 * np.eye(d) for j in keep]),
        log_weights=np.log(sizes[keep] / sizes[keep].sum()),
    )


def _move(
    u: np.ndarray, la: np.ndarray, lb: np.ndarray, beta: float, evaluate: Evaluate, s: SmcSettings,
    rng: np.random.Generator, scale: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int, float]:  # fmt: skip
    """Sweeps until ``s.moves`` accepted moves per particle: ``(u, la, lb, scale, calls, acceptance)``."""
    n, d = u.shape
    base = 2.38 / math.sqrt(2 * d)
    accepted, calls, sweeps = 0.0, 0, 0
    every = round(1.0 / s.jumps) if s.jumps > 0 else 0
    while sweeps < s.max_sweeps and (sweeps < s.min_sweeps or accepted < s.moves):
        sweeps += 1
        calls += n
        if every and sweeps % every == 0:
            u, la, lb, acc = _jump(u, la, lb, beta, evaluate, rng)
            accepted += float(np.mean(acc))
            continue
        u, la, lb, acc = _sweep(u, la, lb, beta, base * scale, evaluate, rng, s.periodic, crossover=s.crossover)
        rate = float(np.mean(acc))
        accepted += rate
        scale *= math.exp(rate - 0.25)  # keep the acceptance near a quarter
    return u, la, lb, scale, calls, accepted / max(sweeps, 1)


def spread_over_mode(
    best: np.ndarray, evaluate: Evaluate, n: int, s: SmcSettings, rng: np.random.Generator, *, jitter: float = 1e-4
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` particles spread over the mode at ``best`` (a search's optimum, unit cube): copies of it jittered by
    ``jitter`` per coordinate, then the sweeps' Metropolis moves at ``beta = 1`` (the posterior, ``L_a L_b``) until
    ``s.moves`` accepted moves per particle. The jitter is small against any mode, and the moves' adaptive scale
    grows the population to the mode's width (copies jittered 2.5 widths out, 0.005 on a needle of 0.002, left 1-2
    of 256 in another mode: measured). A search's final population sits at one point; these follow the mode's
    ridge, which kernels around them then cover (:class:`ModeProposal`). Returns ``(u, log L_a + log L_b)``."""
    u = _fold(best[None, :] + jitter * rng.standard_normal((n, len(best))), s.periodic)
    la, lb = evaluate(u)
    u, la, lb, _, _, _ = _move(u, la, lb, 1.0, evaluate, s, rng, 1.0)
    with np.errstate(invalid="ignore"):
        return u, la + lb


def _eve_variance(eve: np.ndarray, logw: np.ndarray, steps: int) -> float:
    """Lee & Whiteley's (2018) estimate of ``var(Z_hat) / Z^2`` from the Eve indices (each particle's ancestor at
    the start) before the last weighting, the last incremental weights and the number of weightings."""
    n = len(eve)
    w = np.exp(logw - np.max(logw))
    w /= w.sum()
    same = float(np.sum(np.bincount(eve, weights=w, minlength=n) ** 2))
    return max(0.0, 1.0 - (n / (n - 1.0)) ** steps * (1.0 - same))


def temper(
    u: np.ndarray, la: np.ndarray, lb: np.ndarray, evaluate: Evaluate, s: SmcSettings, rng: np.random.Generator,
    *, beta: float = 0.0,
) -> SmcRun:  # fmt: skip
    """From equal-weight particles of ``pi L_a L_b^beta`` (``u`` with their ``log L_a``, ``log L_b``) to
    ``pi L_a L_b`` (module docstring). The returned evidence is ``Z_b = E_{pi L_a L_b^beta}[L_b^(1 - beta)]``, with
    the stated variance of its log."""
    n = len(u)
    log_z, var, calls, scale = 0.0, 0.0, 0, 1.0
    betas: list[float] = [beta]
    rates: list[float] = []
    eve = np.arange(n)
    while beta < 1.0:
        nxt = _next_beta(beta, lb, s.ess_fraction * n)
        with np.errstate(invalid="ignore"):
            logw = np.where(np.isfinite(lb), (nxt - beta) * lb, -np.inf)
        if not np.any(np.isfinite(logw)):
            return SmcRun(u, la, lb, -math.inf, 0.0, calls, betas, rates)
        log_z += float(logsumexp(logw)) - math.log(n)
        var = _eve_variance(eve, logw, len(betas))
        idx = rng.choice(n, size=n, p=np.exp(logw - logsumexp(logw)))  # multinomial, as the error estimate assumes
        u, la, lb, beta, eve = u[idx], la[idx], lb[idx], nxt, eve[idx]
        u, la, lb, scale, c, rate = _move(u, la, lb, beta, evaluate, s, rng, scale)
        calls += c
        betas.append(beta)
        rates.append(rate)
    if s.final_moves > 0:  # sweeps until final_moves accepted, at most 8 per move (acceptance held near a quarter)
        last = dataclasses.replace(s, moves=s.final_moves, max_sweeps=max(s.max_sweeps, math.ceil(8 * s.final_moves)))
        u, la, lb, scale, c, rate = _move(u, la, lb, beta, evaluate, last, rng, scale)
        calls += c
        rates.append(rate)
    return SmcRun(u, la, lb, log_z, var, calls, betas, rates)


def _from_prior(
    evaluate: Evaluate, d: int, s: SmcSettings, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, int] | None:
    """Equal-weight draws of ``pi`` restricted to ``L_a > 0`` (``L_a``'s support), with the log of its prior mass and
    that estimate's variance; ``None`` when no draw is in the support."""
    n = s.particles
    u = rng.random((n, d))
    la, lb = evaluate(u)
    ok = np.isfinite(la) & np.isfinite(lb)
    m = int(ok.sum())
    if m == 0:
        return None
    idx = _systematic(np.where(ok, 0.0, -np.inf), n, rng)
    frac = m / n
    return u[idx], la[idx], lb[idx], math.log(frac), (1.0 - frac) / (n * frac), n


def _stage_one(
    cheap: Evaluate, d: int, s: SmcSettings, rng: np.random.Generator
) -> tuple[SmcRun, float, float, int] | SmcRun:
    """Stage 1, from the prior to the prior times the cheap terms: ``(its run, the log of the support's prior mass,
    that estimate's variance, the calls for the support)``, or an empty run with ``ln Z = -inf`` when no prior draw
    is in the support."""
    start = _from_prior(cheap, d, s, rng)
    if start is None:
        return SmcRun(np.empty((0, d)), np.empty(0), np.empty(0), -math.inf, 0.0, s.particles)
    u, _, lc, log_mass, var_mass, calls = start
    return temper(u, np.zeros(len(u)), lc, cheap, s, rng), log_mass, var_mass, calls


def two_stage(
    cheap: Evaluate, full: Evaluate, d: int, stage1: SmcSettings, stage2: SmcSettings, rng: np.random.Generator,
    *, modes: ModeProposal | None = None, mode_particles: int = 0,
) -> SmcRun:  # fmt: skip
    """The posterior ``pi L_cheap L_data`` by two temperings (module docstring). ``cheap(U)`` returns ``(0,
    log L_cheap)``, ``full(U)`` returns ``(log L_cheap, log L_data)`` (``log L_data`` evaluated only where
    ``log L_cheap`` is finite). The result's ``log_a``/``log_b`` are ``log L_cheap``/``log L_data`` of its particles,
    its evidence ``ln Z = ln Z_support + ln Z_1 + ln Z_2``.

    ``modes``: the data stage starts instead from a defensive mixture (Hesterberg 1995) ``r`` of stage 1's target
    ``p_1 = L_cheap / Z_1`` (its particles; ``Z_1`` as stage 1 estimated it) and ``mode_particles`` draws around the
    modes a search found, and tempers from ``r`` to the posterior along ``r^(1 - beta) (p_1 L_data)^beta``
    (:func:`_from_mixture`): a region the data favour but stage 1 holds too few particles of keeps its particles
    through the tempering, and ``Z_2 = E_r[p_1 L_data / r]`` is ``E_{p_1}[L_data]`` (up to the error of ``Z_1``'s
    estimate)."""
    first = _stage_one(cheap, d, stage1, rng)
    if isinstance(first, SmcRun):
        return first
    one, log_mass, var_mass, calls = first
    if modes is not None and mode_particles > 0:
        two = _from_mixture(one, full, modes, mode_particles, log_mass + one.log_evidence, stage2, rng)
    else:
        two = _data_stage(one, full, stage2, rng)
    if stage2.importance and np.isfinite(two.log_evidence):
        return _importance_run(one, two, full, stage2, rng, calls)
    return SmcRun(
        two.u, two.log_a, two.log_b, log_mass + one.log_evidence + two.log_evidence,
        var_mass + one.log_evidence_var + two.log_evidence_var,
        calls + one.n_calls + two.n_calls, one.betas + [1.0 + b for b in two.betas],
        one.acceptance + two.acceptance,
    )  # fmt: skip


def _data_stage(one: SmcRun, full: Evaluate, s: SmcSettings, rng: np.random.Generator) -> SmcRun:
    """The data stage from stage 1's particles ``one`` (:func:`_first_data_step` on all of them, then tempering to
    ``beta = 1``): its particles, ``ln Z_2`` with its variance, and its calls (stage 1's particles' included)."""
    u2, la, lb, beta, log_z2, var2 = _first_data_step(one.u, full, s, rng)
    u2, la, lb, _, moved, _ = _move(u2, la, lb, beta, full, s, rng, 1.0)
    two = temper(u2, la, lb, full, s, rng, beta=beta)
    two.log_evidence += log_z2
    two.log_evidence_var += var2
    two.n_calls += moved + len(one.u)
    return two


def emulated_two_stage(
    cheap: Evaluate, train: Callable[[np.ndarray], Evaluate], exact: Evaluate, d: int, stage1: SmcSettings,
    stage2: SmcSettings, rng: np.random.Generator, *, refine: Callable[[np.ndarray], Evaluate] | None = None,
    again: Callable[[np.ndarray], Evaluate | None] | None = None,
) -> SmcRun:  # fmt: skip
    """:func:`two_stage` with the data stage on an emulator, then importance-weighted to the exact likelihood
    (:mod:`~fpm_sim.study.calibrate.emulator`). ``train(U)`` is given stage 1's particles and returns the emulator's
    :data:`Evaluate` (``U -> (log L_cheap, emulated log L_data)``); ``exact(U)`` returns ``(log L_cheap, log L_data)``.
    The data stage's particles ``u_i`` (of the emulated posterior ``q``) get the weights ``w_i = L_data(u_i) /
    L_emulated(u_i)``, so that ``Z = Z_q mean(w)``, exact for any emulator. The stated variance of ``ln Z`` adds the
    weights' importance-sampling variance ``1 / ESS - 1 / n`` to the emulated stages'. The result carries the
    normalised log weights; its ``log_b`` is the exact ``log L_data``.

    ``refine(U)``: given the data stage's particles, the emulator refitted with the exact model run at (some of) them;
    the data stage then runs again on it, from stage 1's particles, and only that second stage is weighted and
    reported (the weights stay exact: its particles are new draws given the refitted emulator). An emulator trained on
    the prior side of the posterior alone is least accurate where the posterior is; refitted there, its weights vary
    less.

    ``again(log_w)``: given a weighted stage's normalised log weights, ``None`` to report it, or an emulator refitted
    with every exact run so far (the weights' own included) on which the data stage runs once more, from stage 1's
    particles, and is weighted and reported instead (once at most: where a stage explored beyond the runs its
    emulator was fitted on, its weights are heavy, and the exact runs at its particles are where the emulator was
    missing)."""
    first = _stage_one(cheap, d, stage1, rng)
    if isinstance(first, SmcRun):
        return first
    one, log_mass, var_mass, calls = first

    def weigh(two: SmcRun, emulated: Evaluate) -> SmcRun:
        if stage2.importance:
            return _weighted_importance(one, two, emulated, exact, stage2, rng)
        return _weighted(one, two, exact, log_mass + one.log_evidence, var_mass + one.log_evidence_var)

    emulated = train(one.u)
    two = _data_stage(one, emulated, stage2, rng)
    if refine is not None:  # a second data stage on the emulator refitted with the exact model at the first's particles
        first_calls = two.n_calls
        emulated = refine(two.u)
        two = _data_stage(one, emulated, stage2, rng)
        two.n_calls += first_calls
    run = weigh(two, emulated)
    refit = None if again is None or run.log_weights is None else again(run.log_weights)
    if refit is not None:
        two = _data_stage(one, refit, stage2, rng)
        two.n_calls += run.n_calls - one.n_calls  # the first weighted stage's calls and its exact runs
        run = weigh(two, refit)
    run.n_calls += calls
    return run


def _weighted(one: SmcRun, two: SmcRun, exact: Evaluate, log_z1: float, var1: float) -> SmcRun:
    """The emulated data stage ``two`` weighted to the exact likelihood (:func:`emulated_two_stage`); ``log_z1``,
    ``var1``: the log of the support's mass times stage 1's evidence, and its variance. Its calls leave out the
    support's."""
    la, lb = exact(two.u)
    with np.errstate(invalid="ignore"):
        log_w = np.where(np.isfinite(lb) & np.isfinite(two.log_b), lb - two.log_b, -math.inf)
    n = len(log_w)
    calls = one.n_calls + two.n_calls + n
    if not np.any(np.isfinite(log_w)):
        return SmcRun(two.u, la, lb, -math.inf, 0.0, calls)
    log_mean = float(logsumexp(log_w)) - math.log(n)
    return SmcRun(
        two.u, la, lb, log_z1 + two.log_evidence + log_mean,
        var1 + two.log_evidence_var + max(1.0 / _ess(log_w) - 1.0 / n, 0.0), calls,
        one.betas + [1.0 + b for b in two.betas], one.acceptance + two.acceptance,
        log_weights=log_w - float(logsumexp(log_w)),
    )  # fmt: skip


def _importance_run(
    one: SmcRun, two: SmcRun, full: Evaluate, s: SmcSettings, rng: np.random.Generator, calls: int
) -> SmcRun:  # fmt: skip
    """:func:`two_stage`'s result by importance sampling (``s.importance`` draws of a mixture fitted to the data
    stage's particles ``two.u``): the draws inside the support, their weights, and their evidence."""
    imp = importance_sample(two.u, full, s.importance, rng, periodic=s.periodic)
    ok = np.isfinite(imp.log_w)
    return SmcRun(
        imp.u[ok], imp.log_a[ok], imp.log_b[ok], imp.log_evidence, imp.log_evidence_var,
        calls + one.n_calls + two.n_calls + s.importance, one.betas + [1.0 + b for b in two.betas],
        one.acceptance + two.acceptance, log_weights=imp.normalised_log_weights[ok],
        importance=imp.diagnostics(),
    )  # fmt: skip


def _resampled(log_w: np.ndarray, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` systematic draws by the weights ``log_w``, as ``(distinct rows, log of each one's count)``."""
    rows, counts = np.unique(_systematic(log_w, n, rng), return_counts=True)
    return rows, np.log(counts)


def _weighted_importance(
    one: SmcRun, two: SmcRun, emulated: Evaluate, exact: Evaluate, s: SmcSettings, rng: np.random.Generator
) -> SmcRun:  # fmt: skip
    """The emulated posterior by importance sampling (``s.importance`` draws of a mixture fitted to the data stage's
    particles ``two.u``, :func:`~fpm_sim.study.calibrate.importance.importance_sample`), then weighted to the exact
    likelihood: ``s.particles`` systematic draws by the importance weights, the exact model run once at each distinct
    one (``c_j`` copies), its weight ``c_j L_exact / L_emulated``, and ``Z = Z_emulated sum_j c_j r_j / n``. The
    stated variance of ``ln Z`` is the importance draws' plus the ratio's mean's ``sum_j p_j^2 (r_j / r_bar - 1)^2``
    (``p_j = c_j / n``). The stages' tempering evidences are not used: the draws cover the whole target."""
    imp = importance_sample(two.u, emulated, s.importance, rng, periodic=s.periodic)
    n = s.particles
    calls = one.n_calls + two.n_calls + s.importance
    if not np.isfinite(imp.log_evidence):
        return SmcRun(two.u, two.log_a, two.log_b, -math.inf, 0.0, calls)
    rows, log_c = _resampled(imp.log_w, n, rng)
    u = imp.u[rows]
    la, lb = exact(u)
    with np.errstate(invalid="ignore"):
        log_r = np.where(np.isfinite(lb) & np.isfinite(imp.log_b[rows]), lb - imp.log_b[rows], -math.inf)
    calls += len(rows)
    if not np.any(np.isfinite(log_r)):
        return SmcRun(u, la, lb, -math.inf, 0.0, calls)
    log_w = log_c + log_r
    p, r = np.exp(log_c) / n, np.exp(log_r - np.max(log_r[np.isfinite(log_r)]))
    var_ratio = float(np.sum(p**2 * (r / np.sum(p * r) - 1.0) ** 2))
    return SmcRun(
        u, la, lb, imp.log_evidence + float(logsumexp(log_w)) - math.log(n), imp.log_evidence_var + var_ratio, calls,
        one.betas + [1.0 + b for b in two.betas], one.acceptance + two.acceptance,
        log_weights=log_w - float(logsumexp(log_w)),
        importance=imp.diagnostics(),
    )  # fmt: skip


def _from_mixture(
    one: SmcRun, full: Evaluate, modes: ModeProposal, m: int, log_z1: float, s: SmcSettings,
    rng: np.random.Generator,
) -> SmcRun:  # fmt: skip
    """The data stage from the defensive mixture ``r`` (:func:`two_stage`): ``s.particles`` of the pooled draws
    (stage 1's particles and ``m`` of ``modes``, draws of ``r``), tempered on ``L_a = r``, ``L_b = p_1 L_data / r``;
    the result's ``log_a``/``log_b`` are ``log L_cheap``/``log L_data``, its evidence ``ln Z_2``."""
    n1 = len(one.u)

    def bridged(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        inside = np.all((u >= 0.0) & (u <= 1.0), axis=1)
        lc, ld = np.full(len(u), -math.inf), np.full(len(u), -math.inf)
        if inside.any():
            lc[inside], ld[inside] = full(u[inside])
        log_p1 = lc - log_z1  # the prior is uniform on the cube
        with np.errstate(divide="ignore", invalid="ignore"):
            log_r = np.logaddexp(math.log(n1) + log_p1, math.log(m) + modes.log_density(u)) - math.log(n1 + m)
            log_b = np.where(np.isfinite(log_p1) & np.isfinite(ld), log_p1 + ld - log_r, -math.inf)
        return log_r, log_b

    pool = np.concatenate([one.u, modes.sample(m, rng)])
    u = pool[rng.choice(len(pool), size=min(s.particles, len(pool)), replace=False)]  # draws of r, equal weights
    la, lb = bridged(u)
    run = temper(u, la, lb, bridged, s, rng)
    lc, ld = full(run.u)
    return SmcRun(run.u, lc, ld, run.log_evidence, run.log_evidence_var, run.n_calls + 2 * len(u), run.betas,
                  run.acceptance)  # fmt: skip


def _first_data_step(
    u: np.ndarray, full: Evaluate, s: SmcSettings, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, float]:
    """The data's first tempering step on every particle of the cheap stage (a region the cheap terms give few
    particles but the data favour keeps them for this step), resampled to ``s.particles``: ``(u, log L_a, log L_b,
    beta, ln Z increment, its variance)`` (the importance-sampling variance ``1 / ESS - 1 / n``)."""
    n = len(u)
    la, lb = full(u)
    beta = _next_beta(0.0, lb, s.ess_fraction * min(n, s.particles))
    with np.errstate(invalid="ignore"):
        logw = np.where(np.isfinite(lb), beta * lb, -np.inf)
    if not np.any(np.isfinite(logw)):
        return u[: s.particles], la[: s.particles], lb[: s.particles], 1.0, -math.inf, 0.0
    idx = rng.choice(n, size=s.particles, p=np.exp(logw - logsumexp(logw)))
    return u[idx], la[idx], lb[idx], beta, float(logsumexp(logw)) - math.log(n), 1.0 / _ess(logw) - 1.0 / n


def merge_smc(runs: list[dict[str, Any]], *, islands: bool = False) -> dict[str, Any]:
    """Independent runs of one class as one: ``Z`` their mean (each unbiased), the particles pooled, each run's
    weights (equal, or its importance weights) scaled to ``1 / runs`` of the whole; the stated error
    ``sqrt(sum_r (Z_r / sum Z)^2 s_r^2)``. Each sample keeps the label of the island it came from (``"island"``: its
    run's, offset by the islands of the runs before it; a run without labels is one island), so that a check can
    read the Monte Carlo error from the islands' spread.

    ``islands``: the runs are one run's independent islands (Verge et al. 2015), and the stated error is the largest
    of the above and two from their spread over the ``K`` islands: the sample variance of the ``Z_i``, ``var(Z_bar) /
    Z_bar^2 = sum_i (Z_i / Z_bar - 1)^2 / (K (K - 1))``, and the lognormal one, ``(exp(s^2) - 1) / K`` with ``s^2``
    the sample variance of the ``ln Z_i`` (an SMC's ``ln Z_hat`` is asymptotically normal: Berard, Del Moral & Doucet
    2014). What the particles' genealogy leaves out (the moves' correlation along a ridge) shows in the spread; the
    first alone, set by the largest of a few lognormal values, states too little when they spread by a nat or more
    (class (1, 1, 1) of the study: one run's islands -76.58, -74.29, -72.87, -73.47 gave +- 0.47, the lognormal +- 1.8,
    beside two runs at -71.91 +- 0.15 and -71.99 +- 0.22)."""
    lz = np.array([float(r["logz"][-1]) for r in runs])
    log_z, err = mean_evidence(lz, np.array([float(r["logzerr"][-1]) for r in runs]), islands=islands)
    samples = np.concatenate([r["samples"] for r in runs])
    own = [np.asarray(r["logwt"], float) - z if np.isfinite(z) else np.full(len(r["logwt"]), -math.inf)
           for r, z in zip(runs, lz)]  # fmt: skip
    pooled = np.concatenate(own)
    log_w = pooled - float(logsumexp(pooled)) if np.any(np.isfinite(pooled)) else None
    out = smc_results(samples, np.concatenate([r["logl"] for r in runs]), log_z, err,
                      int(sum(np.sum(r["ncall"]) for r in runs)), int(sum(r["niter"] for r in runs)),
                      log_weights=log_w)  # fmt: skip
    labels, offset = [], 0
    for r in runs:
        own_labels = np.asarray(r.get("island", np.zeros(len(r["samples"]), int)), int)
        labels.append(own_labels + offset)
        offset += int(own_labels.max()) + 1 if len(own_labels) else 1
    out["island"] = np.concatenate(labels)
    return out


def mean_evidence(log_z: np.ndarray, log_z_err: np.ndarray, *, islands: bool = False) -> tuple[float, float]:
    """``(ln Z_bar, its stated error)`` of independent estimates ``ln Z_i +- s_i`` (:func:`merge_smc`'s)."""
    finite = np.isfinite(log_z)
    if not finite.any():
        return -math.inf, 0.0
    out = float(logsumexp(log_z[finite]) - math.log(len(log_z)))
    w = np.exp(log_z[finite] - np.max(log_z[finite]))
    err = float(np.sqrt(np.sum((w / w.sum()) ** 2 * log_z_err[finite] ** 2)))
    k = len(log_z)
    if islands and k > 1:
        ratio = np.where(finite, np.exp(log_z - out), 0.0)  # Z_i / Z_bar
        spread = float(np.sum((ratio - 1.0) ** 2)) / (k * (k - 1))
        lognormal = math.expm1(float(np.var(log_z[finite], ddof=1))) / k if finite.sum() > 1 else 0.0
        err = max(err, math.sqrt(max(spread, lognormal)))
    return out, err


def smc_results(
    samples: np.ndarray, logl: np.ndarray, log_z: float, err: float, calls: int, niter: int, *,
    log_weights: np.ndarray | None = None,
) -> dict[str, Any]:  # fmt: skip
    """What a calibration run reports, in dynesty ``Results``' keys: weights ``ln(1 / n) + ln Z``, or ``ln Z`` plus
    the normalised ``log_weights`` where given (importance weights: :func:`emulated_two_stage`)."""
    n = len(samples)
    if log_weights is None:
        logwt = np.full(n, (log_z - math.log(n)) if n else -math.inf)
    else:
        logwt = np.asarray(log_weights, float) + log_z
    return {
        "samples": samples,
        "logl": logl,
        "logwt": logwt,
        "logz": np.array([log_z]),
        "logzerr": np.array([err]),
        "ncall": np.array([calls]),
        "niter": niter,
    }
