"""A reduced model at an off-grid pose: from the modal atlas (interpolation) vs built directly (issue 7).

(Was ``scripts/benchmark_atlas.py``.) The symmetric manipulator (``benchmarks.common.SYMMETRIC_CONFIG``, the default
of the history); an atlas on a 3 x 3 grid of poses (-100, 0, 100 mm, phi 0) at 4 segments per link (the docs' figures
used 12; ``FPM_SIM_BENCH_FULL=1`` adds 12), 6 tracked modes; at the four cell midpoints the parameter ``way`` is
``atlas.query`` or the direct build (``build_manipulator`` + ``reduce_model``: equilibrium, linearisation,
eigen-solve). ``track_worst_f123_pct`` records the largest f1..f3 difference between the two at the midpoints
(multilinear interpolation over 100 mm: about 2 %).
"""

from __future__ import annotations

import itertools

import numpy as np

from benchmarks.common import require_full, symmetric_config, warm_imports

GRID_M = np.array([-0.1, 0.0, 0.1])
N_MODES = 6
WAYS = ["atlas.query", "direct build"]


def _setting(segments: int):
    from fpm_sim.kinematics import Pose
    from fpm_sim.model.options import ModelOptions

    mids = 0.5 * (GRID_M[1:] + GRID_M[:-1])
    poses = [Pose(float(x), float(y), 0.0) for x, y in itertools.product(mids, mids)]
    return symmetric_config(), ModelOptions(segments=segments), poses


def _atlas(segments: int):
    from fpm_sim.rom.atlas import build_atlas

    manip, opts, _ = _setting(segments)
    return build_atlas(manip, x_m=GRID_M, y_m=GRID_M, options=opts, n_modes=N_MODES)


def _direct(manip, pose, opts):
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.rom.reduction import reduce_model

    return reduce_model(build_manipulator(manip, pose, opts), n_modes=N_MODES)


class AtlasBuild:
    """Building the 3 x 3 atlas (9 poses, mode tracking between them)."""

    params = [[4, 12]]
    param_names = ["segments"]
    number = 1
    repeat = (1, 3, 60.0)
    timeout = 600.0

    def setup(self, segments: int) -> None:
        if segments > 4:
            require_full()
        warm_imports()

    def time_build_atlas(self, segments: int) -> None:
        _atlas(segments)

    def track_worst_f123_pct(self, segments: int) -> float:
        """Largest |f_atlas / f_direct - 1| over f1..f3 at the four midpoints."""
        atlas = _atlas(segments)
        manip, opts, poses = _setting(segments)
        worst = 0.0
        for pose in poses:
            rom, direct = atlas.query(pose), _direct(manip, pose, opts)
            worst = max(worst, float(np.max(np.abs(rom.frequencies_hz[:3] / direct.frequencies_hz[:3] - 1.0))))
        return 100.0 * worst

    track_worst_f123_pct.unit = "%"


class AtlasVsDirect:
    """The reduced models at the four midpoints, one way or the other (the parameter)."""

    params = [[4, 12], WAYS]
    param_names = ["segments", "way"]
    timeout = 600.0

    def setup(self, segments: int, way: str) -> None:
        if segments > 4:
            require_full()
        self.manip, self.opts, self.poses = _setting(segments)
        self.atlas = _atlas(segments) if way == "atlas.query" else None
        if self.atlas is None:
            _direct(self.manip, self.poses[0], self.opts)  # warm-up: what the first build initialises lazily

    def time_midpoints(self, segments: int, way: str) -> None:
        for pose in self.poses:
            if self.atlas is not None:
                self.atlas.query(pose)
            else:
                _direct(self.manip, pose, self.opts)
