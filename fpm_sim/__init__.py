"""fpm-sim: natural frequencies, modes and reduced models of flexible planar parallel manipulators on MuJoCo.

The matrices here are small (hundreds of rows); multithreaded OpenBLAS busy-waits and on a loaded
2-core machine made a 372 x 372 eigen-solve 50 times slower (5 s vs 0.1 s, measured). Importing
``fpm_sim`` therefore limits BLAS to one thread (``FPM_SIM_BLAS_THREADS`` overrides); parallelism
comes from batching poses instead.
"""

import os as _os

_BLAS_THREADS = _os.environ.get("FPM_SIM_BLAS_THREADS", "1")
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, _BLAS_THREADS)  # effective if numpy is not imported yet

import numpy as _np  # noqa: E402,F401  (loads BLAS so that the limit below finds it)
from threadpoolctl import threadpool_limits as _threadpool_limits  # noqa: E402

_threadpool_limits(int(_BLAS_THREADS), user_api="blas")  # effective if numpy was imported before us

__version__ = "0.1.0"
