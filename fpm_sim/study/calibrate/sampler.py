"""Nested sampling of a calibration problem (:class:`~fpm_sim.study.calibrate.problem.FrequencyLikelihood`: the
3RRR's or a described machine's) with dynesty (multimodal posteriors, the evidence with its error), likelihood calls
in a ``spawn`` process pool, a checkpoint file and resuming from it.

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
from fpm_sim.study.calibrate.emulator import PARETO_K_MAX, Emulator, importance_diagnostics, train_emulator
from fpm_sim.study.calibrate.priors import BRANCH_PARAMETER
from fpm_sim.study.calibrate.problem import CalibrationError, CalibrationProblem, FrequencyLikelihood
from fpm_sim.study.calibrate.runs import (
    ClassResult,
    Combined,
    RunsCheck,
    between_run_check,
    combine_classes,
    combine_parts,
)
from fpm_sim.study.calibrate.smc import (
    ModeProposal,
    SmcSettings,
    emulated_two_stage,
    merge_smc,
    smc_results,
    spread_over_mode,
    two_stage,
)
from fpm_sim.study.calibrate.vectorised import (
    cheap_log_likelihood_batch,
    family_frequencies_batch,
    inplane_log_likelihood_batch,
    inplane_split_log_likelihood_batch,
    split_log_likelihood_batch,
    supports,
)
from fpm_sim.study.identify.problem import cyclic_branch_orbits
from fpm_sim.study.loo import LeaveOneOut, leave_one_out, loo_from_components
from fpm_sim.study.readout import draws_components, responsibilities

__all__ = [
    "SAMPLERS",
    "Calibration",
    "ClassSummary",
    "SamplerOptions",
    "class_prior_mass",
    "problem_digest",
    "run_calibration",
    "sample_classes",
    "sampled_classes",
]

SAMPLERS = ("dynesty", "smc")
"""The calibration's samplers (:attr:`SamplerOptions.sampler`)."""

_PROBLEM: FrequencyLikelihood | None = None
"""The problem of this worker process (set by :func:`_init_worker`)."""


def _init_worker(problem: FrequencyLikelihood) -> None:
    global _PROBLEM
    _PROBLEM = problem
    problem.prepare()  # build what every call shares once per worker (the 3RRR's parameter set)


def _worker_log_likelihood(theta: np.ndarray) -> float:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.log_likelihood(theta)


def _worker_prior_transform(u: np.ndarray) -> np.ndarray:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.prior_transform(u)


def _worker_predict(theta: np.ndarray) -> np.ndarray:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.predict(theta)


def _worker_families(theta: np.ndarray) -> np.ndarray:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    out: np.ndarray = _PROBLEM.predict_families(theta)  # type: ignore[attr-defined]
    return out


def _with_class(theta: np.ndarray, klass: int | None) -> np.ndarray:
    """The problem's coordinates: the continuous ones, then the class index (when the branches are enumerated)."""
    return np.asarray(theta, float) if klass is None else np.append(np.asarray(theta, float), float(klass))


def _class_log_likelihood(theta: np.ndarray, klass: int | None) -> float:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    return _PROBLEM.log_likelihood(_with_class(theta, klass))


Part = tuple[int, int, int] | None
"""One part of a split prior (:attr:`SamplerOptions.split`): ``(coordinate, parts, part)``, the coordinate's unit-cube
interval ``[part / parts, (part + 1) / parts)`` (prior mass ``1 / parts``); ``None``: the whole prior."""


def _in_part(u: np.ndarray, part: Part) -> np.ndarray:
    """The unit-cube point ``u`` (or rows of points) of the part's own cube mapped into the whole prior's cube."""
    if part is None:
        return np.asarray(u, float)
    i, n, p = part
    out = np.array(u, float)
    out[..., i] = (p + out[..., i]) / n
    return out


def _class_prior_transform(u: np.ndarray, klass: int | None, part: Part = None) -> np.ndarray:
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    u = _in_part(u, part)
    if klass is None:
        return _PROBLEM.prior_transform(u)
    full = _PROBLEM.prior_transform(np.append(np.asarray(u, float), (klass + 0.5) / len(_PROBLEM.branch_classes)))
    out: np.ndarray = full[:-1]
    return out


Job = tuple[int | None, Part, int, "SamplerOptions", str | None, bool, "ModeProposal | None"]
"""One run: ``(class, part, seed, options, checkpoint, resume, modes)`` (``modes``: the SMC's pooled mode search,
:func:`search_modes`)."""


def _worker_run(job: Job, pool: Any = None) -> tuple[int | None, Part, int, Any, float]:
    """One (class, part, seed) run in this process (its likelihood calls on ``pool`` when given):
    ``(class, part, seed, Results, seconds)``."""
    klass, part, seed, opts, checkpoint, resume, modes = job
    t0 = time.time()
    ck = None if checkpoint is None else Path(checkpoint)
    if opts.sampler == "smc":
        res = _run_smc(klass, seed, opts, checkpoint=ck, resume=resume, pool=pool, part=part, modes=modes)
    else:
        res = _run_class(klass, seed, opts, checkpoint=ck, resume=resume, pool=pool, part=part)
    return klass, part, seed, res, time.time() - t0


def problem_digest(problem: FrequencyLikelihood) -> str:
    """A fingerprint of the problem's data (the repr of its fields: deterministic, unlike a pickle's bytes),
    stored beside a checkpoint to refuse a mismatched resume."""
    fields = tuple(getattr(problem, f.name) for f in dataclasses.fields(problem))  # type: ignore[arg-type]
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
    runs: int = 3
    """Independent runs per elbow-branch class (seeds ``seed, seed + 1, ...``), merged, and checked against each
    other (:mod:`fpm_sim.study.calibrate.runs`); ``max_calls`` is per run."""
    nsigma: float = 3.0
    """The between-run check: ln Z of every pair of runs within this many sigma of their combined error."""
    quantile_tol: float = 0.5
    """The between-run check: each parameter's 5/50/95 % quantiles within this fraction of its sd over the runs."""
    class_threshold: float = 0.01
    """The between-run check: a class some run weights above this must be in the merged posterior."""
    probe_draws: int = 400
    """Prior draws per class to find whether it reaches the measured poses at all (none: the class is skipped)."""
    sampler: str = "dynesty"
    """``"dynesty"``: nested sampling (``live_points``, ``dlogz``, ``sample``, ``walks``, ``max_calls``);
    ``"smc"``: two-stage tempered sequential Monte Carlo (:mod:`fpm_sim.study.calibrate.smc`; ``particles``,
    ``cheap_particles``): on the study's problem every run reaches the statements' region, but the runs still
    disagree (docs/identification.md, "Why independent runs still disagree"), so it is not the default."""
    particles: int = 400
    """SMC: particles of the data stage (each tempering step costs ``moves / acceptance`` sweeps of them)."""
    cheap_particles: int = 2000
    """SMC: particles of the first stage (prior times the cheap terms: the support and the study's statements)."""
    ess_fraction: float = 0.5
    """SMC: each tempering step keeps this fraction of the particles as effective sample size."""
    moves: float = 3.0
    """SMC: accepted Metropolis moves per particle (on average) after each tempering step of the data stage."""
    jumps: float = 0.0
    """SMC: the fraction of the data stage's sweeps that propose independent draws of a Gaussian mixture fitted to
    the particles (:attr:`~fpm_sim.study.calibrate.smc.SmcSettings.jumps`): particles move between modes and along a
    ridge in proportion to the posterior's mass there. 0: none (the default)."""
    importance: int = 0
    """SMC: independent draws of a Student-t mixture fitted to the data stage's final particles whose importance
    weights give each run's evidence and posterior (:mod:`~fpm_sim.study.calibrate.importance`): the stated error is
    then the independent draws' own, where the tempering's misses the correlation its moves leave along a ridge. 0:
    none, the tempering's (the default)."""
    crossover: bool = False
    """SMC: the data stage's Metropolis moves each in a random subspace of the coordinates (DREAM's randomised
    subspace sampling, :attr:`~fpm_sim.study.calibrate.smc.SmcSettings.crossover`): loose coordinates then travel at
    their own width. ``False``: every move in all coordinates (the default)."""
    islands: int = 1
    """SMC: independent islands of each run (Verge et al. 2015), each a whole two-stage SMC of ``particles`` and
    ``cheap_particles`` (and its own emulator): the run's evidence is their mean and its stated error at least their
    spread's, and the between-run check reads each quantile's Monte Carlo error from the islands' spread
    (:func:`~fpm_sim.study.calibrate.runs.islands_cdf_var`), both of which count the correlation the moves leave
    along a ridge that the particles' genealogy misses. 1: none, the genealogy's error (the default)."""
    final_moves: float = 0.0
    """SMC: accepted Metropolis moves per particle (on average) at the data stage's end, on the posterior
    (:attr:`~fpm_sim.study.calibrate.smc.SmcSettings.final_moves`): the particles travel along the ridge the
    tempering covered unevenly. 0: none (the default)."""
    cheap_moves: float = 10.0
    """SMC: the same in the first stage (cheap calls; its thin region needs the moves to be represented alike by
    independent runs: at 3 its particles' shares of the region's parts differed between runs by 0.1-0.13)."""
    mode_starts: int = 0
    """SMC: starts of a differential-evolution search for the posterior's modes on the in-plane surrogate before the
    data stages (vectorised; the 3RRR's problem only; :func:`search_modes`), once per class and pooled: every run of
    the class starts its data stage from a defensive mixture of its first stage's particles and as many draws around
    every mode any start found, their mass counted (:func:`~fpm_sim.study.calibrate.smc.two_stage`). 0: no search
    (the default). Exact on problems with known evidences; measured on the study's problem in docs/identification.md,
    "The needle". The search runs on the surrogate, whose posterior is not the segment model's (its compact region
    is 14 nats lower at the median on the segment model: "An emulator of the segment model"), so on the segment model
    it steers the data stage toward a region the reported model does not favour."""
    emulator: int = 0
    """SMC: the data stage on an emulator of the segment model trained on this many segment-model runs at the first
    stage's particles, then importance-weighted to the segment model (exact;
    :mod:`~fpm_sim.study.calibrate.emulator`). The data stage runs twice, the second time on the emulator refitted
    with as many segment-model runs more at the first's particles: about 2 ``emulator`` + ``particles``
    segment-model calls a run instead of ~20 000. Where the second's importance weights are heavy (Pareto k >= 0.7),
    it runs a third time on a refit with every segment-model run so far, the weights' own included, and that is
    reported (``particles`` more calls). 0: the segment model throughout (the default). The 3RRR's problem
    on the segment model only."""
    split: tuple[str, int] | None = None
    """``(name, n)``: the prior of parameter ``name`` cut into ``n`` parts of equal prior mass (its unit-cube
    coordinate's ``n`` equal intervals: for a uniform prior, equal sub-ranges; ``("...rotation_deg", 2)`` on a
    range symmetric about 0: its sign), each part sampled as a class of its own (every run, every elbow-branch
    class), the parts combined by their evidences, each with prior weight ``1 / n``: a posterior whose separate
    parts independent runs would hold in different shares gets each part's share from its evidence
    (:func:`~fpm_sim.study.calibrate.runs.combine_parts`). ``None``: no split."""

    def check(self) -> None:
        if self.runs < 1:
            raise CalibrationError("must be >= 1", parameter="runs", value=self.runs)
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
        if self.sampler not in SAMPLERS:
            raise CalibrationError(f"must be one of {', '.join(SAMPLERS)}", parameter="sampler", value=self.sampler)
        if self.sampler == "smc":
            self._check_smc()
        elif smc_only := [
            n for n, on in (("emulator", self.emulator), ("mode_starts", self.mode_starts),
                            ("islands", self.islands != 1), ("crossover", self.crossover)) if on
        ]:  # fmt: skip
            name = smc_only[0]
            raise CalibrationError(
                "is the smc sampler's", parameter=name, value=getattr(self, name),
                hint="use the smc sampler, or leave it at its default with nested sampling",
            )  # fmt: skip
        if self.split is not None and (len(self.split) != 2 or not isinstance(self.split[1], int) or self.split[1] < 2):
            raise CalibrationError(
                "must be (parameter name, number of parts >= 2)", parameter="split", value=self.split,
                hint="give the parameter whose prior is cut and into how many equal prior-mass parts, or no split",
            )  # fmt: skip
        if self.max_calls is not None and self.max_calls < self.live_points:
            raise CalibrationError(
                f"must be >= the number of live points ({self.live_points})",
                parameter="max_calls",
                value=self.max_calls,
                hint="allow more likelihood calls or use fewer live points",
            )

    def _check_smc(self) -> None:
        for name in ("particles", "cheap_particles"):
            if getattr(self, name) < 10:
                raise CalibrationError("must be >= 10", parameter=name, value=getattr(self, name))
        if not 0 < self.ess_fraction < 1:
            raise CalibrationError("must be between 0 and 1", parameter="ess_fraction", value=self.ess_fraction)
        for name in ("moves", "cheap_moves"):
            if not getattr(self, name) > 0:
                raise CalibrationError("must be > 0", parameter=name, value=getattr(self, name))
        if not self.final_moves >= 0:
            raise CalibrationError("must be >= 0", parameter="final_moves", value=self.final_moves)
        if not 0 <= self.jumps <= 1:
            raise CalibrationError("must be between 0 and 1", parameter="jumps", value=self.jumps)
        if self.islands < 1:
            raise CalibrationError("must be >= 1", parameter="islands", value=self.islands)
        if self.importance and self.importance < self.particles:
            raise CalibrationError(
                "must be 0 (off) or at least the data stage's particles", parameter="importance", value=self.importance,
                hint="independent draws are worth their calls only by the thousand (docs/identification.md)",
            )  # fmt: skip
        if self.mode_starts < 0:
            raise CalibrationError("must be >= 0", parameter="mode_starts", value=self.mode_starts)
        if self.emulator and self.emulator < 50:
            raise CalibrationError(
                "must be 0 (off) or >= 50 segment-model runs", parameter="emulator", value=self.emulator,
                hint="the emulator's fit needs many more runs than its inputs; 500 is measured",
            )  # fmt: skip
        if self.emulator and self.mode_starts:
            raise CalibrationError(
                "is not used by the emulated data stage (its search would run and its modes be ignored)",
                parameter="mode_starts", value=self.mode_starts,
                hint="leave it 0 with the emulator, or sample the data on the segment model (emulator 0)",
            )  # fmt: skip
        if self.max_calls is not None:
            raise CalibrationError(
                "is nested sampling's (dynesty's) limit", parameter="max_calls", value=self.max_calls,
                hint="leave it unset with the smc sampler, or use the dynesty sampler",
            )  # fmt: skip

    def smc_settings(self) -> tuple[SmcSettings, SmcSettings]:
        """The two stages' :class:`~fpm_sim.study.calibrate.smc.SmcSettings`."""
        one = SmcSettings(self.cheap_particles, self.ess_fraction, self.cheap_moves, max_sweeps=200)
        return one, SmcSettings(
            self.particles, self.ess_fraction, self.moves, final_moves=self.final_moves, jumps=self.jumps,
            importance=self.importance, crossover=self.crossover,
        )  # fmt: skip


@dataclass(frozen=True)
class ClassSummary:
    """One elbow-branch class of an enumerated calibration (:func:`sample_classes`)."""

    klass: int | None
    label: str
    prior_mass: float
    """The fraction of its prior draws that are valid and reach every measured pose."""
    probe_draws: int
    log_evidence: float
    """ln Z of the class's continuous posterior (its runs merged); NaN when skipped."""
    log_evidence_err: float
    weight: float
    """``Z_k / sum Z``: the class's posterior probability."""
    weight_sd: float
    run_log_evidence: list[float]
    """ln Z of each run (seeds in order)."""
    skipped: bool
    """No prior draw reached the measured poses: ``Z_k = 0``, not sampled."""
    size: int = 1
    """The classes it stands for (:func:`sampled_classes`): its evidences count that many times."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "class": self.klass,
            "branches": self.label,
            "prior_reachable_fraction": self.prior_mass,
            "log_evidence": self.log_evidence,
            "log_evidence_err": self.log_evidence_err,
            "weight": self.weight,
            "weight_sd": self.weight_sd,
            "run_log_evidence": self.run_log_evidence,
            "skipped": self.skipped,
        }

    def line(self) -> str:
        if self.skipped:
            return (
                f"{self.label:<16} skipped: none of {self.probe_draws} prior draws reaches every measured pose (Z = 0)"
            )
        runs = ", ".join(f"{z:.2f}" for z in self.run_log_evidence)
        return (
            f"{self.label:<16} ln Z {self.log_evidence:8.2f} +- {self.log_evidence_err:.2f}  weight "
            f"{100 * self.weight:5.1f} +- {100 * self.weight_sd:.1f} %  (runs: {runs}; reachable prior "
            f"{100 * self.prior_mass:.0f} %)"
        )


@dataclass
class Calibration:
    """The result of :func:`run_calibration`: equal-weight draws and the run's diagnostics."""

    problem: FrequencyLikelihood
    options: SamplerOptions
    draws: np.ndarray
    """``(n_draws, ndim)`` equal-weight draws of ``theta``
    (:attr:`~fpm_sim.study.calibrate.problem.FrequencyLikelihood.names`)."""
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
    """:meth:`~fpm_sim.study.calibrate.problem.FrequencyLikelihood.start_log_likelihood`: compare with
    ``log_likelihood.max()``."""
    extra: dict[str, Any] = field(default_factory=dict)
    classes: list[ClassSummary] = field(default_factory=list)
    """Each elbow-branch class sampled (or skipped): its evidence and weight (one entry when the branches are
    fixed)."""
    runs_check: RunsCheck | None = None
    """The between-run check (:mod:`fpm_sim.study.calibrate.runs`); ``None``: one run."""

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
        assert isinstance(p, CalibrationProblem), "the latent-mode model is the 3RRR's"
        out = []
        for t in self.draws:
            freq, probs = p.read_modes(p.config(t))
            out.append((freq, probs, p.discrepancy(t)))
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
        d = np.array([p.discrepancy(t) for t in self.draws])
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
                k: getattr(self.options, k)
                for k in (
                    "sampler",
                    "particles",
                    "cheap_particles",
                    "ess_fraction",
                    "moves",
                    "final_moves",
                    "jumps",
                    "importance",
                    "islands",
                    "crossover",
                    "emulator",
                    "live_points",
                    "dlogz",
                    "seed",
                    "sample",
                    "walks",
                    "max_calls",
                    "runs",
                )
            },
            "classes": [c.to_dict() for c in self.classes],
            **self.problem.notes(),
            "runs_check": None if self.runs_check is None else self.runs_check.to_dict(),
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
        lines += [f"{k.replace('_', ' ')}: {v}" for k, v in self.problem.notes().items()]
        if len(self.classes) > 1:
            lines.append("elbow-branch classes (each sampled on its own, weighted by its evidence):")
            lines += ["  " + c.line() for c in self.classes]
        lines.append(
            "between-run check: none (one run)"
            if self.runs_check is None
            else self.runs_check.table(class_label=self.problem.class_label)
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


def _pool(problem: FrequencyLikelihood, workers: int) -> Any:
    """A spawn pool whose workers hold ``problem`` and ignore Ctrl-C (:func:`fpm_sim.batch.engine.spawn_pool`)."""
    return spawn_pool(workers, _init_worker, (problem,))


def _job_file(checkpoint: Path, klass: int | None, seed: int, part: Part = None) -> Path:
    """The checkpoint file of one (class, part, seed) run, beside ``checkpoint``."""
    tag = f"seed{seed}" if klass is None else f"class{klass}.seed{seed}"
    tag = tag if part is None else f"part{part[2]}of{part[1]}.{tag}"
    return Path(f"{checkpoint}.{tag}")


def _digest_file(checkpoint: Path) -> Path:
    return Path(str(checkpoint) + ".digest")


def _run_class(
    klass: int | None, seed: int, opts: SamplerOptions, *, checkpoint: Path | None, resume: bool, pool: Any = None,
    part: Part = None,
) -> Any:  # fmt: skip
    """dynesty's static sampler on class ``klass``'s continuous posterior to ``opts.dlogz`` (the likelihood
    calls here, or on ``pool``'s workers): a finished run's saved results (``.done``), or restored from its
    checkpoint, or fresh. Returns dynesty's ``Results``."""
    import pickle

    import dynesty

    assert _PROBLEM is not None, "the pool was started without _init_worker"
    kw: dict[str, Any] = {"print_progress": False, "dlogz": opts.dlogz, "maxcall": opts.max_calls}
    done = None if checkpoint is None else Path(f"{checkpoint}.done")
    if checkpoint is not None:
        kw.update(checkpoint_file=str(checkpoint), checkpoint_every=opts.checkpoint_every_s)
    if resume and done is not None and done.exists():
        with done.open("rb") as fh:
            saved = pickle.load(fh)
        _same_sampler(saved, "dynesty", done)
        return saved
    if resume and checkpoint is not None and checkpoint.exists():
        sampler = dynesty.NestedSampler.restore(str(checkpoint), pool=pool)
        # a run interrupted mid-way continues (resume=True); one that ended on max_calls has its final live
        # points added to the results, which dynesty takes out again and continues from with resume=False
        sampler.run_nested(resume=not bool(getattr(sampler, "added_live", False)), **kw)
    else:
        sampler = dynesty.NestedSampler(
            functools.partial(_class_log_likelihood, klass=klass),
            functools.partial(_class_prior_transform, klass=klass, part=part),
            _PROBLEM.ndim - (klass is not None),
            nlive=opts.live_points,
            sample=opts.sample,
            walks=opts.walks,
            rstate=np.random.default_rng(seed),
            pool=pool,
            queue_size=opts.workers if pool is not None else None,
            periodic=list(_periodic(part)) or None,
        )
        sampler.run_nested(**kw)
    res = sampler.results
    if done is not None and (opts.max_calls is None or int(np.sum(res["ncall"])) < opts.max_calls):
        with done.open("wb") as fh:
            pickle.dump(res, fh, protocol=4)
    return res


def _periodic(part: Part) -> tuple[int, ...]:
    """The unit-cube coordinates a sampler wraps around (the priors' whole-turn angles,
    :attr:`~fpm_sim.study.calibrate.priors.Priors.periodic`; a split coordinate's part is an interval, not wrapped)."""
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    per = tuple(getattr(getattr(_PROBLEM, "priors", None), "periodic", ()))
    return tuple(i for i in per if part is None or i != part[0])


def _class_thetas(u: np.ndarray, klass: int | None, part: Part = None) -> np.ndarray:
    """The problem's coordinates (the class's last) at unit-cube rows ``u`` of class ``klass``'s part: row ``i`` is
    ``_with_class(_class_prior_transform(u[i], klass, part), klass)``, vectorised."""
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    u = np.atleast_2d(_in_part(u, part))
    if klass is not None:
        u = np.column_stack([u, np.full(len(u), (klass + 0.5) / len(_PROBLEM.branch_classes))])
    return _PROBLEM.prior_transform(u)


def _smc_cheap(u: np.ndarray, klass: int | None, part: Part = None) -> tuple[np.ndarray, np.ndarray]:
    """SMC's first stage at unit-cube rows ``u``: ``(0, log L_cheap)`` (vectorised over the rows where the problem
    has it, :mod:`~fpm_sim.study.calibrate.vectorised`)."""
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    p = _PROBLEM
    if supports(p):
        return np.zeros(len(u)), cheap_log_likelihood_batch(p, _class_thetas(u, klass, part))  # type: ignore[arg-type]
    cheap = [p.cheap_log_likelihood(_with_class(_class_prior_transform(x, klass, part), klass)) for x in u]
    return np.zeros(len(u)), np.asarray(cheap, float)


def _smc_full(u: np.ndarray, klass: int | None, pool: Any, part: Part = None) -> tuple[np.ndarray, np.ndarray]:
    """SMC's second stage at unit-cube rows ``u``: ``(log L_cheap, log L - log L_cheap)``, the (expensive) full
    likelihood evaluated only where the cheap part is finite (on ``pool``'s workers when given; vectorised on the
    in-plane surrogate)."""
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    if supports(_PROBLEM) and getattr(_PROBLEM, "model", None) == "inplane":
        return inplane_split_log_likelihood_batch(_PROBLEM, _class_thetas(u, klass, part))  # type: ignore[arg-type]
    _, cheap = _smc_cheap(u, klass, part)
    ok = np.isfinite(cheap)
    todo = [_with_class(_class_prior_transform(x, klass, part), klass) for x in u[ok]]
    ll = _worker_log_likelihood
    full = np.asarray(pool.map(ll, todo) if pool is not None else [ll(t) for t in todo], float)
    data = np.full(len(u), -math.inf)
    data[ok] = full - cheap[ok]
    return cheap, np.where(np.isfinite(data), data, -math.inf)


def _emulator_n_free(problem: Any) -> int:
    """How many leading free parameters the emulator's correction reads: all but the ``as-built`` group's (last in
    the parameter set; their effect reaches the correction through the surrogates' frequencies, which are computed
    on the as-built geometry, and leaving 12 near-inert coordinates out keeps the fit's distances meaningful)."""
    specs = getattr(getattr(problem, "parameters", None), "parameters", ())
    return len(problem.priors.parameters) - sum(1 for s in specs if s.group == "as-built")


class _SegmentEmulator:
    """The emulator of one run (:mod:`~fpm_sim.study.calibrate.emulator`) on class ``klass``'s part: ``n``
    segment-model runs (on ``pool``'s workers when given) at stage 1's particles train it (:meth:`train`), ``n`` more
    at the first data stage's refit it with every earlier one (:meth:`refine`), and the weights' runs (:meth:`exact`)
    are kept too. :attr:`fitted` is its last fit."""

    def __init__(self, *, klass: int | None, part: Part, n: int, pool: Any, rng: np.random.Generator) -> None:
        assert _PROBLEM is not None, "the pool was started without _init_worker"
        self.problem: Any = _PROBLEM
        self.klass, self.part, self.n, self.pool, self.rng = klass, part, n, pool, rng
        self.u: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.fitted: Emulator | None = None
        self.rounds = 0
        """Data stages run again on a refit (:meth:`again`)."""

    def _segments(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The class's parameters at the rows of ``u`` and the segment model's first frequencies there (the lower of
        its two mode families, each distinct row run once); the families kept for training."""
        theta = _class_thetas(u, self.klass, self.part)
        uniq, inverse = np.unique(theta, axis=0, return_inverse=True)
        p, pool = self.problem, self.pool
        rows = list(uniq)
        f = np.asarray(pool.map(_worker_families, rows) if pool is not None else [p.predict_families(t) for t in rows])
        f = f.reshape(len(uniq), 2, -1)[inverse.ravel()]
        self.u.append(u)
        self.f.append(f)
        return theta, np.fmin(f[:, 0], f[:, 1])

    def _fit(self) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
        u, f_seg = np.concatenate(self.u), np.concatenate(self.f)
        u, keep = np.unique(u, axis=0, return_index=True)
        p, klass, part = self.problem, self.klass, self.part
        f_sur, _ = family_frequencies_batch(p, _class_thetas(u, klass, part))
        emu = self.fitted = train_emulator(
            u, f_seg[keep], f_sur, n_free=_emulator_n_free(p), rng=self.rng, periodic=_periodic(part)
        )

        def evaluate(uq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            th = _class_thetas(uq, klass, part)
            f, cheap = family_frequencies_batch(p, th)
            return split_log_likelihood_batch(p, th, emu.frequencies(uq, f), cheap, model_error_rel=emu.model_error_rel)

        return evaluate

    def train(self, u: np.ndarray) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """Fitted to the segment model at ``n`` of the distinct rows of ``u`` (stage 1's particles) and at every earlier
        run."""
        uniq = np.unique(u, axis=0)
        self._segments(uniq[self.rng.choice(len(uniq), min(self.n, len(uniq)), replace=False)])
        return self._fit()

    def refine(self, u: np.ndarray) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """Refitted with every segment-model run so far and new ones at ``n`` of the data stage's distinct particles
        ``u``."""
        return self.train(u)

    def again(self, log_w: np.ndarray) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
        """Given a weighted data stage's log weights: where their Pareto k is :data:`PARETO_K_MAX` or more, the
        emulator refitted with every segment-model run so far (the weights' own included: where that stage went beyond
        the earlier runs), for the data stage to run once more on it; else ``None``."""
        if importance_diagnostics(log_w)[1] < PARETO_K_MAX:
            return None
        self.rounds += 1
        return self._fit()

    def exact(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(log L_cheap, log L_data)`` on the segment model at the rows of ``u`` (as :func:`_smc_full`)."""
        theta, f = self._segments(u)
        return split_log_likelihood_batch(self.problem, theta, f, cheap_log_likelihood_batch(self.problem, theta))


MODE_SEARCH: dict[str, Any] = {"popsize": 30, "maxiter": 1000, "tol": 1e-4}
"""The mode search's differential evolution (scipy, ``best1bin``): ``popsize`` per coordinate, at most ``maxiter``
generations, stopped when its population's values agree to a relative ``tol``: converged, not merely gathered (at
``tol = 0.01`` every start of two runs stopped after 40-450 generations on the plateau, log L -78 or -56, and none
reached the compact region: docs/identification.md, "The needle")."""
MODE_SPREAD = SmcSettings(particles=256, moves=20.0, max_sweeps=200)
"""The particles spread over each mode found and their Metropolis moves
(:func:`~fpm_sim.study.calibrate.smc.spread_over_mode`): 256 particles, 20 accepted moves each."""
MODE_KERNELS = 64
"""Kernels kept per start (of its spread particles): the data stage evaluates the mixture's density at every move."""
MODE_WINDOW = 15.0
"""A start whose best log L is more than this below the best start's adds no kernels: its mode holds under e^-15 of
the best one's peak density (the statements' particles, the mixture's other part, still cover the whole prior)."""


def _search_start(job: tuple[int | None, Part, int, int]) -> tuple[float, np.ndarray]:
    """One start of the mode search (in a worker): differential evolution of the in-plane surrogate's log-likelihood
    on class ``klass``'s part (unit cube; seed ``seed``) to convergence, then particles spread over the mode it found.
    Returns ``(best log L, spread particles (MODE_KERNELS, d))``."""
    from scipy.optimize import differential_evolution

    klass, part, d, seed = job
    p = _PROBLEM
    assert p is not None, "the pool was started without _init_worker"
    assert supports(p), "checked by run_calibration"

    def log_l(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v = inplane_log_likelihood_batch(p, _class_thetas(np.clip(u, 0.0, 1.0), klass, part))  # type: ignore[arg-type]
        return np.zeros(len(u)), v

    def neg_log_l(x: np.ndarray) -> np.ndarray:  # (d, S) -> (S,)
        v = log_l(x.T)[1]
        out: np.ndarray = np.where(np.isfinite(v), -v, 1e4)
        return out

    r = differential_evolution(
        neg_log_l, [(0.0, 1.0)] * d, seed=seed, vectorized=True, updating="deferred", polish=False, init="sobol",
        **MODE_SEARCH,
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    u, _ = spread_over_mode(np.asarray(r.x), log_l, MODE_SPREAD.particles, MODE_SPREAD, rng)
    return -float(r.fun), u[rng.choice(len(u), MODE_KERNELS, replace=False)]


def search_modes(
    klass: int | None, part: Part, d: int, starts: int, seed: int, *, pool: Any = None,
    print_func: Callable[..., None] | None = None, label: str = "",
) -> ModeProposal:  # fmt: skip
    """``starts`` searches (:func:`_search_start`, seeds ``1000 seed + k``; on ``pool``'s workers when given) as one
    kernel density (:meth:`~fpm_sim.study.calibrate.smc.ModeProposal.around` each start's spread particles); starts
    more than :data:`MODE_WINDOW` below the best are left out. Each start's best log L is printed (``print_func``):
    whether a run's search reached a mode is then on record. Every run of the class uses it (the search is pooled: a
    mode any start found is in every run's proposal)."""
    jobs = [(klass, part, d, 1000 * seed + k) for k in range(starts)]
    found = list(pool.map(_search_start, jobs)) if pool is not None else [_search_start(j) for j in jobs]
    top = max(f[0] for f in found)
    if print_func is not None:
        for k, (best, _) in enumerate(found):
            out = "" if best >= top - MODE_WINDOW else " (left out)"
            print_func(f"  {label}mode search start {k + 1}/{starts}: best log L {best:.2f}{out}")
    return ModeProposal.around([pop for best, pop in found if best >= top - MODE_WINDOW])


def _run_smc(
    klass: int | None, seed: int, opts: SamplerOptions, *, checkpoint: Path | None, resume: bool, pool: Any = None,
    part: Part = None, modes: ModeProposal | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Two-stage tempered SMC (:func:`~fpm_sim.study.calibrate.smc.two_stage`) on class ``klass``, its data stage
    from a defensive mixture with ``modes`` where given: a finished run's saved results (``.done``), else a fresh run
    (an unfinished SMC run is not continued: it restarts)."""
    import pickle

    assert _PROBLEM is not None, "the pool was started without _init_worker"
    done = None if checkpoint is None else Path(f"{checkpoint}.done")
    if resume and done is not None and done.exists():
        with done.open("rb") as fh:
            out = pickle.load(fh)
        _same_sampler(out, "smc", done)
        return dict(out)
    per = _periodic(part)
    one, two = (dataclasses.replace(x, periodic=per) for x in opts.smc_settings())
    islands = []
    for i in range(opts.islands):  # the first island's stream is the run's seed's: one island is the plain run
        rng = np.random.default_rng(seed if i == 0 else [seed, i])
        emu = _SegmentEmulator(klass=klass, part=part, n=opts.emulator, pool=pool, rng=rng) if opts.emulator else None
        islands.append(_smc_island(klass, part, one, two, rng, opts, emu=emu, pool=pool, modes=modes))
    out = islands[0] if len(islands) == 1 else merge_smc(islands, islands=True)
    if len(islands) > 1:
        out["islands"] = [{"log_evidence": float(r["logz"][-1]), "log_evidence_err": float(r["logzerr"][-1])}
                          for r in islands]  # fmt: skip
        for key in ("importance", "emulator"):  # the island whose weights are least reliable speaks for the run
            diag = [r[key] for r in islands if key in r]
            if diag:
                out[key] = max(diag, key=lambda x: x["pareto_k"])
    if done is not None:
        with done.open("wb") as fh:
            pickle.dump(out, fh, protocol=4)
    return out


def _smc_island(
    klass: int | None, part: Part, one: SmcSettings, two: SmcSettings, rng: np.random.Generator,
    opts: SamplerOptions, *, emu: _SegmentEmulator | None, pool: Any, modes: ModeProposal | None,
) -> dict[str, Any]:  # fmt: skip
    """One island of :func:`_run_smc` (the whole run when it has one): a two-stage SMC, on its own emulator ``emu``
    where given, as :func:`~fpm_sim.study.calibrate.smc.smc_results` with its diagnostics. Each island trains its own,
    so that the islands are independent: the exact weights correct an emulator only where its posterior reaches, and
    islands sharing one would share its misses, which their spread would not show."""
    assert _PROBLEM is not None, "the pool was started without _init_worker"
    d = _PROBLEM.ndim - (klass is not None)
    cheap = functools.partial(_smc_cheap, klass=klass, part=part)
    if emu is not None:
        run = emulated_two_stage(cheap, emu.train, emu.exact, d, one, two, rng, refine=emu.refine, again=emu.again)
    else:
        full = functools.partial(_smc_full, klass=klass, pool=pool, part=part)
        run = two_stage(cheap, full, d, one, two, rng, modes=modes, mode_particles=opts.cheap_particles)
    theta = np.array([_class_prior_transform(x, klass, part) for x in run.u]).reshape(len(run.u), d)
    out = smc_results(theta, run.log_a + run.log_b, run.log_evidence, run.log_evidence_err, run.n_calls,
                      len(run.betas), log_weights=run.log_weights)  # fmt: skip
    if run.importance is not None:
        out["importance"] = dict(run.importance)
    if emu is not None and emu.fitted is not None and run.log_weights is not None:
        ess, k = importance_diagnostics(run.log_weights)
        e = emu.fitted
        out["emulator"] = {"n_train": e.n_train, "held_out_rms": e.held_out_rms, "held_out_max": e.held_out_max,
                           "ess": ess, "pareto_k": k, "particles": len(run.u), "again": emu.rounds}  # fmt: skip
    return out


def _same_sampler(saved: Any, sampler: str, path: Path) -> None:
    """Refuse to resume from a finished run of the other sampler (an SMC run's results are a plain ``dict``)."""
    if isinstance(saved, dict) != (sampler == "smc"):
        other = "dynesty" if sampler == "smc" else "smc"
        raise CalibrationError(
            f"the finished run there was sampled by {other}, not {sampler}",
            parameter="resume",
            file=path,
            hint=f"resume with the sampler {other}, or start a fresh run (resume off)",
        )


def _check_resume(problem: FrequencyLikelihood, checkpoint: Path | None, resume: bool) -> None:
    """Refuse a resume without a checkpoint, or from another problem's (the ``.digest`` file); record the
    problem's fingerprint for a fresh run."""
    if not resume:
        if checkpoint is not None:
            _digest_file(checkpoint).write_text(problem_digest(problem))
        return
    if checkpoint is None or not _digest_file(checkpoint).exists():
        raise CalibrationError(
            "no checkpoint file to resume from",
            parameter="resume",
            value=None if checkpoint is None else str(checkpoint),
            hint="start a fresh run (resume off) first",
        )
    if _digest_file(checkpoint).read_text().strip() != problem_digest(problem):
        raise CalibrationError(
            "the checkpoint belongs to another problem (data, priors, free groups, base description or "
            "segments differ)",
            parameter="resume",
            file=checkpoint,
            hint="start a fresh run (resume off) into an empty or overwritten output folder",
        )


def class_prior_mass(problem: FrequencyLikelihood, klass: int | None, n: int, seed: int) -> float:
    """The fraction of ``n`` prior draws of class ``klass`` that are valid and reach every measured pose."""
    rng = np.random.default_rng(seed)
    ok = 0
    for u in rng.random((n, problem.ndim)):
        t = problem.prior_transform(u)
        if klass is not None:
            t[-1] = float(klass)
        ok += problem.possible(t)
    return ok / n


def _sample_jobs(
    jobs: list[Job],
    pool: Any,
    print_func: Callable[..., None] | None,
    label: Callable[[int | None], str],
) -> dict[tuple[int | None, Part, int], tuple[Any, float]]:
    """Every (class, part, seed) run, ``{(class, part, seed): (Results, s)}``: one run per worker of the pool, or,
    with fewer runs than workers (fixed branches), one run after another here with their likelihood calls on the
    pool."""
    out = {}
    if pool is not None and len(jobs) >= jobs[0][3].workers:
        it = pool.imap_unordered(_worker_run, jobs)
    else:
        it = (_worker_run(j, pool) for j in jobs)
    for klass, part, seed, res, sec in it:
        out[(klass, part, seed)] = (res, sec)
        if print_func is not None:
            where = _part_label(part)
            print_func(
                f"  {label(klass)}{where}seed {seed}: ln Z = {float(res['logz'][-1]):.2f} +- "
                f"{float(res['logzerr'][-1]):.2f}, {int(np.sum(res['ncall']))} calls, {sec:.0f} s "
                f"({len(out)}/{len(jobs)} runs){_emulator_note(res)}"
            )
    return out


def _emulator_note(res: Any) -> str:
    """A run's islands, importance sampling, emulator and importance weights in a few words (``""`` with none); a
    warning where a set of weights' Pareto ``k`` is 0.7 or more (the weighted posterior of that run is not reliable)."""
    isl = res.get("islands") if isinstance(res, dict) else None
    i = res.get("importance") if isinstance(res, dict) else None
    e = res.get("emulator") if isinstance(res, dict) else None
    note = ""
    if isl:
        z = ", ".join(f"{x['log_evidence']:.2f}" for x in isl)
        note += f"; {len(isl)} islands' ln Z {z}"
    if i:
        note += (f"; {i['draws']} importance draws, ESS {i['ess']:.0f}, Pareto k {i['pareto_k']:.2f}, ln Z error "
                 f"{i['log_evidence_err']:.2f}")  # fmt: skip
        if not i["pareto_k"] < PARETO_K_MAX:
            note += " (WARNING: k >= 0.7, the draws' error is unreliable: more draws or particles)"
    if not e:
        return note
    note += (f"; emulator {100 * e['held_out_rms']:.1f} % rms on {e['n_train']} runs, weights ESS {e['ess']:.0f}/"
             f"{e['particles']}, Pareto k {e['pareto_k']:.2f}")  # fmt: skip
    if e.get("again"):
        note += " (sampled again on a refit: the first weights had k >= 0.7)"
    if not e["pareto_k"] < PARETO_K_MAX:
        note += " (WARNING: k >= 0.7, the importance weights are unreliable: more particles or emulator runs)"
    return note


def _part_label(part: Part) -> str:
    """``"part 2/5, "`` (the prior's part a run samples, :attr:`SamplerOptions.split`), or ``""`` for the whole."""
    return "" if part is None else f"part {part[2] + 1}/{part[1]}, "


def _merge(results: list[Any], sampler: str) -> Any:
    """One class's runs as one (dynesty's ``merge_runs``; SMC: :func:`~fpm_sim.study.calibrate.smc.merge_smc`)."""
    if len(results) == 1:
        return results[0]
    if sampler == "smc":
        return merge_smc(results)
    from dynesty.utils import merge_runs

    return merge_runs(results, print_progress=False)


def sample_classes(
    problem: FrequencyLikelihood,
    opts: SamplerOptions,
    pool: Any,
    *,
    checkpoint: Path | None,
    resume: bool,
    print_func: Callable[..., None] | None,
) -> tuple[Combined, RunsCheck | None, list[ClassSummary], dict[str, Any]]:
    """Sample every elbow-branch class ``opts.runs`` times, merge each class's runs, combine the classes by
    their evidences (:mod:`fpm_sim.study.calibrate.runs`) and check the runs against each other."""
    classes = problem.branch_classes
    size = sampled_classes(problem)
    seeds = [opts.seed + r for r in range(opts.runs)]
    mass = {k: class_prior_mass(problem, k, opts.probe_draws, opts.seed) for k in size}
    live = [k for k in size if mass[k] > 0]
    if not live:
        raise CalibrationError(
            f"no prior draw (of {opts.probe_draws} per class) reaches every measured pose: the likelihood is nil",
            parameter="priors",
            hint="widen the geometry priors or check the measured poses",
        )
    parts = _parts(problem, opts)
    _check_resume(problem, checkpoint, resume)
    keys = [(k, p, s) for k in live for p in parts for s in seeds]
    label = functools.partial(_class_label, problem, size)
    prefix = (lambda k: f"class {label(k)}, ") if classes != (None,) else (lambda k: "")

    def finished(k: int | None, p: Part) -> bool:  # every run of (k, p) resumes from its saved results
        return (
            resume
            and checkpoint is not None
            and all(Path(f"{_job_file(checkpoint, k, s, p)}.done").exists() for s in seeds)
        )

    modes = {
        (k, p): search_modes(k, p, problem.ndim - (k is not None), opts.mode_starts, opts.seed, pool=pool,
                             print_func=print_func, label=prefix(k) + _part_label(p))
        for k in live for p in parts if opts.sampler == "smc" and opts.mode_starts and not finished(k, p)
    }  # fmt: skip
    jobs: list[Job] = [
        (k, p, s, opts, None if checkpoint is None else str(_job_file(checkpoint, k, s, p)), resume, modes.get((k, p)))
        for k, p, s in keys
    ]
    done = _sample_jobs(jobs, pool, print_func, prefix)
    run_of = {(k, s): combine_parts([done[(k, p, s)][0] for p in parts]) for k in live for s in seeds}
    merged = [
        _class_result(k, combine_parts([_merge([done[(k, p, s)][0] for s in seeds], opts.sampler) for p in parts]),
                      size[k])
        for k in live
    ]  # fmt: skip
    rng = np.random.default_rng(opts.seed + 1)
    comb = combine_classes(merged, len(classes), opts.draws, rng)
    names = [n for n in problem.names if n != BRANCH_PARAMETER]
    check = None
    per_run = [[_class_result(k, run_of[(k, s)], size[k]) for k in live] for s in seeds]
    if opts.runs > 1:
        check = between_run_check(
            per_run, comb, seeds, names, n_classes=len(classes), n_draws=opts.draws, rng=rng,
            class_label=label, nsigma=opts.nsigma, quantile_tol=opts.quantile_tol,
            class_threshold=opts.class_threshold,
        )  # fmt: skip
    summaries = _summaries(problem, size, mass, live, comb, merged, per_run, opts.probe_draws)
    stats = {
        "n_calls": int(sum(np.sum(r["ncall"]) for r, _ in done.values())),
        "n_iterations": int(sum(int(r["niter"]) for r, _ in done.values())),
        "converged": opts.max_calls is None or all(np.sum(r["ncall"]) < opts.max_calls for r, _ in done.values()),
    }
    return comb, check, summaries, stats


def sampled_classes(problem: FrequencyLikelihood) -> dict[int | None, int]:
    """The elbow-branch classes sampled, each with the number of classes it stands for: every class once, or with
    the priors' ``relabel = "cyclic"`` one class of each cyclic orbit with the orbit's size
    (:func:`~fpm_sim.study.identify.problem.cyclic_branch_orbits`; its evidence counts that many times under the
    uniform prior over the 8)."""
    classes = problem.branch_classes
    if classes == (None,) or not getattr(getattr(problem, "priors", None), "branch_relabel", False):
        return dict.fromkeys(classes, 1)
    return {k: m for k, m in cyclic_branch_orbits().items()}  # a comprehension widens the key type


def _class_label(problem: FrequencyLikelihood, size: dict[int | None, int], klass: int | None) -> str:
    """A class's name, ``" x3"`` added where it stands for its orbit's three classes."""
    m = size.get(klass, 1)
    return problem.class_label(klass) + (f" x{m}" if m > 1 else "")


def _class_result(klass: int | None, res: Any, size: int) -> ClassResult:
    """:meth:`ClassResult.of_results`, its evidence (and weights) counted ``size`` times (:func:`sampled_classes`)."""
    out = ClassResult.of_results(klass, res)
    if size == 1:
        return out
    log_m = math.log(size)
    return dataclasses.replace(out, logwt=out.logwt + log_m, log_evidence=out.log_evidence + log_m)


def _parts(problem: FrequencyLikelihood, opts: SamplerOptions) -> list[Part]:
    """The parts of the prior each class is sampled in (:attr:`SamplerOptions.split`; ``[None]``: the whole)."""
    if opts.split is None:
        return [None]
    name, n = opts.split
    names = [m for m in problem.names if m != BRANCH_PARAMETER]
    if name not in names:
        raise CalibrationError(
            "is not a free continuous parameter of the problem", parameter="split", value=name,
            hint=f"split one of: {', '.join(names)}",
        )  # fmt: skip
    return [(names.index(name), n, p) for p in range(n)]


def _summaries(
    problem: FrequencyLikelihood,
    size: dict[int | None, int],
    mass: dict[int | None, float],
    live: list[int | None],
    comb: Combined,
    merged: list[ClassResult],
    per_run: list[list[ClassResult]],
    probe: int,
) -> list[ClassSummary]:
    """One summary per sampled class (:func:`sampled_classes`; ``per_run[r][j]``: run ``r``'s result of ``live[j]``,
    its evidence counted as :func:`_class_result` counts it)."""
    out = []
    for k, m in size.items():
        name = _class_label(problem, size, k)
        if k not in live:
            out.append(ClassSummary(k, name, 0.0, probe, math.nan, math.nan, 0.0, 0.0, [], True, m))
            continue
        j = live.index(k)
        out.append(
            ClassSummary(
                k, name, mass[k], probe, merged[j].log_evidence, merged[j].log_evidence_err,
                float(comb.weights[j]), float(comb.weights_sd[j]), [r[j].log_evidence for r in per_run], False, m,
            )
        )  # fmt: skip
    return out


def _check_smc_options(problem: FrequencyLikelihood, opts: SamplerOptions) -> None:
    """Refuse SMC options the problem cannot take (the emulator, the mode search), before sampling."""
    segments = supports(problem) and getattr(problem, "model", "") == "segments"
    if opts.sampler == "smc" and opts.emulator and not segments:
        raise CalibrationError(
            "the emulator corrects the 3RRR's vectorised surrogates to its segment model: first frequencies, "
            "independent errors, no rig tests", parameter="emulator", value=opts.emulator,
            hint="set it to 0 for this problem",
        )  # fmt: skip
    if opts.sampler == "smc" and opts.emulator and any(o.label is not None for o in problem.observations):
        raise CalibrationError(
            "the emulator's frequency is the lower of the in-plane and out-of-plane families: unlabelled first "
            "frequencies only", parameter="emulator", value=opts.emulator,
            hint="set it to 0 for data labelled with a mode kind, or remove the labels",
        )  # fmt: skip
    if opts.sampler == "smc" and opts.mode_starts and not supports(problem):
        raise CalibrationError(
            "the mode search runs on the 3RRR's vectorised in-plane surrogate: first in-plane frequencies, independent "
            "errors, no rig tests", parameter="mode_starts", value=opts.mode_starts,
            hint="set it to 0 for this problem",
        )  # fmt: skip


def run_calibration(
    problem: FrequencyLikelihood,
    options: SamplerOptions | None = None,
    *,
    checkpoint: Path | None = None,
    resume: bool = False,
    progress: bool = True,
    print_func: Callable[..., None] | None = None,
) -> Calibration:
    """Sample the posterior of ``problem`` with dynesty's static nested sampler: every elbow-branch class on its
    own, ``options.runs`` times (seeds ``seed, seed + 1, ...``; the (class, seed) runs on ``options.workers``
    processes), each class's runs merged, the classes combined by their evidences, and the runs checked against
    each other (:mod:`fpm_sim.study.calibrate.runs`; :attr:`Calibration.runs_check`).

    ``checkpoint``: the prefix of each run's dynesty checkpoint file (``PREFIX.classK.seedS``, written every
    ``options.checkpoint_every_s`` seconds; a finished run's results beside it as ``.done``; ``PREFIX.digest``
    records the problem's fingerprint); ``resume``: continue from them (refused when the problem differs).
    ``progress``: one line per finished run (on ``print_func``, else standard error).
    """
    import sys

    opts = options or SamplerOptions()
    opts.check()
    _check_smc_options(problem, opts)
    _init_worker(problem)  # this process too: serial runs and the probes run here
    t0 = time.time()
    say = print_func if print_func is not None else (lambda m: print(m, file=sys.stderr))
    pool = _pool(problem, opts.workers) if opts.workers > 1 else None
    try:
        comb, check, summaries, stats = sample_classes(
            problem, opts, pool, checkpoint=checkpoint, resume=resume, print_func=say if progress else None
        )
        draws = comb.draws if problem.branch_classes == (None,) else np.column_stack([comb.draws, comb.klass])
        uniq, inverse = np.unique(draws, axis=0, return_inverse=True)
        preds = pool.map(_worker_predict, list(uniq)) if pool is not None else [problem.predict(t) for t in uniq]
        f_pred = np.asarray(preds)[inverse.ravel()]
    except BaseException:  # Ctrl-C or an error: the workers (which ignore Ctrl-C) stop now, their queued work unrun
        if pool is not None:
            pool.terminate()
        raise
    if pool is not None:
        pool.close()
        pool.join()
    rng = np.random.default_rng(opts.seed + 2)
    f_noisy = np.stack([problem.simulate_measurement(f, t, rng) for f, t in zip(f_pred, draws)])
    if print_func is not None:
        what = "SMC" if opts.sampler == "smc" else "nested sampling"
        print_func(f"{what}: {stats['n_calls']} calls, log Z = {comb.log_evidence:.2f} +- "
                   f"{comb.log_evidence_err:.2f}")  # fmt: skip
    return Calibration(
        problem=problem,
        options=opts,
        draws=draws,
        log_likelihood=comb.log_likelihood,
        log_evidence=comb.log_evidence,
        log_evidence_err=comb.log_evidence_err,
        n_calls=stats["n_calls"],
        n_iterations=stats["n_iterations"],
        ess_kish=comb.ess_kish,
        seconds=time.time() - t0,
        converged=stats["converged"],
        f_pred=f_pred,
        f_noisy=f_noisy,
        start_log_likelihood=problem.start_log_likelihood(),
        classes=summaries,
        runs_check=check,
    )
