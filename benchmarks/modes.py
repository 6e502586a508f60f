"""One pose's modal analysis, stage by stage, and the two modal methods compared (issue 2).

(Was ``scripts/benchmark_modes.py``.) The symmetric manipulator (``benchmarks.common.SYMMETRIC_CONFIG``) at (0, 0, 0):
build (MjSpec -> MjModel, automatic timestep), static equilibrium under gravity, then the modes by ``method``:
``transition_fd`` (``mjd_transitionFD`` + eigen-decomposition + filtering) or ``constrained`` (K by finite differences
+ null-space generalised eigen-solve) at the same equilibrium. ``track_f1_hz`` records the first frequency of each
method: the two must agree (70.835 / 70.836 Hz at 4 segments in the history).
"""

from __future__ import annotations

import mujoco

from benchmarks.common import require_full, symmetric_config, warm_imports

SEGMENTS = [4, 8, 12]
"""Links' segments; 12 (the default resolution, seconds per stage) only with ``FPM_SIM_BENCH_FULL=1``."""


def _built(segments: int):
    if segments > 8:
        require_full()
    from fpm_sim.kinematics import Pose
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.options import ModelOptions

    return build_manipulator(symmetric_config(), Pose(0.0, 0.0, 0.0), ModelOptions(segments=segments))


class Stages:
    """Build and static equilibrium of one pose."""

    params = [SEGMENTS]
    param_names = ["segments"]
    timeout = 300.0

    def setup(self, segments: int) -> None:
        warm_imports()
        self.built = _built(segments)

    def time_build(self, segments: int) -> None:
        _built(segments)

    def time_equilibrium(self, segments: int) -> None:
        from fpm_sim.linear.equilibrium import static_equilibrium

        static_equilibrium(self.built.model, mujoco.MjData(self.built.model))


class Methods:
    """The modes at the static equilibrium, by either method (the parameter)."""

    params = [SEGMENTS, ["transition_fd", "constrained"]]
    param_names = ["segments", "method"]
    timeout = 300.0

    def setup(self, segments: int, method: str) -> None:
        from fpm_sim.linear import solvers
        from fpm_sim.linear.equilibrium import static_equilibrium

        self.built = _built(segments)
        self.qpos = static_equilibrium(self.built.model, mujoco.MjData(self.built.model))
        self.modes = {"transition_fd": solvers.modes_transition_fd, "constrained": solvers.modes_constrained}[method]
        self.modes(self.built, n_modes=6, qpos=self.qpos)  # warm-up: what the first call initialises lazily

    def time_modes(self, segments: int, method: str) -> None:
        self.modes(self.built, n_modes=6, qpos=self.qpos)

    def track_f1_hz(self, segments: int, method: str) -> float:
        return float(self.modes(self.built, n_modes=6, qpos=self.qpos).frequencies_hz[0])

    track_f1_hz.unit = "Hz"
