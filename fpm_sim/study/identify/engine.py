"""Model updating: a global search, a local least-squares refinement, uncertainty and cross-validation.

Cost: ``sum(r_i^2)`` with ``r_i = (f_model,i - f_measured,i) / sigma_i`` over every observation
(poses x modes of every ``--measured`` file) and every rig test, each with its own standard deviation.
Mode matching: an unlabelled ``fK`` is the model's K-th lowest mode at that pose; a labelled one
(``in_plane`` / ``out_of_plane``) is the K-th lowest of that kind, the kind decided by the mode's
strain-energy split (in-plane springs vs the rest), so sorted order is not assumed and a swap of an
in-plane and an out-of-plane mode near a crossing does not swap the match.

Search (:func:`identify`):

1. global exploration: ``"de"`` (the default: differential evolution of every free parameter on the
   full model at the fitted resolution, the elbow-branch combination an integer variable when the
   geometry is free, mutation ``de_strategy``; the best ``refine_per_class`` final-population members of
   each branch combination are candidates, class leaders first),
   ``"multistart"`` (a Latin hypercube of ``n_starts`` points inside the bounds plus the start, each
   scored with the full model), ``"surrogate-de"`` (differential evolution of the geometry on the
   in-plane surrogate, :mod:`fpm_sim.study.inplane_surrogate`, scale-free, for every elbow-branch
   class, each class's best scored with the full model) or ``"hybrid"`` (the last two candidate lists
   together). The best ``n_refine`` candidates are refined. All seeded (``seed``): the same seed gives
   the same result.
2. local refinement of every candidate (in ``workers`` forked processes when there are several):
   bounded least squares (:func:`scipy.optimize.least_squares`, trust-region reflective) on the full
   segment model; the lowest end is the optimum, every end is kept (``Identification.candidates``). The
   Jacobian is by forward finite differences in parameters normalised to their bounds (step ``1e-3`` of
   the bound width). The model's
   geometry enters through MjSpec compilation, which is not differentiable, so the gradients are
   finite differences, not exact (stated in the report).
3. uncertainty: the Gauss-Newton covariance ``s^2 (J'J)^+`` at the optimum with
   ``s^2 = chi^2 / dof`` (the residuals' own scale: model error included, never below what the
   stated sigmas imply when ``chi^2/dof > 1``; with ``chi^2/dof < 1`` the stated sigmas, ``s^2 = 1``).
4. k-fold cross-validation over poses (:func:`cross_validate`): all observations at a held-out pose,
   from every file, leave together; each fold is refitted from the full-data optimum and predicts
   its held-out poses.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import ConfigError, Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import NearSingularityWarning, Pose, assemble_many
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.identify.data import Observation
from fpm_sim.study.identify.parameters import GEOMETRY_GROUPS, ParameterSet
from fpm_sim.study.tables import SubsystemTest

__all__ = [
    "GLOBAL_METHODS",
    "IN_PLANE_THRESHOLD",
    "CrossValidation",
    "Identification",
    "IdentifyOptions",
    "Problem",
    "SearchStep",
    "cross_validate",
    "identify",
    "predict_observations",
    "predict_with_std",
    "variance_scale",
    "workspace_measures",
    "workspace_residuals",
]

GLOBAL_METHODS = ("de", "hybrid", "multistart", "surrogate-de", "none")
IN_PLANE_THRESHOLD = 0.5
"""A mode is ``in_plane`` when more than this fraction of its strain energy is in in-plane springs."""
PENALTY_SIGMAS = 30.0
"""Residual (in sigmas) of an observation the model cannot give (unreachable or singular pose, too few
modes of the asked kind): large, finite, so that the search moves away from it."""
MODE_MARGIN = 4
"""Modes computed beyond the highest one asked for, so that labelled matching finds its kind."""
ELBOW_BRANCHES: tuple[tuple[int, int, int], ...] = (
    (1, 1, 1),
    (-1, -1, -1),
    (1, 1, -1),
    (1, -1, 1),
    (-1, 1, 1),
    (-1, -1, 1),
    (-1, 1, -1),
    (1, -1, -1),
)
"""Every elbow-branch combination: the discrete variable of ``global_method="de"``."""


class IdentificationError(FpmSimError):
    """The identification cannot run as asked (no data, no free parameter, a start that cannot assemble)."""


@dataclass(frozen=True)
class IdentifyOptions:
    """Search settings. ``segments``: spring locations per link of the model fitted."""

    segments: int = 4
    global_method: str = "de"
    n_starts: int = 24
    n_refine: int = 4
    generations: int = 200
    """``de``: generations of the differential evolution (each ``popsize`` x dimensions evaluations)."""
    popsize: int = 8
    """``de``: population size per dimension (scipy's ``popsize``)."""
    surrogate_seeds: int = 2
    """``de`` with the geometry free: members of the initial population per elbow-branch combination whose
    geometry is that branch's in-plane surrogate optimum (:func:`_surrogate_starts`; their other parameters
    from the Sobol sequence like the rest). ``0``: a Sobol population only."""
    de_strategy: str = "best1bin"
    """``de``: scipy's mutation strategy (``"best1bin"``: around the best member, greedy; ``"rand1bin"``: around
    a random member, keeps more basins alive)."""
    refine_per_class: int = 1
    """``de``: final-population members of each elbow-branch class that are candidates for the local
    refinement (its best ones). The candidates are taken class leaders first (every class's best, then every
    class's second best, ...), ``n_refine`` of them."""
    seed: int = 0
    max_nfev: int = 40
    workers: int = 1
    subsystem_segments: int = 8
    timoshenko: bool = False
    """Links as Timoshenko beams (shear springs and section rotary inertia, :class:`ModelOptions`)."""

    def model_options(self) -> ModelOptions:
        if self.timoshenko:
            return ModelOptions(segments=self.segments, axial=False, gravity=False, shear=True, rotary_inertia=True)
        return fast_options(segments=self.segments)


@dataclass
class Problem:
    """What is fitted: the free parameters, the observations, the rig tests."""

    parameters: ParameterSet
    observations: list[Observation]
    subsystem_tests: list[SubsystemTest] = field(default_factory=list)
    subsystem_sigma_pct: float = 1.0
    workspace: list[Pose] = field(default_factory=list)
    """Poses the machine is known to work at (it was placed there with its motors locked): a description
    under which one is unreachable or has a singularity measure below ``min_singularity`` is penalised
    (:meth:`_Objective.workspace_residuals`). Prior knowledge, not data: no frequency is read there."""
    min_singularity: float = 0.05
    """Smallest singularity measure (:mod:`fpm_sim.kinematics`) accepted at a ``workspace`` pose."""

    @property
    def measured(self) -> np.ndarray:
        return np.array([o.freq_hz for o in self.observations] + [t.experimental_hz for t in self.subsystem_tests])

    @property
    def sigma(self) -> np.ndarray:
        return np.array(
            [o.sigma_hz for o in self.observations]
            + [t.experimental_hz * self.subsystem_sigma_pct / 100.0 for t in self.subsystem_tests]
        )

    @property
    def labels(self) -> list[str]:
        return [o.describe() for o in self.observations] + [f"rig {t.label}" for t in self.subsystem_tests]


def check_problem(problem: Problem) -> None:
    """Refuse a problem that cannot be fitted: fewer data than free parameters (the fit would report an optimum
    and uncertainties that the data do not determine), or a measured pose the start description cannot reach
    (its residual would be NaN). Raises :class:`IdentificationError` naming the file and row."""
    n_free, n_data = len(problem.parameters.parameters), len(problem.observations) + len(problem.subsystem_tests)
    if n_data < n_free:
        raise IdentificationError(
            f"{n_data} measured value(s) for {n_free} free parameters ({', '.join(problem.parameters.names)})",
            parameter="measured",
            hint="measure more poses or modes, or free fewer parameters",
        )
    obs = problem.observations
    if not obs:
        return
    asm = assemble_many(
        problem.parameters.start.geometry,
        [o.pose.x_m for o in obs],
        [o.pose.y_m for o in obs],
        [o.pose.phi_rad for o in obs],
    )
    bad = [o for o, ok in zip(obs, asm.reachable) if not ok]
    if bad:
        o = bad[0]
        where = f"row {o.line}" if o.line is not None else o.describe()
        raise IdentificationError(
            f"{o.source}: {where}: the pose (x = {o.pose.x_m * 1e3:g} mm, y = {o.pose.y_m * 1e3:g} mm, phi = "
            f"{o.pose.phi_rad:g} rad) is unreachable for the start description"
            + (f" ({len(bad)} such rows)" if len(bad) > 1 else ""),
            parameter="measured",
            hint="check the pose columns (x_mm, y_mm in mm, phi_rad in rad) or the start description",
        )


def workspace_measures(problem: Problem, config: Manipulator) -> np.ndarray:
    """The singularity measure of each ``problem.workspace`` pose under ``config`` (NaN where unreachable)."""
    ws = problem.workspace
    return assemble_many(config.geometry, [p.x_m for p in ws], [p.y_m for p in ws], [p.phi_rad for p in ws]).singularity


def workspace_residuals(problem: Problem, config: Manipulator) -> np.ndarray:
    """One residual per ``problem.workspace`` pose: ``PENALTY_SIGMAS * (1 - m / m_min)`` where its singularity
    measure ``m`` is below ``m_min = problem.min_singularity`` (a hinge: 0 at and above it), ``PENALTY_SIGMAS``
    where it is unreachable."""
    if not problem.workspace:
        return np.zeros(0)
    m = workspace_measures(problem, config)
    r = PENALTY_SIGMAS * np.clip(1.0 - m / problem.min_singularity, 0.0, 1.0)
    return np.where(np.isfinite(r), r, PENALTY_SIGMAS)


def _unique_poses(obs: Sequence[Observation]) -> tuple[list[Pose], list[int]]:
    keys: dict[tuple, int] = {}
    poses: list[Pose] = []
    index = []
    for o in obs:
        k = (round(o.pose.x_m, 9), round(o.pose.y_m, 9), round(o.pose.phi_rad, 9))
        if k not in keys:
            keys[k] = len(poses)
            poses.append(o.pose)
        index.append(keys[k])
    return poses, index


def predict_observations(
    config: Manipulator,
    observations: Sequence[Observation],
    *,
    options: ModelOptions | None = None,
    workers: int = 1,
) -> np.ndarray:
    """The model's frequency (Hz) for each observation (mode matching as in the module docstring);
    NaN where the model cannot give it."""
    if not observations:
        return np.zeros(0)
    poses, index = _unique_poses(observations)
    labelled = any(o.label for o in observations)
    n_modes = max(o.mode for o in observations) + (MODE_MARGIN if labelled else 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        pf = pose_frequencies(config, poses, n_modes=n_modes, options=options or fast_options(), workers=workers)
    out = np.full(len(observations), np.nan)
    for j, (o, ip) in enumerate(zip(observations, index)):
        f = pf.frequencies_hz[ip]
        if o.label is None:
            out[j] = f[o.mode - 1]
            continue
        frac = pf.in_plane[ip]
        want = frac > IN_PLANE_THRESHOLD if o.label == "in_plane" else frac <= IN_PLANE_THRESHOLD
        cand = f[want & np.isfinite(f)]
        if len(cand) >= o.mode:
            out[j] = cand[o.mode - 1]
    return out


def _subsystem_predictions(config: Manipulator, tests: Sequence[SubsystemTest], segments: int) -> np.ndarray:
    if not tests:
        return np.zeros(0)
    from fpm_sim.study.reproduce import subsystem_frequencies

    return np.array([r.ours_hz for r in subsystem_frequencies(config, segments=segments, tests=list(tests))])


@dataclass
class SearchStep:
    """One entry of the search history."""

    stage: str
    evaluations: int
    cost: float
    seconds: float
    note: str = ""


class _Objective:
    """Residual function in normalised parameters ``z in [0, 1]``, counting evaluations."""

    def __init__(self, problem: Problem, opts: IdentifyOptions, obs_mask: np.ndarray | None = None) -> None:
        self.problem = problem
        self.opts = opts
        self.ps = problem.parameters
        self.lo, self.hi = self.ps.lower, self.ps.upper
        self.width = np.where(self.hi > self.lo, self.hi - self.lo, 1.0)
        n_obs = len(problem.observations)
        self.obs_mask = np.ones(n_obs, bool) if obs_mask is None else obs_mask
        self.obs = [o for o, k in zip(problem.observations, self.obs_mask) if k]
        self.measured = np.concatenate([problem.measured[:n_obs][self.obs_mask], problem.measured[n_obs:]])
        self.sigma = np.concatenate([problem.sigma[:n_obs][self.obs_mask], problem.sigma[n_obs:]])
        self.sub_idx = self.ps.subset(True)
        self.man_idx = self.ps.subset(False)
        self.nfev = 0
        self._cache: dict[bytes, np.ndarray] = {}

    def x(self, z: np.ndarray) -> np.ndarray:
        return self.lo + np.clip(z, 0.0, 1.0) * self.width

    def z(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, float) - self.lo) / self.width

    def predictions(self, x: np.ndarray) -> np.ndarray:
        """Observations then rig tests. The two blocks are cached apart: a finite-difference step in a rig
        parameter re-solves only the rigs, one in a manipulator parameter only the poses."""
        x = np.asarray(x, float)
        n = len(self.obs) + len(self.problem.subsystem_tests)
        try:
            cfg = self.ps.apply(x)
        except (ConfigError, ValueError):
            return np.full(n, np.nan)
        key_m = b"m" + x[self.man_idx].tobytes()
        key_s = b"s" + x[self.sub_idx].tobytes()
        if key_m not in self._cache:
            self.nfev += 1
            self._cache[key_m] = predict_observations(
                cfg, self.obs, options=self.opts.model_options(), workers=self.opts.workers
            )
        if key_s not in self._cache:
            self._cache[key_s] = _subsystem_predictions(cfg, self.problem.subsystem_tests, self.opts.subsystem_segments)
        out = np.concatenate([self._cache[key_m], self._cache[key_s]])
        if len(self._cache) > 8192:
            self._cache.clear()
        return out

    def workspace_residuals(self, x: np.ndarray) -> np.ndarray:
        """The workspace prior's residuals at parameters ``x`` (:func:`workspace_residuals`)."""
        if not self.problem.workspace:
            return np.zeros(0)
        try:
            cfg = self.ps.apply(np.asarray(x, float))
        except (ConfigError, ValueError):
            return np.full(len(self.problem.workspace), PENALTY_SIGMAS)
        return workspace_residuals(self.problem, cfg)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Observations, then rig tests, then workspace poses (in sigmas)."""
        x = self.x(z)
        f = self.predictions(x)
        r = (f - self.measured) / self.sigma
        r = np.where(np.isfinite(r), r, PENALTY_SIGMAS)
        if not self.problem.workspace:
            return r
        return np.concatenate([r, self.workspace_residuals(x)])

    def cost(self, z: np.ndarray) -> float:
        return float(np.sum(self.residuals(z) ** 2))


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
    candidates: list[dict[str, Any]] = field(default_factory=list)
    start_elbow_branch: tuple[int, int, int] | None = None
    """The start description's elbow branches (the global search may pick another class)."""

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
            "candidates": self.candidates,
            "options": vars(self.options),
            "seconds": self.seconds,
        }

    def table(self) -> str:
        """The fit (cost, chi^2 per degree of freedom) and each parameter's value +- one standard deviation."""
        lines = [
            f"identified {len(self.names)} parameters in {self.seconds:.0f} s (cost {self.cost:.4g}, "
            f"chi2/dof {self.chi2_per_dof:.3g})"
        ]
        for n, v, s in zip(self.names, self.values, self.std):
            lines.append(f"  {n:<42} {v:>12.5g} +- {s:.3g}" + ("  (at bound)" if n in self.at_bound else ""))
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


def _least_squares_z(fun: Any, z0: np.ndarray, max_nfev: int) -> Any:
    """Bounded least squares (trust-region reflective) in parameters normalised to their bounds, ``z in [0, 1]``;
    forward finite differences with a step of ``1e-3`` of the bound width. Every local fit here goes through it."""
    return least_squares(
        fun, np.clip(z0, 0.0, 1.0), bounds=(0.0, 1.0), method="trf", diff_step=1e-3, max_nfev=max_nfev, x_scale=1.0
    )


def variance_scale(chi2_per_dof: float) -> float:
    """``s^2 = max(chi^2/dof, 1)`` (1 where there is no degree of freedom, ``chi2_per_dof`` NaN): the factor on
    the Gauss-Newton covariance, and the unit of the report's cost differences between competing optima."""
    return max(chi2_per_dof, 1.0) if math.isfinite(chi2_per_dof) else 1.0


def _lhs(n: int, d: int, seed: int) -> np.ndarray:
    return qmc.LatinHypercube(d=d, seed=seed).random(n)


SURROGATE_BRANCHES: tuple[tuple[int, int, int], ...] = (
    (1, 1, 1),
    (-1, -1, -1),
    (1, 1, -1),
    (1, -1, -1),
    (-1, -1, 1),
    (-1, 1, 1),
)
"""The elbow-branch classes ``global_method="surrogate-de"`` and ``"hybrid"`` explore (kept as published:
their results depend on it); ``"de"`` seeds its population from all of :data:`ELBOW_BRANCHES`."""


def _surrogate_starts(
    obj: _Objective, opts: IdentifyOptions, branches: Sequence[tuple[int, int, int]] = SURROGATE_BRANCHES
) -> list[tuple[np.ndarray, str, tuple[int, int, int]]]:
    """Differential evolution of the ``geometry`` group on the in-plane surrogate, per elbow-branch class
    (best surrogate cost first)."""
    from scipy.optimize import differential_evolution

    from fpm_sim.study.inplane_surrogate import inplane_first_frequencies

    ps = obj.ps
    gi = [i for i, p in enumerate(ps.parameters) if p.group in GEOMETRY_GROUPS]
    if not gi:
        raise IdentificationError(
            "surrogate-de needs the geometry group free", parameter="global_method", hint="add geometry to free"
        )
    first = [k for k, o in enumerate(obj.obs) if o.mode == 1 and o.label in (None, "in_plane")]
    poses = [obj.obs[k].pose for k in first]
    logf = np.log([obj.obs[k].freq_hz for k in first])
    w = 1.0 / np.array([obj.obs[k].sigma_hz / obj.obs[k].freq_hz for k in first])
    z0 = obj.z(ps.x0)
    out = []
    for branch in branches:
        base = ps.start.replace(geometry=dataclasses.replace(ps.start.geometry, elbow_branch=branch))

        def cost(zg: np.ndarray, base: Manipulator = base) -> float:
            z = z0.copy()
            z[gi] = zg
            try:
                cfg = ps.apply(obj.x(z), base=base)
            except (ConfigError, ValueError):
                return 1e6
            f = inplane_first_frequencies(cfg, poses)
            ok = np.isfinite(f) & (f > 0)
            if not ok.any():
                return 1e6
            d = np.log(np.where(ok, f, 1.0)) - logf
            d = d - np.average(d[ok], weights=w[ok] ** 2)  # scale-free: the level comes from the masses
            d = np.where(ok, d * w, PENALTY_SIGMAS)
            return float(np.sum(d**2) + np.sum(workspace_residuals(obj.problem, cfg) ** 2))

        sol = differential_evolution(
            cost, [(0.0, 1.0)] * len(gi), seed=opts.seed, maxiter=80, popsize=12, tol=1e-7, polish=False
        )
        z = z0.copy()
        z[gi] = sol.x
        out.append((z, f"surrogate-de branch {branch}: surrogate cost {sol.fun:.3g}", branch, sol.fun))
    out.sort(key=lambda t: t[3])
    return [(z, note, br) for z, note, br, _ in out]


_DE_STATE: tuple[list[_Objective], np.ndarray, np.ndarray, bool] | None = None
"""The objectives of the running differential evolution: module state so that forked worker processes
inherit them (the parameter setters are closures, which cannot be pickled)."""


def _de_decode(v: np.ndarray, z_fixed: np.ndarray, free: np.ndarray, geometry_free: bool) -> tuple[np.ndarray, int]:
    """A member of the evolution -> normalised parameters (the held ones from ``z_fixed``) and its branch index."""
    z = z_fixed.copy()
    z[free] = np.clip(v[: len(free)], 0.0, 1.0)
    return z, int(np.rint(v[len(free)])) if geometry_free else 0


def _de_member_cost(v: np.ndarray) -> float:
    assert _DE_STATE is not None
    objs, z_fixed, free, geometry_free = _DE_STATE
    z, k = _de_decode(v, z_fixed, free, geometry_free)
    return objs[k].cost(z)


def _full_model_de(
    problem: Problem, obj: _Objective, opts: IdentifyOptions, *, progress: bool = False
) -> list[tuple[float, np.ndarray, str, tuple[int, int, int] | None]]:
    """Differential evolution of every free parameter on the full model (the fitted resolution), with the
    elbow-branch combination as one more, integer, variable when the geometry is free. Returns the final
    population's best member of each branch combination (cost, z, note, branch), best first.

    The rig parameters (seen only by the rig tests, which see nothing else) are separable: they are fitted
    to the rig tests alone first and held there, so that the evolution spends no rig solve per member.
    With ``opts.workers > 1`` each generation's members are scored in that many forked processes (the
    pose loop inside each then runs serially)."""
    import multiprocessing

    from scipy.optimize import differential_evolution

    global _DE_STATE
    ps = problem.parameters
    geometry_free = any(p.group in GEOMETRY_GROUPS for p in ps.parameters)
    branches: list[tuple[int, int, int] | None] = list(ELBOW_BRANCHES) if geometry_free else [None]
    member_opts = dataclasses.replace(opts, workers=1)
    objs = [_Objective(problem if b is None else _with_branch(problem, b), member_opts) for b in branches]
    z_fixed = obj.z(ps.x0)
    free = np.array(obj.man_idx, dtype=int)
    if obj.sub_idx:
        sub = np.array(obj.sub_idx, dtype=int)
        n_obs = len(obj.obs)

        def rig_residuals(zs: np.ndarray) -> np.ndarray:
            z = z_fixed.copy()
            z[sub] = zs
            # the pose block is cached: only the rigs are re-solved (the workspace block does not see them)
            return obj.residuals(z)[n_obs : n_obs + len(problem.subsystem_tests)]

        z_fixed[sub] = _least_squares_z(rig_residuals, z_fixed[sub], max_nfev=40).x
    d = len(free)
    bounds = [(0.0, 1.0)] * d + ([(0.0, len(branches) - 1.0)] if geometry_free else [])
    init = _de_initial_population(obj, opts, free, branches, progress=progress)
    t0, generation = time.time(), [0]

    def report(intermediate_result: Any) -> None:
        generation[0] += 1
        if progress and (generation[0] % 10 == 0 or generation[0] == opts.generations):
            print(
                f"[identify] differential evolution: generation {generation[0]}/{opts.generations}, best cost "
                f"{intermediate_result.fun:.4g} ({time.time() - t0:.0f} s)",
                flush=True,
            )

    integrality = [False] * d + ([True] if geometry_free else [])
    _DE_STATE = (objs, z_fixed, free, geometry_free)
    pool = multiprocessing.get_context("fork").Pool(opts.workers) if opts.workers > 1 else None
    try:
        sol = differential_evolution(
            _de_member_cost,
            bounds,
            integrality=integrality,
            seed=opts.seed,
            maxiter=opts.generations,
            popsize=opts.popsize,
            strategy=opts.de_strategy,
            tol=1e-8,
            polish=False,
            init=init,
            updating="deferred",
            callback=report,
            workers=pool.map if pool is not None else 1,
        )
    finally:
        _DE_STATE = None
        if pool is not None:
            pool.terminate()
    obj.nfev += int(sol.nfev)
    pop = np.atleast_2d(getattr(sol, "population", sol.x[None, :]))
    energies = np.atleast_1d(getattr(sol, "population_energies", [sol.fun]))
    out: dict[int, list[tuple[float, np.ndarray, str, tuple[int, int, int] | None]]] = {}
    note = f"differential evolution ({sol.nit} generations, {sol.nfev} evaluations)"
    for v, e in sorted(zip(pop, energies), key=lambda t: t[1]):
        z, k = _de_decode(v, z_fixed, free, geometry_free)
        members = out.setdefault(k, [])
        if len(members) < max(1, opts.refine_per_class):
            rank = "best" if not members else f"no. {len(members) + 1}"
            where = f" with elbow branches {branches[k]}" if branches[k] is not None else ""
            members.append((float(e), z, f"{note}, {rank} of its final population{where}", branches[k]))
    # class leaders first (every class's best, best first), then every class's second best, ...
    return [
        c
        for rank in range(max(1, opts.refine_per_class))
        for c in sorted((m[rank] for m in out.values() if len(m) > rank), key=lambda t: t[0])
    ]


def _de_initial_population(
    obj: _Objective,
    opts: IdentifyOptions,
    free: np.ndarray,
    branches: Sequence[tuple[int, int, int] | None],
    *,
    progress: bool = False,
) -> np.ndarray:
    """The evolution's first population: a scrambled Sobol sequence (scipy's size for ``init="sobol"``: the
    power of two at or above ``popsize`` x dimensions), its first ``opts.surrogate_seeds`` members per
    elbow-branch combination given that branch's in-plane surrogate optimum as geometry."""
    geometry_free = branches != [None]
    d = len(free) + (1 if geometry_free else 0)
    n = int(2 ** math.ceil(math.log2(max(5, opts.popsize * d))))
    pop = qmc.Sobol(d=d, scramble=True, seed=opts.seed).random(n)
    if geometry_free:
        pop[:, -1] *= len(branches) - 1.0
    if opts.surrogate_seeds <= 0 or not geometry_free:
        return pop
    t0 = time.time()
    geo = [j for j, i in enumerate(free) if obj.ps.parameters[i].group in GEOMETRY_GROUPS]
    row = 0
    found = _surrogate_starts(obj, opts, [b for b in branches if b is not None])
    for z, _, branch in found:
        for _ in range(opts.surrogate_seeds):
            if row >= n:
                break
            pop[row, geo] = z[free[geo]]
            pop[row, -1] = float(branches.index(branch))
            row += 1
    if progress:
        print(
            f"[identify] differential evolution: {row} of {n} first members seeded from the in-plane surrogate's "
            f"optimum of each elbow-branch combination ({time.time() - t0:.0f} s)",
            flush=True,
        )
    return pop


def _with_branch(problem: Problem, branch: tuple[int, int, int]) -> Problem:
    ps = problem.parameters
    start = ps.start.replace(geometry=dataclasses.replace(ps.start.geometry, elbow_branch=branch))
    return dataclasses.replace(problem, parameters=ParameterSet(start, ps.parameters))


_REFINE_STATE: tuple[Problem, IdentifyOptions] | None = None
"""The problem of the running local refinements: module state so that forked worker processes inherit it."""

_Refined = tuple[np.ndarray, np.ndarray, np.ndarray, bool, int]
"""A local refinement's end: normalised parameters, residuals, Jacobian, success, evaluations spent."""


def _refine(job: tuple[np.ndarray, tuple[int, int, int] | None]) -> _Refined:
    """Bounded least squares from ``job = (z, branch)`` on the problem in :data:`_REFINE_STATE` (on the
    elbow-branch combination ``branch`` when given)."""
    assert _REFINE_STATE is not None
    problem, opts = _REFINE_STATE
    z, branch = job
    ob = _Objective(problem if branch is None else _with_branch(problem, branch), opts)
    sol = _least_squares_z(ob.residuals, z, max_nfev=opts.max_nfev)
    return sol.x, sol.fun, sol.jac, bool(sol.success), ob.nfev


def _refine_all(
    problem: Problem, opts: IdentifyOptions, starts: Sequence[tuple[np.ndarray, str, Any]]
) -> Iterator[_Refined]:
    """Every start refined (:func:`_refine`). With ``opts.workers > 1`` and several starts, the starts are
    refined in that many forked processes, one pose loop each (fewer, longer jobs than splitting each
    evaluation's pose loop); otherwise one after the other, each pose loop in ``opts.workers`` processes.
    Yields the ends in the starts' order as they come."""
    import multiprocessing

    global _REFINE_STATE
    jobs = [(z, branch) for z, _, branch in starts]
    parallel = opts.workers > 1 and len(jobs) > 1
    _REFINE_STATE = (problem, dataclasses.replace(opts, workers=1) if parallel else opts)
    try:
        if not parallel:
            for job in jobs:
                yield _refine(job)
            return
        with multiprocessing.get_context("fork").Pool(min(opts.workers, len(jobs))) as pool:
            yield from pool.imap(_refine, jobs, chunksize=1)
    finally:
        _REFINE_STATE = None


def identify(problem: Problem, *, options: IdentifyOptions | None = None, progress: bool = False) -> Identification:
    """Fit ``problem`` (see module docstring). Returns the optimum with its uncertainty and history."""

    opts = options or IdentifyOptions()
    if opts.global_method not in GLOBAL_METHODS:
        raise IdentificationError(
            "unknown global method",
            parameter="global_method",
            value=opts.global_method,
            hint=f"choose from {', '.join(GLOBAL_METHODS)}",
        )
    if not problem.observations and not problem.subsystem_tests:
        raise IdentificationError("no data", parameter="measured", hint="give measured and/or subsystems data")
    check_problem(problem)
    t_start = time.time()
    history: list[SearchStep] = []
    ps = problem.parameters
    obj = _Objective(problem, opts)

    def log(stage: str, cost: float, note: str = "") -> None:
        history.append(SearchStep(stage, obj.nfev, cost, time.time() - t_start, note))
        if progress:
            print(
                f"[identify] {stage}: cost {cost:.4g} ({obj.nfev} evaluations, {time.time() - t_start:.0f} s) {note}",
                flush=True,
            )

    z_start = obj.z(ps.x0)
    c0 = obj.cost(z_start)
    log("start", c0)
    starts: list[tuple[np.ndarray, str, Any]] = []
    scored: list[tuple[float, np.ndarray, str, Any]] = [(c0, z_start, "start description", None)]
    if opts.global_method in ("multistart", "hybrid"):
        pts = _lhs(opts.n_starts, len(ps.parameters), opts.seed)
        for k, z in enumerate(pts):
            scored.append((obj.cost(z), z, f"latin-hypercube point {k}", None))
        log("global latin hypercube", min(t[0] for t in scored), f"{len(pts)} points scored with the full model")
    geometry_free = any(p.group in GEOMETRY_GROUPS for p in ps.parameters)
    if opts.global_method == "surrogate-de" or (opts.global_method == "hybrid" and geometry_free):
        for z, note, branch in _surrogate_starts(obj, opts):
            ob = _Objective(_with_branch(problem, branch), opts)
            scored.append((ob.cost(z), z, note, branch))
            obj.nfev += ob.nfev
        log(
            "global surrogate-de",
            min(t[0] for t in scored),
            "best geometry of each elbow-branch class, scored with the full model",
        )
    if opts.global_method == "de":
        found = _full_model_de(problem, obj, opts, progress=progress)
        log(
            "global differential evolution",
            min(t[0] for t in found),
            f"full model; {len({t[3] for t in found})} elbow-branch classes in the final population",
        )
        # the evolution's candidates in their order (class leaders first), then the start description
        scored = found + scored[:1]
    else:
        scored.sort(key=lambda t: t[0])
    starts = [(z, note, branch) for _, z, note, branch in scored[: max(1, opts.n_refine)]]
    if opts.global_method == "none":
        starts = [(z_start, "start description", None)]

    best = None
    candidates = []
    for (_, note, branch), (zs, fun, jac, success, nfev) in zip(starts, _refine_all(problem, opts, starts)):
        problem_b = problem if branch is None else _with_branch(problem, branch)
        obj.nfev += nfev
        c = float(np.sum(fun**2))
        candidates.append({"from": note, "cost": c, "values": obj.x(zs).tolist(), "success": success})
        log("local least squares", c, f"from {note}")
        if best is None or c < best[0]:
            best = (c, (zs, fun, jac), problem_b)
    assert best is not None
    cost, (z_opt, fun, jz), problem_b = best
    ob = obj if problem_b is problem else _Objective(problem_b, opts)
    x = ob.x(z_opt)
    jx = jz / ob.width[None, :]
    n, k = len(fun) - len(problem.workspace), len(x)  # the workspace residuals are a prior, not data
    dof = max(n - k, 0)
    chi2 = float(np.sum(fun**2))
    chi2_dof = chi2 / dof if dof > 0 else math.nan
    s2 = variance_scale(chi2_dof)
    cov = s2 * np.linalg.pinv(jx.T @ jx)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    eps = 1e-6
    at_bound = [p.name for p, zi in zip(ps.parameters, z_opt) if zi < eps or zi > 1 - eps]
    cfg = problem_b.parameters.apply(x)
    predicted = ob.predictions(x)
    return Identification(
        problem=problem_b,
        values=x,
        std=std,
        correlation=corr,
        predicted=predicted,
        cost=cost,
        chi2_per_dof=chi2_dof,
        dof=dof,
        at_bound=at_bound,
        history=history,
        options=opts,
        seconds=time.time() - t_start,
        config=cfg,
        jacobian=jx,
        candidates=candidates,
        start_elbow_branch=ps.start.geometry.elbow_branch,
    )


def predict_with_std(
    result: Identification, observations: Sequence[Observation], *, rel_step: float = 1e-3
) -> tuple[np.ndarray, np.ndarray]:
    """Predicted frequencies (Hz) for ``observations`` and their standard deviations from the parameters'
    covariance (delta method: ``sqrt(g' C g)`` with ``g`` the forward-difference gradient of each
    prediction, step ``rel_step`` of each parameter's bound width)."""
    ps = result.problem.parameters
    opts = result.options.model_options()
    f0 = predict_observations(result.config, observations, options=opts, workers=result.options.workers)
    cov = np.outer(result.std, result.std) * np.nan_to_num(result.correlation)
    grads = []
    for i, p in enumerate(ps.parameters):
        h = rel_step * (p.upper - p.lower)
        x = result.values.copy()
        x[i] = x[i] + h if x[i] + h <= p.upper else x[i] - h
        step = x[i] - result.values[i]
        f = predict_observations(ps.apply(x), observations, options=opts, workers=result.options.workers)
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
    poses, index = _unique_poses(obs)
    fold = fold_assignment(len(poses), folds, result.options.seed)
    pred = np.full(len(obs), np.nan)
    opts = result.options
    z_best = None
    for k in range(folds):
        train = np.array([fold[i] != k for i in index])
        ob = _Objective(problem, opts, obs_mask=train)
        z_best = ob.z(result.values)
        sol = _least_squares_z(ob.residuals, z_best, max_nfev=max_nfev)
        cfg = problem.parameters.apply(ob.x(sol.x))
        test = [o for o, t in zip(obs, train) if not t]
        f = predict_observations(cfg, test, options=opts.model_options(), workers=opts.workers)
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
