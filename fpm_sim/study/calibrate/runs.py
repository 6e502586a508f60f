"""Enumerated elbow-branch classes and independent runs: combining per-class nested-sampling results by their
evidences, and the between-run convergence check.

The elbow-branch class is discrete and has few values (8), so it is enumerated rather than sampled: the
continuous posterior of each class ``k`` is sampled on its own (evidence ``Z_k``, continuous prior), and with a
uniform prior ``pi_k = 1 / K`` over the ``K`` classes the whole posterior is the mixture

    p(theta, k | y) = pi_k Z_k p(theta | y, k) / Z,      Z = sum_k pi_k Z_k,

so class ``k`` carries the weight ``w_k = Z_k / sum_j Z_j``. A class none of whose prior draws reaches the
measured poses has ``Z_k = 0`` (skipped, reported). Each class is sampled ``runs`` times with seeds ``seed, seed
+ 1, ...``; the runs of one class are merged (``dynesty.utils.merge_runs``, same problem), and the check compares
the runs' own posteriors (each the mixture of its classes by its own evidences):

- ln Z: every pair of runs within ``nsigma`` of their combined stated error (the total, and each class any run
  weights above ``class_threshold``);
- every continuous parameter's 5/50/95 % quantiles: every pair of runs within ``quantile_tol`` of its merged
  posterior sd, or, where further apart, within ``nsigma`` of the pair's Monte Carlo error: a few hundred effective
  draws cannot place a skewed tail's 95 % point to 0.5 sd, and the check must not call that a disagreement. A run's
  posterior is the mixture ``F = sum_k w_k F_k`` of its classes, so its quantile ``x_q`` has two errors: the
  draws' (``var F(x_q) = q (1 - q) / n`` for ``n`` effective draws) and the class weights' (``w_k = Z_k / sum Z``
  moves with the error ``s_k`` of each ``ln Z_k``, to first order ``dF = sum_k w_k (F_k(x_q) - q) d ln Z_k``;
  :func:`class_weights_cdf_var` draws it rather than take the first order; it counts where the classes' draws lie
  apart, as the rotations of two orbits do). The two runs' quantiles are compared in probability, where the error is
  defined: each run's CDF at the other's quantile must lie within ``nsigma`` of the pair's CDF error of ``q`` (a
  quantile in a gap between two classes, where the CDF is flat, may move far on a small change of the weights; the
  delta method's quantile sd, the CDF's over the density at the quantile, kept in :attr:`RunsCheck.quantile_mc_sd`
  for the record, does not hold there). The ln Z criterion above checks that the stated ``s_k`` are honest;
- every class any run weights above ``class_threshold`` is in the merged posterior with at least
  ``class_threshold / runs`` of the weight (what it keeps when only one of the ``runs`` runs found it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fpm_sim.study.calibrate.smc import mean_evidence

__all__ = [
    "ClassResult",
    "Combined",
    "RunsCheck",
    "allocate",
    "between_run_check",
    "class_weights_cdf_var",
    "combine_classes",
    "combine_parts",
    "evidence_weights",
    "islands_cdf_var",
    "quantile_mc_sd",
]

QUANTILES = (0.05, 0.5, 0.95)


@dataclass(frozen=True)
class ClassResult:
    """One class's weighted nested samples (one run, or the merge of its runs)."""

    klass: int | None
    """The elbow-branch class index (``None``: the branches are fixed, one class)."""
    samples: np.ndarray
    """``(n_samples, ndim)`` continuous coordinates."""
    logwt: np.ndarray
    logl: np.ndarray
    log_evidence: float
    log_evidence_err: float
    island: np.ndarray | None = None
    """``(n_samples,)`` each sample's island (an SMC run of independent islands,
    :attr:`~fpm_sim.study.calibrate.sampler.SamplerOptions.islands`); ``None``: one island."""

    @classmethod
    def of_results(cls, klass: int | None, res: Any) -> ClassResult:
        """From a dynesty ``Results`` (or an SMC run's, with its ``"island"`` labels where it has them)."""
        err = float(res["logzerr"][-1])
        island = res.get("island") if isinstance(res, dict) else None
        return cls(
            klass,
            np.asarray(res["samples"], float),
            np.asarray(res["logwt"], float),
            np.asarray(res["logl"], float),
            float(res["logz"][-1]),
            err if math.isfinite(err) else 0.0,
            None if island is None else np.asarray(island, int),
        )


def evidence_weights(log_z: np.ndarray, log_z_err: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The classes' posterior weights ``Z_k / sum Z`` and their sd, from the ln Z errors to first order:
    ``var ln w_k = (1 - w_k)^2 s_k^2 + sum_{j != k} w_j^2 s_j^2`` (the ln Z independent between classes)."""
    log_z = np.asarray(log_z, float)
    s = np.asarray(log_z_err, float)
    w = np.exp(log_z - np.max(log_z))
    w /= w.sum()
    var = np.array([(1 - w[k]) ** 2 * s[k] ** 2 + np.sum(np.delete(w**2 * s**2, k)) for k in range(len(w))])
    out_sd: np.ndarray = w * np.sqrt(var)
    return w, out_sd


def allocate(weights: np.ndarray, n: int) -> np.ndarray:
    """``n`` draws shared out in proportion to ``weights`` (largest remainder: each share within 1 of
    ``n w_k``, total ``n``)."""
    exact = np.asarray(weights, float) * n
    out = np.floor(exact).astype(int)
    rest = n - int(out.sum())
    out[np.argsort(-(exact - out), kind="stable")[:rest]] += 1
    return out


def _equal_weight(logwt: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``n`` equal-weight draws from weighted samples (without repeats while the run has enough)."""
    from dynesty.utils import resample_equal

    w = np.exp(logwt - np.max(logwt))
    w /= w.sum()
    idx_all = resample_equal(np.arange(len(w)), w, rstate=rng)
    out: np.ndarray = rng.choice(idx_all, size=n, replace=n > len(idx_all))
    return out


@dataclass
class Combined:
    """The mixture of the classes: equal-weight draws, the class of each, the evidence and the weights."""

    draws: np.ndarray
    """``(n, ndim)`` continuous coordinates."""
    klass: np.ndarray
    """``(n,)`` the class index of each draw (``-1`` when the branches are fixed)."""
    log_likelihood: np.ndarray
    log_evidence: float
    log_evidence_err: float
    classes: list[int | None]
    weights: np.ndarray
    weights_sd: np.ndarray
    ess_kish: float


def combine_classes(results: Sequence[ClassResult], n_classes: int, n: int, rng: np.random.Generator) -> Combined:
    """``n`` equal-weight draws of the mixture of ``results`` (one per class sampled; a class not among them has
    ``Z_k = 0``) under a uniform prior over ``n_classes`` classes: ``n_k`` draws of class ``k`` in proportion to
    ``Z_k / sum Z`` (:func:`allocate`), in random order; ``ln Z = ln sum_k Z_k / n_classes`` with the error
    ``sqrt(sum_k w_k^2 s_k^2)``."""
    lz = np.array([r.log_evidence for r in results])
    ls = np.array([r.log_evidence_err for r in results])
    w, w_sd = evidence_weights(lz, ls)
    counts = allocate(w, n)
    parts = []
    for r, m in zip(results, counts):
        if m:
            i = _equal_weight(r.logwt, int(m), rng)
            k = -1 if r.klass is None else r.klass
            parts.append((r.samples[i], np.full(int(m), k), r.logl[i]))
    lmax = float(np.max(lz))
    log_z = lmax + math.log(float(np.sum(np.exp(lz - lmax)))) - math.log(n_classes)
    pooled = np.concatenate([r.logwt for r in results])
    order = rng.permutation(n)  # shuffled: the first m draws of the file are a fair sample, not one class's
    return Combined(
        draws=np.concatenate([p[0] for p in parts])[order],
        klass=np.concatenate([p[1] for p in parts])[order],
        log_likelihood=np.concatenate([p[2] for p in parts])[order],
        log_evidence=log_z,
        log_evidence_err=float(np.sqrt(np.sum(w**2 * ls**2))),
        classes=[r.klass for r in results],
        weights=w,
        weights_sd=w_sd,
        ess_kish=_ess_kish(pooled),
    )


def combine_parts(results: Sequence[Any]) -> Any:
    """One class's runs on ``n`` parts of its prior of equal prior mass ``1 / n`` (a split coordinate's intervals;
    each run's evidence ``Z_p`` is that of its part's prior, normalised) as the class's run: ``Z = sum_p Z_p / n``,
    its error ``sqrt(sum_p w_p^2 s_p^2)`` (``w_p = Z_p / sum Z``, the parts independent), the weighted samples
    pooled with ``ln w - ln n`` (each run's weights sum to its ``Z_p``: dynesty's and
    :func:`~fpm_sim.study.calibrate.smc.smc_results`'), so that part ``p`` carries ``w_p`` of the posterior. A part
    whose evidence is nil (``-inf``) carries nothing. Returns the keys :meth:`ClassResult.of_results` reads (and the
    calls and iterations summed); one result is returned as it is."""
    if len(results) == 1:
        return results[0]
    n = len(results)
    ls = np.array([float(r["logzerr"][-1]) for r in results])
    log_z, err = mean_evidence(np.array([float(r["logz"][-1]) for r in results]), np.where(np.isfinite(ls), ls, 0.0))
    return {
        "samples": np.concatenate([np.asarray(r["samples"], float) for r in results]),
        "logwt": np.concatenate([np.asarray(r["logwt"], float) - math.log(n) for r in results]),
        "logl": np.concatenate([np.asarray(r["logl"], float) for r in results]),
        "logz": np.array([log_z]),
        "logzerr": np.array([err]),
        "ncall": np.array([int(sum(np.sum(r["ncall"]) for r in results))]),
        "niter": int(sum(int(r["niter"]) for r in results)),
    }


def _ess_kish(logwt: np.ndarray) -> float:
    v = np.exp(logwt - np.max(logwt))
    return float(v.sum() ** 2 / np.sum(v**2))


@dataclass
class RunsCheck:
    """The between-run check (module docstring): the runs side by side and what disagrees."""

    seeds: list[int]
    names: list[str]
    classes: list[int | None]
    log_evidence: np.ndarray
    """``(runs,)`` each run's total ln Z."""
    log_evidence_err: np.ndarray
    class_log_evidence: np.ndarray
    """``(runs, classes)``"""
    class_log_evidence_err: np.ndarray
    class_weights: np.ndarray
    """``(runs, classes)`` each run's class weights."""
    merged_weights: np.ndarray
    quantiles: np.ndarray
    """``(runs, ndim, 3)`` each run's 5/50/95 % quantiles."""
    merged_sd: np.ndarray
    """``(ndim,)`` the merged posterior's sd of each parameter."""
    quantile_mc_sd: np.ndarray
    """``(runs, ndim, 3)`` each run's Monte Carlo error of each quantile (module docstring), by the delta method."""
    nsigma: float
    quantile_tol: float
    class_threshold: float
    failures: list[str] = field(default_factory=list)
    bad_parameters: list[str] = field(default_factory=list)
    cdf_at: np.ndarray | None = None
    """``(runs, runs, ndim, 3)``: ``[s, r]`` run ``s``'s CDF at run ``r``'s quantiles (``None``: a check saved before
    the comparison in probability, which keeps the delta method's)."""
    cdf_sd: np.ndarray | None = None
    """``(runs, ndim, 3)`` each run's Monte Carlo error of its CDF at its quantiles (the draws' and the weights')."""
    mc_dof: int = 0
    """The degrees of freedom of the draws' Monte Carlo error where it is estimated from the runs' islands (pooled
    over the runs, :func:`islands_cdf_var`); 0: not estimated (the binomial's of the effective draws)."""

    @property
    def mc_nsigma(self) -> float:
        """The comparisons in probability's threshold: ``nsigma`` where their error is known; where it is estimated
        from ``mc_dof`` degrees of freedom, Student's t quantile of the same tail probability (a difference over an
        estimated sd is t-distributed: with 9 degrees of freedom a 3-sigma test's false alarms are 0.27 % at 4.09,
        and 2.4 % at 3 -- over the check's ~200 comparisons, most runs of a sound sampler would fail)."""
        if not self.mc_dof:
            return self.nsigma
        from scipy import stats

        return float(stats.t.ppf(stats.norm.cdf(self.nsigma), self.mc_dof))

    @property
    def passed(self) -> bool:
        return not self.failures

    def spread(self) -> np.ndarray:
        """``(ndim, 3)`` each quantile's spread (max - min) over the runs, in merged posterior sd."""
        sd = np.where(self.merged_sd > 0, self.merged_sd, np.inf)
        out: np.ndarray = np.ptp(self.quantiles, axis=0) / sd[:, None]
        return out

    def excess(self) -> np.ndarray:
        """``(ndim, 3)`` the largest, over the pairs of runs, of the smaller of two ratios; above 1: the runs
        disagree. The quantiles' difference over ``quantile_tol`` posterior sd; and, in probability, each run's CDF at
        the other's quantile less ``q`` over ``nsigma`` of the pair's Monte Carlo error of the CDF (the module
        docstring's error, compared where it is defined: a quantile in a gap between two classes' draws, where the
        CDF is flat, moves far for a small change of the weights, which the delta method's sd does not hold)."""
        q = self.quantiles
        d = np.abs(q[:, None] - q[None, :])
        sd = np.where(self.merged_sd > 0, self.merged_sd, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            by_sd = np.where(d > 0, d / (self.quantile_tol * sd[:, None]), 0.0)
            if self.cdf_at is None or self.cdf_sd is None:  # saved before: the delta method's sd of the quantile
                e, gap = self.quantile_mc_sd, d
            else:
                e, at = self.cdf_sd, self.cdf_at
                gap = np.maximum(np.abs(at - np.array(QUANTILES)), np.abs(np.swapaxes(at, 0, 1) - QUANTILES))
            by_mc = np.where(gap > 0, gap / (self.mc_nsigma * np.sqrt(e[:, None] ** 2 + e[None, :] ** 2)), 0.0)
        out: np.ndarray = np.max(np.minimum(by_sd, by_mc), axis=(0, 1))
        return out

    def criteria(self) -> str:
        dof = self.mc_dof
        islands = f"; the draws' from the runs' islands, {dof} degrees of freedom, Student's t" if dof else ""
        return (
            f"ln Z of every pair of runs within {self.nsigma:g} sigma; 5/50/95 % quantiles of every pair within "
            f"{self.quantile_tol:g} posterior sd, or, where further apart, each run's CDF at the other's quantile "
            f"within {self.mc_nsigma:.3g} sigma of their Monte Carlo error there (the draws' and the class "
            f"weights'{islands}); every class weighted above {100 * self.class_threshold:g} % by a run present in "
            f"the merged posterior"
        )

    def summary_line(self) -> str:
        if self.passed:
            return f"between-run check ({len(self.seeds)} runs, seeds {_seeds(self.seeds)}): PASSED ({self.criteria()})"
        return f"between-run check ({len(self.seeds)} runs, seeds {_seeds(self.seeds)}): FAILED -- " + "; ".join(
            self.failures
        )

    def to_dict(self) -> dict[str, Any]:
        sp, ex = self.spread(), self.excess()
        return {
            "passed": self.passed,
            "seeds": self.seeds,
            "nsigma": self.nsigma,
            "mc_dof": self.mc_dof,
            "mc_nsigma": self.mc_nsigma,
            "quantile_tol_sd": self.quantile_tol,
            "class_threshold": self.class_threshold,
            "failures": self.failures,
            "bad_parameters": self.bad_parameters,
            "log_evidence": self.log_evidence.tolist(),
            "log_evidence_err": self.log_evidence_err.tolist(),
            "classes": [
                {
                    "class": k,
                    "log_evidence": self.class_log_evidence[:, j].tolist(),
                    "log_evidence_err": self.class_log_evidence_err[:, j].tolist(),
                    "weights": self.class_weights[:, j].tolist(),
                    "merged_weight": float(self.merged_weights[j]),
                }
                for j, k in enumerate(self.classes)
            ],
            "parameters": {
                n: {
                    "quantiles": self.quantiles[:, i, :].tolist(),
                    "spread_sd": sp[i].tolist(),
                    "quantile_mc_sd": self.quantile_mc_sd[:, i, :].tolist(),
                    "cdf_sd": None if self.cdf_sd is None else self.cdf_sd[:, i, :].tolist(),
                    "excess": ex[i].tolist(),
                }
                for i, n in enumerate(self.names)
            },
        }

    def table(self, class_label: Any = str) -> str:
        """The runs side by side: ln Z, class weights, each parameter's median and the quantiles' spread."""
        r = len(self.seeds)
        head = f"{'':<40}" + "".join(f" {'seed ' + str(s):>16}" for s in self.seeds)
        lines = [self.summary_line(), head]
        lz = zip(self.log_evidence, self.log_evidence_err)
        lines.append(f"{'ln Z':<40}" + "".join(f" {z:>9.2f} +-{e:>4.2f}" for z, e in lz))
        for j, k in enumerate(self.classes):
            if np.max(self.class_weights[:, j]) > self.class_threshold:
                ws = "".join(f" {100 * w:>15.1f}%" for w in self.class_weights[:, j])
                lines.append(f"{'weight ' + class_label(k):<40}" + ws)
        sp = self.spread()
        lines.append(f"{'median (5/50/95 % spread over runs, sd)':<40}" + " " * (17 * r))
        for i, n in enumerate(self.names):
            flag = "  <-- runs disagree" if n in self.bad_parameters else ""
            lines.append(
                f"{n:<40}"
                + "".join(f" {q:>16.4g}" for q in self.quantiles[:, i, 1])
                + f"  ({sp[i, 0]:.2f}/{sp[i, 1]:.2f}/{sp[i, 2]:.2f}){flag}"
            )
        return "\n".join(lines)


def _seeds(seeds: list[int]) -> str:
    return ", ".join(str(s) for s in seeds)


def _pairs_disagree(z: np.ndarray, e: np.ndarray, nsigma: float) -> bool:
    """Some pair of finite ``z`` further apart than ``nsigma`` of their combined error."""
    ok = np.isfinite(z)
    z, e = z[ok], e[ok]
    d = np.abs(z[:, None] - z[None, :])
    s = np.sqrt(e[:, None] ** 2 + e[None, :] ** 2)
    return bool(np.any(d > nsigma * s + 1e-12))


def between_run_check(
    per_run: Sequence[Sequence[ClassResult]],
    merged: Combined,
    seeds: Sequence[int],
    names: Sequence[str],
    *,
    n_classes: int,
    n_draws: int,
    rng: np.random.Generator,
    class_label: Any = str,
    nsigma: float = 3.0,
    quantile_tol: float = 0.5,
    class_threshold: float = 0.01,
) -> RunsCheck:
    """Compare the runs (``per_run[r]``: run ``r``'s result of every class in ``merged.classes``, in that order)
    with each other and with ``merged`` (the module docstring's three criteria)."""
    runs = [combine_classes(list(rr), n_classes, n_draws, rng) for rr in per_run]
    cz = np.array([[c.log_evidence for c in rr] for rr in per_run])
    ce = np.array([[c.log_evidence_err for c in rr] for rr in per_run])
    q = np.array([np.quantile(r.draws, QUANTILES, axis=0).T for r in runs])
    weights_var = np.array([class_weights_cdf_var(r, qr, err, rng) for r, qr, err in zip(runs, q, ce)])
    ess = np.array([r.ess_kish for r in runs])
    draws_var, dof = _draws_cdf_var(ess), 0
    by_islands = [islands_cdf_var(list(rr), r.weights, qr) for rr, r, qr in zip(per_run, runs, q)]
    if all(v is not None for v in by_islands):  # the runs sample one posterior alike (the check's hypothesis): pooled
        draws_var = np.maximum(draws_var, np.mean(np.array(by_islands), axis=0)[None])
        dof = sum(_islands(rr) - 1 for rr in per_run)
    mc = quantile_mc_sd(merged.draws, ess, weights_var=weights_var, draws_var=draws_var)
    cdf_at = np.array([[_cdf(rs.draws, qr) for qr in q] for rs in runs])
    chk = RunsCheck(
        seeds=list(seeds),
        names=list(names),
        classes=list(merged.classes),
        log_evidence=np.array([r.log_evidence for r in runs]),
        log_evidence_err=np.array([r.log_evidence_err for r in runs]),
        class_log_evidence=cz,
        class_log_evidence_err=ce,
        class_weights=np.array([r.weights for r in runs]),
        merged_weights=merged.weights,
        quantiles=q,
        merged_sd=np.std(merged.draws, axis=0),
        quantile_mc_sd=mc,
        cdf_at=cdf_at,
        cdf_sd=np.sqrt(draws_var + weights_var),
        mc_dof=dof,
        nsigma=nsigma,
        quantile_tol=quantile_tol,
        class_threshold=class_threshold,
    )
    _judge(chk, merged, class_label)
    return chk


def quantile_mc_sd(
    draws: np.ndarray, ess: np.ndarray, *, half_width: float = 0.025, weights_var: np.ndarray | None = None,
    draws_var: np.ndarray | None = None,
) -> np.ndarray:  # fmt: skip
    """``(runs, ndim, 3)`` the Monte Carlo sd of the 5/50/95 % quantiles of a run of effective sample size
    ``ess[r]``: ``sqrt(q (1 - q) / ess + weights_var) / p(x_q)``, the density at the quantile read from ``draws`` as
    ``2 half_width / (x_{q + half_width} - x_{q - half_width})``; ``weights_var``: ``(runs, ndim, 3)`` the variance
    of the run's CDF at its quantiles from its class weights (:func:`class_weights_cdf_var`), none by default;
    ``draws_var``: the draws' variance of the CDF where it is known better than ``q (1 - q) / ess`` (from islands,
    :func:`islands_cdf_var`)."""
    q = np.array(QUANTILES)
    lo = np.quantile(draws, np.clip(q - half_width, 0, 1), axis=0).T
    hi = np.quantile(draws, np.clip(q + half_width, 0, 1), axis=0).T
    inv_density = (hi - lo) / (np.clip(q + half_width, 0, 1) - np.clip(q - half_width, 0, 1))
    var = _draws_cdf_var(ess) if draws_var is None else draws_var
    if weights_var is not None:
        var = var + weights_var
    out: np.ndarray = np.sqrt(var) * inv_density[None, :, :]
    return out


def _draws_cdf_var(ess: np.ndarray) -> np.ndarray:
    """``(runs, 1, 3)`` the variance ``q (1 - q) / ess`` of a run's CDF at its 5/50/95 % quantiles from its draws."""
    q = np.array(QUANTILES)
    out: np.ndarray = (q * (1 - q))[None, None, :] / np.maximum(ess, 1.0)[:, None, None]
    return out


def islands_cdf_var(results: Sequence[ClassResult], weights: np.ndarray, at: np.ndarray) -> np.ndarray | None:
    """``(ndim, 3)`` the variance of a run's CDF at ``at`` (``(ndim, 3)``) from the spread of its independent islands:
    the run's CDF is ``F = sum_k W_k F_k`` over its classes (``weights``), each class's the weighted mean of its ``K``
    islands' (each carries ``p_ki`` of the class's weight, ``1 / K`` in :func:`~fpm_sim.study.calibrate.smc.merge_smc`),
    so ``var F = sum_k W_k^2 K / (K - 1) sum_i (A_ki - p_ki F_k)^2`` (a ratio estimator's), ``A_ki`` island ``i``'s
    weight at or below ``at``. Unlike
    ``q (1 - q) / ESS`` of the pooled draws it counts the correlation between an island's particles (the moves'
    along a ridge). ``None`` where a sampled class has no island labels or one island."""
    out = np.zeros(at.shape)
    for r, w_k in zip(results, weights):
        if not len(r.samples) or not w_k > 0:
            continue
        labels = np.unique(r.island) if r.island is not None else np.zeros(0, int)
        if len(labels) < 2:
            return None
        assert r.island is not None
        p = np.exp(r.logwt - np.max(r.logwt))
        p /= p.sum()
        below = r.samples[:, :, None] <= at[None]
        f_k = np.einsum("n,nij->ij", p, below)
        acc = np.zeros(at.shape)
        for i in labels:
            mine = r.island == i
            acc += (np.einsum("n,nij->ij", p[mine], below[mine]) - p[mine].sum() * f_k) ** 2
        out += w_k**2 * len(labels) / (len(labels) - 1) * acc
    return out


def _islands(results: Sequence[ClassResult]) -> int:
    """The fewest islands any sampled class of a run has."""
    return min(len(np.unique(r.island)) for r in results if r.island is not None and len(r.samples))


def _cdf(draws: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``(ndim, 3)`` the fraction of ``draws`` (``(n, ndim)``) at or below each of ``at`` (``(ndim, 3)``)."""
    out: np.ndarray = np.mean(draws[:, :, None] <= at[None], axis=0)
    return out


def class_weights_cdf_var(
    run: Combined, quantiles: np.ndarray, log_z_err: np.ndarray, rng: np.random.Generator, *, draws: int = 20_000
) -> np.ndarray:
    """``(ndim, 3)`` the variance of the run's CDF at its own 5/50/95 % ``quantiles`` (``(ndim, 3)``) that its class
    weights' errors give (module docstring): each ``ln Z_k`` drawn ``draws`` times about its value with its stated
    error ``log_z_err[k]``, the weights ``Z_k / sum Z`` recomputed, and the mixture ``sum_k w_k F_k(x_q)`` of the run's
    per-class CDFs ``F_k`` evaluated each time (the first-order ``sum_k w_k^2 s_k^2 (F_k - q)^2`` is 6-28 % low at
    errors of 0.4 in ln Z: measured in ``tests/study/test_calibrate_runs.py``). A class without draws adds nothing."""
    cdf = np.zeros((len(run.classes), *quantiles.shape))
    for k, klass in enumerate(run.classes):
        mine = run.draws[run.klass == (-1 if klass is None else klass)]
        if len(mine):
            cdf[k] = _cdf(mine, quantiles)
    with np.errstate(divide="ignore"):
        log_w = np.log(run.weights)[None, :] + np.asarray(log_z_err, float)[None, :] * rng.standard_normal(
            (draws, len(run.classes))
        )
    w = np.exp(log_w - np.max(log_w, axis=1, keepdims=True))
    w /= w.sum(axis=1, keepdims=True)
    out: np.ndarray = np.var(np.einsum("mk,kij->mij", w, cdf), axis=0)
    return out


def _judge(chk: RunsCheck, merged: Combined, class_label: Any) -> None:
    """Fill ``chk.failures`` and ``chk.bad_parameters``."""
    if _pairs_disagree(chk.log_evidence, chk.log_evidence_err, chk.nsigma):
        zs = ", ".join(f"{z:.2f} +- {e:.2f}" for z, e in zip(chk.log_evidence, chk.log_evidence_err))
        chk.failures.append(f"ln Z differs between runs beyond {chk.nsigma:g} sigma ({zs})")
    found = np.max(chk.class_weights, axis=0) > chk.class_threshold
    for j, k in enumerate(chk.classes):
        if found[j] and _pairs_disagree(chk.class_log_evidence[:, j], chk.class_log_evidence_err[:, j], chk.nsigma):
            chk.failures.append(f"class {class_label(k)}: ln Z differs between runs beyond {chk.nsigma:g} sigma")
        present = np.any(merged.klass == (-1 if k is None else k))
        if found[j] and (merged.weights[j] < chk.class_threshold / len(chk.seeds) or not present):
            chk.failures.append(
                f"class {class_label(k)}: weighted {100 * np.max(chk.class_weights[:, j]):.1f} % by a run but "
                f"{100 * merged.weights[j]:.2f} % in the merged posterior"
            )
    bad = np.any(chk.excess() > 1.0, axis=1)
    chk.bad_parameters = [n for n, b in zip(chk.names, bad) if b]
    if chk.bad_parameters:
        chk.failures.append(
            f"quantiles disagree by more than {chk.quantile_tol:g} sd (and, in probability, their Monte Carlo error) "
            f"for: "
            f"{', '.join(chk.bad_parameters)}"
        )
