"""Differential evolution of every free parameter on the full model (the fitted resolution), with the
elbow-branch combination as one more, integer, variable when the geometry is free (the default global search,
``global_method="de"``).

The first population is a scrambled Sobol sequence, its first members per branch combination seeded from the
in-plane surrogate's optimum (:func:`initial_population`). The rig parameters (seen only by the rig tests,
which see nothing else) are separable: they are fitted to the rig tests alone first and held there, so that the
evolution spends no rig solve per member. With ``workers > 1`` each generation's members are scored in that
many ``spawn`` processes that receive the members' objectives once, in their initializer (the pose loop inside
each then runs serially). The candidates: the best ``refine_per_class`` final-population members of each
branch combination, class leaders first (every class's best, best first, then every class's second best, ...).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution
from scipy.stats import qmc

from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.parameters import GEOMETRY_GROUPS
from fpm_sim.study.identify.problem import ELBOW_BRANCHES, IdentifyOptions
from fpm_sim.study.identify.strategies import Candidate, spawn_pool
from fpm_sim.study.identify.strategies.lsq import least_squares_z
from fpm_sim.study.identify.strategies.surrogate import surrogate_starts

__all__ = ["DifferentialEvolution", "Members", "initial_population"]

Branch = tuple[int, int, int] | None


@dataclass
class Members:
    """The evolution's cost of a member ``v`` (picklable: a ``spawn`` worker receives it whole): the free
    parameters ``v[:len(free)]`` over the held ``z_fixed``, scored on the objective of branch ``v[-1]``."""

    objectives: list[Objective]
    z_fixed: np.ndarray
    free: np.ndarray
    geometry_free: bool

    def decode(self, v: np.ndarray) -> tuple[np.ndarray, int]:
        """A member -> normalised parameters (the held ones from ``z_fixed``) and its branch index."""
        z = self.z_fixed.copy()
        z[self.free] = np.clip(v[: len(self.free)], 0.0, 1.0)
        return z, int(np.rint(v[len(self.free)])) if self.geometry_free else 0

    def __call__(self, v: np.ndarray) -> float:
        z, k = self.decode(v)
        return self.objectives[k].cost(z)


_WORKER: Members | None = None
"""The members of this pool worker process (set by :func:`_init_worker`; unused in the parent)."""


def _init_worker(members: Members) -> None:
    global _WORKER
    _WORKER = members


def _worker_cost(v: np.ndarray) -> float:
    assert _WORKER is not None, "the pool was started without _init_worker"
    return _WORKER(v)


def initial_population(
    obj: Objective,
    opts: IdentifyOptions,
    free: np.ndarray,
    branches: Sequence[Branch],
    *,
    progress: bool = False,
) -> np.ndarray:
    """The evolution's first population: a scrambled Sobol sequence (scipy's size for ``init="sobol"``: the
    power of two at or above ``popsize`` x dimensions), its first ``opts.surrogate_seeds`` members per
    elbow-branch combination given that branch's in-plane surrogate optimum as geometry."""
    geometry_free = list(branches) != [None]
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
    found = surrogate_starts(obj, opts, [b for b in branches if b is not None])
    for z, _, branch in found:
        for _ in range(opts.surrogate_seeds):
            if row >= n:
                break
            pop[row, geo] = z[free[geo]]
            pop[row, -1] = float(list(branches).index(branch))
            row += 1
    if progress:
        print(
            f"[identify] differential evolution: {row} of {n} first members seeded from the in-plane surrogate's "
            f"optimum of each elbow-branch combination ({time.time() - t0:.0f} s)",
            flush=True,
        )
    return pop


def _held_rig_parameters(obj: Objective) -> np.ndarray:
    """The start's normalised parameters with the rig parameters fitted to the rig tests alone (the pose block
    is cached: only the rigs are re-solved; the workspace block does not see them)."""
    z_fixed = obj.z(obj.ps.x0)
    if not obj.sub_idx:
        return z_fixed
    sub = np.array(obj.sub_idx, dtype=int)
    n_obs, n_rig = len(obj.obs), len(obj.problem.subsystem_tests)

    def rig_residuals(zs: np.ndarray) -> np.ndarray:
        z = z_fixed.copy()
        z[sub] = zs
        return obj.residuals(z)[n_obs : n_obs + n_rig]

    z_fixed[sub] = least_squares_z(rig_residuals, z_fixed[sub], max_nfev=40).x
    return z_fixed


def _evolve(members: Members, init: np.ndarray, opts: IdentifyOptions, *, workers: int, progress: bool) -> Any:
    """SciPy's differential evolution of ``members`` from ``init`` (deferred updating: a generation's members
    are independent, so their scoring order, and the processes that score them, do not change the result).
    Returns SciPy's ``OptimizeResult`` (Any: SciPy has no types)."""
    n_branches = len(members.objectives)
    d = len(members.free)
    bounds = [(0.0, 1.0)] * d + ([(0.0, n_branches - 1.0)] if members.geometry_free else [])
    integrality = [False] * d + ([True] if members.geometry_free else [])
    t0, generation = time.time(), [0]

    def report(intermediate_result: Any) -> None:
        generation[0] += 1
        if progress and (generation[0] % 10 == 0 or generation[0] == opts.generations):
            print(
                f"[identify] differential evolution: generation {generation[0]}/{opts.generations}, best cost "
                f"{intermediate_result.fun:.4g} ({time.time() - t0:.0f} s)",
                flush=True,
            )

    settings = dict(
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
    )
    if workers <= 1:
        return differential_evolution(members, bounds, workers=1, **settings)
    pool = spawn_pool(workers, _init_worker, (members,))
    try:
        return differential_evolution(_worker_cost, bounds, workers=pool.map, **settings)
    finally:
        pool.terminate()


def _class_candidates(sol: Any, members: Members, branches: Sequence[Branch], per_class: int) -> list[Candidate]:
    """The best ``per_class`` final-population members of each branch class, class leaders first."""
    pop = np.atleast_2d(getattr(sol, "population", sol.x[None, :]))
    energies = np.atleast_1d(getattr(sol, "population_energies", [sol.fun]))
    out: dict[int, list[Candidate]] = {}
    note = f"differential evolution ({sol.nit} generations, {sol.nfev} evaluations)"
    for v, e in sorted(zip(pop, energies), key=lambda t: t[1]):
        z, k = members.decode(v)
        found = out.setdefault(k, [])
        if len(found) < max(1, per_class):
            rank = "best" if not found else f"no. {len(found) + 1}"
            where = f" with elbow branches {branches[k]}" if branches[k] is not None else ""
            found.append(Candidate(z, float(e), f"{note}, {rank} of its final population{where}", branches[k]))
    return [
        c
        for rank in range(max(1, per_class))
        for c in sorted((m[rank] for m in out.values() if len(m) > rank), key=lambda c: c.cost)
    ]


@dataclass(frozen=True)
class DifferentialEvolution:
    """The full-model differential evolution as a :class:`~fpm_sim.study.identify.strategies.Strategy`
    (settings from the objective's options: ``generations``, ``popsize``, ``de_strategy``,
    ``surrogate_seeds``, ``refine_per_class``)."""

    def search(self, objective: Objective, *, seed: int, workers: int, progress: bool) -> list[Candidate]:
        """The final population's best members of each branch class (module docstring)."""
        opts = dataclasses.replace(objective.opts, seed=seed)
        branches: list[Branch] = list(ELBOW_BRANCHES) if objective.problem.geometry_free else [None]
        member_opts = dataclasses.replace(opts, workers=1)
        members = Members(
            [Objective(objective.problem, member_opts, branch=b) for b in branches],
            _held_rig_parameters(objective),
            np.array(objective.man_idx, dtype=int),
            objective.problem.geometry_free,
        )
        init = initial_population(objective, opts, members.free, branches, progress=progress)
        sol = _evolve(members, init, opts, workers=workers, progress=progress)
        objective.nfev += int(sol.nfev)
        return _class_candidates(sol, members, branches, opts.refine_per_class)
