"""First natural frequencies of a described architecture over its workspace (``fpm-sim sweep --config machine.toml``).

The pose loop of any :class:`fpm_sim.architecture.Description`: at each task pose the general inverse kinematics
(warm-started from the previous pose of the chunk), the singularity measures, the general MuJoCo model
(:func:`fpm_sim.model.general.build_general`) and the constrained eigen-solve. Its policy is the 3RRR pose loop's:
gravity off, inextensible links (no axial springs), the resolution of the options. A pose is ``unreachable`` when
no assembly in the working mode exists, ``singular`` below :data:`fpm_sim.kinematics.SINGULAR_TOL` (its modes are
not computed) and ``near_singular`` below :data:`fpm_sim.kinematics.NEAR_SINGULAR_WARN`.

Grids are in the architecture's own task coordinates: ``x`` and ``y`` every ``step_mm`` over the box the chains
can reach, the other task coordinates held (``z_mm`` for a spatial machine: a horizontal slice; ``phi_rad`` for a
planar one that sets it).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import Description, TaskPose
from fpm_sim.architecture.kinematics import UnreachableTaskPoseError, closure_reach, solve_task_pose
from fpm_sim.batch.engine import spawn_pool
from fpm_sim.errors import FpmSimError
from fpm_sim.figures import write_table_and_figure
from fpm_sim.kinematics import NEAR_SINGULAR_WARN, SINGULAR_TOL
from fpm_sim.model.options import ModelOptions

__all__ = ["TaskSweep", "read_task_poses_csv", "sweep_task", "sweep_task_many", "task_grid"]

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


def read_task_poses_csv(path: str | Path, desc: Description, *, parameter: str = "poses") -> list[TaskPose]:
    """Task poses from a CSV with one column per task coordinate of ``desc`` (``x_mm``, ``y_mm``, ``z_mm``,
    ``phi_rad``; other columns ignored); errors name ``parameter``, the file and the row."""
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
    if not poses:
        raise PosesFileError(f"{p}: no rows after the header", parameter=parameter)
    return poses


def _one(desc: Description, pose: TaskPose, opts: ModelOptions, n_modes: int, start: Any) -> tuple[Any, ...]:
    """(status, frequencies, type 1, type 2, unknowns for the next pose's start) at one pose."""
    from fpm_sim.linear.solvers import modes_constrained
    from fpm_sim.model.general import build_general

    nan = np.full(n_modes, np.nan)
    try:
        asm = solve_task_pose(desc, pose, start=start)
    except UnreachableTaskPoseError:
        return "unreachable", nan, math.nan, math.nan, None
    t1, t2 = asm.singularity_type1, asm.singularity_type2
    if min(t1, t2) < SINGULAR_TOL:
        return "singular", nan, t1, t2, None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = modes_constrained(build_general(desc, pose, opts, assembly=asm), n_modes=n_modes).frequencies_hz
    out = nan.copy()
    out[: len(f)] = f[:n_modes]
    status = "near_singular" if min(t1, t2) < NEAR_SINGULAR_WARN else "ok"
    return status, out, t1, t2, None


def _chunk(args: tuple[Description, list[TaskPose], ModelOptions, int]) -> list[tuple[Any, ...]]:
    desc, poses, opts, n_modes = args
    return [_one(desc, p, opts, n_modes, None) for p in poses]


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
        import csv

        rows = self.rows()
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)

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
) -> TaskSweep:
    """The first ``n_modes`` frequencies (Hz) at every pose (module docstring), on ``workers`` processes."""
    (sw,) = sweep_task_many([desc], poses, options=options, n_modes=n_modes, workers=workers)
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
    pool of ``workers`` processes."""
    opts = replace(options or ModelOptions(), gravity=False, axial=False)
    n = workers if workers > 1 and len(poses) > workers else 1
    jobs = [(d, poses[i::n], opts, n_modes) for d in descs for i in range(n)]
    if workers > 1 and len(jobs) > 1:
        with spawn_pool(workers) as pool:  # its workers ignore Ctrl-C: this process alone stops, and stops them
            parts = pool.map(_chunk, jobs)
    else:
        parts = [_chunk(job) for job in jobs]
    out = []
    for d, desc in enumerate(descs):
        results: list[tuple[Any, ...]] = [None] * len(poses)  # type: ignore[list-item]
        for i in range(n):
            results[i::n] = parts[d * n + i]
        out.append(
            TaskSweep(
                name=desc.name,
                task=desc.task,
                poses=list(poses),
                freq_hz=np.array([r[1] for r in results]).reshape(len(poses), n_modes),
                status=[r[0] for r in results],
                type1=np.array([r[2] for r in results], float),
                type2=np.array([r[3] for r in results], float),
                grid="poses",
                options=opts,
            )
        )
    return out
