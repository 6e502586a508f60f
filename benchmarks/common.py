"""Shared by the benchmark modules: the switch for the expensive cases and a spread of reachable poses."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

FULL_ENV = "FPM_SIM_BENCH_FULL"
"""Set to 1 to run the expensive cases too (MJX compiles for minutes; dense grids take tens of seconds)."""


def warm_imports() -> None:
    """Import what the timed calls import lazily (SciPy, the linear layer, the model builder, the pose loop, the
    atlas), so that the first parameter of a benchmark does not pay them: asv times all of a benchmark's
    parameters in one process, one after another. Call it from ``setup``."""
    import scipy.linalg  # noqa: F401

    import fpm_sim.batch.frequencies
    import fpm_sim.batch.pose_loop
    import fpm_sim.linear.equilibrium
    import fpm_sim.linear.solvers
    import fpm_sim.model.manipulator
    import fpm_sim.rom.atlas
    import fpm_sim.rom.reduction  # noqa: F401


def full_run() -> bool:
    """Whether the expensive cases run (``FPM_SIM_BENCH_FULL=1``)."""
    return os.environ.get(FULL_ENV, "") == "1"


def require_full() -> None:
    """Skip the calling benchmark's ``setup`` (asv reports it as skipped) unless the expensive cases are on."""
    if not full_run():
        raise NotImplementedError(f"expensive case: set {FULL_ENV}=1 to run it")


def reachable_poses(config, n: int) -> list:
    """``n`` reachable poses spread evenly over the 5 mm dense grid at phi = 0 (the backends' dense set)."""
    from fpm_sim.kinematics import NearSingularityWarning, inverse_kinematics
    from fpm_sim.study.sweep import dense_grid

    ok = []
    for p in dense_grid(config, step_mm=5.0):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", NearSingularityWarning)
                inverse_kinematics(config.geometry, p)
        except ValueError:
            continue
        ok.append(p)
    idx = np.linspace(0, len(ok) - 1, n).round().astype(int)
    return [ok[i] for i in idx]


SYMMETRIC_CONFIG = Path(__file__).resolve().parents[1] / "tests" / "data" / "symmetric_3rrr.toml"
"""The well-conditioned, three-fold symmetric 3RRR (the default before the identification of issue 4; a data file
of the source checkout). The single-pose method benchmarks use it, as their history in docs/benchmarks.md did:
the identified default's static equilibrium at 12 segments is ill-conditioned (docs/benchmarks.md, issue 4) and
its flex model is unstable under ``mjd_transitionFD``, which would time the equilibrium's struggle, not the method."""


def symmetric_config():
    """:data:`SYMMETRIC_CONFIG`, loaded."""
    from fpm_sim.config import load_config

    return load_config(SYMMETRIC_CONFIG)


class OneBlasThread:
    """A base for benchmarks that time dense eigen-solves: BLAS limited to one thread from ``setup`` (call
    :meth:`limit_blas`) to ``teardown``, as the pose loop runs its solves (``fpm_sim/linear/threads.py``:
    multithreaded OpenBLAS busy-waits on these small matrices). Forked worker processes inherit the limit."""

    def limit_blas(self) -> None:
        from fpm_sim.linear.threads import blas_threads

        self._blas = blas_threads()
        self._blas.__enter__()

    def teardown(self, *params: object) -> None:
        if hasattr(self, "_blas"):  # not when setup skipped the case
            self._blas.__exit__(None, None, None)
