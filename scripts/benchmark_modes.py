"""Time one pose's modal analysis, stage by stage, at three segment counts, for both methods.

Usage: python scripts/benchmark_modes.py [--segments 4 8 12] [--repeat 3]

Stages: build (MjSpec -> MjModel, automatic timestep), equilibrium (static, under gravity),
transitionFD (mjd_transitionFD + eigen-decomposition + filtering), constrained (K by finite
differences + null-space generalised eigen-solve). Prints the median of --repeat runs and the ratio
of the two methods.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import mujoco

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.linear.equilibrium import static_equilibrium
from fpm_sim.linear.modal import modes_constrained, modes_transition_fd
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions


def time_once(segments: int) -> dict[str, float]:
    cfg = default_config()
    t0 = time.perf_counter()
    built = build_manipulator(cfg, Pose(0.0, 0.0, 0.0), ModelOptions(segments=segments))
    t1 = time.perf_counter()
    q = static_equilibrium(built.model, mujoco.MjData(built.model))
    t2 = time.perf_counter()
    fd = modes_transition_fd(built, n_modes=6, qpos=q)
    t3 = time.perf_counter()
    con = modes_constrained(built, n_modes=6, qpos=q)
    t4 = time.perf_counter()
    return {
        "nv": built.model.nv,
        "build": t1 - t0,
        "equilibrium": t2 - t1,
        "transition_fd": t3 - t2,
        "constrained": t4 - t3,
        "f1_fd": fd.frequencies_hz[0],
        "f1_con": con.frequencies_hz[0],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--segments", type=int, nargs="+", default=[4, 8, 12])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(
        f"# {platform.processor() or platform.machine()}, mujoco {mujoco.__version__}, default manipulator at (0,0,0)"
    )
    print(
        f"{'segments':>8} {'nv':>5} {'build s':>8} {'equil s':>8} {'tFD s':>8} {'constr s':>9} "
        f"{'total(tFD) s':>12} {'tFD/constr':>10} {'f1 tFD Hz':>10} {'f1 con Hz':>10}"
    )
    for n in args.segments:
        runs = [time_once(n) for _ in range(args.repeat)]
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        total = med["build"] + med["equilibrium"] + med["transition_fd"]
        print(
            f"{n:>8} {int(med['nv']):>5} {med['build']:>8.3f} {med['equilibrium']:>8.3f} {med['transition_fd']:>8.3f} "
            f"{med['constrained']:>9.3f} {total:>12.3f} {med['transition_fd'] / med['constrained']:>10.2f} "
            f"{med['f1_fd']:>10.3f} {med['f1_con']:>10.3f}"
        )


if __name__ == "__main__":
    main()
