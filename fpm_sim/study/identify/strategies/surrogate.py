"""Differential evolution of the geometry on the in-plane surrogate (:mod:`fpm_sim.study.inplane_surrogate`),
scale-free (the level of the frequencies comes from the masses), one run per elbow-branch class; each class's
best is then scored with the full model."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution

from fpm_sim.config import ConfigError, Manipulator
from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.parameters import GEOMETRY_GROUPS
from fpm_sim.study.identify.problem import (
    PENALTY_SIGMAS,
    SURROGATE_BRANCHES,
    IdentificationError,
    IdentifyOptions,
    workspace_residuals,
)
from fpm_sim.study.identify.strategies import Candidate
from fpm_sim.study.inplane_surrogate import inplane_first_frequencies

__all__ = ["SurrogateDE", "surrogate_starts"]


@dataclass(frozen=True)
class _SurrogateCost:
    """The surrogate's scale-free misfit of the geometry ``zg`` (the other parameters at ``z0``) on ``base``."""

    objective: Objective
    base: Manipulator
    geometry: tuple[int, ...]
    z0: np.ndarray
    logf: np.ndarray
    weights: np.ndarray
    first: tuple[int, ...]

    def __call__(self, zg: np.ndarray) -> float:
        obj = self.objective
        z = self.z0.copy()
        z[list(self.geometry)] = zg
        try:
            cfg = obj.ps.apply(obj.x(z), base=self.base)
        except (ConfigError, ValueError):
            return 1e6
        f = inplane_first_frequencies(cfg, [obj.obs[k].pose for k in self.first])
        ok = np.isfinite(f) & (f > 0)
        if not ok.any():
            return 1e6
        w = self.weights
        d = np.log(np.where(ok, f, 1.0)) - self.logf
        d = d - np.average(d[ok], weights=w[ok] ** 2)  # scale-free: the level comes from the masses
        d = np.where(ok, d * w, PENALTY_SIGMAS)
        return float(np.sum(d**2) + np.sum(workspace_residuals(obj.problem, cfg) ** 2))


def surrogate_starts(
    obj: Objective, opts: IdentifyOptions, branches: Sequence[tuple[int, int, int]] = SURROGATE_BRANCHES
) -> list[tuple[np.ndarray, str, tuple[int, int, int]]]:
    """Differential evolution of the geometry groups on the in-plane surrogate, per elbow-branch class in
    ``branches`` (seed ``opts.seed``): ``(z, note, branch)``, best surrogate cost first."""
    ps = obj.ps
    gi = [i for i, p in enumerate(ps.parameters) if p.group in GEOMETRY_GROUPS]
    if not gi:
        raise IdentificationError(
            "surrogate-de needs the geometry group free", parameter="global_method", hint="add geometry to free"
        )
    first = [k for k, o in enumerate(obj.obs) if o.mode == 1 and o.label in (None, "in_plane")]
    logf = np.log([obj.obs[k].freq_hz for k in first])
    w = 1.0 / np.array([obj.obs[k].sigma_hz / obj.obs[k].freq_hz for k in first])
    z0 = obj.z(ps.x0)
    out = []
    for branch in branches:
        base = ps.start.replace(geometry=dataclasses.replace(ps.start.geometry, elbow_branch=branch))
        cost = _SurrogateCost(obj, base, tuple(gi), z0, logf, w, tuple(first))
        sol = differential_evolution(
            cost, [(0.0, 1.0)] * len(gi), seed=opts.seed, maxiter=80, popsize=12, tol=1e-7, polish=False
        )
        z = z0.copy()
        z[gi] = sol.x
        out.append((z, f"surrogate-de branch {branch}: surrogate cost {sol.fun:.3g}", branch, sol.fun))
    out.sort(key=lambda t: t[3])
    return [(z, note, br) for z, note, br, _ in out]


@dataclass(frozen=True)
class SurrogateDE:
    """The surrogate's best geometry of each class in ``branches``, scored with the full model on that class."""

    branches: tuple[tuple[int, int, int], ...] = SURROGATE_BRANCHES

    def search(self, objective: Objective, *, seed: int, workers: int, progress: bool) -> list[Candidate]:
        """One candidate per class, in the surrogate's order (``workers``, ``progress`` unused)."""
        opts = dataclasses.replace(objective.opts, seed=seed)
        out = []
        for z, note, branch in surrogate_starts(objective, opts, self.branches):
            ob = Objective(objective.problem, objective.opts, branch=branch)
            out.append(Candidate(z, ob.cost(z), note, branch))
            objective.nfev += ob.nfev
        return out
