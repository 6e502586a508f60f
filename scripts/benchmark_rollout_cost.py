"""Benchmark: cost of the full nonlinear rollout by link discretisation (5 mm links, pose (0, 0)).

For each discretisation: degrees of freedom, automatic timestep, measured wall time per ``mj_step``
(``--steps`` steps from ``qpos0``, i.e. while sagging under gravity) and the resulting estimate for
the study's 0.2 s transient per load axis; ratios against the first row (6 segments, inextensible:
what ``fpm-sim transient --study`` uses).

    python scripts/benchmark_rollout_cost.py [--steps 1000]
"""

from __future__ import annotations

import argparse
import time

import mujoco

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions

CASES = [(6, False), (12, False), (12, True)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--duration-s", type=float, default=0.2)
    args = ap.parse_args()
    manip = default_config().with_section(thickness_m=0.005)
    base = None
    print(
        f"{'segments':>8} {'axial':>6} {'nv':>5} {'timestep (us)':>14} {'us/step':>9} "
        f"{'0.2 s est. (s)':>15} {'ratio':>7}"
    )
    for seg, axial in CASES:
        built = build_manipulator(manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=seg, axial=axial))
        data = mujoco.MjData(built.model)
        mujoco.mj_step(built.model, data)  # warm-up
        t0 = time.perf_counter()
        mujoco.mj_step(built.model, data, nstep=args.steps)
        per = (time.perf_counter() - t0) / args.steps
        est = args.duration_s / built.timestep_s * per
        base = base or est
        print(
            f"{seg:>8} {axial!s:>6} {built.model.nv:>5} {built.timestep_s * 1e6:>14.3f} {per * 1e6:>9.1f} "
            f"{est:>15.1f} {est / base:>7.1f}"
        )


if __name__ == "__main__":
    main()
