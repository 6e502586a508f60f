"""Model updating: a global search, a local least-squares refinement, uncertainty and cross-validation.

What is fitted and the model's predictions: :mod:`.problem`; the cost ``sum(r_i^2)`` with
``r_i = (f_model,i - f_measured,i) / sigma_i`` over every observation (poses x modes of every ``--measured``
file) and every rig test, each with its own standard deviation: :mod:`.objective`; the searches:
:mod:`.strategies`.

Search (:func:`identify`):

1. global exploration: ``"auto"`` (the default) is ``"staged"`` where the data are rich (at least
   :data:`~fpm_sim.study.identify.problem.RICH_DATA_RATIO` data per free parameter), else ``"de"``;
   ``"staged"`` (a continuation from the start description and a few prior samples, ``staged_starts``: the
   parameters freed in stages, masses and sections, then the collective geometry, then each chain's, each stage
   a bounded least-squares fit with the exact Jacobian where the model allows it; every start's end is a
   candidate; :mod:`.strategies.staged`; it stays on the start's elbow branches), ``"de"`` (differential
   evolution of every free parameter on the
   full model at the fitted resolution, the elbow-branch combination an integer variable when the
   geometry is free, mutation ``de_strategy``; the best ``refine_per_class`` final-population members of
   each branch combination are candidates, class leaders first; :mod:`.strategies.de`),
   ``"multistart"`` (a Latin hypercube of ``n_starts`` points inside the bounds plus the start, each
   scored with the full model; :mod:`.strategies.multistart`), ``"surrogate-de"`` (differential evolution
   of the geometry on the in-plane surrogate, :mod:`fpm_sim.study.inplane_surrogate`, scale-free, for every
   elbow-branch class, each class's best scored with the full model; :mod:`.strategies.surrogate`) or
   ``"hybrid"`` (the last two candidate lists together). The best ``n_refine`` candidates are refined. All
   seeded (``seed``): the same seed gives the same result.
2. local refinement of every candidate (in ``workers`` spawned processes when there are several;
   :mod:`.strategies.lsq`): bounded least squares (:func:`scipy.optimize.least_squares`, trust-region
   reflective) on the full segment model; the lowest end is the optimum, every end is kept
   (``Identification.candidates``). The Jacobian is by forward finite differences in parameters normalised
   to their bounds (step ``1e-3`` of the bound width; the default), or with ``jacobian="exact"`` from the
   eigen-solve's sensitivities (:mod:`.sensitivity`; stated in the report).
3. uncertainty: the Gauss-Newton covariance ``s^2 (J'J)^+`` at the optimum with
   ``s^2 = chi^2 / dof`` (the residuals' own scale: model error included, never below what the
   stated sigmas imply when ``chi^2/dof > 1``; with ``chi^2/dof < 1`` the stated sigmas, ``s^2 = 1``).
4. diagnosis (:mod:`.diagnosis`): the chi-squared test of the cost against the noise floor, which parameters
   the data determine, the measured poses the identified machine cannot reach or puts near a singularity.
5. k-fold cross-validation over poses (:func:`cross_validate`): all observations at a held-out pose,
   from every file, leave together; each fold is refitted from the full-data optimum and predicts
   its held-out poses.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fpm_sim.config import Manipulator
from fpm_sim.study.identify.data import Observation
from fpm_sim.study.identify.diagnosis import Diagnosis, diagnose
from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.problem import (
    GLOBAL_METHODS,
    JACOBIANS,
    PAIRINGS,
    RICH_DATA_RATIO,
    SURROGATE_BRANCHES,
    IdentificationError,
    IdentifyOptions,
    Problem,
    check_problem,
    predict_observations,
    unique_poses,
    with_branch,
)
from fpm_sim.study.identify.strategies import Candidate, Strategy
from fpm_sim.study.identify.strategies.de import DifferentialEvolution
from fpm_sim.study.identify.strategies.lsq import LeastSquares, least_squares_z, objective_jacobian
from fpm_sim.study.identify.strategies.multistart import LatinHypercube
from fpm_sim.study.identify.strategies.staged import StagedLeastSquares
from fpm_sim.study.identify.strategies.surrogate import SurrogateDE

__all__ = [
    "CrossValidation",
    "Identification",
    "SearchStep",
    "cross_validate",
    "fold_assignment",
    "identify",
    "predict_with_std",
    "resolve_global_method",
    "variance_scale",
]


@dataclass
class SearchStep:
    """One entry of the search history."""

    stage: str
    evaluations: int
    cost: float
    seconds: float
    note: str = ""


@dataclass
class Identification:
    """The result of :func:`identify`."""

    problem: Problem
    values: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    predicted: np.ndarray
    cost: float
    chi2_per_dof: float
    dof: int
    at_bound: list[str]
    history: list[SearchStep]
    options: IdentifyOptions
    seconds: float
    config: Manipulator
    jacobian: np.ndarray
    candidates: list[Candidate] = field(default_factory=list)
    """Every local refinement's end (:class:`~fpm_sim.study.identify.strategies.Candidate`), in the order of
    their starts."""
    start_elbow_branch: tuple[int, int, int] | None = None
    """The start description's elbow branches (the global search may pick another class)."""
    diagnosis: Diagnosis | None = None
    """Whether the fit found the machine (:mod:`.diagnosis`): the noise-floor test, what the data determine, the
    measured poses the identified machine cannot reach or puts near a singularity."""

    @property
    def names(self) -> list[str]:
        return self.problem.parameters.names

    @property
    def measured(self) -> np.ndarray:
        return self.problem.measured

    @property
    def residual_pct(self) -> np.ndarray:
        return 100.0 * (self.predicted / self.measured - 1.0)

    def to_dict(self) -> dict[str, Any]:
        p = self.problem
        return {
            "parameters": {
                n: {"value": float(v), "std": float(s), "start": float(fp.start), "bounds": [fp.lower, fp.upper]}
                for n, v, s, fp in zip(self.names, self.values, self.std, p.parameters.parameters)
            },
            "correlation": self.correlation.tolist(),
            "at_bound": self.at_bound,
            "cost": self.cost,
            "chi2_per_dof": self.chi2_per_dof,
            "dof": self.dof,
            "residuals": [
                {
                    "data": lab,
                    "measured_hz": float(m),
                    "predicted_hz": float(f),
                    "sigma_hz": float(s),
                    "error_pct": float(e),
                }
                for lab, m, f, s, e in zip(p.labels, self.measured, self.predicted, p.sigma, self.residual_pct)
            ],
            "history": [vars(h) for h in self.history],
            "candidates": [
                {"from": c.origin, "cost": c.cost, "values": p.parameters.from_unit(c.z).tolist(), "success": c.success}
                for c in self.candidates
            ],
            "options": vars(self.options),
            "seconds": self.seconds,
            "diagnosis": self.diagnosis.to_dict() if self.diagnosis is not None else None,
        }

    def table(self) -> str:
        """The fit (cost, chi^2 per degree of freedom) and each parameter's value +- one standard deviation."""
        lines = [
            f"identified {len(self.names)} parameters in {self.seconds:.0f} s (cost {self.cost:.4g}, "
            f"chi2/dof {self.chi2_per_dof:.3g})"
        ]
        for n, v, s in zip(self.names, self.values, self.std):
            lines.append(f"  {n:<42} {v:>12.5g} +- {s:.3g}" + ("  (at bound)" if n in self.at_bound else ""))
        if self.diagnosis is not None:
            lines += ["  " + line for line in self.diagnosis.lines()]
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, cv: CrossValidation | None = None) -> Any:
        """Model against measured frequency (Hz) of every measured pose, by data source (with ``cv``: also the
        cross-validated predictions); returns the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5.5, 5), constrained_layout=True)
        p = self.problem
        n_obs = len(p.observations)
        meas, pred = self.measured[:n_obs], self.predicted[:n_obs]
        sources = [o.source for o in p.observations]
        for s in sorted(set(sources)):
            m = np.array([x == s for x in sources])
            ax.errorbar(meas[m], pred[m], xerr=p.sigma[:n_obs][m], fmt="o", label=f"{s} (in-sample)", alpha=0.8)
            if cv is not None:
                ax.plot(meas[m], cv.predicted[m], "x", label=f"{s} (cross-validated)")
        if n_obs:
            lim = [np.nanmin(meas) * 0.9, np.nanmax(meas) * 1.1]
            ax.plot(lim, lim, "k--", lw=0.8)
        ax.set_xlabel("measured (Hz)")
        ax.set_ylabel("model (Hz)")
        ax.legend(fontsize=7)
        return ax.figure


def variance_scale(chi2_per_dof: float) -> float:
    """``s^2 = max(chi^2/dof, 1)`` (1 where there is no degree of freedom, ``chi2_per_dof`` NaN): the factor on
    the Gauss-Newton covariance, and the unit of the report's cost differences between competing optima."""
    return max(chi2_per_dof, 1.0) if math.isfinite(chi2_per_dof) else 1.0


class _History:
    """The search history, printed as it grows when ``progress``."""

    def __init__(self, obj: Objective, *, progress: bool) -> None:
        self.obj, self.progress = obj, progress
        self.steps: list[SearchStep] = []
        self.t_start = time.time()

    def log(self, stage: str, cost: float, note: str = "") -> None:
        elapsed = time.time() - self.t_start
        self.steps.append(SearchStep(stage, self.obj.nfev, cost, elapsed, note))
        if self.progress:
            print(
                f"[identify] {stage}: cost {cost:.4g} ({self.obj.nfev} evaluations, {elapsed:.0f} s) {note}",
                flush=True,
            )


def _check_request(problem: Problem, opts: IdentifyOptions) -> None:
    """Refuse an unknown global method, a problem without data or one that cannot be fitted."""
    if opts.global_method not in GLOBAL_METHODS:
        raise IdentificationError(
            "unknown global method",
            parameter="global_method",
            value=opts.global_method,
            hint=f"choose from {', '.join(GLOBAL_METHODS)}",
        )
    for name, value, allowed in (("pairing", opts.pairing, PAIRINGS), ("jacobian", opts.jacobian, JACOBIANS)):
        if value not in allowed:
            raise IdentificationError(
                f"unknown {name}", parameter=name, value=value, hint=f"choose from {', '.join(allowed)}"
            )
    for name in ("staged_starts", "staged_max_nfev"):
        if getattr(opts, name) < 1:
            raise IdentificationError("must be >= 1", parameter=name, value=getattr(opts, name))
    if not 0.0 <= opts.staged_spread <= 1.0:
        raise IdentificationError(
            "must be between 0 and 1 (a fraction of each bound's width)",
            parameter="staged_spread",
            value=opts.staged_spread,
        )
    if not problem.observations and not problem.subsystem_tests:
        raise IdentificationError("no data", parameter="measured", hint="give measured and/or subsystems data")
    check_problem(problem)


def _global_candidates(
    obj: Objective, opts: IdentifyOptions, start: Candidate, history: _History, *, progress: bool
) -> list[Candidate]:
    """The starts of the local refinement (module docstring, step 1): the global method's candidates, best
    first (``"de"``: in the evolution's order, then the start description), ``n_refine`` of them."""
    method = opts.global_method
    if method == "none":
        return [start]
    scored = [start]
    if method in ("multistart", "hybrid"):
        lhs: Strategy = LatinHypercube(opts.n_starts)
        points = lhs.search(obj, seed=opts.seed, workers=1, progress=progress)
        scored += points
        history.log(
            "global latin hypercube", min(c.cost for c in scored), f"{len(points)} points scored with the full model"
        )
    if method == "surrogate-de" or (method == "hybrid" and obj.problem.geometry_free):
        surrogate: Strategy = SurrogateDE(SURROGATE_BRANCHES)
        scored += surrogate.search(obj, seed=opts.seed, workers=1, progress=progress)
        history.log(
            "global surrogate-de",
            min(c.cost for c in scored),
            "best geometry of each elbow-branch class, scored with the full model",
        )
    if method == "staged":
        from fpm_sim.study.identify.sensitivity import supported

        staged: Strategy = StagedLeastSquares(
            opts.staged_starts, opts.staged_spread, opts.staged_max_nfev, supported(opts.model_options())
        )
        found = staged.search(obj, seed=opts.seed, workers=opts.workers, progress=progress)
        for c in found:
            history.log("staged least squares", c.cost, c.origin)
        return sorted(found, key=lambda c: c.cost)[: max(1, opts.n_refine)]
    if method == "de":
        de: Strategy = DifferentialEvolution()
        found = de.search(obj, seed=opts.seed, workers=opts.workers, progress=progress)
        history.log(
            "global differential evolution",
            min(c.cost for c in found),
            f"full model; {len({c.branch for c in found})} elbow-branch classes in the final population",
        )
        scored = [*found, start]  # the evolution's candidates in their order (class leaders first), then the start
    else:
        scored.sort(key=lambda c: c.cost)
    return scored[: max(1, opts.n_refine)]


def _uncertainty(
    best: Candidate, obj: Objective, n_workspace: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
    """At the optimum (module docstring, step 3): the Jacobian in the parameters' units, the standard
    deviations, the correlation matrix, chi^2 per degree of freedom and the degrees of freedom."""
    assert best.residuals is not None
    assert best.jacobian is not None
    fun = best.residuals
    jx = best.jacobian / obj.width[None, :]
    n, k = len(fun) - n_workspace, len(obj.width)  # the workspace residuals are a prior, not data
    dof = max(n - k, 0)
    chi2 = float(np.sum(fun**2))
    chi2_dof = chi2 / dof if dof > 0 else math.nan
    cov = variance_scale(chi2_dof) * np.linalg.pinv(jx.T @ jx)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    return jx, std, corr, chi2_dof, dof


def resolve_global_method(problem: Problem, opts: IdentifyOptions) -> tuple[str, str]:
    """The global method that runs for ``opts.global_method`` (``"auto"``: ``"staged"`` for rich data,
    :data:`~fpm_sim.study.identify.problem.RICH_DATA_RATIO`, else ``"de"``) and why, in words."""
    if opts.global_method != "auto":
        return opts.global_method, ""
    n_data = len(problem.observations) + len(problem.subsystem_tests)
    n_free = len(problem.parameters.parameters)
    rich = n_data >= RICH_DATA_RATIO * n_free
    return ("staged" if rich else "de"), (
        f"auto: {'staged' if rich else 'de'} ({n_data} data for {n_free} free parameters, rich from "
        f"{RICH_DATA_RATIO} per parameter)"
    )


def identify(problem: Problem, *, options: IdentifyOptions | None = None, progress: bool = False) -> Identification:
    """Fit ``problem`` (see module docstring). Returns the optimum with its uncertainty and history (its options
    name the global method that ran: ``"auto"`` resolved)."""
    opts = options or IdentifyOptions()
    _check_request(problem, opts)
    method, why = resolve_global_method(problem, opts)
    opts = dataclasses.replace(opts, global_method=method)
    obj = Objective(problem, opts)
    history = _History(obj, progress=progress)
    ps = problem.parameters
    z_start = obj.z(ps.x0)
    start = Candidate(z_start, obj.cost(z_start), "start description")
    history.log("start", start.cost, why)
    starts = _global_candidates(obj, opts, start, history, progress=progress)
    ends: list[Candidate] = []
    for end in LeastSquares(tuple(starts)).ends(obj, workers=opts.workers):
        obj.nfev += end.nfev
        ends.append(end)
        history.log("local least squares", end.cost, f"from {end.origin}")
    best = min(ends, key=lambda c: c.cost)  # the first of equal costs
    problem_b = problem if best.branch is None else with_branch(problem, best.branch)
    ob = obj if problem_b is problem else Objective(problem_b, opts)
    x = ob.x(best.z)
    jx, std, corr, chi2_dof, dof = _uncertainty(best, ob, len(problem.workspace))
    assert best.residuals is not None
    n_data = len(best.residuals) - len(problem.workspace)  # the workspace residuals are a prior, not data
    config = problem_b.parameters.apply(x)
    diagnosis = diagnose(problem_b, config, best.residuals[:n_data], jx[:n_data], ob.width)
    eps = 1e-6
    return Identification(
        problem=problem_b,
        values=x,
        std=std,
        correlation=corr,
        predicted=ob.predictions(x),
        cost=best.cost,
        chi2_per_dof=chi2_dof,
        dof=dof,
        at_bound=[p.name for p, zi in zip(ps.parameters, best.z) if zi < eps or zi > 1 - eps],
        history=history.steps,
        options=opts,
        seconds=time.time() - history.t_start,
        config=config,
        jacobian=jx,
        candidates=ends,
        start_elbow_branch=ps.start.geometry.elbow_branch,
        diagnosis=diagnosis,
    )


def predict_with_std(
    result: Identification, observations: Sequence[Observation], *, rel_step: float = 1e-3
) -> tuple[np.ndarray, np.ndarray]:
    """Predicted frequencies (Hz) for ``observations`` and their standard deviations from the parameters'
    covariance (delta method: ``sqrt(g' C g)`` with ``g`` the forward-difference gradient of each
    prediction, step ``rel_step`` of each parameter's bound width)."""
    ps = result.problem.parameters
    opts = result.options.model_options()
    f0 = predict_observations(
        result.config, observations, options=opts, workers=result.options.workers, pairing=result.options.pairing
    )
    cov = np.outer(result.std, result.std) * np.nan_to_num(result.correlation)
    grads = []
    for i, p in enumerate(ps.parameters):
        h = rel_step * (p.upper - p.lower)
        x = result.values.copy()
        x[i] = x[i] + h if x[i] + h <= p.upper else x[i] - h
        step = x[i] - result.values[i]
        f = predict_observations(
            ps.apply(x), observations, options=opts, workers=result.options.workers, pairing=result.options.pairing
        )
        grads.append((f - f0) / step)
    g = np.array(grads).T  # (n_obs, n_params)
    return f0, np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g, cov, g), 0.0))


@dataclass
class CrossValidation:
    """k-fold cross-validated predictions: for each observation, the prediction of the fit that did not see its pose."""

    folds: int
    fold_of_pose: list[int]
    predicted: np.ndarray
    measured: np.ndarray
    sources: list[str]
    labels: list[str]
    seconds: float

    def error_pct(self) -> np.ndarray:
        return 100.0 * (self.predicted / self.measured - 1.0)

    def mean_abs_pct(self, source: str | None = None) -> float:
        e = self.error_pct()
        m = np.array([source is None or s == source for s in self.sources]) & np.isfinite(e)
        return float(np.mean(np.abs(e[m]))) if m.any() else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {
            "folds": self.folds,
            "fold_of_pose": self.fold_of_pose,
            "predictions": [
                {"data": lab, "source": s, "measured_hz": float(m), "cv_predicted_hz": float(p)}
                for lab, s, m, p in zip(self.labels, self.sources, self.measured, self.predicted)
            ],
            "mean_abs_pct": {s: self.mean_abs_pct(s) for s in sorted(set(self.sources))},
            "seconds": self.seconds,
        }

    def table(self) -> str:
        """Each observation's measured and cross-validated frequency (Hz), and the mean error per source."""
        lines = [f"{self.folds}-fold cross-validation ({self.seconds:.0f} s)"]
        lines.append(f"  {'data':<36} {'measured Hz':>11} {'CV Hz':>9} {'err %':>7}")
        for lab, m, p, e in zip(self.labels, self.measured, self.predicted, self.error_pct()):
            lines.append(f"  {lab:<36} {m:>11.3f} {p:>9.3f} {e:>+7.2f}")
        for s in sorted(set(self.sources)):
            lines.append(f"  {s}: mean |err| {self.mean_abs_pct(s):.2f} %")
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Cross-validated prediction against measured frequency (Hz), by source; returns the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5.5, 5), constrained_layout=True)
        for s in sorted(set(self.sources)):
            m = np.array([x == s for x in self.sources])
            ax.plot(self.measured[m], self.predicted[m], "x", label=f"{s} ({self.mean_abs_pct(s):.2f} % mean |err|)")
        ok = np.isfinite(self.measured)
        if ok.any():
            lim = [np.min(self.measured[ok]) * 0.9, np.max(self.measured[ok]) * 1.1]
            ax.plot(lim, lim, "k--", lw=0.8)
        ax.set_xlabel("measured (Hz)")
        ax.set_ylabel("cross-validated model (Hz)")
        ax.set_title(f"{self.folds}-fold cross-validation", fontsize=9)
        ax.legend(fontsize=7)
        return ax.figure


def fold_assignment(n_poses: int, folds: int, seed: int) -> np.ndarray:
    """Fold (0 .. folds-1) of each of ``n_poses`` poses: a seeded permutation dealt round-robin."""
    if not 2 <= folds <= n_poses:
        raise IdentificationError(
            f"must be between 2 and the number of poses ({n_poses})", parameter="folds", value=folds
        )
    perm = np.random.default_rng(seed).permutation(n_poses)
    out = np.empty(n_poses, int)
    out[perm] = np.arange(n_poses) % folds
    return out


def cross_validate(
    result: Identification, *, folds: int, max_nfev: int = 12, progress: bool = False
) -> CrossValidation:
    """k-fold cross-validation over poses, each fold refitted from ``result``'s optimum (see module docstring)."""
    t0 = time.time()
    problem = result.problem
    obs = problem.observations
    poses, index = unique_poses(obs)
    fold = fold_assignment(len(poses), folds, result.options.seed)
    pred = np.full(len(obs), np.nan)
    opts = result.options
    z_best = None
    for k in range(folds):
        train = np.array([fold[i] != k for i in index])
        ob = Objective(problem, opts, obs_mask=train)
        z_best = ob.z(result.values)
        sol = least_squares_z(ob.residuals, z_best, max_nfev=max_nfev, jac=objective_jacobian(ob))
        cfg = problem.parameters.apply(ob.x(sol.x))
        test = [o for o, t in zip(obs, train) if not t]
        f = predict_observations(cfg, test, options=opts.model_options(), workers=opts.workers, pairing=opts.pairing)
        pred[~train] = f
        if progress:
            print(
                f"[identify] fold {k + 1}/{folds}: {len(test)} held-out observations ({time.time() - t0:.0f} s)",
                flush=True,
            )
    return CrossValidation(
        folds=folds,
        fold_of_pose=fold.tolist(),
        predicted=pred,
        measured=np.array([o.freq_hz for o in obs]),
        sources=[o.source for o in obs],
        labels=[o.describe() for o in obs],
        seconds=time.time() - t0,
    )
