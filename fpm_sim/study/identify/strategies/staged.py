"""Continuation with multi-start (``global_method="staged"``): the model-updating practice of freeing the
parameters in stages, each stage a bounded least-squares fit (trust-region reflective, the Levenberg-Marquardt
family with bounds) with the exact Jacobian, from the previous stage's optimum; repeated from a few samples of
the prior, the lowest end kept.

Stages (:func:`stages`), each skipped where it frees nothing new:

1. ``physical``: every parameter outside the geometry groups (masses, sections, compliance, hubs, offsets, rig),
   the geometry held at the start's. The frequencies' level and the mass/stiffness balance first.
2. ``geometry``: those and the collective geometry: the ``geometry`` group's parameters, and each per-chain
   geometry field tied across the chains (one direction per field that moves every chain's value by the same
   fraction of its bounds' width: the same relative length change, the same angle change): six directions
   for ``geometry-per-chain``'s eighteen.
3. ``per-chain``: every parameter, each chain's own.

Each stage minimises the robust loss :data:`ROBUST_LOSS` of the residuals (in sigmas), in a linear subspace
``z = z_prev + B u`` of the parameters normalised to their bounds, ``u`` bounded so that ``z`` stays in [0, 1];
its Jacobian is the objective's (exact where the model allows it, :mod:`fpm_sim.study.identify.sensitivity`,
else forward differences) times ``B``, the columns outside the stage never computed.

Starts (:func:`prior_starts`): the start description, then ``staged_starts - 1`` samples of the prior (seeded):
every parameter outside the geometry groups uniform over its bounds (the first stage fits them from anywhere
in their range), every geometry parameter uniform within ``+-staged_spread / 2`` of its start (fractions of
its bounds' width: an as-built machine is near its drawing; the per-chain bounds are +-15 deg and -20/+25 %).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.parameters import GEOMETRY_GROUPS
from fpm_sim.study.identify.strategies import Candidate

__all__ = ["ROBUST_LOSS", "ROBUST_SCALE", "Stage", "StagedLeastSquares", "fit_stage", "prior_starts", "stages"]


@dataclass(frozen=True)
class Stage:
    """One stage: its name and its directions ``B`` (columns, in normalised parameters; each a 0/1 vector,
    the columns' supports disjoint)."""

    name: str
    basis: np.ndarray

    @property
    def columns(self) -> list[int]:
        """The parameters the stage moves."""
        return [int(i) for i in np.flatnonzero(self.basis.any(axis=1))]


def _field(name: str) -> str:
    """A per-chain parameter's field (``geometry.base_angle_deg[2]`` -> ``geometry.base_angle_deg``)."""
    return name.split("[", 1)[0]


def stages(objective: Objective) -> list[Stage]:
    """The stages of the module docstring for ``objective``'s free parameters, those that free nothing new
    dropped."""
    params = objective.ps.parameters
    n = len(params)
    physical = [i for i, p in enumerate(params) if p.group not in GEOMETRY_GROUPS]
    collective = [i for i, p in enumerate(params) if p.group == "geometry"]
    per_chain: dict[str, list[int]] = {}
    for i, p in enumerate(params):
        if p.group == "geometry-per-chain":
            per_chain.setdefault(_field(p.name), []).append(i)

    def basis(singles: list[int], tied: list[list[int]]) -> np.ndarray:
        b = np.zeros((n, len(singles) + len(tied)))
        for j, i in enumerate(singles):
            b[i, j] = 1.0
        for j, members in enumerate(tied, start=len(singles)):
            b[members, j] = 1.0
        return b

    wanted = [
        Stage("physical", basis(physical, [])),
        Stage("geometry", basis(physical + collective, list(per_chain.values()))),
        Stage("per-chain", basis(list(range(n)), [])),
    ]
    out: list[Stage] = []
    for s in wanted:
        if s.basis.shape[1] and (not out or s.basis.shape[1] > out[-1].basis.shape[1]):
            out.append(s)
    return out


def prior_starts(objective: Objective, n: int, spread: float, seed: int) -> list[tuple[np.ndarray, str]]:
    """The start description, then ``n - 1`` samples of the prior (module docstring), normalised."""
    z0 = objective.z(objective.ps.x0)
    geometric = np.array([p.group in GEOMETRY_GROUPS for p in objective.ps.parameters])
    rng = np.random.default_rng(seed)
    out = [(z0, "start description")]
    for k in range(1, max(1, n)):
        u = rng.uniform(size=len(z0))
        z = np.where(geometric, z0 + spread * (u - 0.5), u)
        out.append((np.clip(z, 0.0, 1.0), f"prior sample {k}"))
    return out


def _stage_bounds(z: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``u`` keeping ``z + B u`` in [0, 1] (disjoint 0/1 columns), never empty."""
    lo = np.array([-z[col > 0].min() for col in b.T])
    hi = np.array([1.0 - z[col > 0].max() for col in b.T])
    return np.minimum(lo, -1e-9), np.maximum(hi, 1e-9)


ROBUST_LOSS = "soft_l1"
"""The stages' loss (SciPy's ``least_squares`` ``loss``): ``soft_l1``, ``2 (sqrt(1 + (r/c)^2) - 1)``, quadratic
below ``c`` and linear above it, so that a few poses the stage's model cannot fit yet (the geometry still
collective: a pose near a singularity, whose frequencies move most with each chain's geometry) do not pull the
early stages away from the basin of the rest. The local refinement that follows the search is plain least
squares: the optimum and its statistics are the least-squares ones. Measured on as-built machine 1 of
``tests/helpers/asbuilt.py`` (from the start and 5 prior samples): plain least squares ends at 13.2 per datum
from every start, soft_l1 reaches the floor (0.65) from two of six within 40 evaluations per stage."""
ROBUST_SCALE = 3.0
"""``c`` of :data:`ROBUST_LOSS`, in sigmas: a residual up to 3 sigma is noise, weighed in full."""


def fit_stage(
    objective: Objective, stage: Stage, z: np.ndarray, max_nfev: int, exact: bool
) -> tuple[np.ndarray, float, int]:
    """One stage's least squares (the robust loss :data:`ROBUST_LOSS`) from ``z``: the end, its cost (the plain
    sum of squares) and the evaluations spent (module docstring)."""
    b = stage.basis
    columns = stage.columns

    def point(u: np.ndarray) -> np.ndarray:
        return np.clip(z + b @ u, 0.0, 1.0)

    def fun(u: np.ndarray) -> np.ndarray:
        return objective.residuals(point(u))

    jac: Callable[[np.ndarray], np.ndarray] | str = "2-point"
    if exact:
        jac = lambda u: objective.jacobian(point(u), columns) @ b  # noqa: E731
    lo, hi = _stage_bounds(z, b)
    before = objective.nfev
    sol = least_squares(
        fun,
        np.zeros(b.shape[1]),
        jac=jac,
        bounds=(lo, hi),
        method="trf",
        diff_step=1e-3,
        max_nfev=max_nfev,
        loss=ROBUST_LOSS,
        f_scale=ROBUST_SCALE,
    )
    return point(sol.x), float(np.sum(sol.fun**2)), objective.nfev - before


@dataclass(frozen=True)
class StagedLeastSquares:
    """The continuation from every start (module docstring) as a
    :class:`~fpm_sim.study.identify.strategies.Strategy`: one candidate per start, its last stage's end, in the
    starts' order; each stage's cost per datum in its ``origin``."""

    n_starts: int
    spread: float
    max_nfev: int
    exact: bool

    def search(self, objective: Objective, *, seed: int, workers: int, progress: bool) -> list[Candidate]:
        """The ends (``workers`` unused: the starts run one after the other, each pose loop in the objective's
        processes)."""
        plan = stages(objective)
        n_data = max(1, len(objective.obs) + len(objective.problem.subsystem_tests))
        out = []
        for z, origin in prior_starts(objective, self.n_starts, self.spread, seed):
            notes = []
            cost = objective.cost(z)
            for stage in plan:
                z, cost, nfev = fit_stage(objective, stage, z, self.max_nfev, self.exact)
                notes.append(f"{stage.name} {cost / n_data:.3g}")
                if progress:
                    print(
                        f"[identify] staged from {origin}: stage {stage.name} ({stage.basis.shape[1]} directions), "
                        f"cost per datum {cost / n_data:.4g} ({nfev} evaluations)",
                        flush=True,
                    )
            note = "staged from " + origin + " (cost per datum by stage: " + ", ".join(notes) + ")"
            out.append(Candidate(z, cost if math.isfinite(cost) else math.inf, note))
        return out
