"""The dense workspace sweep: the re-posing pose loop against the per-pose compile it replaced (issues 4, 13).

(Was ``scripts/benchmark_sweep.py``.) The embedded default on the dense grid at phi = 0, 6 segments, inextensible,
gravity off, 3 modes; grid step 20 mm (``FPM_SIM_BENCH_FULL=1`` adds the docs' 10 mm). The parameter ``way``:

- ``before``: the pose loop as it was (one MuJoCo model compiled per pose, ``scipy.linalg.eigh`` of the lowest
  modes; :func:`_before_solve_pose` is cf32cb4's, verbatim);
- ``now``: :func:`fpm_sim.batch.pose_loop.solve_poses` (one compiled model re-posed per pose);
- the floors: the constrained eigen-solves alone on every computed pose's matrices, as the loop runs them (in-plane
  and out-of-plane blocks), on the whole matrices, and the whole matrices' lowest three eigenpairs only.

In-process ways are timed in CPU time of this process (``time.process_time``: insensitive to other programs on the
cores), both with one BLAS thread as the pose loop runs its solves (multithreaded OpenBLAS busy-waits on these small
matrices: ``fpm_sim/linear/threads.py``). ``TwoProcesses`` times the old process pool against the ``cpu`` backend on
a two-worker Dask ``LocalCluster`` (wall, cluster start included); ``DaskTasks`` Dask's cost per no-op task;
``FullVsFast`` one pose's full default analysis against the fast path (``FPM_SIM_BENCH_FULL=1``).
"""

from __future__ import annotations

import math
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import mujoco
import numpy as np
import scipy.linalg

from benchmarks.common import OneBlasThread, require_full, warm_imports

STEPS_MM = [20.0, 10.0]
SEGMENTS = 6
N_MODES = 3
WAYS = [
    "before: a model per pose",
    "now: one model re-posed",
    "floor: eigen-solves in blocks",
    "floor: eigen-solves, whole matrix",
    "floor: whole matrix, lowest 3",
]


def _grid(step_mm: float):
    from fpm_sim.batch.pose_loop import fast_options
    from fpm_sim.config import default_config
    from fpm_sim.study.sweep import dense_grid

    if step_mm < STEPS_MM[0]:
        require_full()
    cfg = default_config()
    return cfg, dense_grid(cfg, step_mm=step_mm), fast_options(segments=SEGMENTS)


def _before_solve_pose(manip, pose, opts, n_modes):
    from fpm_sim.batch.pose_loop import IN_PLANE_KINDS, assemble_pose
    from fpm_sim.linear.equilibrium import equality_jacobian
    from fpm_sim.linear.matrices import mass_matrix
    from fpm_sim.linear.nullspace import NULLSPACE_RCOND
    from fpm_sim.model.passive import dof_stiffness

    nan = np.full(n_modes, np.nan)
    built, singularity, status = assemble_pose(manip, pose, opts)
    if built is None:
        return nan, nan, singularity, status
    model = built.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mass = mass_matrix(model, data)
    k = dof_stiffness(model)
    jac = equality_jacobian(model, data)
    z = scipy.linalg.null_space(jac, rcond=NULLSPACE_RCOND)
    kr = z.T @ (k[:, None] * z)
    mr = z.T @ mass @ z
    n = min(n_modes, kr.shape[0])
    w2, x = scipy.linalg.eigh(0.5 * (kr + kr.T), 0.5 * (mr + mr.T), subset_by_index=[0, n - 1])
    freq = np.full(n_modes, np.nan)
    freq[:n] = np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi)
    inplane_mask = np.array([kind in IN_PLANE_KINDS for kind in built.dof_kinds])
    frac = np.full(n_modes, np.nan)
    for i in range(n):
        v = z @ x[:, i]
        e = k * v**2
        tot = float(e.sum())
        frac[i] = float(e[inplane_mask].sum()) / tot if tot > 0 else math.nan
    return freq, frac, singularity, status


def _before_chunk(args):
    manip, poses, opts, n_modes = args
    return [_before_solve_pose(manip, p, opts, n_modes) for p in poses]


def _before(cfg, poses, opts, workers: int) -> np.ndarray:
    if workers <= 1:
        res = [_before_solve_pose(cfg, p, opts, N_MODES) for p in poses]
    else:
        chunk = max(1, min(16, len(poses) // (4 * workers)))
        jobs = [(cfg, poses[i : i + chunk], opts, N_MODES) for i in range(0, len(poses), chunk)]
        res = []
        with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("fork")) as ex:
            for r in ex.map(_before_chunk, jobs):
                res.extend(r)
    return np.array([r[0] for r in res])


def _matrices(cfg, poses, opts) -> list:
    """Every computed pose's mass, stiffness, weld Jacobian, its unit scales and its plane blocks."""
    from fpm_sim.batch.pose_loop import PoseModel, plane_blocks, pose_assembly, structural_length_m
    from fpm_sim.linear.equilibrium import equality_jacobian
    from fpm_sim.linear.matrices import mass_matrix
    from fpm_sim.linear.nullspace import unit_scales

    mats = []
    pm = None
    for p in poses:
        asm, _, _ = pose_assembly(cfg, p)
        if asm is None:
            continue
        pm = pm or PoseModel(cfg, opts, asm)
        pm.set_pose(asm)
        mujoco.mj_fwdPosition(pm.model, pm.data)
        m, j = mass_matrix(pm.model, pm.data), equality_jacobian(pm.model, pm.data)
        rs, cs = unit_scales(pm.model, pm.data, structural_length_m(pm.model))
        blocks = plane_blocks(m, j, pm.in_plane) or [(np.arange(m.shape[0]), np.arange(j.shape[0]))]
        sub = [(m[np.ix_(d, d)], np.diag(pm.stiffness[d]), j[np.ix_(r, d)], rs[r], cs[d]) for d, r in blocks]
        mats.append((m, np.diag(pm.stiffness), j, rs, cs, sub))
    return mats


def _floor(mats: list, way: str) -> None:
    from fpm_sim.linear.nullspace import scaled_null_space
    from fpm_sim.linear.solvers import reduced_eigenproblem

    for m, k, j, rs, cs, sub in mats:
        if way == "floor: eigen-solves in blocks":
            for mb, kb, jb, rsb, csb in sub:
                reduced_eigenproblem(mb, kb, scaled_null_space(jb, rsb, csb)[2])
        elif way == "floor: eigen-solves, whole matrix":
            reduced_eigenproblem(m, k, scaled_null_space(j, rs, cs)[2])
        else:
            z = scaled_null_space(j, rs, cs)[2]
            kr, mr = z.T @ k @ z, z.T @ m @ z
            scipy.linalg.eigh(0.5 * (kr + kr.T), 0.5 * (mr + mr.T), subset_by_index=[0, N_MODES - 1])


class Sweep(OneBlasThread):
    """The dense grid in this process, one way (the parameter), CPU time of this process."""

    params = [STEPS_MM, WAYS]
    param_names = ["step_mm", "way"]
    timer = time.process_time
    number = 1
    repeat = (1, 5, 60.0)
    timeout = 900.0

    def setup(self, step_mm: float, way: str) -> None:
        self.cfg, self.poses, self.opts = _grid(step_mm)
        warm_imports()
        self.mats = _matrices(self.cfg, self.poses, self.opts) if way.startswith("floor") else []
        self.limit_blas()

    def time_grid(self, step_mm: float, way: str) -> None:
        from fpm_sim.batch.pose_loop import solve_poses

        if way.startswith("before"):
            _before(self.cfg, self.poses, self.opts, 1)
        elif way.startswith("now"):
            solve_poses(self.cfg, self.poses, n_modes=N_MODES, options=self.opts)
        else:
            _floor(self.mats, way)


class SweepAgreement:
    """The old loop against the new one on the 20 mm grid: same statuses, f1..f3 equal to round-off."""

    timeout = 600.0

    def setup(self) -> None:
        from fpm_sim.batch.pose_loop import solve_poses
        from fpm_sim.linear.threads import blas_threads

        cfg, poses, opts = _grid(STEPS_MM[0])
        with blas_threads():
            self.before = _before(cfg, poses, opts, 1)
            self.now = solve_poses(cfg, poses, n_modes=N_MODES, options=opts)
        if not np.array_equal(np.isfinite(self.before), np.isfinite(self.now.frequencies_hz)):
            raise AssertionError("the old and the new loop computed different poses")

    def track_max_rel_diff_ok_poses(self) -> float:
        """Largest |f_now / f_before - 1| over f1..f3 at the poses with status ``ok`` (singularity >= 0.05)."""
        clean = np.array([s == "ok" for s in self.now.status])
        return float(np.nanmax(np.abs(self.now.frequencies_hz[clean] / self.before[clean] - 1.0)))

    track_max_rel_diff_ok_poses.unit = "relative"

    def track_max_rel_diff_all_poses(self) -> float:
        """The same over every computed pose (near-singular ones included: round-off grows as w_max^2 / w^2)."""
        ok = np.isfinite(self.before)
        return float(np.abs(self.now.frequencies_hz[ok] / self.before[ok] - 1.0).max())

    track_max_rel_diff_all_poses.unit = "relative"


class TwoProcesses(OneBlasThread):
    """The 20 mm grid on two processes (wall): the old fork pool or the cpu backend on a Dask LocalCluster."""

    params = [["process pool (before)", "Dask LocalCluster, start included (now)"]]
    param_names = ["way"]
    number = 1
    repeat = (1, 3, 60.0)
    timeout = 600.0

    def setup(self, way: str) -> None:
        self.cfg, self.poses, self.opts = _grid(STEPS_MM[0])
        self.limit_blas()

    def time_grid(self, way: str) -> None:
        from fpm_sim.batch.engine import EngineOptions
        from fpm_sim.batch.frequencies import pose_frequencies

        if way.startswith("process pool"):
            _before(self.cfg, self.poses, self.opts, 2)
        else:
            engine = EngineOptions(scheduler="local", workers=2)
            pose_frequencies(self.cfg, self.poses, n_modes=N_MODES, options=self.opts, engine=engine)


class DaskTasks:
    """Dask's cost per no-op task on a 2-worker LocalCluster: 200 submitted at once, or one at a time. The task is
    the builtin ``abs``: a function of this module would have to be importable in the workers, which asv's
    benchmark package is not."""

    params = [["at once", "one at a time"]]
    param_names = ["submitted"]
    number = 1
    repeat = (1, 3, 60.0)
    timeout = 300.0
    n_tasks = 200

    def setup(self, submitted: str) -> None:
        from distributed import Client, LocalCluster

        self.cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
        self.client = Client(self.cluster)
        self.client.wait_for_workers(2)

    def teardown(self, submitted: str) -> None:
        self.client.close()
        self.cluster.close()

    def time_tasks(self, submitted: str) -> None:
        if submitted == "at once":
            self.client.gather(self.client.map(abs, range(self.n_tasks), pure=False))
        else:
            for i in range(self.n_tasks):
                self.client.submit(abs, i, pure=False).result()


class FullVsFast:
    """One pose, (100, -100, 0) mm: the full default analysis (default resolution, gravity equilibrium,
    ``mjd_transitionFD``) or the fast path (6 segments, inextensible, gravity off, constrained eigen-solve)."""

    params = [["full analysis", "fast path"]]
    param_names = ["way"]
    number = 1
    repeat = (1, 3, 60.0)
    timeout = 600.0

    def setup(self, way: str) -> None:
        from fpm_sim.batch.pose_loop import fast_options
        from fpm_sim.config import default_config
        from fpm_sim.kinematics import Pose

        require_full()
        self.cfg, self.pose = default_config(), Pose.from_mm(100.0, -100.0, 0.0)
        self.opts = fast_options(segments=SEGMENTS)

    def _f(self, way: str) -> np.ndarray:
        from fpm_sim.batch.pose_loop import solve_poses
        from fpm_sim.linear.analysis import manipulator_modes

        if way == "full analysis":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return np.asarray(manipulator_modes(self.cfg, self.pose, n_modes=N_MODES).frequencies_hz)
        return solve_poses(self.cfg, [self.pose], n_modes=N_MODES, options=self.opts).frequencies_hz[0]

    def time_pose(self, way: str) -> None:
        self._f(way)


class FullVsFastAgreement:
    """The fast path's first frequency against the full analysis's at (100, -100, 0) mm (``FPM_SIM_BENCH_FULL=1``)."""

    timeout = 600.0

    def setup(self) -> None:
        require_full()

    def track_fast_minus_full_f1_pct(self) -> float:
        """100 (f1_fast / f1_full - 1): 6 instead of 12 segments and no gravity prestress (docs: +0.6 %)."""
        run = FullVsFast()
        run.setup("fast path")
        return float(100.0 * (run._f("fast path")[0] / run._f("full analysis")[0] - 1.0))

    track_fast_minus_full_f1_pct.unit = "%"
