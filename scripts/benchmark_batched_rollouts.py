"""Benchmark: batched rollouts of one model in 1 vs 2 ``mujoco.rollout`` threads (no GIL), one run.

The default machine at (0, 0, 0), the default fidelity without axial springs, ``--n`` constant end-effector
wrenches (a fan of in-plane forces), each rolled out for ``--duration-s`` on the discrete integrator
(:mod:`fpm_sim.sim.batched`). Both thread counts run the same batch back to back; prints their wall times, the
ratio, and checks that the two Datasets are identical.

    nice -n 10 python scripts/benchmark_batched_rollouts.py [--segments 12] [--n 8] [--duration-s 0.02]
"""

from __future__ import annotations

import argparse
import math
import os
import warnings

import numpy as np

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.sim.batched import batched_rollouts
from fpm_sim.sim.stepping import first_frequency_hz


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=None, help="default: the standard fidelity (12)")
    ap.add_argument("--n", type=int, default=8, help="rollouts in the batch")
    ap.add_argument("--duration-s", type=float, default=0.02)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    manip = default_config()
    built = build_manipulator(manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=args.segments, axial=False))
    f1 = first_frequency_hz(built)
    ang = np.linspace(0.0, 2 * math.pi, args.n, endpoint=False)
    wrenches = np.column_stack([10 * np.cos(ang), 10 * np.sin(ang), np.zeros(args.n)])
    print(f"cpus visible: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}; nv {built.model.nv}")
    runs = {
        t: batched_rollouts(built, manip, wrenches, duration_s=args.duration_s, threads=t, f1_hz=f1) for t in (1, 2)
    }
    st = runs[1].attrs["stepping"]
    print(f"{args.n} rollouts of {args.duration_s:g} s, {runs[1].attrs['n_steps_per_rollout']} steps each; {st}")
    for t, ds in runs.items():
        print(f"threads {t}: wall {ds.attrs['wall_s']:.2f} s")
    print(f"ratio 1 / 2 threads: {runs[1].attrs['wall_s'] / runs[2].attrs['wall_s']:.2f}x")
    print(f"identical results: {bool(np.array_equal(runs[1].ee_disp.values, runs[2].ee_disp.values))}")


if __name__ == "__main__":
    main()
