"""Identification of a described architecture (``fpm-sim identify --config machine.toml``): dotted paths into its file
fitted to measured natural frequencies at poses in its task coordinates.

The measured file has one column per task coordinate (``x_mm``, ``y_mm``, ``z_mm``, ``phi_rad``), any of
``f1_hz, f2_hz, ...`` (the K-th lowest mode; blank: not measured) and an optional ``sigma_hz`` (one standard deviation
of every frequency of its row; else the file's relative sigma). The free parameters are dotted paths
(:mod:`fpm_sim.architecture.edit`) with bounds (``PATH=lo:hi``; default a factor of 4 either side of the file's
positive value). The fit is bounded least squares from the file's values (SciPy's trust-region reflective) on the
described architecture's own pose loop; the uncertainty is the Gauss-Newton covariance ``(J'J)^-1`` at the optimum.
The 3RRR's global searches, elbow-branch classes, rig tests, workspace prior and cross-validation are its own
(:mod:`fpm_sim.study.identify.engine`).

An imported model (:mod:`fpm_sim.architecture.imported`) is identified the same way, posed in joint space: its
measured file has one column per joint (rad for a hinge, m for a slide; every column other than ``fK_hz`` and
``sigma_hz`` must name a hinge or slide of its model, :func:`read_joint_measured_csv`; or, where it names an
``[end_effector]``, one column per task coordinate, solved to joint values once), its paths are into the imported
TOML (``sections.tube.outer_diameter_m``, ``materials.aluminium.density_kg_m3``), and its frequencies are
:func:`~fpm_sim.batch.joint_sweep.sweep_joints`'s (gravity off, inextensible links, its locked joints locked).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import Description, TaskPose, description_value, with_description_value
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.batch.joint_sweep import sweep_joints, task_columns
from fpm_sim.batch.task_sweep import sweep_task_many
from fpm_sim.errors import FpmSimError
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.identify.data import DEFAULT_SIGMA_PCT, DataError, read_cell, read_csv_rows

__all__ = [
    "DescribedIdentification",
    "TaskMeasurements",
    "check_measured_poses",
    "edited_description",
    "identify_description",
    "parse_free_paths",
    "pose_columns",
    "read_joint_measured_csv",
    "read_task_measured_csv",
    "task_frequencies",
]

Machine = Description | ImportedDescription
"""What is identified: a described architecture, or an imported model (module docstring)."""
MeasuredPose = TaskPose | dict[str, float]
"""A measured pose: task coordinates, or an imported model's ``{joint: value}`` (rad or m)."""
UNREACHED_RESIDUAL = 1e3
"""The residual of a measured frequency the model cannot compute (its pose unreachable or singular there)."""


@dataclass
class TaskMeasurements:
    """Measured frequencies at task poses: ``freq_hz`` and ``sigma_hz`` are ``(pose, mode)``, NaN where not measured."""

    source: str
    poses: Sequence[MeasuredPose]
    """Task poses, or an imported model's joint-space poses."""
    freq_hz: np.ndarray
    sigma_hz: np.ndarray
    lines: list[int] = field(default_factory=list)
    """Each pose's line in its file (for messages)."""

    @property
    def n_modes(self) -> int:
        return int(self.freq_hz.shape[1])


def read_task_measured_csv(
    path: str | Path, desc: Machine, *, sigma_pct: float = DEFAULT_SIGMA_PCT
) -> TaskMeasurements:
    """The measured frequencies of ``path`` (module docstring) at poses in ``desc``'s task coordinates."""
    p = Path(path)
    rows = read_csv_rows(p)
    columns = {c: ("phi_rad" if c == "phi" else f"{c}_mm") for c in desc.task}
    header = set(rows[0][1])
    missing = sorted(set(columns.values()) - header)
    modes = sorted(int(h[1:-3]) for h in header if h.startswith("f") and h.endswith("_hz") and h[1:-3].isdigit())
    if missing or not modes:
        raise DataError(
            f"missing column(s) {', '.join(missing) or 'f1_hz'}",
            file=p,
            hint=f"{desc.name}'s measured file has {','.join(columns.values())}, f1_hz, f2_hz, ... [, sigma_hz]",
        )
    if "mode" in header:
        raise DataError("a mode column (in/out-of-plane labels) is the 3RRR's; give fK_hz as the K-th lowest", file=p)
    if not sigma_pct > 0:
        raise DataError("must be > 0", parameter="sigma_pct", value=sigma_pct, file=p)
    n = max(modes)
    poses, freq, sigma = [], np.full((len(rows), n), np.nan), np.full((len(rows), n), np.nan)
    for i, (line, row) in enumerate(rows):
        vals = {c: read_cell(row.get(col), p, line, col) for c, col in columns.items()}
        if any(math.isnan(v) for v in vals.values()):
            raise DataError("every task coordinate must be given", file=p, row=line)
        poses.append(TaskPose(*(vals.get(c, 0.0) * (1.0 if c == "phi" else 1e-3) for c in ("x", "y", "z", "phi"))))
        _read_frequencies(row, p, line, modes, freq[i], sigma[i], sigma_pct)
    if not np.isfinite(freq).any():
        raise DataError("no measured frequency", file=p, hint="fill f1_hz, f2_hz, ... on some rows")
    return TaskMeasurements(p.name, poses, freq, sigma, [line for line, _ in rows])


def pose_columns(pose: MeasuredPose, task: Sequence[str]) -> dict[str, float]:
    """A measured pose as its file's columns: ``x_mm``, ..., ``phi_rad`` in ``task``'s coordinates, or a joint-space
    pose's joint values (rad or m)."""
    if isinstance(pose, dict):
        return dict(pose)
    return {("phi_rad" if c == "phi" else f"{c}_mm"): pose.value(c) * (1 if c == "phi" else 1e3) for c in task}


def _pose_text(p: MeasuredPose, task: Sequence[str]) -> str:
    """``(x=120 mm, phi=0.1)``, or a joint-space pose's ``(shoulder=0.3, elbow=-1.1)``."""
    if isinstance(p, dict):
        return "(" + ", ".join(f"{j}={v:g}" for j, v in p.items()) + ")"
    return "(" + ", ".join(f"{c}={p.value(c):g}" if c == "phi" else f"{c}={p.value(c) * 1e3:g} mm" for c in task) + ")"


def _task_of(desc: Machine) -> tuple[str, ...]:
    return tuple(desc.task) if isinstance(desc, Description) else ()


def read_joint_measured_csv(
    path: str | Path, desc: ImportedDescription, *, sigma_pct: float = DEFAULT_SIGMA_PCT
) -> TaskMeasurements:
    """The measured frequencies of ``path`` at an imported model's joint-space poses (module docstring): one column
    per joint, ``f1_hz, f2_hz, ...`` and an optional ``sigma_hz``; a column naming no joint is refused by name.

    Where ``desc`` names an ``[end_effector]`` and the file's pose columns are its task coordinates (``x_mm``,
    ``y_mm``, ``phi_rad``, ...), the poses are read as task poses (:func:`read_task_measured_csv`) and solved to
    joint values once (:func:`fpm_sim.model.imported_pose.joint_poses_of`, each solve started from the row before):
    the imported file's numbers are the beams', not the joints', so every parameter value takes the same joint
    values."""
    from fpm_sim.model.imported import posable_joints

    p = Path(path)
    rows = read_csv_rows(p)
    header = list(rows[0][1])
    joints = posable_joints(desc)
    modes = sorted(int(h[1:-3]) for h in header if h.startswith("f") and h.endswith("_hz") and h[1:-3].isdigit())
    cols = [h for h in header if h not in {f"f{k}_hz" for k in modes} | {"sigma_hz"}]
    if desc.task and modes and set(cols) == task_columns(desc):
        from fpm_sim.model.imported_pose import ImportedPoseError, joint_poses_of

        data = read_task_measured_csv(p, desc, sigma_pct=sigma_pct)
        task_poses = [q for q in data.poses if isinstance(q, TaskPose)]
        assert len(task_poses) == len(data.poses), "read_task_measured_csv reads task poses only"  # labels align
        try:
            poses = joint_poses_of(desc, task_poses, labels=[f"{p}: row {n}" for n in data.lines])
        except ImportedPoseError as e:  # a data error: its label names the file and the row
            raise DataError(e.message, hint=e.hint) from e
        return dataclasses.replace(data, poses=poses)
    unknown = [c for c in cols if c not in joints]
    if unknown or not cols or not modes:
        task = f"; or one column per task coordinate ({', '.join(sorted(task_columns(desc)))})" if desc.task else ""
        raise DataError(
            f"column(s) {', '.join(unknown)} name no hinge or slide joint of {desc.model_path.name}"
            if unknown
            else f"missing column(s) {'f1_hz' if not modes else 'of joint values'}",
            file=p,
            hint=f"{desc.name}'s measured file has one column per joint (among {', '.join(joints)}){task}, f1_hz, "
            "f2_hz, ... [, sigma_hz]",
        )
    if not sigma_pct > 0:
        raise DataError("must be > 0", parameter="sigma_pct", value=sigma_pct, file=p)
    n = max(modes)
    poses, freq, sigma = [], np.full((len(rows), n), np.nan), np.full((len(rows), n), np.nan)
    for i, (line, row) in enumerate(rows):
        q = {c: read_cell(row.get(c), p, line, c) for c in cols}
        if any(math.isnan(v) for v in q.values()):
            raise DataError("every joint column must be given", file=p, row=line)
        poses.append(q)
        _read_frequencies(row, p, line, modes, freq[i], sigma[i], sigma_pct)
    if not np.isfinite(freq).any():
        raise DataError("no measured frequency", file=p, hint="fill f1_hz, f2_hz, ... on some rows")
    return TaskMeasurements(p.name, poses, freq, sigma, [line for line, _ in rows])


def _read_frequencies(
    row: Mapping[str, Any], p: Path, line: int, modes: list[int], freq: np.ndarray, sigma: np.ndarray, pct: float
) -> None:
    """A row's ``fK_hz`` (> 0 or blank) into ``freq`` and its ``sigma_hz`` (else ``pct`` % of each) into ``sigma``."""
    for k in modes:
        f = read_cell(row.get(f"f{k}_hz"), p, line, f"f{k}_hz")
        if not (math.isnan(f) or f > 0):
            raise DataError("must be > 0", parameter=f"f{k}_hz", value=f, file=p, row=line)
        freq[k - 1] = f
    s = read_cell(row.get("sigma_hz"), p, line, "sigma_hz")
    if not (math.isnan(s) or s > 0):
        raise DataError("must be > 0", parameter="sigma_hz", value=s, file=p, row=line)
    sigma[:] = s if not math.isnan(s) else freq * pct / 100.0


def parse_free_paths(text: str, desc: Machine) -> dict[str, tuple[float, float]]:
    """``PATH[=lo:hi],...`` as ``{path: (lo, hi)}``: each path read in ``desc``'s file, its value inside its bounds
    (default ``value / 4 .. 4 value`` for a positive value; any other needs bounds)."""
    out: dict[str, tuple[float, float]] = {}
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        path, _, spec = item.partition("=")
        path = path.strip()
        try:
            value = description_value(desc, path)
        except FpmSimError as exc:
            raise FpmSimError(f"field {path!r}: {exc.message}", parameter="free", hint=exc.hint) from None
        if spec:
            try:
                lo, hi = (float(x) for x in spec.split(":"))
            except ValueError:
                raise FpmSimError(
                    "bounds are lo:hi", parameter="free", value=item, hint=f"e.g. {path}=0.004:0.01"
                ) from None
        elif value > 0:
            lo, hi = value / 4.0, value * 4.0
        else:
            raise FpmSimError(
                f"{path} is {value:g} in the file: give its bounds", parameter="free", hint=f"{path}=lo:hi"
            )
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi and lo <= value <= hi):
            raise FpmSimError(
                f"{path}: bounds must hold the file's value {value:g} (lo < hi)", parameter="free", value=item
            )
        out[path] = (lo, hi)
    if not out:
        raise FpmSimError("give at least one dotted path", parameter="free", hint="e.g. sections.bar.height_m")
    return out


@dataclass
class DescribedIdentification:
    """The fitted dotted paths of a described architecture (:func:`identify_description`); a :class:`fpm_sim.Result`."""

    name: str
    paths: list[str]
    start: np.ndarray
    values: np.ndarray
    std: np.ndarray
    bounds: list[tuple[float, float]]
    measured: TaskMeasurements
    model_hz: np.ndarray
    cost: float
    nfev: int
    message: str
    fitted: Machine = field(repr=False)
    diagnosis: dict[str, Any] = field(default_factory=dict)
    """Whether the fit found the machine (:mod:`fpm_sim.study.identify.diagnosis`): ``summary`` (the one-line
    verdict), ``noise_floor``, ``determination``, and ``poses_without_frequency`` (measured poses where the fitted
    machine computes no frequency: unreachable or singular in its working mode)."""

    def rows(self) -> list[dict[str, Any]]:
        """One row per measured frequency: pose (task coordinates), mode, measured, model, error (%)."""
        out = []
        for i, p in enumerate(self.measured.poses):
            for k in range(self.measured.n_modes):
                f = self.measured.freq_hz[i, k]
                if math.isnan(f):
                    continue
                m = self.model_hz[i, k]
                out.append(
                    {
                        **pose_columns(p, _task_of(self.fitted)),
                        "mode": k + 1,
                        "measured_hz": float(f),
                        "model_hz": None if math.isnan(m) else float(m),
                        "error_pct": None if math.isnan(m) else float(100.0 * (m / f - 1.0)),
                    }
                )
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "config": self.name,
            "method": "bounded least squares from the file's values (trf)",
            "parameters": [
                {
                    "path": p,
                    "start": float(s),
                    "value": float(v),
                    "std": None if not math.isfinite(e) else float(e),
                    "bounds": list(b),
                }
                for p, s, v, e, b in zip(self.paths, self.start, self.values, self.std, self.bounds)
            ],
            "cost": self.cost,
            "nfev": self.nfev,
            "message": self.message,
            "data": self.measured.source,
            "rows": self.rows(),
            "diagnosis": self.diagnosis,
        }

    def table(self) -> str:
        head = f"{self.name}: {len(self.paths)} free, {len(self.rows())} measured frequencies, {self.nfev} evaluations"
        lines = [head]
        for p, s, v, e in zip(self.paths, self.start, self.values, self.std):
            lines.append(f"  {p}: {s:.6g} -> {v:.6g} +- {e:.3g}")
        errs = [abs(r["error_pct"]) for r in self.rows() if r["error_pct"] is not None]
        if errs:
            lines.append(f"  mean |error| {np.mean(errs):.3f} %, max {np.max(errs):.3f} %")
        if self.diagnosis:
            lines.append(f"  {self.diagnosis['summary']}")
            und = [p for p, d in self.diagnosis["determination"]["parameters"].items() if not d["determined"]]
            if und:
                lines.append(f"  not determined by the data: {', '.join(und)}")
            if self.diagnosis["poses_without_frequency"]:
                lines.append(
                    "  measured poses where the fitted machine computes no frequency: "
                    + ", ".join(self.diagnosis["poses_without_frequency"])
                )
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Model against measured frequency, one point per measured frequency."""
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(4.5, 4), constrained_layout=True) if ax is None else (ax.figure, ax)
        rows = [r for r in self.rows() if r["model_hz"] is not None]
        x = [r["measured_hz"] for r in rows]
        ax.scatter(x, [r["model_hz"] for r in rows], s=12)
        if x:
            ax.plot([min(x), max(x)], [min(x), max(x)], "k:", lw=0.8)
        ax.set_xlabel("measured (Hz)")
        ax.set_ylabel("fitted model (Hz)")
        ax.set_title(f"{self.name}: fitted {', '.join(self.paths)}", fontsize=8)
        return fig


def edited_description(desc: Machine, values: Mapping[str, float], source: str) -> Machine:
    """``desc`` with each dotted path of ``values`` set (:func:`~fpm_sim.architecture.edit.with_description_value`)."""
    for path, v in values.items():
        desc = with_description_value(desc, path, float(v), source=source)
    return desc


def task_frequencies(desc: Machine, data: TaskMeasurements, options: ModelOptions) -> np.ndarray:
    """``(pose, mode)`` the lowest elastic frequencies (Hz, actuators locked) at the measured poses; NaN where none
    (an imported model that cannot be built at a pose, e.g. a density that leaves an inertial below its beam's)."""
    if isinstance(desc, ImportedDescription):
        joint_poses = [p for p in data.poses if isinstance(p, dict)]
        try:
            return sweep_joints(desc, joint_poses, options=options, n_modes=data.n_modes).freq_hz
        except FpmSimError:
            return np.full(data.freq_hz.shape, np.nan)
    task_poses = [p for p in data.poses if isinstance(p, TaskPose)]
    (sw,) = sweep_task_many([desc], task_poses, options=options, n_modes=data.n_modes)
    return sw.freq_hz


def check_measured_poses(desc: Machine, data: TaskMeasurements, options: ModelOptions) -> None:
    """Every measured frequency is computed by the file's machine (its pose reachable and not singular there, the
    mode among those computed): else the row is named. An imported model that cannot be built at a measured pose
    raises naming the pose."""
    if isinstance(desc, ImportedDescription):
        sweep_joints(desc, [p for p in data.poses if isinstance(p, dict)], options=options, n_modes=data.n_modes)
    model = task_frequencies(desc, data, options)
    for i, line in enumerate(data.lines or range(2, len(data.poses) + 2)):
        bad = np.isfinite(data.freq_hz[i]) & ~np.isfinite(model[i])
        if bad.any():
            raise DataError(
                f"the file's machine computes no f{int(np.flatnonzero(bad)[0]) + 1} at this pose (unreachable or "
                "singular in its working mode)",
                parameter="measured",
                file=data.source,
                row=line,
                hint="check the pose's columns and units (mm, rad) and the description's working mode",
            )


def identify_description(
    desc: Machine,
    data: TaskMeasurements,
    free: Mapping[str, tuple[float, float]],
    *,
    options: ModelOptions | None = None,
    max_nfev: int = 30,
) -> DescribedIdentification:
    """Fit the dotted paths ``free`` (``{path: (lo, hi)}``) of ``desc`` to ``data`` (module docstring)."""
    from scipy.optimize import least_squares

    opts = options or ModelOptions(gravity=False, axial=False)
    paths = list(free)
    start = np.array([description_value(desc, p) for p in paths])
    scale = np.where(start != 0, np.abs(start), [hi - lo for lo, hi in free.values()])
    lo = np.array([b[0] for b in free.values()])
    hi = np.array([b[1] for b in free.values()])
    measured = np.isfinite(data.freq_hz)
    check_measured_poses(desc, data, opts)
    source = f"identified: {data.source}, fpm-sim identify (bounded least squares)"

    def values_of(u: np.ndarray) -> np.ndarray:
        return np.clip(start + u * scale, lo, hi)

    def residuals(u: Sequence[float]) -> np.ndarray:
        edited = edited_description(desc, dict(zip(paths, values_of(np.asarray(u)))), source)
        model = task_frequencies(edited, data, opts)
        r = (model[measured] - data.freq_hz[measured]) / data.sigma_hz[measured]
        return np.where(np.isfinite(r), r, UNREACHED_RESIDUAL)

    fit = least_squares(
        residuals,
        np.zeros(len(paths)),
        bounds=((lo - start) / scale, (hi - start) / scale),
        method="trf",
        diff_step=1e-5,
        max_nfev=max_nfev,
    )
    values = values_of(fit.x)
    try:
        cov = np.linalg.inv(fit.jac.T @ fit.jac)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None)) * scale
    except np.linalg.LinAlgError:
        std = np.full(len(paths), np.inf)
    fitted = edited_description(desc, dict(zip(paths, values)), source)
    model_hz = task_frequencies(fitted, data, opts)
    return DescribedIdentification(
        name=desc.name,
        paths=paths,
        start=start,
        values=values,
        std=std,
        bounds=[(float(a), float(b)) for a, b in zip(lo, hi)],
        measured=data,
        model_hz=model_hz,
        cost=float(fit.cost),
        nfev=int(fit.nfev),
        message=str(fit.message),
        fitted=fitted,
        diagnosis=_diagnosis(fit.fun, fit.jac / scale[None, :], hi - lo, paths, data, model_hz, _task_of(fitted)),
    )


def _diagnosis(
    residuals: np.ndarray,
    jac: np.ndarray,
    width: np.ndarray,
    paths: list[str],
    data: TaskMeasurements,
    model_hz: np.ndarray,
    task: Sequence[str],
) -> dict[str, Any]:
    """The noise-floor test and what the data determine (:mod:`fpm_sim.study.identify.diagnosis`; ``jac`` in the
    paths' units), and the measured poses where the fitted machine computes no frequency."""
    from fpm_sim.study.identify.diagnosis import determination, noise_floor

    floor = noise_floor(residuals, len(paths))
    lost = [
        _pose_text(p, task)
        for i, p in enumerate(data.poses)
        if (np.isfinite(data.freq_hz[i]) & ~np.isfinite(model_hz[i])).any()
    ]
    return {
        "summary": floor.summary(),
        "noise_floor": floor.to_dict(),
        "determination": determination(jac, np.where(width > 0, width, 1.0), paths).to_dict(),
        "poses_without_frequency": lost,
    }
