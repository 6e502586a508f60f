"""Nested sampling of a :class:`CalibrationProblem` with dynesty (multimodal posteriors, the evidence with its
error), likelihood calls in a ``spawn`` process pool, a checkpoint file and resuming from it.

The pool's workers receive the problem once, in their initializer (:func:`_init_worker`), and evaluate the
module-level :func:`_worker_log_likelihood` / :func:`_worker_prior_transform`; nothing relies on ``fork``.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.batch.engine import spawn_pool
from fpm_sim.figures import bands_against_measured
from fpm_sim.study.calibrate.problem import CalibrationError, CalibrationProblem
from fpm_sim.study.loo import LeaveOneOut, leave_one_out, loo_from_components
from fpm_sim.study.readout import draws_components, responsibilities

__all__ = ["Calibration", "SamplerOptions", "problem_digest", "run_calibration"]

_PROBLEM: CalibrationProblem | None = None
"""The problem of this worker process (set by :func:`_init_worker`)."""


def _init_worker(problem: CalibrationProblem) -> None:
    global _PROBLEM
    _PROBLEM = problem
    _ = problem.parameters  # build the parameter set once per worker


def _worker_log_likelihood(theta: np.ndarray) -> float:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.log_likelihood(theta)


def _worker_prior_transform(u: np.ndarray) -> np.ndarray:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.prior_transform(u)


def _worker_predict(theta: np.ndarray) -> np.ndarray:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.predict(theta)


def problem_digest(problem: CalibrationProblem) -> str:
    """A fingerprint of the problem's data (the repr of its fields: deterministic, unlike a pickle's bytes),
    stored beside a checkpoint to refuse a mismatched resume."""
    fields = tuple(getattr(problem, f.name) for f in dataclasses.fields(problem))
    return hashlib.sha256(repr(fields).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class SamplerOptions:
    """dynesty settings. ``sample``: its proposal (``"rwalk"``: random walks from live points, robust in 10-20
    dimensions; ``"unif"``: uniform in the bounding ellipsoids, for few dimensions)."""

    live_points: int = 250
    dlogz: float = 0.5
    seed: int = 0
    workers: int = 1
    sample: str = "rwalk"
    walks: int | None = None
    """``rwalk``: steps of each random walk (dynesty's default when None: 20 + ndim)."""
    max_calls: int | None = None
    draws: int = 1000
    """Equal-weight draws resampled from the weighted samples for the posterior file."""
    checkpoint_every_s: float = 60.0

    def check(self) -> None:
        if self.live_points < 2:
            raise CalibrationError("must be >= 2", parameter="live_points", value=self.live_points)
        if not self.dlogz > 0:
            raise CalibrationError("must be > 0", parameter="dlogz", value=self.dlogz)
        if self.workers < 1:
            raise CalibrationError("must be >= 1", parameter="workers", value=self.workers)
        if self.walks is not None and self.walks < 2:
            raise CalibrationError("must be >= 2", parameter="walks", value=self.walks)
        if self.draws < 1:
            raise CalibrationError("must be >= 1", parameter="draws", value=self.draws)
        if self.max_calls is not None and self.max_calls < self.live_points:
            raise CalibrationError(
                f"must be >= the number of live points ({self.live_points})",
                parameter="max_calls",
                value=self.max_calls,
                hint="allow more likelihood calls or use fewer live points",
            )


@dataclass
class Calibration:
    """The result of :func:`run_calibration`: equal-weight draws and the run's diagnostics."""

    problem: CalibrationProblem
    options: SamplerOptions
    draws: np.ndarray
    """``(n_draws, ndim)`` equal-weight draws of ``theta`` (:attr:`CalibrationProblem.names`)."""
    log_likelihood: np.ndarray
    """``(n_draws,)``"""
    log_evidence: float
    log_evidence_err: float
    n_calls: int
    n_iterations: int
    ess_kish: float
    """Kish's effective sample size of the weighted nested samples, ``(sum w)^2 / sum w^2``."""
    seconds: float
    converged: bool
    """The run stopped on ``dlogz`` (False: on ``max_calls``)."""
    f_pred: np.ndarray
    """``(n_draws, n_data)`` the model's frequencies at each draw (observations then rig tests)."""
    f_noisy: np.ndarray
    """``(n_draws, n_data)`` ``f_pred`` plus one draw of the likelihood's noise (``s_i``): the predictive of a
    new measurement, what coverage is checked against."""
    start_log_likelihood: float = math.nan
    """:meth:`CalibrationProblem.start_log_likelihood`: compare with ``log_likelihood.max()``."""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def missed_start(self) -> bool:
        """The start description fits better (by more than 1 in log L) than every draw: the sampler missed its
        region, the posterior is incomplete (more live points needed)."""
        return bool(self.start_log_likelihood > float(np.max(self.log_likelihood)) + 1.0)

    @property
    def names(self) -> list[str]:
        return self.problem.names

    @functools.cached_property
    def readouts(self) -> list[tuple[np.ndarray, np.ndarray, float]] | None:
        """Under the latent-mode model (:mod:`fpm_sim.study.readout`): per draw the lowest modes' frequencies at
        the observations ``(n, modes)``, the read probabilities ``(setups, n, modes)`` and the discrepancy;
        ``None`` otherwise."""
        p = self.problem
        if p.priors.mode_read is None:
            return None
        out = []
        for t in self.draws:
            freq, probs = p.read_modes(p.config(t))
            out.append((freq, probs, p.split(t)[1]))
        return out

    def _components(self, *, leave_out: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(n_draws, n_obs, C)`` means, sds and weights of each draw's predictive of every observation
        (latent-mode model only; :func:`fpm_sim.study.readout.components`)."""
        p = self.problem
        n = len(p.observations)
        assert self.readouts is not None
        freq, probs, d = (np.array([r[j] for r in self.readouts]) for j in range(3))
        return draws_components(p.measured[:n], p.sigma[:n], freq, probs, d, leave_out=leave_out)

    @functools.cached_property
    def predictive_sample(self) -> np.ndarray:
        """``(n_draws, n_data)`` one draw of a new measurement per posterior draw: :attr:`f_noisy`, or under the
        latent-mode model a draw of the mixture (setup given the data, mode by its read probability, then the
        discrepancy and noise), seeded."""
        if self.readouts is None:
            return self.f_noisy
        mu, sd, w = self._components(leave_out=False)
        rng = np.random.default_rng(0)
        cum = np.cumsum(w, axis=-1)
        pick = (rng.random(cum.shape[:-1])[..., None] > cum).sum(axis=-1).clip(max=w.shape[-1] - 1)
        m = np.take_along_axis(mu, pick[..., None], -1)[..., 0]
        v = np.take_along_axis(sd, pick[..., None], -1)[..., 0]
        out = self.f_noisy.copy()
        out[:, : mu.shape[1]] = m + v * rng.standard_normal(m.shape)
        return out

    def read_responsibility(self) -> np.ndarray | None:
        """``(n_obs, modes)`` posterior probability that each measured value was mode ``k`` (latent-mode model;
        ``None`` otherwise): the draws' :func:`fpm_sim.study.readout.responsibilities`, averaged."""
        if self.readouts is None:
            return None
        p = self.problem
        n = len(p.observations)
        r = [responsibilities(p.measured[:n], p.sigma[:n], f, pr, d) for f, pr, d in self.readouts]
        out: np.ndarray = np.mean(r, axis=0)
        return out

    def column(self, name: str) -> np.ndarray:
        return self.draws[:, self.names.index(name)]

    def quantiles(self, q: tuple[float, ...] = (0.05, 0.5, 0.95)) -> np.ndarray:
        """``(ndim, len(q))`` marginal quantiles of every coordinate."""
        out: np.ndarray = np.quantile(self.draws, q, axis=0).T
        return out

    def bands(self, level: float, *, noisy: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Central ``level`` predictive band (lower, upper) of every datum."""
        f = self.predictive_sample if noisy else self.f_pred
        a = 0.5 * (1.0 - level)
        lo: np.ndarray = np.quantile(f, a, axis=0)
        hi: np.ndarray = np.quantile(f, 1.0 - a, axis=0)
        return lo, hi

    def coverage(self, level: float) -> np.ndarray:
        """Per datum: the measured value lies in the ``level`` predictive band (bool)."""
        lo, hi = self.bands(level)
        y = self.problem.measured
        inside: np.ndarray = (y >= lo) & (y <= hi)
        return inside

    def leave_one_out(self) -> LeaveOneOut:
        """PSIS leave-one-out predictive of every measured pose (:mod:`fpm_sim.study.loo`; rig tests aside)."""
        p = self.problem
        n = len(p.observations)
        if self.readouts is not None:
            mu, sd, w = self._components(leave_out=True)
            return loo_from_components(mu, sd, w, p.measured[:n], labels=p.labels[:n])
        d = np.array([p.split(t)[1] for t in self.draws])
        ls = None if p.priors.length_scale is None else np.array([p.length_scale_m(t) for t in self.draws])
        return leave_one_out(
            self.f_pred[:, :n],
            p.measured[:n],
            p.sigma[:n],
            d,
            features=p.features,
            length_scale_m=ls,
            labels=p.labels[:n],
        )

    def to_dict(self) -> dict[str, Any]:
        q = self.quantiles()
        pri = {p.name: p for p in self.problem.priors.parameters}
        pri.update({h.name: h for h in self.problem.priors.hyperpriors})
        params = {}
        for i, n in enumerate(self.names):
            params[n] = {
                "q05": float(q[i, 0]),
                "median": float(q[i, 1]),
                "q95": float(q[i, 2]),
                "mean": float(np.mean(self.draws[:, i])),
                "sd": float(np.std(self.draws[:, i])),
                "prior": pri[n].describe() if n in pri else self.problem.priors.branch_reason,
            }
        lo50, hi50 = self.bands(0.5)
        lo90, hi90 = self.bands(0.9)
        data = [
            {
                "label": lab,
                "measured_hz": float(y),
                "median_hz": float(m),
                "band50_hz": [float(a), float(b)],
                "band90_hz": [float(c), float(d)],
            }
            for lab, y, m, a, b, c, d in zip(
                self.problem.labels, self.problem.measured, np.median(self.f_pred, axis=0), lo50, hi50, lo90, hi90
            )
        ]
        return {
            "names": self.names,
            "parameters": params,
            "log_evidence": self.log_evidence,
            "log_evidence_err": self.log_evidence_err,
            "n_calls": self.n_calls,
            "n_iterations": self.n_iterations,
            "ess_kish": self.ess_kish,
            "n_draws": len(self.draws),
            "seconds": self.seconds,
            "converged": self.converged,
            "start_log_likelihood": self.start_log_likelihood,
            "max_log_likelihood": float(np.max(self.log_likelihood)),
            "missed_start": self.missed_start,
            "coverage50": float(np.mean(self.coverage(0.5))),
            "coverage90": float(np.mean(self.coverage(0.9))),
            "leave_one_out": self.leave_one_out().to_dict() if len(self.problem.observations) > 1 else None,
            "data": data,
            "options": {
                k: getattr(self.options, k) for k in ("live_points", "dlogz", "seed", "sample", "walks", "max_calls")
            },
        }

    def table(self) -> str:
        q = self.quantiles()
        lines = [
            f"log-evidence {self.log_evidence:.2f} +- {self.log_evidence_err:.2f}; {self.n_calls} likelihood calls, "
            f"{self.n_iterations} iterations, Kish ESS {self.ess_kish:.0f}, {self.seconds:.0f} s"
            + ("" if self.converged else " (stopped on the likelihood-call limit (max_calls): NOT converged)"),
            f"best log-likelihood among the draws {np.max(self.log_likelihood):.2f}; at the start description "
            f"{self.start_log_likelihood:.2f}"
            + (
                " -- the sampler MISSED the start's region: posterior incomplete, use more live points"
                if self.missed_start
                else ""
            ),
            f"{'parameter':<40} {'5 %':>11} {'50 %':>11} {'95 %':>11}",
        ]
        for i, n in enumerate(self.names):
            lines.append(f"{n:<40} {q[i, 0]:>11.4g} {q[i, 1]:>11.4g} {q[i, 2]:>11.4g}")
        c50, c90 = self.coverage(0.5), self.coverage(0.9)
        lines.append(
            f"measured values inside the 50 % / 90 % predictive bands: {c50.sum()}/{len(c50)} / {c90.sum()}/{len(c90)}"
        )
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Predicted (median, 50 % and 90 % predictive bands) against measured, per datum."""
        import matplotlib.pyplot as plt

        fig = ax.figure if ax is not None else plt.figure(figsize=(6.5, 5.5))
        ax = ax if ax is not None else fig.add_subplot(111)
        lo50, hi50 = self.bands(0.5)
        lo90, hi90 = self.bands(0.9)
        med = np.median(self.predictive_sample, axis=0)
        bands_against_measured(
            ax,
            self.problem.measured,
            [lo90, lo50, med, hi50, hi90],
            what="predictive",
            colour="tab:blue",
            ylabel="predicted frequency (Hz)",
            title=f"posterior predictive at the data ({len(self.draws)} draws)",
        )
        return fig


def _ess_kish(logwt: np.ndarray) -> float:
    w = np.exp(logwt - np.max(logwt))
    return float(w.sum() ** 2 / np.sum(w**2))


def _pool(problem: CalibrationProblem, workers: int) -> Any:
    """A spawn pool whose workers hold ``problem`` and ignore Ctrl-C (:func:`fpm_sim.batch.engine.spawn_pool`)."""
    return spawn_pool(workers, _init_worker, (problem,))


def _run_sampler(
    problem: CalibrationProblem,
    opts: SamplerOptions,
    pool: Any,
    *,
    checkpoint: Path | None,
    resume: bool,
    progress: bool,
) -> Any:
    """dynesty's static sampler run to ``opts.dlogz``: a fresh one, or restored from ``checkpoint`` (checked
    against the problem's fingerprint in the ``.digest`` file beside it)."""
    import dynesty

    digest = problem_digest(problem)
    kw: dict[str, Any] = {}
    if checkpoint is not None:
        kw.update(checkpoint_file=str(checkpoint), checkpoint_every=opts.checkpoint_every_s)
    digest_file = Path(str(checkpoint) + ".digest")
    if resume:
        if checkpoint is None or not Path(checkpoint).exists():
            raise CalibrationError(
                "no checkpoint file to resume from",
                parameter="resume",
                value=None if checkpoint is None else str(checkpoint),
                hint="start a fresh run (resume off) first",
            )
        if not digest_file.exists() or digest_file.read_text().strip() != digest:
            raise CalibrationError(
                "the checkpoint belongs to another problem (data, priors, free groups, base description or "
                "segments differ)",
                parameter="resume",
                file=checkpoint,
                hint="start a fresh run (resume off) into an empty or overwritten output folder",
            )
        sampler = dynesty.NestedSampler.restore(str(checkpoint), pool=pool)
        # a run interrupted mid-way continues (resume=True); one that ended on max_calls has its final live
        # points added to the results, which dynesty takes out again and continues from with resume=False
        finished = bool(getattr(sampler, "added_live", False))
        sampler.run_nested(dlogz=opts.dlogz, maxcall=opts.max_calls, print_progress=progress, resume=not finished, **kw)
        return sampler
    if checkpoint is not None:
        digest_file.write_text(digest)
    sampler = dynesty.NestedSampler(
        _worker_log_likelihood,
        _worker_prior_transform,
        problem.ndim,
        nlive=opts.live_points,
        sample=opts.sample,
        walks=opts.walks,
        rstate=np.random.default_rng(opts.seed),
        pool=pool,
        queue_size=opts.workers if pool is not None else None,
    )
    sampler.run_nested(dlogz=opts.dlogz, maxcall=opts.max_calls, print_progress=progress, **kw)
    return sampler


def _equal_weight_indices(logwt: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``n`` equal-weight draws (at most as many as the run has samples) from the weighted samples."""
    from dynesty.utils import resample_equal

    w = np.exp(logwt - np.max(logwt))
    w /= w.sum()
    idx_all = resample_equal(np.arange(len(w)), w, rstate=rng)
    out: np.ndarray = rng.choice(idx_all, size=min(n, len(idx_all)), replace=False)
    return out


def run_calibration(
    problem: CalibrationProblem,
    options: SamplerOptions | None = None,
    *,
    checkpoint: Path | None = None,
    resume: bool = False,
    progress: bool = True,
    print_func: Callable[..., None] | None = None,
) -> Calibration:
    """Sample the posterior of ``problem`` with dynesty's static nested sampler.

    ``checkpoint``: dynesty's checkpoint file, written every ``options.checkpoint_every_s`` seconds (a
    ``.digest`` file beside it records the problem's fingerprint); ``resume``: continue from it (refused when
    the problem differs).
    """
    opts = options or SamplerOptions()
    opts.check()
    _init_worker(problem)  # this process too: dynesty may call the functions here
    t0 = time.time()
    pool = _pool(problem, opts.workers) if opts.workers > 1 else None
    try:
        sampler = _run_sampler(problem, opts, pool, checkpoint=checkpoint, resume=resume, progress=progress)
        res = sampler.results
        logwt = np.asarray(res["logwt"])
        rng = np.random.default_rng(opts.seed + 1)
        idx = _equal_weight_indices(logwt, opts.draws, rng)
        draws = np.asarray(res["samples"])[idx]
        logl = np.asarray(res["logl"])[idx]
        uniq, inverse = np.unique(idx, return_inverse=True)
        thetas = [np.asarray(res["samples"])[i] for i in uniq]
        preds = pool.map(_worker_predict, thetas) if pool is not None else [problem.predict(t) for t in thetas]
        f_pred = np.asarray(preds)[inverse.ravel()]
        n_calls = int(np.sum(res["ncall"]))
        niter = int(res["niter"])
        logz, logzerr = float(res["logz"][-1]), float(res["logzerr"][-1])
        ess = _ess_kish(logwt)
        # the run stops on dlogz unless max_calls came first
        converged = opts.max_calls is None or n_calls < opts.max_calls
    except BaseException:  # Ctrl-C or an error: the workers (which ignore Ctrl-C) stop now, their queued work unrun
        if pool is not None:
            pool.terminate()
        raise
    if pool is not None:
        pool.close()
        pool.join()
    f_noisy = np.stack([problem.simulate_measurement(f, t, rng) for f, t in zip(f_pred, draws)])
    start_ll = problem.start_log_likelihood()
    if print_func is not None:
        print_func(f"nested sampling: {n_calls} calls, log Z = {logz:.2f} +- {logzerr:.2f}")
    return Calibration(
        problem=problem,
        options=opts,
        draws=draws,
        log_likelihood=logl,
        log_evidence=logz,
        log_evidence_err=logzerr if math.isfinite(logzerr) else math.nan,
        n_calls=n_calls,
        n_iterations=niter,
        ess_kish=ess,
        seconds=time.time() - t0,
        converged=converged,
        f_pred=f_pred,
        f_noisy=f_noisy,
        start_log_likelihood=start_ll,
    )
