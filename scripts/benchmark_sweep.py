"""Benchmark of the dense workspace sweep: the re-posing pose loop against the per-pose compile it replaced.

    python scripts/benchmark_sweep.py [--step-mm 10] [--segments 6] [--skip-dask] [--full-poses 3]

Measured in one run, on the same poses:

1. "before": the pose loop as it was (one MuJoCo model compiled per pose, ``scipy.linalg.eigh`` of the lowest
   modes; copied below verbatim as :func:`_before_solve_pose`), in this process and on its two-process pool;
2. "now": :func:`fpm_sim.batch.pose_loop.solve_poses` (one compiled model re-posed per pose) in this
   process, and the ``cpu`` backend on a two-worker Dask ``LocalCluster`` (cluster start included);
3. "floor": the constrained eigen-solves alone (:func:`fpm_sim.linear.modal.reduced_eigenproblem` on the
   matrices of every computed pose, nothing else), and, for reference, the same with the lowest three
   eigenpairs only (``subset_by_index``);
4. the largest relative difference of f1..f3 between "before" and "now" (same segments).

Prints CPU times of this process (``time.process_time``: what a pose costs, insensitive to other programs
sharing the cores) for the in-process runs and the floors, and wall times for the multi-process runs (their
work happens in other processes). On a shared machine absolute times move; the ratios come from one run.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import mujoco
import numpy as np
import scipy.linalg

import fpm_sim  # noqa: F401  (single-threaded BLAS)
from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import IN_PLANE_KINDS, assemble_pose, fast_options, solve_poses
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.linear.analysis import manipulator_modes
from fpm_sim.linear.equilibrium import EquilibriumError
from fpm_sim.linear.modal import (
    NULLSPACE_RCOND,
    equality_jacobian,
    mass_matrix,
    reduced_eigenproblem,
    scaled_null_space,
    unit_scales,
)
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.options import dof_stiffness
from fpm_sim.study.sweep import dense_grid


def _before_solve_pose(manip, pose, opts, n_modes):
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


def _before(cfg, poses, opts, workers):
    if workers <= 1:
        res = [_before_solve_pose(cfg, p, opts, 3) for p in poses]
    else:
        chunk = max(1, min(16, len(poses) // (4 * workers)))
        jobs = [(cfg, poses[i : i + chunk], opts, 3) for i in range(0, len(poses), chunk)]
        res = []
        with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("fork")) as ex:
            for r in ex.map(_before_chunk, jobs):
                res.extend(r)
    return np.array([r[0] for r in res])


def _floor(cfg, poses, opts):
    """Seconds of the eigen-solves alone: as the pose loop runs them (in-plane and out-of-plane blocks),
    on the whole matrices (one reduced_eigenproblem per pose), and the whole matrices' lowest three only."""
    from fpm_sim.batch.pose_loop import PoseModel, plane_blocks, pose_assembly, structural_length_m

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
    t0 = time.process_time()
    for *_, sub in mats:
        for m, k, j, rs, cs in sub:
            reduced_eigenproblem(m, k, scaled_null_space(j, rs, cs)[2])
    t_blocks = time.process_time() - t0
    t0 = time.process_time()
    for m, k, j, rs, cs, _ in mats:
        reduced_eigenproblem(m, k, scaled_null_space(j, rs, cs)[2])
    t_full = time.process_time() - t0
    t0 = time.process_time()
    for m, k, j, rs, cs, _ in mats:
        z = scaled_null_space(j, rs, cs)[2]
        kr, mr = z.T @ k @ z, z.T @ m @ z
        scipy.linalg.eigh(0.5 * (kr + kr.T), 0.5 * (mr + mr.T), subset_by_index=[0, 2])
    return t_blocks, t_full, time.process_time() - t0, len(mats)


def _noop(item: int) -> int:
    return item


def _engine_overhead(n_tasks: int) -> tuple[float, float, float]:
    """Seconds to start a 2-worker LocalCluster, and per no-op task (submit to result) on it, for n_tasks
    tasks: submitted all at once (throughput), and one at a time (latency)."""
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as client:
            client.wait_for_workers(2)
            t_start = time.perf_counter() - t0
            t0 = time.perf_counter()
            client.gather(client.map(_noop, range(n_tasks), pure=False))
            t_many = (time.perf_counter() - t0) / n_tasks
            t0 = time.perf_counter()
            for i in range(100):
                client.submit(_noop, i, pure=False).result()
            t_one = (time.perf_counter() - t0) / 100
    return t_start, t_many, t_one


def _time_jax(cfg, poses, now, opts, n):
    """The batched JAX backend (issue 5) on the first n computed poses: its stages, against this loop."""
    from fpm_sim.batch import jax_backend
    from fpm_sim.batch.frequencies import BACKENDS

    name = next((k for k, v in BACKENDS.items() if k != "cpu"), None)
    if name is None:
        print("  no JAX backend registered")
        return
    picks = [p for p, s in zip(poses, now.status) if s in ("ok", "near_singular")][:n]
    for call in ("first", "second"):
        t0 = time.perf_counter()
        res = pose_frequencies(cfg, picks, backend=name, n_modes=3, options=opts)
        wall = time.perf_counter() - t0
        t = jax_backend.LAST_TIMINGS
        print(
            f"  JAX backend {name!r}, {len(picks)} poses, {call} call: {wall:.2f} s wall (build {t.build_s:.2f} s, "
            f"compile {t.compile_s:.2f} s, run {t.run_s:.3f} s = {t.run_s / len(picks) * 1e3:.2f} ms per pose)"
        )
    t0 = time.process_time()
    ref = solve_poses(cfg, picks, n_modes=3, options=opts)
    t_cpu = time.process_time() - t0
    rel = np.nanmax(np.abs(res.frequencies_hz / ref.frequencies_hz - 1))
    print(
        f"  this loop on the same poses: {t_cpu:.2f} s CPU ({t_cpu / len(picks) * 1e3:.2f} ms per pose); "
        f"max rel diff {rel:.1e}"
    )


def main() -> None:
    # Both ways with one BLAS thread, as the pose loop runs its solves: multithreaded OpenBLAS busy-waits on
    # small matrices (fpm_sim.linear.threads), which would make the old loop look 30x slower than it was.
    with blas_threads():
        _main()


def _main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step-mm", type=float, default=10.0)
    ap.add_argument("--segments", type=int, default=6)
    ap.add_argument("--skip-dask", action="store_true", help="skip the two-process runs (pool and Dask cluster)")
    ap.add_argument("--full-poses", type=int, default=0, help="poses compared with the full analysis (slow)")
    ap.add_argument("--mjx", type=int, default=0, help="also time the JAX backend on this many computed poses")
    ap.add_argument("--engine-tasks", type=int, default=2000, help="no-op tasks timing Dask's per-task cost (0: skip)")
    args = ap.parse_args()
    cfg = default_config()
    opts = fast_options(segments=args.segments)
    t0 = time.process_time()
    poses = dense_grid(cfg, step_mm=args.step_mm)
    t_grid = time.process_time() - t0
    times: dict[str, float] = {}

    t0 = time.process_time()
    f_before = _before(cfg, poses, opts, 1)
    times["before, 1 process (CPU)"] = time.process_time() - t0
    t0 = time.process_time()
    now = solve_poses(cfg, poses, n_modes=3, options=opts)
    times["now, 1 process (CPU)"] = time.process_time() - t0
    if not args.skip_dask:
        t0 = time.perf_counter()
        _before(cfg, poses, opts, 2)
        times["before, 2-process pool (wall)"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        dask = pose_frequencies(cfg, poses, n_modes=3, options=opts, engine=EngineOptions(scheduler="local", workers=2))
        times["now, Dask LocalCluster 2 workers, start incl. (wall)"] = time.perf_counter() - t0
        same = np.array_equal(dask.frequencies_hz, now.frequencies_hz, equal_nan=True)
        print(f"Dask run equals the in-process run: {same}")
    t_floor, t_whole, t_whole3, n_ok = _floor(cfg, poses, opts)

    print(f"dense grid, step {args.step_mm:g} mm, {args.segments} segments: {len(poses)} points ({n_ok} computed)")
    print(f"  grid setup {t_grid:.3f} s")
    for k, t in times.items():
        print(f"  {k:<52} {t:8.2f} s  ({t / max(n_ok, 1) * 1e3:6.2f} ms per computed pose)")
    floors = {
        "eigen-solves alone, as the loop runs them (2 blocks)": t_floor,
        "eigen-solves alone, whole matrix (as before)": t_whole,
        "eigen-solves alone, whole matrix, lowest 3 only": t_whole3,
    }
    for k, t in floors.items():
        print(f"  {k:<52} {t:8.2f} s  ({t / n_ok * 1e3:6.2f} ms)")
    b1, n1 = times["before, 1 process (CPU)"], times["now, 1 process (CPU)"]
    print(f"  speed-up, 1 process: {b1 / n1:.1f}x;  now / eigen-solve floor: {n1 / t_floor:.2f}x")
    if not args.skip_dask:
        b2, d2 = times["before, 2-process pool (wall)"], times["now, Dask LocalCluster 2 workers, start incl. (wall)"]
        print(f"  speed-up, 2 processes (wall): before pool / now Dask: {b2 / d2:.1f}x")
    fb, fn = f_before, now.frequencies_hz
    ok = np.isfinite(fb) & np.isfinite(fn)
    rel = np.abs(fn[ok] / fb[ok] - 1.0)
    clean = np.array([s == "ok" for s in now.status])  # away from singularities (measure >= 0.05)
    rel_ok = np.abs(fn[clean] / fb[clean] - 1.0)
    print(
        f"  statuses agree: {np.array_equal(np.isfinite(fb), np.isfinite(fn))};  max |f/f_before - 1| over f1..f3: "
        f"{rel.max():.2e} (f1: {np.nanmax(np.abs(fn[:, 0] / fb[:, 0] - 1)):.2e}); at the 'ok' poses: "
        f"{np.nanmax(rel_ok):.2e}"
    )
    if args.mjx:
        _time_jax(cfg, poses, now, opts, args.mjx)
    if args.engine_tasks:
        t_start, t_many, t_one = _engine_overhead(args.engine_tasks)
        print(
            f"  Dask LocalCluster (2 workers): start {t_start:.2f} s; per no-op task {t_many * 1e3:.2f} ms "
            f"({args.engine_tasks} submitted at once), {t_one * 1e3:.2f} ms (one at a time)"
        )
    picks = [Pose.from_mm(0, 0, 0.2), Pose.from_mm(100, -100, 0.0), Pose.from_mm(-50, 50, 0.0)][: args.full_poses]
    for p in picks:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                full = manipulator_modes(cfg, p, n_modes=3).frequencies_hz
        except EquilibriumError as exc:
            print(f"  {p.label()}: full analysis failed ({exc})")
            continue
        fast = solve_poses(cfg, [p], n_modes=3, options=opts).frequencies_hz[0]
        dev = np.round(100 * (fast / full - 1), 3)
        print(f"  {p.label()}: full {np.round(full, 3)} Hz, fast {np.round(fast, 3)} Hz, diff {dev} %")


if __name__ == "__main__":
    main()
