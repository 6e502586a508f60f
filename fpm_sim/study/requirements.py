"""Frequency requirements: read them from ``fpm-requirements.toml``, evaluate them, report margins.

A requirement is one of three kinds:

- ``min_frequency``: mode ``mode`` (1-based, sorted order) stays at or above ``at_least_hz`` at every pose of
  its pose set, for every payload of its range;
- ``band_exclusion``: none of the lowest ``n_modes`` modes enters ``band_hz = [low, high]`` at any pose, for
  any payload of the range;
- ``match_measurements``: the model's frequencies at the poses of ``measured_csv`` (the form
  :func:`fpm_sim.study.identify.data.read_measured_csv` reads) are within ``tolerance_pct`` of the measured
  ones.

Payload ranges: the payload (``hardware.payload.mass_kg``, inertia kept as in the description) adds a
positive semi-definite term, linear in the mass, to the mass matrix; the pose loop's stiffness does not
depend on it (gravity off). By the Courant-Fischer min-max theorem every natural frequency is then a
continuous, non-increasing function of the payload mass, so over ``[m_lo, m_hi]`` mode ``k`` sweeps exactly
``[f_k(m_hi), f_k(m_lo)]``: evaluating the two ends is the whole range, for both kinds (tested in
``tests/test_testing.py`` with a payload between the ends).

Pose sets (``poses = ...``): ``"workspace"`` (the reachable points of the dense grid, 10 mm, phi 0),
``{ grid = "dense", step_mm = 20, phi_rad = 0.0 }`` (reachable points only: the rest is outside the
workspace), ``{ grid = "paper", reading = "x+" }`` (the study's 25 poses), ``{ file = "poses.csv" }``
(columns ``x_mm,y_mm,phi_rad``, relative to the requirements file), ``{ list = [[x_mm, y_mm, phi_rad], ...] }``.
A pose named explicitly (file or list) that is unreachable or singular is an error, not a skipped point.

An imported model (:mod:`fpm_sim.architecture.imported`) is posed in joint space: its pose sets are
``{ joints_file = "q.csv" }`` (one column per joint, rad for a hinge, m for a slide, as
:func:`~fpm_sim.batch.joint_sweep.read_joint_poses_csv` reads it) or ``{ joints = [{ shoulder = 0.3, elbow = -1.1 },
...] }``; where its description names an ``[end_effector]``, also ``{ file = "poses.csv" }`` with its task
coordinates' columns (solved to joint values, :mod:`fpm_sim.model.imported_pose`). Any other task-space pose set on
it (and a joint-space one on any other machine) is refused naming the requirement.
Its frequencies are :func:`~fpm_sim.batch.joint_sweep.sweep_joints`'s (gravity off, inextensible links).

Sweeps are shared: :class:`SweepCache` keys the pose loop's results on the description, the poses, the
payload and the resolution, and :func:`check_requirements` asks each key once, for the most modes any
requirement needs from it.
"""

from __future__ import annotations

import dataclasses
import math
import time
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import Description, TaskPose
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.joint_sweep import JointSweep, check_joint_poses, read_joint_poses_csv, sweep_joints
from fpm_sim.batch.pose_loop import PoseFrequencies, fast_options, pose_assembly, read_poses_csv
from fpm_sim.batch.task_sweep import TaskSweep, read_task_poses_csv, sweep_task, task_grid
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError, read_text_input
from fpm_sim.kinematics import SINGULAR_TOL, Pose, assemble_many, checked_pose_mm
from fpm_sim.model.options import ModelOptions, resolution_label
from fpm_sim.study.identify.data import read_measured_csv
from fpm_sim.study.identify.problem import predict_observations
from fpm_sim.study.poses import parse_reading, study_poses
from fpm_sim.study.sweep import dense_grid

__all__ = [
    "KINDS",
    "CheckReport",
    "ModeFrequencies",
    "PoseSpec",
    "Requirement",
    "RequirementError",
    "RequirementOutcome",
    "RequirementsFile",
    "SweepCache",
    "check_requirements",
    "effective_requirements",
    "evaluate",
    "load_requirements",
    "options_for",
    "parse_pose_spec",
    "parse_requirements",
    "pose_text",
    "prepare_sweeps",
    "with_payload",
]

KINDS = ("min_frequency", "band_exclusion", "match_measurements")
WORKSPACE_STEP_MM = 10.0
"""Grid step of ``poses = "workspace"`` (the dense sweep's default)."""

_COMMON_KEYS = {"name", "kind", "poses", "payload_kg", "segments"}
_KIND_KEYS = {
    "min_frequency": _COMMON_KEYS | {"at_least_hz", "mode", "probability"},
    "band_exclusion": _COMMON_KEYS | {"band_hz", "n_modes"},
    "match_measurements": {"name", "kind", "payload_kg", "segments", "measured_csv", "tolerance_pct"},
}
_POSE_KEYS = {"grid", "step_mm", "phi_rad", "reading", "file", "list", "min_singularity", "cylinder"}
_POSE_KEYS |= {"joints", "joints_file"}
JOINT_KINDS = ("joints", "joints_file")
"""The pose sets of an imported model (joint space, module docstring)."""
Machine = Manipulator | Description | ImportedDescription
"""What a requirement is evaluated on."""
JointPose = dict[str, float]
"""An imported model's pose: ``{joint: value}`` (rad for a hinge, m for a slide)."""
AnyPose = Pose | TaskPose | JointPose
_CYLINDER_KEYS = {"radius_mm", "z_mm", "step_mm"}
USABLE = ("ok", "near_singular")
"""The pose loop's statuses a requirement evaluates (a workspace grid's other points lie outside the workspace)."""


class RequirementError(FpmSimError):
    """A requirements file or a requirement that cannot be evaluated; the message names the requirement and key."""


def pose_text(pose: AnyPose) -> str:
    """``(x=50.0 mm, y=-20.0 mm, phi=0.000 rad)``; a task pose with its non-zero z and phi; a joint-space pose
    ``(shoulder=0.3, elbow=-1.1)`` (rad or m)."""
    if isinstance(pose, dict):
        return "(" + ", ".join(f"{j}={v:g}" for j, v in pose.items()) + ")"
    if isinstance(pose, TaskPose):
        return pose.label(("x", "y") + (("z",) if pose.z_m else ()) + (("phi",) if pose.phi_rad else ()))
    return pose.label()


def options_for(segments: int | None) -> ModelOptions:
    """The pose loop's options at ``segments`` per link (None: the shared default fidelity)."""
    return fast_options() if segments is None else fast_options(segments=segments)


def with_payload(config: Manipulator, payload_kg: float) -> Manipulator:
    """``config`` with ``hardware.payload.mass_kg = payload_kg`` (inertia kept), validated."""
    hw = config.hardware
    payload = dataclasses.replace(hw.payload, mass_kg=float(payload_kg))
    return config.replace(hardware=dataclasses.replace(hw, payload=payload))


# --------------------------------------------------------------------------------------------- pose sets


@dataclass(frozen=True)
class PoseSpec:
    """How a requirement names its poses (see the module docstring); :meth:`resolve` gives them."""

    kind: str = "workspace"
    step_mm: float = WORKSPACE_STEP_MM
    phi_rad: float = 0.0
    reading: str = "x+"
    file: str | None = None
    points: tuple[tuple[float, float, float], ...] = ()
    min_singularity: float = 0.0
    """Grid points whose singularity measure (0 singular .. 1) is below this are left out (the usable
    workspace); 0 keeps every reachable, non-singular point."""
    radius_mm: float = 0.0
    z_mm: tuple[float, float] = (0.0, 0.0)
    """``kind = "cylinder"`` (a described spatial architecture): points within ``radius_mm`` of the z axis on a
    ``step_mm`` grid in x, y and z, from ``z_mm[0]`` to ``z_mm[1]``."""
    joints: tuple[tuple[tuple[str, float], ...], ...] = ()
    """``kind = "joints"`` (an imported model): each pose's ``(joint, value)`` pairs (``kind = "joints_file"`` reads
    them from ``file``)."""

    def describe(self) -> str:
        if self.kind == "cylinder":
            lo, hi = self.z_mm
            return f"cylinder of radius {self.radius_mm:g} mm, z {lo:g}..{hi:g} mm, {self.step_mm:g} mm grid"
        if self.kind == "workspace":
            far = f", singularity measure >= {self.min_singularity:g}" if self.min_singularity else ""
            return f"reachable workspace, {self.step_mm:g} mm grid, phi {self.phi_rad:g} rad{far}"
        if self.kind == "paper":
            return f"the study's 25 poses (reading {self.reading})"
        if self.kind == "file":
            return f"poses of {self.file}"
        if self.kind == "joints_file":
            return f"joint-space poses of {self.file}"
        if self.kind == "joints":
            return f"{len(self.joints)} listed joint-space poses"
        return f"{len(self.points)} listed poses"

    def resolve(self, config: Machine, where: str) -> list[Pose] | list[TaskPose] | list[JointPose]:
        """The poses; an explicitly named pose that is unreachable or singular raises, naming ``where``. For a
        described architecture, task poses (a grid's unreachable points are left to the evaluation to drop); for an
        imported model, joint-space poses (module docstring)."""
        if isinstance(config, ImportedDescription) or self.kind in JOINT_KINDS:
            return self._joint_poses(config, where)
        if isinstance(config, Description):
            return self._task_poses(config, where)
        if self.kind == "cylinder":
            raise RequirementError(f"{where}.poses: a cylinder is a spatial machine's pose set; the 3RRR is planar")
        if self.kind == "workspace":
            grid = dense_grid(config, step_mm=self.step_mm, phi_rad=self.phi_rad)
            many = assemble_many(
                config.geometry, [p.x_m for p in grid], [p.y_m for p in grid], [p.phi_rad for p in grid]
            )
            # the pose loop's statuses ok / near_singular (pose_assembly): reachable and not singular
            keep = many.reachable & (many.singularity >= max(SINGULAR_TOL, self.min_singularity))
            poses = [p for p, k in zip(grid, keep) if k]
        elif self.kind == "paper":
            poses = [sp.pose for sp in study_poses(parse_reading(self.reading))]
        else:
            if self.kind == "file":
                poses = read_poses_csv(self.file or "", parameter=f"{where}.poses.file")
            else:
                if any(len(p) != 3 for p in self.points):
                    raise RequirementError(f"{where}.poses.list: the 3RRR's poses are [x_mm, y_mm, phi_rad]")
                poses = [checked_pose_mm(x, y, phi, file=where) for x, y, phi in self.points]
            for p in poses:
                status = pose_assembly(config, p)[2]
                if status not in ("ok", "near_singular"):
                    raise RequirementError(
                        f"{where}.poses: pose {pose_text(p)} is {status} for {config.name!r}; remove it or move it "
                        "inside the reachable workspace (fpm-sim sweep shows it)"
                    )
        if not poses:
            raise RequirementError(f"{where}.poses: the pose set ({self.describe()}) is empty; give at least one pose")
        return poses

    def _joint_poses(self, config: Machine, where: str) -> list[JointPose]:
        """The joint-space poses of an imported model; a task-space set on it, or a joint-space one on another
        machine, is refused naming ``where``."""
        if not isinstance(config, ImportedDescription):
            raise RequirementError(
                f"{where}.poses: {self.describe()} are an imported model's joint values; {config.name!r} is posed by "
                "its task coordinates: give a task-space pose set (docs/testing.md)"
            )
        if self.kind == "file" and config.end_effector is not None:  # task poses of its end-effector site
            return read_joint_poses_csv(self.file or "", config, parameter=f"{where}.poses.file")
        if self.kind not in JOINT_KINDS:
            raise RequirementError(
                f"{where}.poses: {self.describe()} is a task-space pose set and {config.name!r} is an imported model "
                'posed by its joints: give poses = { joints_file = "q.csv" } (one column per joint) or '
                "{ joints = [{ NAME = VALUE, ... }, ...] } (rad for a hinge, m for a slide); or name its "
                '[end_effector] and give poses = { file = "poses.csv" } (columns: its task coordinates)'
            )
        if self.kind == "joints_file":
            return read_joint_poses_csv(self.file or "", config, parameter=f"{where}.poses.joints_file")
        return check_joint_poses(config, [dict(p) for p in self.joints], parameter=f"{where}.poses.joints")

    def _task_poses(self, desc: Description, where: str) -> list[TaskPose]:
        """The pose set of a described architecture, in its task coordinates (module docstring)."""
        home = desc.check_poses[0] if desc.check_poses else {}
        if self.kind == "paper":
            raise RequirementError(f"{where}.poses: the study's 25 poses are the 3RRR's; {desc.name!r} has its own")
        if self.kind == "workspace":
            return task_grid(desc, step_mm=self.step_mm, held={"z": home.get("z", 0.0), "phi": self.phi_rad})[0]
        if self.kind == "cylinder":
            lo, hi = sorted(self.z_mm)
            heights = np.arange(lo, hi + 1e-9, self.step_mm)
            poses = []
            for z in heights:
                grid = task_grid(desc, step_mm=self.step_mm, held={"z": z * 1e-3})[0]
                poses += [p for p in grid if math.hypot(p.x_m, p.y_m) <= self.radius_mm * 1e-3 + 1e-12]
            return poses
        if self.kind == "file":
            return read_task_poses_csv(self.file or "", desc, parameter=f"{where}.poses.file")
        coords = list(desc.task)
        out = []
        for i, p in enumerate(self.points):
            if len(p) != len(coords):
                raise RequirementError(f"{where}.poses.list[{i}]: {desc.name!r} takes [{', '.join(coords)}] (mm, rad)")
            v = dict(zip(coords, p))
            out.append(TaskPose.from_mm(v.get("x", 0.0), v.get("y", 0.0), v.get("z", 0.0), v.get("phi", 0.0)))
        return out


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RequirementError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def parse_pose_spec(value: Any, where: str, base: Path) -> PoseSpec:
    if value == "workspace":
        return PoseSpec()
    if not isinstance(value, dict):
        raise RequirementError(
            f'{where} must be "workspace" or a table: {{ grid = "dense", step_mm = 20 }}, {{ grid = "paper" }}, '
            f'{{ file = "poses.csv" }} or {{ list = [[x_mm, y_mm, phi_rad], ...] }}; got {value!r}'
        )
    unknown = set(value) - _POSE_KEYS
    if unknown:
        raise RequirementError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; allowed: {sorted(_POSE_KEYS)}")
    forms = [k for k in ("grid", "file", "list", "cylinder", *JOINT_KINDS) if k in value]
    if len(forms) != 1:
        raise RequirementError(
            f"{where} needs exactly one of grid, file, list, cylinder, joints or joints_file, got {forms or 'none'}"
        )
    if forms[0] in JOINT_KINDS:
        return _joint_spec(value, forms[0], where, base)
    if "cylinder" in value:
        return _cylinder(value["cylinder"], f"{where}.cylinder")
    if "file" in value:
        if not isinstance(value["file"], str):
            raise RequirementError(f"{where}.file must be a path (string), got {value['file']!r}")
        return PoseSpec(kind="file", file=str(base / value["file"]))
    if "list" in value:
        pts = value["list"]
        if not isinstance(pts, list) or not all(isinstance(p, list) and 2 <= len(p) <= 3 for p in pts):
            raise RequirementError(
                f"{where}.list must be a list of poses in the task coordinates ([x_mm, y_mm, phi_rad] for the 3RRR, "
                f"[x_mm, y_mm, z_mm] for a Delta), got {pts!r}"
            )
        points = tuple(tuple(_number(c, f"{where}.list[{i}]") for c in p) for i, p in enumerate(pts))
        return PoseSpec(kind="list", points=points)  # type: ignore[arg-type]
    grid = value["grid"]
    if grid == "dense":
        step = _number(value.get("step_mm", WORKSPACE_STEP_MM), f"{where}.step_mm")
        if step <= 0:
            raise RequirementError(f"{where}.step_mm must be > 0, got {step}")
        far = _number(value.get("min_singularity", 0.0), f"{where}.min_singularity")
        if not 0 <= far < 1:
            raise RequirementError(f"{where}.min_singularity must be in [0, 1), got {far:g}")
        return PoseSpec(
            step_mm=step, phi_rad=_number(value.get("phi_rad", 0.0), f"{where}.phi_rad"), min_singularity=far
        )
    if grid == "paper":
        reading = value.get("reading", "x+")
        parse_reading(str(reading))
        return PoseSpec(kind="paper", reading=str(reading))
    raise RequirementError(f'{where}.grid must be "dense" or "paper", got {grid!r}')


def _joint_spec(value: dict[str, Any], form: str, where: str, base: Path) -> PoseSpec:
    """``{ joints_file = "q.csv" }`` or ``{ joints = [{ NAME = VALUE, ... }, ...] }`` (an imported model's)."""
    extra = sorted(set(value) - {form})
    if extra:
        raise RequirementError(f"{where}: {form} takes no other key; remove {', '.join(extra)}")
    if form == "joints_file":
        if not isinstance(value[form], str):
            raise RequirementError(f"{where}.joints_file must be a path (string), got {value[form]!r}")
        return PoseSpec(kind="joints_file", file=str(base / value[form]))
    rows = value[form]
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) and r for r in rows):
        raise RequirementError(
            f"{where}.joints must be a list of {{ NAME = VALUE, ... }} tables (rad for a hinge, m for a slide), "
            f"got {rows!r}"
        )
    poses = tuple(
        tuple((str(j), _number(v, f"{where}.joints[{i}].{j}")) for j, v in r.items()) for i, r in enumerate(rows)
    )
    return PoseSpec(kind="joints", joints=poses)


def _cylinder(value: Any, where: str) -> PoseSpec:
    """``{ radius_mm = .., z_mm = [low, high], step_mm = .. }``."""
    if not isinstance(value, dict) or set(value) != _CYLINDER_KEYS:
        raise RequirementError(f"{where} must be {{ radius_mm = .., z_mm = [low, high], step_mm = .. }}, got {value!r}")
    z = value["z_mm"]
    if not isinstance(z, list) or len(z) != 2:
        raise RequirementError(f"{where}.z_mm must be [low, high] (mm), got {z!r}")
    radius, step = _number(value["radius_mm"], f"{where}.radius_mm"), _number(value["step_mm"], f"{where}.step_mm")
    if radius <= 0 or step <= 0:
        raise RequirementError(f"{where}: radius_mm and step_mm must be > 0, got {radius:g} and {step:g}")
    lo, hi = (_number(v, f"{where}.z_mm") for v in z)
    return PoseSpec(kind="cylinder", radius_mm=radius, z_mm=(lo, hi), step_mm=step)


# --------------------------------------------------------------------------------------------- requirements


@dataclass(frozen=True)
class Requirement:
    """One requirement (see the module docstring for the kinds); SI units except the named ``_mm`` keys."""

    name: str
    kind: str
    poses: PoseSpec = field(default_factory=PoseSpec)
    payload_kg: tuple[float, ...] = ()
    """Payload masses evaluated (the ends of the range); empty: the description's own payload."""
    segments: int | None = None
    at_least_hz: float = math.nan
    mode: int = 1
    band_hz: tuple[float, float] = (math.nan, math.nan)
    n_modes: int = 6
    measured_csv: str | None = None
    tolerance_pct: float = math.nan
    probability: float | None = None

    def modes_needed(self) -> int:
        return self.mode if self.kind == "min_frequency" else self.n_modes

    def options(self, default_segments: int | None = None) -> ModelOptions:
        seg = self.segments if self.segments is not None else default_segments
        return options_for(seg)

    def describe(self) -> str:
        pay = "" if not self.payload_kg else f", payload {' .. '.join(f'{m:g}' for m in self.payload_kg)} kg"
        if self.kind == "min_frequency":
            return f"f{self.mode} >= {self.at_least_hz:g} Hz over {self.poses.describe()}{pay}"
        if self.kind == "band_exclusion":
            lo, hi = self.band_hz
            return f"no mode 1..{self.n_modes} in {lo:g}..{hi:g} Hz over {self.poses.describe()}{pay}"
        return f"within {self.tolerance_pct:g} % of {Path(self.measured_csv or '').name}{pay}"


def _requirement(t: Any, i: int, base: Path, default_segments: int | None) -> Requirement:
    where = f"requirement[{i}]"
    if not isinstance(t, dict):
        raise RequirementError(f"{where} must be a table ([[requirement]]), got {t!r}")
    name = t.get("name")
    if not isinstance(name, str) or not name.strip():
        raise RequirementError(f"{where}: missing 'name' (a short text naming the requirement)")
    where = f"requirement {name!r}"
    kind = t.get("kind")
    if kind not in KINDS:
        raise RequirementError(f"{where}: unknown kind {kind!r} (key 'kind'); use one of {', '.join(KINDS)}")
    unknown = set(t) - _KIND_KEYS[kind]
    if unknown:
        raise RequirementError(
            f"{where}: unknown key(s) {', '.join(sorted(unknown))} for kind {kind}; allowed: "
            f"{', '.join(sorted(_KIND_KEYS[kind]))}"
        )
    kw: dict[str, Any] = {"name": name, "kind": kind}
    if "poses" in t:
        kw["poses"] = parse_pose_spec(t["poses"], f"{where}.poses", base)
    if "payload_kg" in t:
        raw = t["payload_kg"] if isinstance(t["payload_kg"], list) else [t["payload_kg"]]
        pay = [_number(m, f"{where}.payload_kg") for m in raw]
        if not 1 <= len(pay) <= 2 or any(m < 0 for m in pay):
            raise RequirementError(
                f"{where}.payload_kg must be a mass >= 0 or a range [low, high] (kg), got {t['payload_kg']!r}"
            )
        kw["payload_kg"] = tuple(sorted(set(pay)))
    seg = t.get("segments", default_segments)
    if seg is not None and (isinstance(seg, bool) or not isinstance(seg, int) or seg < 1):
        raise RequirementError(f"{where}.segments must be a whole number >= 1, got {seg!r}")
    kw["segments"] = seg
    if kind == "min_frequency":
        if "at_least_hz" not in t:
            raise RequirementError(f"{where}: missing 'at_least_hz' (the lowest allowed frequency, Hz)")
        kw["at_least_hz"] = _number(t["at_least_hz"], f"{where}.at_least_hz")
        mode = t.get("mode", 1)
        if isinstance(mode, bool) or not isinstance(mode, int) or mode < 1:
            raise RequirementError(f"{where}.mode must be a whole number >= 1 (1 = lowest mode), got {mode!r}")
        kw["mode"] = mode
        if "probability" in t:
            kw["probability"] = _number(t["probability"], f"{where}.probability")
    elif kind == "band_exclusion":
        band = t.get("band_hz")
        if not isinstance(band, list) or len(band) != 2:
            raise RequirementError(f"{where}.band_hz must be [low_hz, high_hz], got {band!r}")
        lo, hi = (_number(b, f"{where}.band_hz") for b in band)
        if not 0 <= lo < hi:
            raise RequirementError(f"{where}.band_hz must satisfy 0 <= low < high, got [{lo:g}, {hi:g}]")
        kw["band_hz"] = (lo, hi)
        n = t.get("n_modes", 6)
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 200:
            raise RequirementError(f"{where}.n_modes must be a whole number in 1..200, got {n!r}")
        kw["n_modes"] = n
    else:
        csv_path = t.get("measured_csv")
        if not isinstance(csv_path, str):
            raise RequirementError(f"{where}: missing 'measured_csv' (a CSV of measured frequencies, see docs)")
        kw["measured_csv"] = str(base / csv_path)
        if "tolerance_pct" not in t:
            raise RequirementError(f"{where}: missing 'tolerance_pct' (allowed model-vs-measurement difference, %)")
        tol = _number(t["tolerance_pct"], f"{where}.tolerance_pct")
        if not tol > 0:
            raise RequirementError(f"{where}.tolerance_pct must be > 0, got {tol:g}")
        kw["tolerance_pct"] = tol
        if len(kw.get("payload_kg", ())) > 1:
            raise RequirementError(f"{where}.payload_kg: measurements were taken at one payload; give one mass")
    return Requirement(**kw)


@dataclass(frozen=True)
class RequirementsFile:
    """The requirements of one file, with its settings (``config`` path, default ``segments``)."""

    path: Path
    requirements: tuple[Requirement, ...]
    config: Path | None = None
    segments: int | None = None

    def __getitem__(self, name: str) -> Requirement:
        for r in self.requirements:
            if r.name == name:
                return r
        raise RequirementError(
            f"{self.path}: no requirement named {name!r}; names: {', '.join(r.name for r in self.requirements)}"
        )


def parse_requirements(data: dict[str, Any], path: Path) -> RequirementsFile:
    """Requirements from the parsed TOML ``data`` of ``path`` (relative paths are relative to its folder)."""
    base = path.parent
    unknown = set(data) - {"settings", "requirement"}
    if unknown:
        raise RequirementError(
            f"{path}: unknown top-level key(s) {', '.join(sorted(unknown))}; use [settings] and [[requirement]]"
        )
    settings = data.get("settings", {})
    if not isinstance(settings, dict) or set(settings) - {"config", "segments"}:
        raise RequirementError(f"{path}: [settings] takes 'config' (a description TOML) and 'segments'; got {settings}")
    seg = settings.get("segments")
    if seg is not None and (isinstance(seg, bool) or not isinstance(seg, int) or seg < 1):
        raise RequirementError(f"{path}: settings.segments must be a whole number >= 1, got {seg!r}")
    config = settings.get("config")
    if config is not None and not isinstance(config, str):
        raise RequirementError(f"{path}: settings.config must be a path (string), got {config!r}")
    reqs = data.get("requirement", [])
    if not isinstance(reqs, list) or not reqs:
        raise RequirementError(f"{path}: no requirement; add [[requirement]] tables (name, kind, ...)")
    try:
        parsed = tuple(_requirement(t, i, base, seg) for i, t in enumerate(reqs))
    except RequirementError as exc:
        raise RequirementError(f"{path}: {exc}") from None
    names = [r.name for r in parsed]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise RequirementError(f"{path}: requirement name(s) used twice: {', '.join(dup)}; names must be unique")
    return RequirementsFile(path, parsed, base / config if config else None, seg)


def load_requirements(path: str | Path) -> RequirementsFile:
    """Read ``fpm-requirements.toml``; :class:`RequirementError` names the file, requirement and key."""
    p = Path(path)
    if p.is_dir():
        raise RequirementError(f"{p} is a folder; give a requirements TOML file (fpm-requirements.toml)")
    try:
        hint = "give fpm-requirements.toml (docs/testing.md)"
        text = read_text_input(p, error=RequirementError, kind="a requirements TOML file", hint=hint)
        data = tomllib.loads(text)
    except FileNotFoundError:
        raise RequirementError(f"{p}: file not found; give a requirements TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise RequirementError(f"{p} is not valid TOML ({exc}); fix the syntax") from None
    return parse_requirements(data, p)


# --------------------------------------------------------------------------------------------- the shared sweeps


def _pose_key(poses: Sequence[AnyPose]) -> tuple[tuple[Any, ...], ...]:
    return tuple(
        tuple(sorted((j, round(v, 12)) for j, v in p.items()))
        if isinstance(p, dict)
        else (round(p.x_m, 9), round(p.y_m, 9), round(p.phi_rad, 9))
        + ((round(p.z_m, 9),) if isinstance(p, TaskPose) else ())
        for p in poses
    )


class SweepCache:
    """The pose loop's results keyed on (description, poses, payload, resolution), each computed once.

    A request for more modes than a cached entry holds recomputes it with the larger count;
    :func:`check_requirements` asks the largest count first. ``computed`` counts the sweeps run.
    """

    def __init__(self) -> None:
        self._store: dict[tuple[Any, ...], Any] = {}
        self.computed = 0

    def frequencies(
        self,
        config: Machine,
        poses: Sequence[AnyPose],
        payload_kg: float | None,
        options: ModelOptions,
        n_modes: int,
    ) -> PoseFrequencies | TaskSweep | JointSweep:
        """The lowest ``n_modes`` frequencies at ``poses`` with ``payload_kg`` (None: the description's); a
        described architecture's come from its own pose loop (:func:`fpm_sim.batch.task_sweep.sweep_task`), an
        imported model's from :func:`fpm_sim.batch.joint_sweep.sweep_joints` at joint-space poses."""
        # a Description holds tables (unhashable): the session's one object stands for it
        who = ("described", id(config)) if isinstance(config, Description | ImportedDescription) else config
        key = (who, _pose_key(poses), payload_kg, options)
        hit = self._store.get(key)
        if hit is not None and hit.frequencies_hz.shape[1] >= n_modes:
            return hit
        if isinstance(config, ImportedDescription):
            joint_poses = [p for p in poses if isinstance(p, dict)]
            hit = sweep_joints(config, joint_poses, options=options, n_modes=n_modes)
        elif isinstance(config, Description):
            task_poses = [p for p in poses if isinstance(p, TaskPose)]
            hit = sweep_task(config, task_poses, options=options, n_modes=n_modes)
        else:
            cfg = config if payload_kg is None else with_payload(config, payload_kg)
            pts = [p for p in poses if isinstance(p, Pose)]
            hit = pose_frequencies(cfg, pts, n_modes=n_modes, options=options, desc="requirements")
        self._store[key] = hit
        self.computed += 1
        return hit


# --------------------------------------------------------------------------------------------- outcomes


@dataclass
class RequirementOutcome:
    """The verdict on one requirement: pass/fail, the worst point and its margin (positive = met)."""

    name: str
    kind: str
    passed: bool
    margin_hz: float
    margin_pct: float
    worst_pose: AnyPose | None
    """The worst pose: the 3RRR's, a task pose, or an imported model's ``{joint: value}`` (rad or m)."""
    worst_mode: int
    worst_value_hz: float
    worst_payload_kg: float | None
    n_points: int
    n_failing: int
    resolution: str
    message: str
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: verdict, margin (Hz, %), worst pose (mm, rad), mode, payload, resolution, message."""
        p = self.worst_pose
        return {
            "name": self.name,
            "kind": self.kind,
            "passed": self.passed,
            "margin_hz": self.margin_hz,
            "margin_pct": self.margin_pct,
            "worst_pose": None
            if p is None
            else dict(p)
            if isinstance(p, dict)
            else {"x_mm": p.x_m * 1e3, "y_mm": p.y_m * 1e3, "phi_rad": p.phi_rad}
            | ({"z_mm": p.z_m * 1e3} if isinstance(p, TaskPose) else {}),
            "worst_mode": self.worst_mode,
            "worst_value_hz": self.worst_value_hz,
            "worst_payload_kg": self.worst_payload_kg,
            "n_points": self.n_points,
            "n_failing": self.n_failing,
            "resolution": self.resolution,
            "message": self.message,
            "seconds": self.seconds,
        }


def _payload_text(m: float | None) -> str:
    return "the description's payload" if m is None else f"payload {m:g} kg"


def _grid_outcome(
    req: Requirement,
    poses: Sequence[AnyPose],
    margins: np.ndarray,
    refs: np.ndarray,
    values: np.ndarray,
    payloads: np.ndarray,
    opts: ModelOptions,
    describe: Any,
) -> RequirementOutcome:
    """The worst entry of ``margins`` ``(n_poses, n_modes)`` (NaN counts as failing: no frequency there).

    ``refs``: what the margin is relative to (%); ``values``: the frequency reported; ``payloads``: its payload
    (NaN: the description's); ``describe(value, margin_hz, margin_pct) -> str``.
    """
    m = np.where(np.isnan(margins), -np.inf, margins)
    i, k = (int(v) for v in np.unravel_index(int(np.argmin(m)), m.shape))
    margin, ref, value = float(m[i, k]), float(refs[i, k]), float(values[i, k])
    pay = None if np.isnan(payloads[i, k]) else float(payloads[i, k])
    n_fail = int(np.sum(np.any(m < 0, axis=1)))
    mode = req.mode if req.kind == "min_frequency" else int(k) + 1
    pct = 100.0 * margin / ref if ref else math.nan
    res = resolution_label(opts)
    passed = n_fail == 0
    head = f"requirement {req.name!r} ({req.kind}: {req.describe()}) {'passed' if passed else 'FAILED'}"
    where = f"mode {mode} at pose {pose_text(poses[i])} with {_payload_text(pay)}"
    detail = describe(value, margin, pct) if math.isfinite(value) else "no frequency computed there (NaN)"
    msg = f"{head}: worst {where}: {detail}; {n_fail} of {len(poses)} poses fail; resolution: {res}"
    return RequirementOutcome(
        req.name, req.kind, passed, margin, pct, poses[i], mode, value, pay, len(poses), n_fail, res, msg
    )


def _payloads(req: Requirement) -> list[float | None]:
    return list(req.payload_kg) if req.payload_kg else [None]


def _needed_payloads(req: Requirement) -> list[float | None]:
    """The payloads a requirement evaluates: the heaviest for ``min_frequency`` (every frequency falls with
    the payload, module docstring), both ends for ``band_exclusion`` (a mode sweeps the interval between)."""
    pays = _payloads(req)
    return pays[-1:] if req.kind == "min_frequency" else pays


def _check_payload(req: Requirement, config: Machine) -> None:
    if req.payload_kg and isinstance(config, Description):
        raise RequirementError(
            f"requirement {req.name!r}: payload_kg varies the 3RRR's hardware.payload; a described architecture "
            "carries its payload as an end-effector lump (remove payload_kg)"
        )
    if req.payload_kg and isinstance(config, ImportedDescription):
        raise RequirementError(
            f"requirement {req.name!r}: payload_kg varies the 3RRR's hardware.payload; an imported model carries "
            "its payload as bodies of its MuJoCo file (remove payload_kg)"
        )


def _check_probability(req: Requirement) -> None:
    if req.probability is not None:
        raise RequirementError(
            f"requirement {req.name!r}: probability= needs a posterior (fpm-sim calibrate); not available yet, "
            "remove 'probability' to check the description's own values"
        )


def evaluate(
    req: Requirement,
    config: Machine,
    *,
    cache: SweepCache | None = None,
    default_segments: int | None = None,
    poses: Sequence[AnyPose] | None = None,
) -> RequirementOutcome:
    """Evaluate one requirement on ``config`` (``poses`` overrides the requirement's pose set, already resolved)."""
    t0 = time.perf_counter()
    cache = cache or SweepCache()
    opts = req.options(default_segments)
    where = f"requirement {req.name!r}"
    if req.kind == "match_measurements":
        out = _evaluate_measurements(req, config, opts)
    else:
        _check_probability(req)
        _check_payload(req, config)
        pts: list[Any] = list(poses) if poses is not None else list(req.poses.resolve(config, where))
        n = req.modes_needed()
        pays = _needed_payloads(req)
        pts, sweeps = _usable(req, config, pts, [cache.frequencies(config, pts, m, opts, n) for m in pays], n)
        light, heavy = sweeps[0], sweeps[-1]
        pay_light, pay_heavy = (math.nan if m is None else m for m in (pays[0], pays[-1]))
        if req.kind == "min_frequency":
            f = heavy[:, req.mode - 1 : req.mode]
            bound = req.at_least_hz
            out = _grid_outcome(
                req,
                pts,
                f - bound,
                np.full_like(f, bound),
                f,
                np.full_like(f, pay_heavy),
                opts,
                lambda v, m, pct: (
                    f"{v:.3f} Hz, {'margin' if m >= 0 else 'short by'} {abs(m):.3f} Hz "
                    f"({abs(pct):.2f} % of {bound:g} Hz)"
                ),
            )
        else:
            lo, hi = req.band_hz
            below, above = lo - light, heavy - hi  # mode k sweeps [heavy, light] over the payload range
            use_light = below >= above
            out = _grid_outcome(
                req,
                pts,
                np.maximum(below, above),
                np.where(use_light, light, heavy),
                np.where(use_light, light, heavy),
                np.where(use_light, pay_light, pay_heavy),
                opts,
                lambda v, m, pct: (
                    f"{v:.3f} Hz, "
                    + (
                        f"{m:.3f} Hz ({pct:.2f} %) outside {lo:g}..{hi:g} Hz"
                        if m >= 0
                        else f"inside {lo:g}..{hi:g} Hz by {-m:.3f} Hz ({-pct:.2f} %: the smallest shift "
                        "that clears the band)"
                    )
                ),
            )
    out.seconds = time.perf_counter() - t0
    return out


def _usable(
    req: Requirement, config: Machine, pts: list[Any], sweeps: list[Any], n: int
) -> tuple[list[Any], list[np.ndarray]]:
    """The poses a requirement evaluates and their lowest ``n`` frequencies per payload. A described architecture's
    grid keeps its reachable, non-singular points (:data:`USABLE`); a pose it names explicitly must be one. An
    imported model's joint-space poses are all evaluated (a pose it cannot be built at raises in its sweep)."""
    if not isinstance(config, Description):
        return pts, [s.frequencies_hz[:, :n] for s in sweeps]
    status = sweeps[0].status
    keep = [i for i, s in enumerate(status) if s in USABLE]
    bad = [i for i, s in enumerate(status) if s not in USABLE]
    if bad and req.poses.kind in ("list", "file"):
        raise RequirementError(
            f"requirement {req.name!r}.poses: pose {pose_text(pts[bad[0]])} is {status[bad[0]]} for {config.name!r}; "
            "remove it or move it inside the reachable workspace (fpm-sim sweep shows it)"
        )
    if not keep:
        raise RequirementError(f"requirement {req.name!r}.poses: no reachable pose in {req.poses.describe()}")
    return [pts[i] for i in keep], [s.frequencies_hz[keep, :n] for s in sweeps]


def _evaluate_measurements(req: Requirement, config: Machine, opts: ModelOptions) -> RequirementOutcome:
    where = f"requirement {req.name!r}"
    if isinstance(config, Description | ImportedDescription):
        raise RequirementError(f"{where}: match_measurements reads the 3RRR's measured poses; not for {config.name!r}")
    ds = read_measured_csv(req.measured_csv or "")
    obs = ds.observations
    if not obs:
        raise RequirementError(f"{where}.measured_csv {req.measured_csv}: no measured frequency in it")
    for o in obs:
        status = pose_assembly(config, o.pose)[2]
        if status not in ("ok", "near_singular"):
            raise RequirementError(
                f"{where}.measured_csv: pose {pose_text(o.pose)} is {status} for {config.name!r}; the measurement "
                "cannot be of this description (check the file's x_mm,y_mm,phi_rad or the description)"
            )
    pay = req.payload_kg[0] if req.payload_kg else None
    cfg = config if pay is None else with_payload(config, pay)
    pred = predict_observations(cfg, obs, options=opts)
    meas = np.array([o.freq_hz for o in obs])
    err_pct = 100.0 * (pred - meas) / meas
    margins = req.tolerance_pct - np.abs(err_pct)
    j = int(np.argmin(np.where(np.isnan(margins), -np.inf, margins)))
    o = obs[j]
    n_fail = int(np.sum(~(margins >= 0)))
    res = resolution_label(opts)
    passed = n_fail == 0
    kind = f" ({o.label})" if o.label else ""
    if np.isnan(pred[j]):
        detail = f"the model has no mode {o.mode}{kind} there (measured {o.freq_hz:.3f} Hz)"
    else:
        detail = (
            f"model {pred[j]:.3f} Hz vs measured {o.freq_hz:.3f} Hz: {pred[j] - o.freq_hz:+.3f} Hz "
            f"({err_pct[j]:+.2f} %), margin {margins[j]:.2f} % of the {req.tolerance_pct:g} % tolerance"
        )
    msg = (
        f"requirement {req.name!r} (match_measurements: {req.describe()}) {'passed' if passed else 'FAILED'}: worst "
        f"mode {o.mode}{kind} at pose {pose_text(o.pose)} with {_payload_text(pay)}: {detail}; {n_fail} of "
        f"{len(obs)} measured frequencies fail; resolution: {res}"
    )
    margin_hz = float(abs(meas[j]) * margins[j] / 100.0) if np.isfinite(margins[j]) else -math.inf
    return RequirementOutcome(
        req.name,
        req.kind,
        passed,
        margin_hz,
        float(margins[j]) if np.isfinite(margins[j]) else -math.inf,
        o.pose,
        o.mode,
        float(pred[j]),
        pay,
        len(obs),
        n_fail,
        res,
        msg,
    )


# --------------------------------------------------------------------------------------------- a whole file


@dataclass
class CheckReport:
    """The outcomes of every requirement of a file (``fpm-sim check``)."""

    source: str
    config_name: str
    outcomes: list[RequirementOutcome]
    sweeps: int = 0
    """Pose-loop sweeps run (shared between requirements with the same poses, payload and resolution)."""
    seconds: float = 0.0
    """Wall time of the whole check, the shared sweeps included (each outcome's time excludes them)."""

    @property
    def passed(self) -> bool:
        return all(o.passed for o in self.outcomes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: source, description, verdict, sweeps run, one entry per requirement."""
        return {
            "source": self.source,
            "config": self.config_name,
            "passed": self.passed,
            "sweeps": self.sweeps,
            "seconds": self.seconds,
            "requirements": [o.to_dict() for o in self.outcomes],
        }

    def table(self) -> str:
        """Requirement, worst pose (mm, rad; an imported model's joint values), mode, margin (Hz, %), pass/fail."""
        w = max(len("requirement"), *(len(o.name) for o in self.outcomes))
        spatial = any(isinstance(o.worst_pose, TaskPose) and o.worst_pose.z_m for o in self.outcomes)
        head = "worst pose (x mm, y mm, z mm)" if spatial else "worst pose (x mm, y mm, phi rad)"
        if any(isinstance(o.worst_pose, dict) for o in self.outcomes):
            head = "worst pose (joints, rad or m)"
        lines = [
            f"{self.source} on {self.config_name}: {sum(o.passed for o in self.outcomes)} of {len(self.outcomes)} "
            f"requirements pass ({self.sweeps} sweeps)",
            f"{'requirement':<{w}}  {head:<34}  {'mode':>4}  {'margin Hz':>10}  {'margin %':>9}  result",
        ]
        for o in self.outcomes:
            p = o.worst_pose
            if isinstance(p, dict):
                pose = pose_text(p)
            else:
                last = f"{p.z_m * 1e3:.1f}" if spatial and isinstance(p, TaskPose) else f"{p.phi_rad:.3f}" if p else ""
                pose = "-" if p is None else f"({p.x_m * 1e3:.1f}, {p.y_m * 1e3:.1f}, {last})"
            lines.append(
                f"{o.name:<{w}}  {pose:<34}  {o.worst_mode:>4}  {o.margin_hz:>10.3f}  {o.margin_pct:>9.2f}  "
                f"{'pass' if o.passed else 'FAIL'}"
            )
        lines += [o.message for o in self.outcomes if not o.passed]
        lines += [f"resolution: {r}" for r in dict.fromkeys(o.resolution for o in self.outcomes)]
        return "\n".join(lines)

    def plot(self, ax: Any = None) -> Any:
        """Horizontal bars of each requirement's margin (%), red where it fails; the ``Figure``."""
        import matplotlib.pyplot as plt

        if ax is None:
            width = 5.0 + 0.07 * max(len(o.name) for o in self.outcomes)  # room for the names
            fig, ax = plt.subplots(figsize=(width, 0.5 * len(self.outcomes) + 1.5), constrained_layout=True)
        else:
            fig = ax.figure
        names = [o.name for o in self.outcomes][::-1]
        vals = [o.margin_pct if math.isfinite(o.margin_pct) else -100.0 for o in self.outcomes][::-1]
        colors = ["tab:green" if o.passed else "tab:red" for o in self.outcomes][::-1]
        bars = ax.barh(names, vals, color=colors)
        ax.bar_label(bars, labels=[f"{v:.1f} %" for v in vals], padding=3, fontsize=8)
        ax.margins(x=0.15)
        ax.axvline(0.0, color="black", lw=1)
        ax.set_xlabel("margin at the worst point (%; < 0 fails)")
        import textwrap

        ax.set_title(textwrap.fill(f"{self.source} on {self.config_name}", int(11 * fig.get_figwidth())), fontsize=8)
        return fig

    def junit_xml(self) -> str:
        """JUnit XML: one ``testcase`` per requirement, a ``failure`` with the message where it fails."""
        suite = ET.Element(
            "testsuite",
            name="fpm-requirements",
            tests=str(len(self.outcomes)),
            failures=str(sum(not o.passed for o in self.outcomes)),
            errors="0",
            time=f"{max(self.seconds, sum(o.seconds for o in self.outcomes)):.3f}",
        )
        for o in self.outcomes:
            case = ET.SubElement(
                suite, "testcase", classname=Path(self.source).stem, name=o.name, time=f"{o.seconds:.3f}"
            )
            if not o.passed:
                fail = ET.SubElement(case, "failure", message=o.message, type=o.kind)
                fail.text = o.message
            else:
                ET.SubElement(case, "system-out").text = o.message
        root = ET.Element("testsuites")
        root.append(suite)
        ET.indent(root)
        return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"

    def write_junit(self, path: str | Path) -> Path:
        """Write :meth:`junit_xml` atomically."""
        from fpm_sim.outputs import atomic_file

        with atomic_file(path) as tmp:
            tmp.write_text(self.junit_xml())
        return Path(path)


def effective_requirements(reqs: RequirementsFile, segments: int | None = None) -> list[Requirement]:
    """The requirements of ``reqs`` with ``segments`` (when given) overriding each one's resolution."""
    return [r if segments is None else dataclasses.replace(r, segments=segments) for r in reqs.requirements]


def prepare_sweeps(
    requirements: Sequence[Requirement],
    config: Machine,
    cache: SweepCache,
    *,
    keep_errors: bool = False,
) -> list[list[Pose] | list[TaskPose] | list[JointPose] | FpmSimError | None]:
    """Resolve every requirement's poses, then run each shared sweep once, for the most modes it is asked for.

    Returns per requirement its poses (None for ``match_measurements``); a requirement whose poses cannot be
    resolved raises, or with ``keep_errors`` gets its :class:`FpmSimError` in its place (the others still run).
    """
    resolved: list[list[Pose] | list[TaskPose] | list[JointPose] | FpmSimError | None] = []
    # requirements naming the same pose set resolve it once
    by_spec: dict[PoseSpec, list[Pose] | list[TaskPose] | list[JointPose]] = {}
    for r in requirements:
        if r.kind == "match_measurements":
            resolved.append(None)
            continue
        try:
            _check_probability(r)
            _check_payload(r, config)
            if r.poses not in by_spec:
                by_spec[r.poses] = r.poses.resolve(config, f"requirement {r.name!r}")
            resolved.append(by_spec[r.poses])
        except FpmSimError as exc:
            if not keep_errors:
                raise
            resolved.append(exc)
    need: dict[tuple[Any, ...], tuple[list[Any], float | None, ModelOptions, int]] = {}
    for r, pts in zip(requirements, resolved):
        if not isinstance(pts, list):
            continue
        opts = r.options()
        for m in _needed_payloads(r):
            key = (_pose_key(pts), m, opts)
            n = max(r.modes_needed(), need[key][3] if key in need else 0)
            need[key] = (pts, m, opts, n)
    for pts, m, opts, n in need.values():
        cache.frequencies(config, pts, m, opts, n)
    return resolved


def check_requirements(
    reqs: RequirementsFile,
    config: Machine,
    *,
    cache: SweepCache | None = None,
    segments: int | None = None,
) -> CheckReport:
    """Evaluate every requirement of ``reqs`` on ``config`` (``segments`` overrides the file's resolution).

    Pose sets are resolved (and checked) first, so that bad input fails before any sweep; each shared sweep
    is then run once, for the most modes the requirements that share it need (:func:`prepare_sweeps`).
    """
    t0 = time.perf_counter()
    cache = cache or SweepCache()
    before = cache.computed
    effective = effective_requirements(reqs, segments)
    try:
        resolved = prepare_sweeps(effective, config, cache)
    except FpmSimError as exc:
        raise RequirementError(f"{reqs.path}: {exc}") from None
    outcomes = [
        evaluate(r, config, cache=cache, poses=pts if isinstance(pts, list) else None)
        for r, pts in zip(effective, resolved)
    ]
    return CheckReport(reqs.path.name, config.name, outcomes, cache.computed - before, time.perf_counter() - t0)


# --------------------------------------------------------------------------------------------- for assertions


@dataclass
class ModeFrequencies:
    """One mode's frequency at each pose of a set (``fpm_sweep.mode(...)``); compares with a number.

    ``mode >= 40.0`` is True when every pose's value is at least 40 Hz (NaN never satisfies it); the pytest
    plugin explains a failed comparison with the worst pose, the shortfall and the resolution.
    """

    mode: int
    poses: list[Any]
    values_hz: np.ndarray
    payload_kg: float | None
    resolution: str

    def _holds(self, op: str, bound: float) -> np.ndarray:
        v = self.values_hz
        ok: np.ndarray = {">=": v >= bound, ">": v > bound, "<=": v <= bound, "<": v < bound}[op]
        return ok

    def __ge__(self, bound: float) -> bool:
        return bool(np.all(self._holds(">=", bound)))

    def __gt__(self, bound: float) -> bool:
        return bool(np.all(self._holds(">", bound)))

    def __le__(self, bound: float) -> bool:
        return bool(np.all(self._holds("<=", bound)))

    def __lt__(self, bound: float) -> bool:
        return bool(np.all(self._holds("<", bound)))

    def explain(self, op: str, bound: float) -> list[str]:
        """Lines saying where ``self <op> bound`` fails: the worst pose, the mode, the margin, the resolution."""
        ok = self._holds(op, bound)
        bad = np.flatnonzero(~ok)
        if not bad.size:
            return [f"f{self.mode} {op} {bound:g} Hz holds at all {len(self.poses)} poses"]
        low = op in (">=", ">")
        gap = np.where(np.isnan(self.values_hz), np.inf, (bound - self.values_hz) if low else (self.values_hz - bound))
        i = int(bad[np.argmax(gap[bad])])
        v = float(self.values_hz[i])
        return [
            f"f{self.mode} {op} {bound:g} Hz fails at {bad.size} of {len(self.poses)} poses "
            f"({_payload_text(self.payload_kg)})",
            f"worst: mode {self.mode} at pose {pose_text(self.poses[i])}: {v:.3f} Hz, "
            f"{abs(v - bound):.3f} Hz ({100 * abs(v - bound) / bound:.2f} %) {'below' if low else 'above'} "
            f"{bound:g} Hz",
            f"resolution: {self.resolution}",
        ]
