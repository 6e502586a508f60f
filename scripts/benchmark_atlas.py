"""Benchmark: a reduced model at an off-grid pose from the modal atlas vs built directly.

Builds an atlas on a grid of study poses (default 3 x 3, -100..100 mm, phi 0) at the given
resolution, then at the cell midpoints compares two ways of getting the reduced model: ``atlas.query``
(interpolation) and a direct build (``build_manipulator`` + ``reduce_model``: equilibrium,
linearisation, eigen-solve). Prints the wall times, their ratio, and the largest f1..f3 difference.

    python scripts/benchmark_atlas.py [--segments 12] [--axial] [--grid-mm -100 0 100]
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.atlas import build_atlas
from fpm_sim.rom.reduction import reduce_model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, default=12)
    ap.add_argument("--axial", action="store_true")
    ap.add_argument("--grid-mm", type=float, nargs="+", default=[-100.0, 0.0, 100.0])
    ap.add_argument("--modes", type=int, default=6)
    args = ap.parse_args()
    manip = default_config()
    opts = ModelOptions(segments=args.segments, axial=args.axial)
    grid = np.array(sorted(args.grid_mm)) * 1e-3
    t0 = time.perf_counter()
    atlas = build_atlas(manip, x_m=grid, y_m=grid, options=opts, n_modes=args.modes)
    t_build = time.perf_counter() - t0
    mids = 0.5 * (grid[1:] + grid[:-1])
    poses = [Pose(float(x), float(y), 0.0) for x, y in itertools.product(mids, mids)]
    t_query = t_direct = 0.0
    worst = 0.0
    for pose in poses:
        t0 = time.perf_counter()
        rom = atlas.query(pose)
        t_query += time.perf_counter() - t0
        t0 = time.perf_counter()
        direct = reduce_model(build_manipulator(manip, pose, opts), n_modes=args.modes)
        t_direct += time.perf_counter() - t0
        worst = max(worst, float(np.max(np.abs(rom.frequencies_hz[:3] / direct.frequencies_hz[:3] - 1.0))))
    n = len(poses)
    print(
        f"model: {args.segments} segments, axial {args.axial}, nv {atlas.parameters['nv']}; atlas "
        f"{len(grid)} x {len(grid)} poses, {args.modes} modes"
    )
    print(f"atlas build: {t_build:.2f} s ({t_build / len(grid) ** 2:.3f} s per grid pose)")
    print(f"{'way':<32} {'per pose (s)':>13}")
    print(f"{'atlas.query (interpolation)':<32} {t_query / n:>13.5f}")
    print(f"{'direct (build + reduce_model)':<32} {t_direct / n:>13.5f}")
    print(f"ratio direct / query: {t_direct / t_query:.0f}x over {n} midpoints")
    print(f"largest f1..f3 difference at the midpoints: {worst * 100:.3f} %")


if __name__ == "__main__":
    main()
