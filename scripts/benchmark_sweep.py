"""Benchmark of the dense workspace sweep: the fast pose loop on 1 vs 2 workers, and its accuracy
and cost against the full default analysis at a few poses.

    python scripts/benchmark_sweep.py [--step-mm 10] [--full-poses 3]

Prints wall times, the ratio between the two ways, and the fast path's deviation from the full
analysis (12 segments, axial springs, gravity equilibrium, mjd_transitionFD).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.linear.analysis import manipulator_modes
from fpm_sim.linear.equilibrium import EquilibriumError
from fpm_sim.study.sweep import dense_grid


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step-mm", type=float, default=10.0)
    ap.add_argument("--full-poses", type=int, default=3, help="poses compared with the full analysis")
    args = ap.parse_args()
    cfg = default_config()
    t0 = time.perf_counter()
    poses = dense_grid(cfg, step_mm=args.step_mm)
    t_grid = time.perf_counter() - t0
    times = {}
    results = {}
    for workers in (1, 2):
        t0 = time.perf_counter()
        results[workers] = pose_frequencies(cfg, poses, n_modes=3, workers=workers)
        times[workers] = time.perf_counter() - t0
    res = results[2]
    n_ok = sum(s in ("ok", "near_singular") for s in res.status)
    print(f"dense grid, step {args.step_mm:g} mm: {len(poses)} points ({n_ok} computed), grid setup {t_grid:.2f} s")
    for w, t in times.items():
        print(f"  fast path, {w} worker(s): {t:.2f} s  ({t / max(n_ok, 1) * 1e3:.1f} ms per computed pose)")
    print(f"  ratio 1 worker / 2 workers: {times[1] / times[2]:.2f}")
    same = np.allclose(results[1].frequencies_hz, results[2].frequencies_hz, equal_nan=True)
    print(f"  identical results: {same}")
    # study poses (the table's (0, 0), a corner and a low-frequency pose), rows = x, +0.2 rad
    picks = [Pose.from_mm(0, 0, 0.2), Pose.from_mm(100, -100, 0.0), Pose.from_mm(-50, 50, 0.0)][: args.full_poses]
    t_full, t_fast, n_done = 0.0, 0.0, 0
    for p in picks:
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                full = manipulator_modes(p, config=cfg, n_modes=3).frequencies_hz
        except EquilibriumError as exc:
            print(f"  {p.label()}: full analysis failed ({exc})")
            continue
        t_full += time.perf_counter() - t0
        t0 = time.perf_counter()
        fast = pose_frequencies(cfg, [p], n_modes=3, options=fast_options()).frequencies_hz[0]
        t_fast += time.perf_counter() - t0
        n_done += 1
        dev = 100 * (fast / full - 1)
        print(
            f"  {p.label()}: full {np.round(full, 3)} Hz, fast {np.round(fast, 3)} Hz, fast - full {np.round(dev, 3)} %"
        )
    if n_done:
        print(
            f"  per pose: full analysis {t_full / n_done:.2f} s, fast path {t_fast / n_done * 1e3:.1f} ms, "
            f"ratio {t_full / t_fast:.0f}"
        )


if __name__ == "__main__":
    main()
