"""The evidence and the posterior by importance sampling from a mixture fitted to a sampler's particles: independent
draws, so the stated error is the draws' own.

Tempered SMC finds the posterior, but its evidence's stated error (the particles' genealogy, Lee & Whiteley 2018)
counts only the correlation that resampling leaves: where the Metropolis moves do not decorrelate the particles
along a ridge, independent runs of the study's calibration spread 1-2 nats in ln Z against stated errors of
0.2-0.5, and their quantiles and class weights with them (docs/identification.md, "Importance sampling after the
tempering"). Importance sampling from a proposal fitted to the final particles turns the sampler into a proposal
builder (as nested sampling with normalising flows does, Williams et al. 2023's i-nessai; and Perrakis et al.'s 2015
mixture importance sampling of the marginal likelihood): ``M`` independent draws ``x_i`` of the proposal ``q`` give

    Z_hat = mean_i w_i,    w_i = pi(x_i) L(x_i) / q(x_i),    var(Z_hat) / Z^2 ~ sum (w_i - w_bar)^2 / (M w_bar)^2,

unbiased for any ``q`` that covers the target, with an error estimated from independent draws; a poor ``q`` shows as
a small effective sample size and a large Pareto ``k`` (Vehtari et al. 2024), not as a confident wrong answer. The
weighted draws are the run's posterior.

The proposal (:class:`ProbitMixture`) is a mixture of multivariate Student-t distributions in probit coordinates
``z = Phi^-1(u)`` of the unit cube (where the calibration's prior is uniform): there the prior is a standard normal,
so a parameter the data leave at its prior (the as-built deviations) is fitted exactly by a Gaussian, where a
Gaussian on the cube fits a uniform poorly (each such coordinate costs a factor of about 1.2 in the weights' second
moment, 10 over 12 of them); the t's tails (``df`` :data:`IMPORTANCE_DF`) keep the weights bounded where the target
is wider than the particles show, and each component's covariance is its cluster's shrunk towards the population's
and inflated by :data:`IMPORTANCE_INFLATE`. A whole-turn (periodic) coordinate is first rotated so that its particles'
circular mean sits at the cube's centre, a measure-preserving shift, so a mode across the seam is one cluster.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.special import gammaln, logsumexp, ndtr, ndtri

__all__ = [
    "IMPORTANCE_DF", "IMPORTANCE_INFLATE", "Importance", "ProbitMixture", "importance_diagnostics", "importance_sample",
    "kmeans_clusters",
]  # fmt: skip

IMPORTANCE_DF = 5.0
"""The Student-t components' degrees of freedom: tails heavier than a Gaussian's, so the weights stay bounded where
the target's tails reach past the particles (at 5 the variance is finite and the core close to Gaussian)."""
IMPORTANCE_INFLATE = 1.5
"""Each component's covariance is its (shrunk) cluster's times this: the particles of a tempering under-spread a
ridge they did not fully travel, and a proposal narrower than its target gives heavy weights."""
IMPORTANCE_COMPONENTS = 8
"""The most components of the mixture (k-means clusters of at least ``4 d`` particles)."""
_EDGE = 1e-12
"""Unit-cube positions are kept this far inside the faces before ``Phi^-1`` (a particle exactly on a face)."""

Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``U (n, d) -> (log L_a, log L_b)`` at the rows of ``U`` (as :mod:`~fpm_sim.study.calibrate.smc`'s)."""


@dataclass(frozen=True)
class ProbitMixture:
    """A Student-t mixture in probit coordinates of the unit cube (module docstring): ``u = (Phi(z) - shift) mod 1``
    on the ``periodic`` coordinates, ``u = Phi(z)`` on the others."""

    means: np.ndarray
    """``(k, d)`` the components' centres (probit coordinates)."""
    chols: np.ndarray
    """``(k, d, d)`` the Cholesky factors of their scale matrices."""
    log_weights: np.ndarray
    """``(k,)`` normalised."""
    shift: np.ndarray
    """``(d,)`` added (mod 1) to a periodic coordinate before ``Phi^-1``; 0 elsewhere."""
    periodic: tuple[int, ...] = ()
    df: float = IMPORTANCE_DF

    @classmethod
    def fit(
        cls, pop: np.ndarray, rng: np.random.Generator, *, periodic: tuple[int, ...] = (),
        components: int = IMPORTANCE_COMPONENTS, inflate: float = IMPORTANCE_INFLATE, df: float = IMPORTANCE_DF,
    ) -> ProbitMixture:  # fmt: skip
        """Fitted to the particles ``pop`` (``(n, d)``, unit cube): k-means clusters in probit coordinates
        (:func:`kmeans_clusters`), each component its cluster's mean and covariance, the covariance shrunk towards the
        clusters' pooled one ``W`` (``(n_k S_k + d W) / (n_k + d)``, so a small cluster is not degenerate) times
        ``inflate``, weighted by the clusters' sizes."""
        d = pop.shape[1]
        shift = np.zeros(d)
        if periodic:
            p = list(periodic)
            ang = 2.0 * math.pi * pop[:, p]
            centre = np.mod(np.arctan2(np.sin(ang).mean(axis=0), np.cos(ang).mean(axis=0)) / (2.0 * math.pi), 1.0)
            shift[p] = np.mod(0.5 - centre, 1.0)
        z = ndtri(np.clip(np.mod(pop + shift, 1.0) if periodic else pop, _EDGE, 1.0 - _EDGE))
        labels, sizes, keep = kmeans_clusters(z, components, rng, scale_floor=1e-9, min_size=2)
        own = {j: np.atleast_2d(np.cov(z[labels == j].T, bias=True)) for j in keep}
        within = sum(sizes[j] * own[j] for j in keep) / sizes[keep].sum() + 1e-9 * np.eye(d)
        means, chols = [], []
        for j in keep:
            zj = z[labels == j]
            cov = (sizes[j] * own[j] + d * within) / (sizes[j] + d)
            means.append(zj.mean(axis=0))
            chols.append(np.linalg.cholesky(inflate * cov))
        w = sizes[keep].astype(float)
        return cls(np.array(means), np.array(chols), np.log(w / w.sum()), shift, tuple(periodic), df)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, d)`` draws in probit coordinates."""
        k = rng.choice(len(self.means), size=n, p=np.exp(self.log_weights))
        g = rng.standard_normal((n, self.means.shape[1]))
        scale = np.sqrt(self.df / rng.chisquare(self.df, n))
        out: np.ndarray = self.means[k] + scale[:, None] * np.einsum("nij,nj->ni", self.chols[k], g)
        return out

    def log_density(self, z: np.ndarray, *, block: int = 2048) -> np.ndarray:
        """``(n,)`` the mixture's log-density at the rows of ``z`` (probit coordinates)."""
        d = self.means.shape[1]
        nu = self.df
        log_det = np.sum(np.log(np.diagonal(self.chols, axis1=1, axis2=2)), axis=1)
        norm = gammaln(0.5 * (nu + d)) - gammaln(0.5 * nu) - 0.5 * d * math.log(nu * math.pi) - log_det
        inv = np.linalg.inv(self.chols)
        out = np.empty(len(z))
        for i in range(0, len(z), block):
            diff = z[i : i + block, None, :] - self.means[None]
            m = np.sum(np.einsum("kij,bkj->bki", inv, diff) ** 2, axis=-1)
            comp = norm[None] + self.log_weights[None] - 0.5 * (nu + d) * np.log1p(m / nu)
            out[i : i + block] = logsumexp(comp, axis=1)
        return out

    def to_cube(self, z: np.ndarray) -> np.ndarray:
        """The unit-cube positions of probit rows ``z`` (kept :data:`_EDGE` inside the faces)."""
        u = np.clip(ndtr(z), _EDGE, 1.0 - _EDGE)
        if self.periodic:
            p = list(self.periodic)
            u[:, p] = np.mod(u[:, p] - self.shift[p], 1.0)
        out: np.ndarray = u
        return out


def kmeans_clusters(
    x: np.ndarray, components: int, rng: np.random.Generator, *, scale_floor: float, min_size: int
) -> tuple[np.ndarray, np.ndarray, list[int]]:  # fmt: skip
    """k-means clusters of the rows of ``x`` (``(n, d)``; each coordinate over its sd plus ``scale_floor``; k-means++
    starts): at most ``components`` and ``n / (4 d)`` of them. Returns ``(each row's cluster, each cluster's size,
    the clusters of at least min_size rows, or the largest where none is)``: the mixtures fitted to a population
    (this module's, and the SMC's jumps') share it."""
    from scipy.cluster.vq import kmeans2

    n, d = x.shape
    k = max(1, min(components, n // (4 * d)))
    labels = kmeans2(x / (np.std(x, axis=0) + scale_floor), k, seed=rng, minit="++")[1] if k > 1 else np.zeros(n, int)
    sizes = np.bincount(labels, minlength=k)
    keep = [j for j in range(k) if sizes[j] >= min_size] or [int(np.argmax(sizes))]
    return labels, sizes, keep


@dataclass(frozen=True)
class Importance:
    """Independent draws of a :class:`ProbitMixture` weighted to the target ``pi L_a L_b`` on the unit cube."""

    u: np.ndarray
    """``(M, d)`` the draws (unit cube)."""
    log_a: np.ndarray
    log_b: np.ndarray
    log_w: np.ndarray
    """``(M,)`` unnormalised log weights ``log L_a + log L_b + log pi(z) - log q(z)`` (``-inf``: outside the
    target's support)."""

    @property
    def log_evidence(self) -> float:
        if not np.any(np.isfinite(self.log_w)):
            return -math.inf
        return float(logsumexp(self.log_w)) - math.log(len(self.log_w))

    @property
    def log_evidence_var(self) -> float:
        """The variance of ``ln Z_hat`` (delta method): ``sum (w_i - w_bar)^2 / (M (M - 1) w_bar^2)``."""
        if not np.any(np.isfinite(self.log_w)):
            return 0.0
        w = np.exp(self.log_w - np.max(self.log_w))
        m = len(w)
        return float(np.sum((w - w.mean()) ** 2) / (m * (m - 1) * w.mean() ** 2))

    def diagnostics(self) -> dict[str, float]:
        """The draws, their effective sample size, Pareto ``k`` and the stated error of ``ln Z``."""
        ess, k = importance_diagnostics(self.log_w)
        return {
            "draws": len(self.log_w),
            "ess": ess,
            "pareto_k": k,
            "log_evidence_err": math.sqrt(self.log_evidence_var),
        }

    @property
    def normalised_log_weights(self) -> np.ndarray:
        out: np.ndarray = self.log_w - float(logsumexp(self.log_w))
        return out


def importance_sample(
    pop: np.ndarray, evaluate: Evaluate, draws: int, rng: np.random.Generator, *, periodic: tuple[int, ...] = (),
    block: int = 5000,
) -> Importance:  # fmt: skip
    """``draws`` independent draws of a :class:`ProbitMixture` fitted to the particles ``pop``, weighted to ``pi L_a
    L_b`` (``evaluate`` run ``block`` rows at a time; the prior ``pi`` is uniform on the cube, a standard normal in
    probit coordinates)."""
    q = ProbitMixture.fit(pop, rng, periodic=periodic)
    z = q.sample(draws, rng)
    u = q.to_cube(z)
    la, lb = np.empty(draws), np.empty(draws)
    for i in range(0, draws, block):
        la[i : i + block], lb[i : i + block] = evaluate(u[i : i + block])
    log_prior = -0.5 * np.sum(z**2, axis=1) - 0.5 * z.shape[1] * math.log(2.0 * math.pi)
    with np.errstate(invalid="ignore"):
        log_w = np.where(np.isfinite(la) & np.isfinite(lb), la + lb + log_prior - q.log_density(z), -math.inf)
    return Importance(u, la, lb, log_w)


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
