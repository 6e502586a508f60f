"""The fpm-sim benchmark suite (airspeed velocity): ``asv run --python=same --quick --show-stderr``.

One module per subject; where two ways of doing the same work are compared (backends, before and after, serial
and parallel), they are one benchmark whose parameter is the way, timed in the same run. Expensive cases are
skipped unless ``FPM_SIM_BENCH_FULL=1`` is set (:func:`benchmarks.common.require_full`). docs/benchmarks.md
holds the figures and how to compare two commits.
"""
