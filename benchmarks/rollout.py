"""Cost of the full nonlinear rollout by link discretisation: 5 mm links at (0, 0) (issue 6).

(Was ``scripts/benchmark_rollout_cost.py``.) The parameter is the discretisation (segments per link, axial
springs); ``time_200_steps`` is 200 ``mj_step`` from ``qpos0`` on (the links sagging under gravity),
``track_timestep_us`` the model's automatic timestep. One 0.2 s load axis of the study's transient costs
``0.2 s / timestep * time_200_steps / 200``: 6 segments inextensible is what ``fpm-sim transient --study`` uses.
"""

from __future__ import annotations

import mujoco

CASES = ["6 segments", "12 segments", "12 segments, axial"]
STEPS = 200


def _built(case: str):
    from fpm_sim.config import default_config
    from fpm_sim.kinematics import Pose
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.options import ModelOptions

    segments, axial = int(case.split()[0]), case.endswith("axial")
    manip = default_config().with_section(thickness_m=0.005)
    return build_manipulator(manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=segments, axial=axial))


class RolloutStep:
    """One ``mj_step`` of the 5 mm-link manipulator."""

    params = [CASES]
    param_names = ["discretisation"]

    def setup(self, case: str) -> None:
        self.built = _built(case)
        self.data = mujoco.MjData(self.built.model)
        mujoco.mj_step(self.built.model, self.data)  # warm-up

    def time_200_steps(self, case: str) -> None:
        """200 steps per call (asv times each call alone after a setup; one step is too short to time)."""
        mujoco.mj_step(self.built.model, self.data, nstep=STEPS)

    def track_timestep_us(self, case: str) -> float:
        return float(self.built.timestep_s * 1e6)

    track_timestep_us.unit = "us"

    def track_nv(self, case: str) -> int:
        return int(self.built.model.nv)

    track_nv.unit = "dof"
