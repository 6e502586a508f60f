"""Search strategies of an identification, one module each, behind one small protocol (:class:`Strategy`).

- :mod:`.staged`: the continuation (masses and sections, then the collective geometry, then each chain's) with
  exact derivatives from the start and a few prior samples (the default global search for rich data);
- :mod:`.de`: differential evolution of every free parameter on the full model (the default otherwise);
- :mod:`.multistart`: a Latin hypercube of starts scored with the full model;
- :mod:`.surrogate`: differential evolution of the geometry on the in-plane surrogate, per elbow-branch class;
- :mod:`.lsq`: bounded least squares from given starts (the local refinement every search ends with).

Each takes the picklable :class:`~fpm_sim.study.identify.objective.Objective` and returns
:class:`Candidate` s. Worker processes (``workers > 1``) are a ``spawn`` pool that receives what it needs once,
in its initializer (:func:`spawn_pool`); nothing relies on ``fork``. The nested sampler of
:mod:`fpm_sim.study.calibrate` is no strategy here: it returns a posterior, not candidates.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from fpm_sim.batch.engine import spawn_pool as engine_spawn_pool
from fpm_sim.study.identify.objective import Objective

__all__ = ["Candidate", "Strategy", "spawn_pool"]


@dataclass(frozen=True)
class Candidate:
    """A point of the search: normalised parameters, their cost, where they came from and on which elbow
    branches; for the end of a local refinement also its residuals, Jacobian (in ``z``) and success.

    Attributes
    ----------
    z
        Parameters normalised to their bounds, in [0, 1].
    cost
        ``sum(r^2)`` of the objective at ``z`` (on ``branch``).
    origin
        Where it came from, in words (``"start description"``, ``"latin-hypercube point 3"``, ...).
    branch
        The elbow-branch combination it is scored on (``None``: the start description's).
    residuals, jacobian, success
        Set by the local refinement (:mod:`.lsq`) at its end; ``None`` otherwise.
    nfev
        Model evaluations the refinement spent.
    """

    z: np.ndarray
    cost: float
    origin: str
    branch: tuple[int, int, int] | None = None
    residuals: np.ndarray | None = None
    jacobian: np.ndarray | None = None
    success: bool | None = None
    nfev: int = 0


class Strategy(Protocol):
    """A search: from the objective to candidates, best first or in its own stated order."""

    def search(self, objective: Objective, *, seed: int, workers: int, progress: bool) -> list[Candidate]:
        """Run the search on ``objective`` (adding its model evaluations to ``objective.nfev``).

        Parameters
        ----------
        objective
            What is minimised.
        seed
            The seed of every random choice: the same seed gives the same candidates.
        workers
            Processes to use (1: this one).
        progress
            Print progress lines.
        """
        ...


def spawn_pool(workers: int, initializer: Callable[..., None], initargs: tuple[Any, ...]) -> Any:
    """A ``spawn`` process pool of ``workers`` whose workers each get ``initargs`` once, through
    ``initializer`` (picklable data only: spawn-safe), and ignore Ctrl-C (:func:`fpm_sim.batch.engine.spawn_pool`:
    stop it with ``terminate()``)."""
    return engine_spawn_pool(workers, initializer, initargs)
