"""Described architectures (issue 28, item 6): a sweep pose's cost per degree of freedom, and what the general
inverse kinematics adds over a closed form.

- ``SweepPosePerDof``: a row of each machine's dense sweep (``N_POSES`` poses 5 mm apart) as
  :func:`fpm_sim.batch.task_sweep.sweep_task` runs it (inverse kinematics warm-started from the neighbour,
  singularity measures, one compiled model re-posed, constrained eigen-solve of 3 modes; fidelity standard,
  inextensible, gravity off), against the same row of the 3RRR's own pose loop
  (:func:`fpm_sim.batch.pose_loop.solve_poses`, closed-form kinematics, one compiled model re-posed) at the same
  options. ``track_*`` reports each machine's seconds per pose per degree of freedom over the 3RRR's (the target:
  at most 1.5).
- ``InverseKinematics``: the 3RRR's row assembled by the general solver as the sweep runs it (warm-started) against
  the closed form (:func:`fpm_sim.kinematics.assemble_many`, which the 3RRR's loop runs), and
  ``track_ik_adds_to_sweep_pose``: the general solver's extra time over the closed form's, as a share of a sweep pose
  that used the closed form (the target: at most 10 %).

CPU time of this process (``time.process_time``), one BLAS thread, as the pose loops run.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

from benchmarks.common import OneBlasThread, warm_imports

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "architectures"
MACHINES = ["3RRR (its own pose loop)", "3RRR (general path)", "five_bar", "delta"]
N_POSES = 24


def _general(name: str):
    import fpm_sim as fs
    from fpm_sim.architecture.three_rrr import description_of_3rrr

    if name.startswith("3RRR"):
        desc = description_of_3rrr(fs.default_config())
        poses = [fs.TaskPose(-0.06 + 0.005 * k, 0.0, 0.0, 0.0) for k in range(N_POSES)]
    else:
        desc = fs.load_description(EXAMPLES / f"{name}.toml")
        home = desc.check_poses[0]
        poses = [
            fs.TaskPose(home.get("x", 0.0) - 0.06 + 0.005 * k, home.get("y", 0.0), home.get("z", 0.0))
            for k in range(N_POSES)
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
        poses = [fs.Pose(-0.06 + 0.005 * k, 0.0, 0.0) for k in range(N_POSES)]
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
    """The 3RRR's row by the general solver (warm-started, as the sweep runs it) and by the closed form (module
    docstring)."""

    params = [["closed form", "general solver"]]
    param_names = ["way"]

    def setup(self, way: str) -> None:
        import fpm_sim as fs

        warm_imports()
        self.cfg = fs.default_config()
        self.desc, self.poses = _general(MACHINES[1])

    def time_poses(self, way: str) -> None:
        from fpm_sim.architecture import solve_task_pose, task_unknowns
        from fpm_sim.kinematics import assemble_many

        if way == "closed form":
            ps = self.poses
            assemble_many(self.cfg.geometry, [p.x_m for p in ps], [p.y_m for p in ps], [p.phi_rad for p in ps])
            return
        start = None
        for p in self.poses:
            start = task_unknowns(self.desc, solve_task_pose(self.desc, p, start=start))

    def track_ik_adds_to_sweep_pose(self, way: str) -> float:
        """The general solver's extra CPU time over the closed form's, per pose, as a share of a general sweep pose
        of the 3RRR that used the closed form (the same for both parameters: the comparison is the point)."""
        seconds = {}
        for w in ("closed form", "general solver"):
            t = time.process_time()
            self.time_poses(w)
            seconds[w] = (time.process_time() - t) / N_POSES
        pose, _ = _sweep_pose_seconds(MACHINES[1])
        extra = seconds["general solver"] - seconds["closed form"]
        return extra / (pose - extra)
