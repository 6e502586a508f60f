"""Local refinement: bounded least squares (:func:`scipy.optimize.least_squares`, trust-region reflective) on
the full segment model from each start, in parameters normalised to their bounds.

The Jacobian is by forward finite differences (step ``1e-3`` of the bound width) of the whole frequency
computation (``IdentifyOptions.jacobian = "fd"``, the default), or exact (``"exact"``): the eigen-solve's
sensitivities of :mod:`fpm_sim.study.identify.sensitivity`, geometry included. With ``workers > 1`` and several
starts, the starts are refined in that many ``spawn`` processes, one pose loop each (fewer, longer jobs than
splitting each evaluation's pose loop); otherwise one after the other, each pose loop in the options' ``workers``
processes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.problem import IdentifyOptions, Problem
from fpm_sim.study.identify.strategies import Candidate, spawn_pool

__all__ = ["LeastSquares", "least_squares_z", "objective_jacobian", "refine"]

_WORKER: tuple[Problem, IdentifyOptions] | None = None
"""The problem of this pool worker process (set by :func:`_init_worker`; unused in the parent)."""


def least_squares_z(
    fun: Callable[[np.ndarray], np.ndarray],
    z0: np.ndarray,
    max_nfev: int,
    jac: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Any:
    """Bounded least squares (trust-region reflective) in parameters normalised to their bounds, ``z in [0, 1]``;
    the Jacobian ``jac`` where given, else forward finite differences with a step of ``1e-3`` of the bound width.
    Every local fit here goes through it. Returns SciPy's ``OptimizeResult`` (Any: SciPy has no types)."""
    return least_squares(
        fun,
        np.clip(z0, 0.0, 1.0),
        jac="2-point" if jac is None else jac,
        bounds=(0.0, 1.0),
        method="trf",
        diff_step=1e-3,
        max_nfev=max_nfev,
        x_scale=1.0,
    )


def objective_jacobian(ob: Objective) -> Callable[[np.ndarray], np.ndarray] | None:
    """The exact Jacobian of ``ob`` where its options ask for it and its model allows it, else ``None`` (finite
    differences)."""
    from fpm_sim.study.identify.sensitivity import supported

    if ob.opts.jacobian == "exact" and supported(ob.opts.model_options()):
        return ob.jacobian
    return None


def refine(problem: Problem, opts: IdentifyOptions, start: Candidate) -> Candidate:
    """Bounded least squares from ``start`` (on its elbow branches when it has some); the end as a candidate
    with its residuals, Jacobian in ``z``, success and the evaluations spent."""
    ob = Objective(problem, opts, branch=start.branch)
    sol = least_squares_z(ob.residuals, start.z, max_nfev=opts.max_nfev, jac=objective_jacobian(ob))
    return Candidate(
        z=sol.x,
        cost=float(np.sum(sol.fun**2)),
        origin=start.origin,
        branch=start.branch,
        residuals=sol.fun,
        jacobian=sol.jac,
        success=bool(sol.success),
        nfev=ob.nfev,
    )


def _init_worker(problem: Problem, opts: IdentifyOptions) -> None:
    global _WORKER
    _WORKER = (problem, opts)


def _worker_refine(start: Candidate) -> Candidate:
    assert _WORKER is not None, "the pool was started without _init_worker"
    return refine(*_WORKER, start)


@dataclass(frozen=True)
class LeastSquares:
    """The local refinement as a :class:`~fpm_sim.study.identify.strategies.Strategy`: every one of ``starts``
    refined (:func:`refine`), in their order."""

    starts: tuple[Candidate, ...]

    def ends(self, objective: Objective, *, workers: int = 1) -> Iterator[Candidate]:
        """The refined ends on ``objective``'s problem, in ``workers`` processes when there are several starts
        (module docstring), yielded in the starts' order as they come (``objective.nfev`` not updated)."""
        problem, opts = objective.problem, objective.opts
        if workers <= 1 or len(self.starts) <= 1:
            for s in self.starts:
                yield refine(problem, opts, s)
            return
        member_opts = dataclasses.replace(opts, workers=1)
        with spawn_pool(min(workers, len(self.starts)), _init_worker, (problem, member_opts)) as pool:
            yield from pool.imap(_worker_refine, list(self.starts), chunksize=1)

    def search(self, objective: Objective, *, seed: int, workers: int, progress: bool) -> list[Candidate]:
        """The refined ends, their evaluations added to ``objective.nfev`` (``seed`` unused: the refinement is
        deterministic; ``progress`` unused)."""
        ends = list(self.ends(objective, workers=workers))
        objective.nfev += sum(e.nfev for e in ends)
        return ends
