"""Benchmark: the study transient's full nonlinear rollout on the explicit reference vs the discrete integrator.

Pose (0, 0), 5 mm links, motors locked, a constant 10 N end-effector force in x then y, 0.2 s at a 0.1 ms output
step (``fpm_sim.study.transient``), no axial springs. The same model is stepped twice in one run: by its own
``implicitfast`` integrator at the automatic explicit-spring step (the reference) and by MuJoCo's ``discrete``
integrator at the step of the band (default 5 x f1, :mod:`fpm_sim.sim.stepping`). Prints both wall times, their
ratio, the numerical damping and period error the discrete step states at the band's top, and the NRMS
difference of the two displacement histories per load axis (the issue's bound: 1 %).

    nice -n 10 python scripts/benchmark_integrators.py [--segments 12] [--duration-s 0.2] [--band-hz HZ]
"""

from __future__ import annotations

import argparse
import platform
import warnings

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.study.transient import nrms_error, study_transient


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=12)
    ap.add_argument("--duration-s", type=float, default=0.2)
    ap.add_argument("--band-hz", type=float, default=None, help="the discrete step's band (default 5 x f1)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    runs = {
        i: study_transient(
            default_config(),
            segments=args.segments,
            duration_s=args.duration_s,
            integrator=i,
            step_band_hz=args.band_hz,
        )
        for i in ("explicit", "discrete")
    }
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    ref, disc = runs["explicit"], runs["discrete"]
    print(f"model: {args.segments} segments/link, no axial springs, nv {ref.parameters['nv']}, {args.duration_s:g} s")
    for name, r in runs.items():
        print(f"{name:<9} {r.stepping.line()}")
    print(f"{'axis':>4} {'explicit (s)':>13} {'discrete (s)':>13} {'ratio':>7} {'NRMS discrete vs explicit':>26}")
    for a in ("x", "y"):
        e, d = ref.case(a), disc.case(a)
        print(
            f"{a:>4} {e.wall_full_s:>13.2f} {d.wall_full_s:>13.2f} {e.wall_full_s / d.wall_full_s:>6.0f}x "
            f"{nrms_error(e.disp_full_m, d.disp_full_m):>25.3%}"
        )
    we = sum(c.wall_full_s for c in ref.cases)
    wd = sum(c.wall_full_s for c in disc.cases)
    print(f"both axes: explicit {we:.1f} s, discrete {wd:.1f} s: {we / wd:.0f}x")


if __name__ == "__main__":
    main()
