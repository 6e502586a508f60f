"""Described architectures (issue 28, item 6): a sweep pose's cost per degree of freedom, and what the general
inverse kinematics adds over a closed form.

- ``SweepPosePerDof``: one pose of each machine's dense sweep as :func:`fpm_sim.batch.task_sweep.sweep_task` runs
  it (inverse kinematics, singularity measures, model built, constrained eigen-solve of 3 modes; fidelity standard,
  inextensible, gravity off), against one pose of the 3RRR's own pose loop
  (:func:`fpm_sim.batch.pose_loop.solve_poses`, one compiled model re-posed) at the same options. ``track_*``
  reports each machine's seconds per pose per degree of freedom over the 3RRR's (the target: at most 1.5).
- ``InverseKinematics``: the 3RRR's poses assembled by the general solver against the closed form
  (:func:`fpm_sim.kinematics.inverse_kinematics`), and ``track_ik_share_of_sweep_pose``: the general solver's time
  as a share of the general sweep pose (the target: at most 10 % over a closed form).

CPU time of this process (``time.process_time``), one BLAS thread, as the pose loops run.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

from benchmarks.common import OneBlasThread, warm_imports

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "architectures"
MACHINES = ["3RRR (its own pose loop)", "3RRR (general path)", "five_bar", "delta"]
N_POSES = 6


def _general(name: str):
    import fpm_sim as fs
    from fpm_sim.architecture.three_rrr import description_of_3rrr

    if name.startswith("3RRR"):
        desc = description_of_3rrr(fs.default_config())
        poses = [fs.TaskPose(0.01 * k, -0.01 * k, 0.0, 0.05 * k) for k in range(N_POSES)]
    else:
        desc = fs.load_description(EXAMPLES / f"{name}.toml")
        home = desc.check_poses[0]
        poses = [
            fs.TaskPose(home.get("x", 0.0) + 0.005 * k, home.get("y", 0.0), home.get("z", 0.0)) for k in range(N_POSES)
        ]
    return desc, poses


def _sweep_pose_seconds(name: str) -> tuple[float, int]:
    """CPU seconds per pose and the model's degrees of freedom."""
    import fpm_sim as fs
    from fpm_sim.batch.task_sweep import sweep_task

    opts = fs.ModelOptions(axial=False, gravity=False)
    if name == MACHINES[0]:
        from fpm_sim.batch.pose_loop import fast_options, solve_poses
        from fpm_sim.model.manipulator import build_manipulator

        cfg = fs.default_config()
        poses = [fs.Pose(0.01 * k, -0.01 * k, 0.05 * k) for k in range(N_POSES)]
        t = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            solve_poses(cfg, poses, options=fast_options(), n_modes=3)
        dt = (time.process_time() - t) / N_POSES
        return dt, int(build_manipulator(cfg, poses[0], fast_options()).model.nv)
    from fpm_sim.model.general import build_general

    desc, poses = _general(name)
    t = time.process_time()
    sweep_task(desc, poses, options=opts, n_modes=3)
    dt = (time.process_time() - t) / N_POSES
    return dt, int(build_general(desc, poses[0], opts).model.nv)


class SweepPosePerDof(OneBlasThread):
    """Seconds per sweep pose, per machine (module docstring)."""

    params = [MACHINES]
    param_names = ["machine"]
    timeout = 600

    def setup(self, machine: str) -> None:
        warm_imports()
        self.limit_blas()
        _sweep_pose_seconds(machine)  # warm: the first pose pays the compile of MuJoCo's code paths

    def time_pose(self, machine: str) -> None:
        _sweep_pose_seconds(machine)


class PerDofRatio(OneBlasThread):
    """Each machine's seconds per pose per degree of freedom over the 3RRR's own pose loop's (target <= 1.5)."""

    params = [MACHINES[1:]]
    param_names = ["machine"]
    timeout = 600

    def setup(self, machine: str) -> None:
        warm_imports()
        self.limit_blas()
        base, base_nv = _sweep_pose_seconds(MACHINES[0])
        self.base = base / base_nv

    def track_per_dof_over_3rrr(self, machine: str) -> float:
        dt, nv = _sweep_pose_seconds(machine)
        return (dt / nv) / self.base


class InverseKinematics:
    """The 3RRR's poses by the general solver against the closed form (module docstring)."""

    params = [["closed form", "general solver"]]
    param_names = ["way"]

    def setup(self, way: str) -> None:
        import fpm_sim as fs

        self.cfg = fs.default_config()
        self.desc, self.poses = _general(MACHINES[1])

    def time_poses(self, way: str) -> None:
        from fpm_sim.architecture import solve_task_pose
        from fpm_sim.kinematics import Pose, inverse_kinematics

        for p in self.poses:
            if way == "closed form":
                inverse_kinematics(self.cfg.geometry, Pose(p.x_m, p.y_m, p.phi_rad))
            else:
                solve_task_pose(self.desc, p)

    def track_ik_share_of_sweep_pose(self, way: str) -> float:
        """The solver's CPU time as a share of a general sweep pose of the 3RRR (the IK's cost in a sweep)."""
        t = time.process_time()
        self.time_poses(way)
        ik = (time.process_time() - t) / N_POSES
        pose, _ = _sweep_pose_seconds(MACHINES[1])
        return ik / pose
