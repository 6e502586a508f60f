"""BLAS threads around the dense eigen-solves, and only there.

The matrices here are small (hundreds of rows); multithreaded OpenBLAS busy-waits, and on a loaded
2-core machine that made a 372 x 372 eigen-solve 50 times slower (5 s vs 0.1 s, measured). The solves
therefore run under :func:`blas_threads`, which limits BLAS to one thread for their duration, unless
the user has chosen a thread count (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``:
then nothing is changed) or set ``FPM_SIM_BLAS_THREADS`` (that count is used). Importing fpm_sim
changes nothing.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["USER_THREAD_VARIABLES", "blas_thread_limit", "blas_threads"]

USER_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""Environment variables by which a user sets BLAS threads; any of them set: we leave BLAS alone."""


def blas_thread_limit() -> int | None:
    """The BLAS thread count to use around the eigen-solves, or ``None`` to leave the user's setting."""
    own = os.environ.get("FPM_SIM_BLAS_THREADS")
    if own:
        try:
            return max(1, int(own))
        except ValueError:
            return 1
    if any(os.environ.get(v) for v in USER_THREAD_VARIABLES):
        return None
    return 1


@contextmanager
def blas_threads() -> Iterator[None]:
    """Limit BLAS threads (see the module docstring) for the duration of the block; restored after."""
    limit = blas_thread_limit()
    if limit is None:
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=limit, user_api="blas"):
        yield
