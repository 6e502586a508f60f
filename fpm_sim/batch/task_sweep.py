"""First natural frequencies of a described architecture over its workspace (``fpm-sim sweep --config machine.toml``).

The pose loop of any :class:`fpm_sim.architecture.Description`: at each task pose the general inverse kinematics
(warm-started from the previous pose of the chunk), the singularity measures, and the constrained eigen-solve on one
compiled model re-posed at every pose (:class:`fpm_sim.batch.task_pose_model.TaskPoseModel`, the 3RRR loop's way).
Its policy is the 3RRR pose loop's: gravity off, inextensible links (no axial springs), the resolution of the
options. A pose is ``unreachable`` when no assembly in the working mode exists, ``singular`` below
:data:`fpm_sim.kinematics.SINGULAR_TOL` (its modes are not computed) or when the constraint rank decision loses a
loop direction, and ``near_singular`` below :data:`fpm_sim.kinematics.NEAR_SINGULAR_WARN`.

Grids are in the architecture's own task coordinates: ``x`` and ``y`` every ``step_mm`` over the box the chains
can reach, the other task coordinates held (``z_mm`` for a spatial machine: a horizontal slice; ``phi_rad`` for a
planar one that sets it).
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from fpm_sim.architecture import Description, TaskPose
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.architecture.kinematics import UnreachableTaskPoseError, closure_reach, solve_task_pose, task_unknowns
from fpm_sim.batch.engine import spawn_pool
from fpm_sim.batch.task_pose_model import TaskPoseModel
from fpm_sim.errors import FpmSimError
from fpm_sim.figures import write_table_and_figure
from fpm_sim.kinematics import NEAR_SINGULAR_WARN, SINGULAR_TOL
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.options import ModelOptions
from fpm_sim.outputs import write_csv_rows

__all__ = ["TaskSweep", "read_task_poses_csv", "sweep_task", "sweep_task_many", "task_grid", "task_statuses"]

MAX_GRID_POINTS = 40_000


def _reach_box(desc: Description) -> tuple[float, float, float, float]:
    """``(x_min, x_max, y_min, y_max)`` (m) of a box that holds every reachable end-effector position: where every
    closed chain reaches (:func:`fpm_sim.architecture.kinematics.closure_reach`), the boxes' intersection."""
    boxes = []
    for _, c, base, reach in closure_reach(desc):
        r = reach + float(np.linalg.norm(desc.end_effector.attachments_m[str(c.end_joint.at)]))  # type: ignore[union-attr]
        boxes.append((base[0] - r, base[0] + r, base[1] - r, base[1] + r))
    if not boxes:
        total = sum(lk.length_m for c in desc.chains for lk in c.links)
        return (-total, total, -total, total)
    return (max(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), min(b[3] for b in boxes))


def task_grid(
    desc: Description, *, step_mm: float, held: dict[str, float]
) -> tuple[list[TaskPose], np.ndarray, np.ndarray]:
    """Task poses every ``step_mm`` in x and y over the reach box, the other task coordinates at ``held`` (SI: m,
    rad); returns the poses and the x and y ticks (mm)."""
    if not (math.isfinite(step_mm) and step_mm > 0):
        raise FpmSimError("must be > 0", parameter="step_mm", value=step_mm)
    x0, x1, y0, y1 = _reach_box(desc)
    xs = np.arange(math.floor(x0 * 1e3 / step_mm), math.ceil(x1 * 1e3 / step_mm) + 1) * step_mm
    ys = np.arange(math.floor(y0 * 1e3 / step_mm), math.ceil(y1 * 1e3 / step_mm) + 1) * step_mm
    if xs.size * ys.size > MAX_GRID_POINTS:
        raise FpmSimError(
            f"gives {xs.size} x {ys.size} points", parameter="step_mm", value=step_mm, hint="use a larger step"
        )
    poses = [TaskPose(x * 1e-3, y * 1e-3, held.get("z", 0.0), held.get("phi", 0.0)) for y in ys for x in xs]
    return poses, xs, ys


def read_task_poses_csv(
    path: str | Path,
    desc: Description | ImportedDescription,
    *,
    parameter: str = "poses",
    lines: list[int] | None = None,
) -> list[TaskPose]:
    """Task poses from a CSV with one column per task coordinate of ``desc`` (``x_mm``, ``y_mm``, ``z_mm``,
    ``phi_rad``; other columns ignored); errors name ``parameter``, the file and the row. ``lines``: if given, each
    pose's row (line number) is appended to it."""
    import csv

    from fpm_sim.batch.pose_loop import PosesFileError

    p = Path(path)
    if not p.is_file():
        raise PosesFileError(f"{p}: no such file", parameter=parameter)
    names = {c: ("phi_rad" if c == "phi" else f"{c}_mm") for c in desc.task}
    poses = []
    with open(p, newline="", encoding="utf-8-sig") as fh:
        reader = csv.DictReader(fh)
        missing = set(names.values()) - {h.strip() for h in reader.fieldnames or []}
        if missing:
            raise PosesFileError(
                f"{p}: missing column(s) {', '.join(sorted(missing))}",
                parameter=parameter,
                hint=f"{desc.name}'s task coordinates are {','.join(names.values())}",
            )
        for r in reader:
            r = {(k or "").strip(): v for k, v in r.items()}
            vals = {}
            for c, col in names.items():
                try:
                    v = float(r[col])
                except (TypeError, ValueError):
                    v = math.nan
                if not math.isfinite(v) or (c == "phi" and abs(v) > math.pi):
                    raise PosesFileError(
                        f"{p}: row {reader.line_num}: {col} must be a finite number"
                        + (" within -pi..pi" if c == "phi" else ""),
                        parameter=parameter,
                    )
                vals[c] = v if c == "phi" else v * 1e-3
            poses.append(TaskPose(vals.get("x", 0.0), vals.get("y", 0.0), vals.get("z", 0.0), vals.get("phi", 0.0)))
            if lines is not None:
                lines.append(reader.line_num)
    if not poses:
        raise PosesFileError(f"{p}: no rows after the header", parameter=parameter)
    return poses


def _kinematics_row(desc: Description, pose: TaskPose, n_modes: int, start: np.ndarray | None) -> tuple[Any, ...]:
    """(status, NaN frequencies, type 1, type 2, unknowns for the next pose's start, assembly or None) at one pose."""
    nan = np.full(n_modes, np.nan)
    try:
        asm = solve_task_pose(desc, pose, start=start)
    except UnreachableTaskPoseError:
        return "unreachable", nan, math.nan, math.nan, None, None
    t1, t2 = asm.singularity_type1, asm.singularity_type2
    z = task_unknowns(desc, asm)
    if min(t1, t2) < SINGULAR_TOL:
        return "singular", nan, t1, t2, z, None
    return ("near_singular" if min(t1, t2) < NEAR_SINGULAR_WARN else "ok"), nan, t1, t2, z, asm


def task_statuses(desc: Description, poses: Sequence[TaskPose]) -> list[str]:
    """Each pose's status from the kinematics alone (no model built): ``ok``, ``near_singular``, ``singular`` or
    ``unreachable`` as the pose loop gives them (less its constraint rank decision), each pose's inverse kinematics
    started from the last assembled pose's."""
    start, out = None, []
    for p in poses:
        row = _kinematics_row(desc, p, 1, start)
        start = row[4] if row[4] is not None else start
        out.append(str(row[0]))
    return out


def _one(
    desc: Description, pose: TaskPose, opts: ModelOptions, n_modes: int, start: np.ndarray | None, cache: _Loop
) -> tuple[Any, ...]:
    """(status, frequencies, type 1, type 2, unknowns for the next pose's start) at one pose."""
    status, nan, t1, t2, z, asm = _kinematics_row(desc, pose, n_modes, start)
    if asm is None:
        return status, nan, t1, t2, z
    if cache.model is None:  # compiled once, at the chunk's first pose with modes (mobility checked there)
        cache.model = TaskPoseModel(desc, opts, asm)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f, deficient = cache.model.solve(asm, n_modes)
    if deficient:  # the constraint rank decision (consistent units) lost a loop direction
        return "singular", nan, t1, t2, z
    return status, f, t1, t2, z


@dataclass
class _Loop:
    """A chunk's re-posed model (compiled at its first pose with modes)."""

    model: TaskPoseModel | None = None


def _chunk(args: tuple[Description, list[TaskPose], ModelOptions, int]) -> list[tuple[Any, ...]]:
    """The chunk's poses in order, each one's inverse kinematics started from the last assembled pose's."""
    desc, poses, opts, n_modes = args
    cache, start, out = _Loop(), None, []
    with blas_threads():  # one BLAS thread around the dense solves (fpm_sim.linear.threads)
        for p in poses:
            row = _one(desc, p, opts, n_modes, start, cache)
            start = row[4] if row[4] is not None else start
            out.append(row)
    return out


@dataclass
class TaskSweep:
    """Frequencies of a described architecture over task poses (:func:`sweep_task`); a :class:`fpm_sim.Result`."""

    name: str
    task: tuple[str, ...]
    poses: list[TaskPose]
    freq_hz: np.ndarray
    status: list[str]
    type1: np.ndarray
    type2: np.ndarray
    grid: str
    step_mm: float | None = None
    options: ModelOptions | None = None

    @property
    def frequencies_hz(self) -> np.ndarray:
        """``(n_poses, n_modes)`` frequencies (Hz; NaN where not computed), as the 3RRR's pose loop names them."""
        return self.freq_hz

    def rows(self) -> list[dict[str, Any]]:
        """One row per pose: its task coordinates (mm, rad), status, singularity measures, f1..fn (Hz)."""
        out = []
        for k, p in enumerate(self.poses):
            row: dict[str, Any] = {
                ("phi_rad" if c == "phi" else f"{c}_mm"): (p.value(c) if c == "phi" else p.value(c) * 1e3)
                for c in self.task
            }
            row["status"] = self.status[k]
            row["singularity_type1"] = float(self.type1[k])
            row["singularity_type2"] = float(self.type2[k])
            for m, f in enumerate(self.freq_hz[k]):
                row[f"f{m + 1}_hz"] = float(f)
            out.append(row)
        return out

    def counts(self) -> dict[str, int]:
        return {s: self.status.count(s) for s in sorted(set(self.status))}

    def write_csv(self, path: Path) -> None:
        write_csv_rows(path, self.rows())

    def to_dict(self) -> dict[str, Any]:
        rows = [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()} for r in self.rows()]
        return {"config": self.name, "task": list(self.task), "grid": self.grid, "counts": self.counts(), "rows": rows}

    def to_xarray(self) -> Any:
        from fpm_sim.results import frequencies_dataset

        return frequencies_dataset(
            self.freq_hz,
            x_mm=[p.x_m * 1e3 for p in self.poses],
            y_mm=[p.y_m * 1e3 for p in self.poses],
            phi_rad=[p.phi_rad for p in self.poses],
            status=self.status,
            coords={"z_mm": ("pose", [p.z_m * 1e3 for p in self.poses])},
            attrs={"config": self.name, "task": ",".join(self.task)},
        )

    def table(self) -> str:
        f1 = self.freq_hz[:, 0]
        ok = f1[np.isfinite(f1)]
        lines = [
            f"{self.name}: {len(self.poses)} poses (" + ", ".join(f"{k} {v}" for k, v in self.counts().items()) + ")"
        ]
        if ok.size:
            lines.append(f"f1 range: {ok.min():.2f} .. {ok.max():.2f} Hz")
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        from fpm_sim.batch.task_sweep_plot import plot_task_sweep

        return plot_task_sweep(self, ax)

    def write(self, out_dir: str | Path) -> list[Path]:
        """``sweep_<grid>.csv`` and ``sweep_<grid>.png`` in ``out_dir``."""
        paths: list[Path] = write_table_and_figure(self, out_dir, f"sweep_{self.grid}")
        return paths


def sweep_task(
    desc: Description,
    poses: list[TaskPose],
    *,
    options: ModelOptions | None = None,
    n_modes: int = 3,
    workers: int = 1,
    grid: str = "poses",
    step_mm: float | None = None,
    progress: bool = False,
    backend: str = "cpu",
) -> TaskSweep:
    """The first ``n_modes`` frequencies (Hz) at every pose (module docstring), on ``workers`` processes.

    ``backend``: ``"cpu"`` (this loop), or ``"jax"`` / ``"mjx"``: the kinematics and the re-posed models here, the
    eigen-solves of all poses in one batched call of that backend (:func:`batched_task_modes`; ``workers``
    unused)."""
    opts = replace(options or ModelOptions(), gravity=False, axial=False)
    if backend != "cpu":
        results = batched_task_modes(desc, poses, opts, n_modes, backend=backend)
        return _task_sweep(desc, poses, results, opts, n_modes, grid=grid, step_mm=step_mm)
    (sw,) = sweep_task_many([desc], poses, options=opts, n_modes=n_modes, workers=workers)
    return replace(sw, grid=grid, step_mm=step_mm)


def sweep_task_many(
    descs: Sequence[Description],
    poses: list[TaskPose],
    *,
    options: ModelOptions | None = None,
    n_modes: int = 3,
    workers: int = 1,
) -> list[TaskSweep]:
    """:func:`sweep_task` of several descriptions (a design study's designs) over the same poses, their chunks on one
    pool of ``workers`` processes. A chunk is a contiguous run of the poses: each pose's inverse kinematics starts
    from its neighbour's."""
    opts = replace(options or ModelOptions(), gravity=False, axial=False)
    n = workers if workers > 1 and len(poses) > workers else 1
    bounds = np.linspace(0, len(poses), n + 1).astype(int)
    jobs = [(d, poses[lo:hi], opts, n_modes) for d in descs for lo, hi in itertools.pairwise(bounds)]
    if workers > 1 and len(jobs) > 1:
        with spawn_pool(workers) as pool:  # its workers ignore Ctrl-C: this process alone stops, and stops them
            parts = pool.map(_chunk, jobs)
    else:
        parts = [_chunk(job) for job in jobs]
    return [
        _task_sweep(desc, poses, [row for part in parts[d * n : (d + 1) * n] for row in part], opts, n_modes)
        for d, desc in enumerate(descs)
    ]


def _task_sweep(
    desc: Description,
    poses: list[TaskPose],
    results: list[tuple[Any, ...]],
    opts: ModelOptions,
    n_modes: int,
    *,
    grid: str = "poses",
    step_mm: float | None = None,
) -> TaskSweep:
    return TaskSweep(
        name=desc.name,
        task=desc.task,
        poses=list(poses),
        freq_hz=np.array([r[1] for r in results]).reshape(len(poses), n_modes),
        status=[r[0] for r in results],
        type1=np.array([r[2] for r in results], float),
        type2=np.array([r[3] for r in results], float),
        grid=grid,
        step_mm=step_mm,
        options=opts,
    )


BATCHED_BACKENDS = ("jax", "mjx")
"""Backends that solve a described machine's poses in one batched call (JAX and MJX, imported when called)."""


def batched_task_modes(
    desc: Description, poses: list[TaskPose], opts: ModelOptions, n_modes: int, *, backend: str
) -> list[tuple[Any, ...]]:
    """The sweep's rows (as :func:`_chunk`'s) with the eigen-solves of ``backend`` (:data:`BATCHED_BACKENDS`): the
    kinematics (warm-started) and one re-posed model per pose here, copied per pose, then every pose's constrained
    eigenproblem in one call of the backend's solver. The rank decision is the cpu loop's (consistent units).

    Raises
    ------
    FpmSimError
        What the backend cannot linearise (the ``jax`` formulas: hinge and slide joints closed by welds; MJX: no
        long serial chain), named by the backend's own check.
    """
    import copy

    from fpm_sim.batch.jax_backend import BackendTimings, check_options, x64
    from fpm_sim.linear.nullspace import constraint_rank
    from fpm_sim.model.spec import BuiltModel

    if backend not in BATCHED_BACKENDS:
        raise FpmSimError(f"unknown backend {backend!r}", parameter="backend", value=backend, hint="cpu, jax or mjx")
    check_options(opts, backend)
    _check_batched(desc, backend)
    rows: list[tuple[Any, ...]] = []
    built: list[tuple[int, Any]] = []
    start, loop = None, _Loop()
    for p in poses:
        row = _kinematics_row(desc, p, n_modes, start)
        start = row[4] if row[4] is not None else start
        if row[0] in ("ok", "near_singular"):
            loop.model = loop.model or TaskPoseModel(desc, opts, row[5])
            loop.model.set_pose(row[5])
            built.append((len(rows), replace(loop.model.built, model=copy.copy(loop.model.model))))
        rows.append(row[:5])
    if not built:
        return rows
    if backend == "jax":
        from fpm_sim.batch.jax_backend import solve_jax_models as solve
    else:
        from fpm_sim.batch.mjx_backend import solve_mjx_models as solve
    models: list[BuiltModel] = [b for _, b in built]
    with x64():
        w2 = solve(models, n_modes, BackendTimings(poses=len(models)), 0.0)[0]
    for r, (i, b) in enumerate(built):
        data = mujoco.MjData(b.model)
        mujoco.mj_forward(b.model, data)
        if constraint_rank(b.model, data, warn=False).deficient:
            rows[i] = ("singular", rows[i][1], *rows[i][2:])
            continue
        f = np.full(n_modes, np.nan)
        f[: w2.shape[1]] = np.sqrt(np.maximum(w2[r], 0.0)) / (2 * np.pi)
        rows[i] = (rows[i][0], f, *rows[i][2:])
    return rows


def _check_batched(desc: Description, backend: str) -> None:
    """Refuse what the ``jax`` backend's formulas do not hold yet, naming the joint: a chain closed on the end
    effector by a spherical joint is a ``connect`` equality, and those formulas close loops by welds only (MJX's
    pipeline takes both)."""
    if backend != "jax":
        return
    closed = [(i, c) for i, c in enumerate(desc.chains) if c.end_joint is not None]
    for i, c in closed[1:]:  # the first closed chain carries the end effector; the others close loops on it
        end = c.end_joint
        if end is not None and end.type == "spherical":
            raise FpmSimError(
                f"chains[{i}].path[{len(c.path) - 1}].type = 'spherical': the jax backend closes loops by welds "
                "only, and a spherical end joint is a point (connect) constraint",
                parameter="backend",
                value=backend,
                hint="use the mjx backend (MJX's own pipeline takes it) or cpu",
            )
