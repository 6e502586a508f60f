"""Benchmark: the study's transient by the full nonlinear rollout vs the reduced model, one run.

Pose (0, 0), 5 mm links, motors locked, constant 10 N end-effector force in x then y, 0.2 s at a
0.1 ms output step (see fpm_sim.transient). Both ways use the same discretisation. The full model
is stepped with ``mj_step`` (Python loop over output steps, ``nstep`` steps in C per output step);
the reduced model is built (linearisation + constrained eigen-solve) and simulated by its exact
zero-order-hold discretisation. Prints wall times and ratios; the study's COMSOL full model took
4 min 32 s (other hardware, other model).

    python scripts/benchmark_transient.py [--segments 6] [--repeat 3]
"""

from __future__ import annotations

import argparse
import platform
import time

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.study.transient import STUDY_FULL_MODEL_WALL_S, study_transient


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=1, help="repeat and keep the fastest of each")
    args = ap.parse_args()
    best = None
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        res = study_transient(default_config(), segments=args.segments)
        total = time.perf_counter() - t0
        s = res.summary()
        row = (s["wall_full_s"], s["wall_rom_build_s"], s["wall_rom_total_s"] - s["wall_rom_build_s"], total, res)
        best = row if best is None or row[0] < best[0] else best
    full, build, sim, total, res = best
    p = res.parameters
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(
        f"model: {p['segments']} segments/link, axial={p['axial']}, nv={p['nv']}, timestep {p['timestep_s']:.4g} s, "
        f"{round(p['duration_s'] / p['timestep_s'])} steps per load axis; ROM {res.rom.n_modes} modes"
    )
    print(f"{'way':<40} {'wall (s)':>10}")
    print(f"{'full nonlinear rollout (x and y)':<40} {full:>10.3f}")
    print(f"{'reduced model: build':<40} {build:>10.4f}")
    print(f"{'reduced model: simulate (x and y)':<40} {sim:>10.4f}")
    print(f"{'reduced model: build + simulate':<40} {build + sim:>10.4f}")
    print(f"ratio full / reduced (build + simulate): {full / (build + sim):.0f}x")
    print(f"ratio full / reduced (simulate only):    {full / sim:.0f}x")
    print(
        f"study's COMSOL full model: {STUDY_FULL_MODEL_WALL_S} s; ratio to our full rollout: "
        f"{STUDY_FULL_MODEL_WALL_S / full:.1f}x"
    )
    for c in res.cases:
        print(f"load {c.axis}: NRMS error {c.nrms:.2%}")


if __name__ == "__main__":
    main()
