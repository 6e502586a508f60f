"""Multistart: a Latin hypercube of points inside the bounds, each scored with the full model."""

from __future__ import annotations

from dataclasses import dataclass

from scipy.stats import qmc

from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.strategies import Candidate

__all__ = ["LatinHypercube"]


@dataclass(frozen=True)
class LatinHypercube:
    """``n_starts`` Latin-hypercube points (seeded), in their order, scored in this process."""

    n_starts: int

    def search(self, objective: Objective, *, seed: int, workers: int, progress: bool) -> list[Candidate]:
        """The points with their costs (``workers``, ``progress`` unused: the scoring is serial and quiet)."""
        pts = qmc.LatinHypercube(d=len(objective.ps.parameters), seed=seed).random(self.n_starts)
        return [Candidate(z, objective.cost(z), f"latin-hypercube point {k}") for k, z in enumerate(pts)]
