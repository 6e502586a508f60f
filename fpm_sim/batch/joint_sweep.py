"""First natural frequencies of an imported model (:mod:`fpm_sim.architecture.imported`) over joint-space poses.

An imported model is posed by its joints' values (MuJoCo's joint coordinates, rad for a
hinge, m for a slide), one ``{joint: value}`` mapping per pose; joints a pose does not name stay at the model's
reference. At each pose the model is built posed (:func:`fpm_sim.model.imported.build_imported`) and its modes
solved (:func:`fpm_sim.linear.analysis.analyse`). The policy is the described architectures' pose loop's
(:mod:`fpm_sim.batch.task_sweep`): gravity off, inextensible links, the resolution of the options.

A CSV of poses (``fpm-sim sweep --poses``, ``fpm-sim modes --poses``) has one column per joint name, in radians
(hinges) or metres (slides); a column that names no hinge or slide of the model, or a cell that is not a finite
number, is refused naming the column and the row. A model whose description names an end-effector site
(``[end_effector]``) may be posed in task space instead: a CSV whose columns are its task coordinates (``x_mm``,
``y_mm``, ``z_mm``, ``phi_rad``, as a described architecture's) is solved to joint values row by row
(:func:`fpm_sim.model.imported_pose.joint_poses_of`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import TaskPose
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.errors import FpmSimError
from fpm_sim.figures import write_table_and_figure
from fpm_sim.model.options import ModelOptions
from fpm_sim.outputs import write_csv_rows

__all__ = [
    "JointSweep",
    "check_joint_poses",
    "modes_at_joint_poses",
    "read_imported_poses_csv",
    "read_joint_poses_csv",
    "sweep_joints",
    "task_columns",
]


class JointPosesError(FpmSimError):
    """Joint-space poses (``poses``) that name no joint of the model, or values that are not finite numbers or lie
    outside a joint's stated range."""


def check_joint_poses(
    desc: ImportedDescription, poses: Sequence[Mapping[str, float]], *, parameter: str = "poses"
) -> list[dict[str, float]]:
    """``poses`` as plain ``{joint: float}`` dicts, each joint a hinge or slide of ``desc``'s model and each value
    finite and inside the joint's stated range; errors name ``parameter``, the pose (1-based) and the joint."""
    from fpm_sim.model.imported import joint_ranges, load_spec, range_problem

    ranges = joint_ranges(load_spec(desc).compile())
    if not poses:
        raise JointPosesError("no poses given", parameter=parameter, hint="give at least one {joint: value} pose")
    out = []
    for k, pose in enumerate(poses):
        if not isinstance(pose, Mapping):
            raise JointPosesError(f"pose {k + 1} is not a {{joint: value}} mapping", parameter=parameter, value=pose)
        row = {}
        for name, value in pose.items():
            if name not in ranges:
                raise JointPosesError(
                    f"pose {k + 1}: no hinge or slide joint {name!r} in {desc.model_path.name}",
                    parameter=parameter,
                    hint=f"its joints: {', '.join(ranges)}",
                )
            try:
                v = float(value)
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v):
                raise JointPosesError(f"pose {k + 1}: joint {name!r} must be a finite number", parameter=parameter)
            if problem := range_problem(ranges, str(name), v):
                raise JointPosesError(
                    f"pose {k + 1}: {problem}",
                    parameter=parameter,
                    hint="pose it inside the range, or widen the range in the model file",
                )
            row[str(name)] = v
        out.append(row)
    return out


def task_columns(desc: ImportedDescription) -> set[str]:
    """The CSV columns of ``desc``'s task coordinates (``x_mm`` ... ``phi_rad``; none without an end effector)."""
    return {"phi_rad" if c == "phi" else f"{c}_mm" for c in desc.task}


def read_joint_poses_csv(
    path: str | Path, desc: ImportedDescription, *, parameter: str = "poses"
) -> list[dict[str, float]]:
    """Joint-space poses from a CSV (module docstring): one column per joint name, or the task coordinates' columns
    (:func:`read_imported_poses_csv`) solved to joint values (:func:`fpm_sim.model.imported_pose.joint_poses_of`)."""
    poses = read_imported_poses_csv(path, desc, parameter=parameter)
    if poses and isinstance(poses[0], TaskPose):
        from fpm_sim.model.imported_pose import joint_poses_of

        return joint_poses_of(desc, [p for p in poses if isinstance(p, TaskPose)])
    return [p for p in poses if isinstance(p, dict)]


def read_imported_poses_csv(
    path: str | Path, desc: ImportedDescription, *, parameter: str = "poses"
) -> list[TaskPose] | list[dict[str, float]]:
    """An imported model's poses from a CSV as they are written: task poses
    (:func:`fpm_sim.batch.task_sweep.read_task_poses_csv`) where its columns are the task coordinates of the model's
    ``[end_effector]``, else joint values (:func:`_read_joint_columns`, which names what is wrong)."""
    import csv

    from fpm_sim.batch.task_sweep import read_task_poses_csv

    p = Path(path)
    if desc.task and p.is_file():
        with open(p, newline="", encoding="utf-8-sig") as fh:
            columns = {h.strip() for h in next(csv.reader(fh), [])}
        if columns == task_columns(desc):
            return read_task_poses_csv(p, desc, parameter=parameter)
    return _read_joint_columns(p, desc, parameter=parameter)


def _read_joint_columns(p: Path, desc: ImportedDescription, *, parameter: str) -> list[dict[str, float]]:
    """The rows of a CSV with one column per joint name (rad or m), each cell checked (module docstring)."""
    import csv

    from fpm_sim.model.imported import posable_joints

    if not p.is_file():
        raise JointPosesError(f"{p}: no such file", parameter=parameter)
    joints = posable_joints(desc)
    poses = []
    with open(p, newline="", encoding="utf-8-sig") as fh:
        reader = csv.DictReader(fh)
        columns = [(h or "").strip() for h in reader.fieldnames or []]
        unknown = [c for c in columns if c not in joints]
        if unknown or not columns:
            task = f"; or task poses, one column per task coordinate: {', '.join(sorted(task_columns(desc)))}"
            raise JointPosesError(
                f"{p}: column(s) {', '.join(unknown) or '(none)'} name no hinge or slide joint of "
                f"{desc.model_path.name}",
                parameter=parameter,
                hint=f"one column per joint, among: {', '.join(joints)}" + (task if desc.task else ""),
            )
        for r in reader:
            r = {(k or "").strip(): v for k, v in r.items()}
            row = {}
            for c in columns:
                try:
                    v = float(r[c])
                except (TypeError, ValueError):
                    v = math.nan
                if not math.isfinite(v):
                    raise JointPosesError(
                        f"{p}: row {reader.line_num}: joint column {c} is missing or not a finite number",
                        parameter=parameter,
                        hint="give every joint column a value on every row (rad for a hinge, m for a slide)",
                    )
                row[c] = v
            poses.append(row)
    if not poses:
        raise JointPosesError(f"{p}: no rows after the header", parameter=parameter)
    return poses


@dataclass
class JointSweep:
    """Frequencies of an imported model over joint-space poses (:func:`sweep_joints`); a :class:`fpm_sim.Result`."""

    name: str
    joints: tuple[str, ...]
    poses: list[dict[str, float]]
    freq_hz: np.ndarray
    options: ModelOptions | None = None

    @property
    def frequencies_hz(self) -> np.ndarray:
        """``(n_poses, n_modes)`` frequencies (Hz; NaN beyond the model's physical modes)."""
        return self.freq_hz

    def rows(self) -> list[dict[str, Any]]:
        """One row per pose: its joint values (rad or m; the model's reference value where a pose names none),
        f1..fn (Hz)."""
        out = []
        for k, p in enumerate(self.poses):
            row: dict[str, Any] = {"pose": k + 1, **{j: p.get(j, math.nan) for j in self.joints}}
            for m, f in enumerate(self.freq_hz[k]):
                row[f"f{m + 1}_hz"] = float(f)
            out.append(row)
        return out

    def write_csv(self, path: Path) -> None:
        write_csv_rows(path, self.rows())

    def to_dict(self) -> dict[str, Any]:
        rows = [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()} for r in self.rows()]
        return {"config": self.name, "joints": list(self.joints), "grid": "poses", "rows": rows}

    def table(self) -> str:
        n = self.freq_hz.shape[1]
        head = f"{'pose':>4}  " + "  ".join(f"{j:>10}" for j in self.joints)
        head += "  " + "  ".join(f"{'f' + str(m + 1) + ' (Hz)':>10}" for m in range(n))
        lines = [f"{self.name}: {len(self.poses)} joint-space poses", head]
        for k, p in enumerate(self.poses):
            vals = "  ".join(f"{p[j]:>10.4g}" if j in p else f"{'ref':>10}" for j in self.joints)
            lines.append(f"{k + 1:>4}  {vals}  " + "  ".join(f"{f:>10.3f}" for f in self.freq_hz[k]))
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """The frequencies against the pose's number, one line per mode."""
        import matplotlib.pyplot as plt

        if ax is None:
            fig, ax = plt.subplots(figsize=(6.4, 4.0), layout="constrained")
        else:
            fig = ax.figure
        k = np.arange(1, len(self.poses) + 1)
        for m in range(self.freq_hz.shape[1]):
            ax.plot(k, self.freq_hz[:, m], "o-", label=f"f{m + 1}")
        ax.set_xlabel("pose (row of the poses)")
        ax.set_ylabel("frequency (Hz)")
        ax.set_title(f"{self.name}: first frequencies over joint-space poses")
        ax.legend()
        return fig

    def write(self, out_dir: str | Path) -> list[Path]:
        """``sweep_poses.csv`` and ``sweep_poses.png`` in ``out_dir``."""
        paths: list[Path] = write_table_and_figure(self, out_dir, "sweep_poses")
        return paths


def _at_pose(k: int, q: Mapping[str, float], message: str) -> str:
    """An error's message prefixed by the pose it happened at: its number (1-based) and joint values."""
    return f"pose {k + 1} ({', '.join(f'{j} = {v:g}' for j, v in q.items())}): {message}"


def modes_at_joint_poses(
    desc: ImportedDescription,
    poses: Sequence[Mapping[str, float]],
    *,
    options: ModelOptions | None = None,
    n_modes: int | None = 6,
    method: str = "transition_fd",
) -> list[Any]:
    """The modes (:class:`~fpm_sim.linear.modes.ModalResult`) of ``desc`` at each joint-space pose, with ``options``
    as given; an error at a pose names it (1-based) and its joint values."""
    from fpm_sim.linear.analysis import analyse
    from fpm_sim.model.imported import build_imported

    out = []
    for k, q in enumerate(check_joint_poses(desc, poses)):
        try:
            out.append(analyse(build_imported(desc, q, options), method, n_modes))
        except FpmSimError as e:
            e.message = _at_pose(k, q, e.message)
            raise
    return out


def sweep_joints(
    desc: ImportedDescription,
    poses: Sequence[Mapping[str, float]],
    *,
    options: ModelOptions | None = None,
    n_modes: int = 3,
    method: str = "constrained",
) -> JointSweep:
    """The first ``n_modes`` frequencies (Hz) of ``desc`` at every joint-space pose (module docstring).

    ``method``: ``"constrained"`` (the pose loop's: one compiled model posed at every pose,
    :class:`~fpm_sim.batch.imported_pose_model.ImportedPoseModel`, the exact constrained eigen-solve) or any
    method of :func:`fpm_sim.linear.analysis.analyse` on a model built at each pose (``"transition_fd"``: ~100x the
    time)."""
    checked = check_joint_poses(desc, poses)
    opts = replace(options or ModelOptions(), gravity=False, axial=False)
    freq = np.full((len(checked), n_modes), np.nan)
    if method == "constrained":
        from fpm_sim.batch.imported_pose_model import ImportedPoseModel
        from fpm_sim.linear.threads import blas_threads

        loop = ImportedPoseModel(desc, opts)
        with blas_threads():  # one BLAS thread around the dense solves, as the described pose loop
            for k, q in enumerate(checked):
                try:
                    freq[k] = loop.solve(q, n_modes)[0]
                except FpmSimError as e:
                    e.message = _at_pose(k, q, e.message)
                    raise
    else:
        for k, result in enumerate(modes_at_joint_poses(desc, checked, options=opts, n_modes=n_modes, method=method)):
            f = np.asarray(result.frequencies_hz, float)[:n_modes]
            freq[k, : f.size] = f
    joints = tuple(dict.fromkeys(j for q in checked for j in q))
    return JointSweep(name=desc.name, joints=joints, poses=checked, freq_hz=freq, options=opts)
