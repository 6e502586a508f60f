"""Design studies: the pose loop over every design x pose, as one xarray Dataset with a per-design summary.

A design is the manipulator description with some dotted fields changed (``section.thickness_m``,
``hardware.payload.mass_kg``, ``geometry.distal_length_m``, ...), or a described architecture with some dotted paths
of its file changed (``sections.bar.height_m``, ``chains.left.proximal.length_m``: :mod:`fpm_sim.architecture.edit`).
:func:`design_study` runs the pose loop's chunks for all designs on the engine (:mod:`fpm_sim.batch.engine`: Dask,
streamed to disk, resumable): every task is one design and one chunk of poses, and every worker compiles one model
per design (:class:`fpm_sim.batch.pose_loop.PoseModel`) and re-poses it. A described architecture's designs run on
its own pose loop over task poses (:func:`fpm_sim.batch.task_sweep.sweep_task_many`, :mod:`fpm_sim.designs.described`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import math
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from fpm_sim.architecture import Description, TaskPose, machine_parameter, with_machine_parameter
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import (
    STATUS_UNREACHABLE,
    PoseFrequencies,
    fast_options,
    read_poses_csv,
    solve_configs,
)
from fpm_sim.config import Manipulator
from fpm_sim.designs.described import description_link_mass_kg, description_moving_mass_kg, solve_descriptions
from fpm_sim.designs.imported import (
    imported_joint_poses,
    imported_link_mass_kg,
    imported_moving_mass_kg,
    solve_imported,
)
from fpm_sim.errors import FpmSimError, FpmSimWarning, read_text_input
from fpm_sim.figures import wrap_title
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions, resolution_footer

__all__ = [
    "COMPUTED",
    "DesignError",
    "DesignResult",
    "apply_design",
    "design_study",
    "factorial",
    "link_mass_kg",
    "moving_mass_kg",
    "parse_spec",
    "parse_vary",
    "read_designs_csv",
    "read_poses_csv",
    "write_netcdf",
]

COMPUTED = ("ok", "near_singular")
"""Statuses whose frequencies are computed."""


M = TypeVar("M", Manipulator, Description, ImportedDescription)
P = TypeVar("P", Pose, TaskPose)


class DesignError(FpmSimError):
    """A design study was asked for something it cannot do (bad field, value, spec or file)."""


# ----------------------------------------------------------------------------------------------- inputs


def parse_spec(spec: str, *, name: str = "SPEC", parameter: str | None = None) -> list[float]:
    """Values of ``a,b,c`` (a list) or ``start:stop:count`` (``count`` values from ``start`` to ``stop``)."""
    text = spec.strip()
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
            if count < 1:
                raise ValueError
            return [float(v) for v in np.linspace(start, stop, count)]
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise DesignError(
            f"{name} {spec!r}: give a list a,b,c or a range start:stop:count (count an integer >= 1)",
            parameter=parameter,
        ) from None
    if not values:
        raise DesignError(
            f"{name} {spec!r} is empty: give a list a,b,c or a range start:stop:count", parameter=parameter
        )
    if not all(math.isfinite(v) for v in values):
        raise DesignError(f"{name} {spec!r}: every value must be finite", parameter=parameter)
    return values


Machine = Manipulator | Description | ImportedDescription
"""What a design study varies: the 3RRR's description, a described architecture or an imported model."""
FILE_FORMS = (Description, ImportedDescription)
"""The forms whose fields are dotted paths into their own file (:mod:`fpm_sim.architecture.edit`)."""
JointPose = Mapping[str, float]
"""An imported model's pose by joint values (``{joint: rad or m}``)."""


def _check_field(config: Machine, name: str, parameter: str = "vary") -> None:
    """Raise :class:`DesignError` naming ``parameter`` (``vary`` or ``designs``) unless ``name`` is a settable
    numeric field of ``config``."""
    try:
        machine_parameter(config, name)
    except FpmSimError as exc:
        where = (
            "fields are dotted paths into the description's file (docs/architectures.md, Dotted paths)"
            if isinstance(config, Description)
            else "fields are dotted paths into the imported description's file (docs/import.md)"
            if isinstance(config, ImportedDescription)
            else "fields are dotted paths of the description (see `fpm-sim config`)"
        )
        raise DesignError(
            f"field {name!r}: {exc.message}",
            parameter=parameter,
            hint=f"{exc.hint + '; ' if exc.hint else ''}{where}",
        ) from None


def parse_vary(items: Sequence[str], config: Machine) -> dict[str, list[float]]:
    """``["FIELD=SPEC", ...]`` (the ``vary`` items) as ``{field: values}``, fields checked on ``config``."""
    out: dict[str, list[float]] = {}
    for item in items:
        if "=" not in item:
            raise DesignError(
                "write FIELD=SPEC", parameter="vary", value=item, hint="e.g. section.thickness_m=0.005:0.03:6"
            )
        name, spec = (s.strip() for s in item.split("=", 1))
        _check_field(config, name)
        if name in out:
            raise DesignError(f"{name} given twice", parameter="vary", hint="give all its values in one SPEC")
        out[name] = parse_spec(spec, name=name, parameter="vary")
        if isinstance(config, FILE_FORMS):  # each value read into the file now (cheap), before any warning or work
            for v in out[name]:
                apply_design(config, {name: v})  # type: ignore[type-var]
    return out


def factorial(vary: Mapping[str, Sequence[float]]) -> list[dict[str, float]]:
    """Every combination of the values (the first field varies slowest)."""
    names = list(vary)
    return [dict(zip(names, combo)) for combo in itertools.product(*(vary[n] for n in names))]


def read_designs_csv(path: str | Path, config: Machine) -> list[dict[str, float]]:
    """Designs from a CSV file: one column per dotted field, one row per design."""
    p = Path(path)
    if not p.is_file():
        raise DesignError(f"{p}: no such file", parameter="designs")
    hint = "give a CSV file of designs: a header of dotted fields, then one design per row"
    text = read_text_input(p, error=DesignError, parameter="designs", kind="a CSV file", hint=hint, newline="")
    reader = csv.reader(io.StringIO(text, newline=""))
    header = [h.strip() for h in next(reader, [])]
    rows = [r for r in reader if any(c.strip() for c in r)]
    if not header or not rows:
        raise DesignError(
            f"{p}: no rows", parameter="designs", hint="write a header of dotted fields, then one design per row"
        )
    if len(set(header)) != len(header) or "" in header:
        raise DesignError(f"{p}: the header {header} has an empty or repeated column", parameter="designs")
    for name in header:
        _check_field(config, name, "designs")
    designs: list[dict[str, float]] = []
    for line, r in enumerate(rows, start=2):
        if len(r) != len(header):
            raise DesignError(f"{p}: row {line} has {len(r)} cells for {len(header)} columns", parameter="designs")
        try:
            values = [float(v) for v in r]
        except ValueError:
            raise DesignError(
                f"{p}: row {line}: every cell must be a number (SI units, as the field's name says)",
                parameter="designs",
                value=r,
            ) from None
        if not all(math.isfinite(v) for v in values):
            raise DesignError(f"{p}: row {line}: cells must be finite", parameter="designs", value=r)
        designs.append(dict(zip(header, values)))
        if isinstance(config, FILE_FORMS):  # each row read into the file now (cheap), before any work
            apply_design(config, designs[-1])  # type: ignore[type-var]
    return designs


def apply_design(config: M, values: Mapping[str, float]) -> M:
    """``config`` with the dotted fields set (validated; a name that says what changed)."""
    out = config
    for name, v in values.items():
        try:
            out = with_machine_parameter(out, name, float(v))
        except FpmSimError as exc:
            if isinstance(config, FILE_FORMS):  # the file's own error, naming the path
                raise DesignError(exc.message, parameter=name, value=v, hint=exc.hint) from None
            raise DesignError(f"design {dict(values)}: {name} = {v} is not valid ({exc})") from None
        except ValueError as exc:
            raise DesignError(f"design {dict(values)}: {name} = {v} is not valid ({exc})") from None
    label = ", ".join(f"{k}={v:g}" for k, v in values.items())
    return dataclasses.replace(out, name=f"{config.name} [{label}]") if label else out


def link_mass_kg(config: Machine) -> float:
    """Mass of the six links (kg): section area x density x link lengths (a described architecture: of all its
    links; an imported model: of its flexible links' beams, :func:`fpm_sim.designs.imported.imported_link_mass_kg`)."""
    if isinstance(config, Description):
        return description_link_mass_kg(config)
    if isinstance(config, ImportedDescription):
        return imported_link_mass_kg(config)
    g = config.geometry
    p, d = g.proximal_length_m, g.distal_length_m
    if isinstance(p, (tuple, list)) or isinstance(d, (tuple, list)):
        total_length_m = sum(g.proximal_length_per_chain) + sum(g.distal_length_per_chain)  # per-chain lengths
    else:
        total_length_m = 3.0 * (p + d)
    return total_length_m * config.section.area_m2 * config.material.density_kg_m3


def moving_mass_kg(config: Machine) -> float:
    """Everything that moves with the platform or the links (kg): links, joint hardware, platform, payload
    (the motor flanges turn in place and are left out; a described architecture: its lumps but those on the
    ground, :func:`fpm_sim.designs.described.description_moving_mass_kg`; an imported model: its bodies that a joint
    separates from the world, :func:`fpm_sim.designs.imported.imported_moving_mass_kg`)."""
    if isinstance(config, Description):
        return description_moving_mass_kg(config)
    if isinstance(config, ImportedDescription):
        return imported_moving_mass_kg(config)
    hw = config.hardware
    return (
        link_mass_kg(config)
        + 3.0 * (hw.elbow_joint.mass_kg + hw.platform_joint.mass_kg)
        + hw.platform.mass_kg
        + hw.payload.mass_kg
    )


# ----------------------------------------------------------------------------------------------- result


@dataclass
class DesignResult:
    """Frequencies over designs x poses (:func:`design_study`).

    Attributes
    ----------
    config
        The base description (the 3RRR's or a described architecture).
    fields
        The varied dotted fields (SI units in their names).
    designs
        One ``{field: value}`` per design.
    factorial
        The designs are the full factorial of :attr:`levels`.
    levels
        ``{field: values}`` of a factorial study (in order), else each field's distinct values.
    poses
        The poses (shared by all designs): the 3RRR's, a described architecture's task poses, or an imported model's
        task poses or joint values (``{joint: rad or m}``, where it was posed in joint space).
    frequencies_hz
        ``(n_designs, n_poses, n_modes)``; NaN where not computed.
    in_plane
        ``(n_designs, n_poses)``: mode 1's share of strain energy in in-plane springs (NaN on a described
        architecture: not computed there).
    singularity
        ``(n_designs, n_poses)`` singularity measure (NaN where unreachable; a described architecture: the smaller of
        its type 1 and type 2 measures).
    status
        ``(n_designs, n_poses)`` ``ok``, ``near_singular``, ``singular`` or ``unreachable``.
    f_min_hz
        Threshold of the workspace share in the summary (``None``: not computed).
    link_mass_kg, moving_mass_kg
        ``(n_designs,)``.
    elapsed_s
        Wall time of the study.
    """

    config: Machine
    fields: list[str]
    designs: list[dict[str, float]]
    factorial: bool
    levels: dict[str, list[float]]
    poses: Sequence[Pose | TaskPose | JointPose]
    frequencies_hz: np.ndarray
    in_plane: np.ndarray
    singularity: np.ndarray
    status: np.ndarray
    f_min_hz: float | None
    link_mass_kg: np.ndarray
    moving_mass_kg: np.ndarray
    elapsed_s: float = 0.0
    options: ModelOptions = field(default_factory=fast_options)

    @property
    def n_modes(self) -> int:
        return int(self.frequencies_hz.shape[2])

    @property
    def spatial(self) -> bool:
        """The poses have a z coordinate (a spatial described architecture, an imported model posed in x, y, z)."""
        return isinstance(self.config, FILE_FORMS) and "z" in self.config.task

    @property
    def joint_space(self) -> bool:
        """The poses are an imported model's joint values (no task coordinates: no maps, no weakest x, y)."""
        return bool(self.poses) and isinstance(self.poses[0], Mapping)

    def pose_columns(self) -> dict[str, list[float]]:
        """The poses' columns: ``x_mm``, ``y_mm`` (``z_mm`` where spatial), ``phi_rad``; or, posed in joint space, one
        column per joint named (rad or m; NaN where a pose names none)."""
        if self.joint_space:
            joints = dict.fromkeys(j for p in self.poses for j in p)  # type: ignore[union-attr]
            return {j: [float(p.get(j, math.nan)) for p in self.poses] for j in joints}  # type: ignore[union-attr]
        poses: list[Any] = list(self.poses)
        return {
            "x_mm": [round(p.x_m * 1e3, 6) for p in poses],
            "y_mm": [round(p.y_m * 1e3, 6) for p in poses],
            **({"z_mm": [round(getattr(p, "z_m", 0.0) * 1e3, 6) for p in poses]} if self.spatial else {}),
            "phi_rad": [p.phi_rad for p in poses],
        }

    def pose_frequencies(self, design: int) -> PoseFrequencies:
        """Design ``design``'s result as the pose loop returns it."""
        return PoseFrequencies(
            poses=list(self.poses),  # type: ignore[arg-type]
            frequencies_hz=self.frequencies_hz[design],
            in_plane=np.column_stack([self.in_plane[design]] + [np.full(len(self.poses), np.nan)] * (self.n_modes - 1)),
            singularity=self.singularity[design],
            status=list(self.status[design]),
        )

    def summary(self) -> list[dict[str, Any]]:
        """Per design: min and mean f1 over the computed poses (``ok`` and ``near_singular``), min f1 over the
        ``ok`` poses (away from singularities, where f1 does not dive to zero), the share of the reachable poses
        with ``f1 >= f_min_hz`` (singular poses count as reachable and below), the weakest pose, counts, link
        and moving mass."""
        rows = []
        for d, values in enumerate(self.designs):
            st = self.status[d]
            computed = np.isin(st, COMPUTED) & np.isfinite(self.frequencies_hz[d, :, 0])
            reachable = st != STATUS_UNREACHABLE
            f1 = self.frequencies_hz[d, computed, 0]
            f1_ok = self.frequencies_hz[d, (st == "ok") & computed, 0]
            share = math.nan
            if self.f_min_hz is not None and reachable.any():
                share = float(np.sum(f1 >= self.f_min_hz) / reachable.sum())
            worst = int(np.flatnonzero(computed)[np.argmin(f1)]) if f1.size else None
            where = self._weakest(worst)
            row: dict[str, Any] = dict(values)
            row.update(
                {
                    "min_f1_hz": float(f1.min()) if f1.size else math.nan,
                    "mean_f1_hz": float(f1.mean()) if f1.size else math.nan,
                    "min_f1_ok_hz": float(f1_ok.min()) if f1_ok.size else math.nan,
                    "share_above_f_min": share,
                    "computed_poses": int(computed.sum()),
                    "reachable_poses": int(reachable.sum()),
                    **where,
                    "link_mass_kg": float(self.link_mass_kg[d]),
                    "moving_mass_kg": float(self.moving_mass_kg[d]),
                }
            )
            rows.append(row)
        return rows

    def _weakest(self, worst: int | None) -> dict[str, float]:
        """The summary's weakest pose: ``weakest_x_mm``, ``weakest_y_mm`` (NaN when none is computed); joint poses:
        ``weakest_pose`` (its row, 1-based)."""
        if self.joint_space:
            return {"weakest_pose": math.nan if worst is None else worst + 1}
        cols = self.pose_columns()
        return {f"weakest_{c}": math.nan if worst is None else cols[c][worst] for c in ("x_mm", "y_mm")}

    def table(self) -> str:
        """The summary as a text table."""
        rows = self.summary()
        share_head = f"share>={self.f_min_hz:g}Hz" if self.f_min_hz is not None else "share"
        heads = [*self.fields, "min f1 Hz", "min f1 ok Hz", "mean f1 Hz", share_head, "poses", "links kg", "moving kg"]
        width = [max(len(h), 12) for h in heads]
        lines = ["  ".join(h.rjust(w) for h, w in zip(heads, width))]
        for r in rows:
            cells = [f"{r[f]:.6g}" for f in self.fields] + [
                f"{r['min_f1_hz']:.2f}",
                f"{r['min_f1_ok_hz']:.2f}",
                f"{r['mean_f1_hz']:.2f}",
                "-" if math.isnan(r["share_above_f_min"]) else f"{100 * r['share_above_f_min']:.1f} %",
                f"{r['computed_poses']}/{len(self.poses)}",
                f"{r['link_mass_kg']:.4f}",
                f"{r['moving_mass_kg']:.4f}",
            ]
            lines.append("  ".join(c.rjust(w) for c, w in zip(cells, width)))
        lines.append(resolution_footer(self.options))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: fields, designs, poses, summary, and the frequencies per design and pose."""
        return {
            "config": self.config.name,
            "fields": list(self.fields),
            "designs": [dict(d) for d in self.designs],
            "factorial": self.factorial,
            "f_min_hz": self.f_min_hz,
            "n_modes": self.n_modes,
            **self._poses_dict(),
            "summary": self.summary(),
            "frequencies_hz": np.where(np.isfinite(self.frequencies_hz), self.frequencies_hz, np.array(None)).tolist(),
            "status": self.status.tolist(),
            "elapsed_s": self.elapsed_s,
        }

    def _poses_dict(self) -> dict[str, Any]:
        """:meth:`to_dict`'s poses: ``poses_mm_rad`` (x, y, phi; ``poses_z_mm`` where spatial), or ``poses_joints``
        (the joint values, posed in joint space)."""
        if self.joint_space:
            joint_poses: list[Any] = list(self.poses)
            return {"poses_joints": [dict(p) for p in joint_poses]}
        poses: list[Any] = list(self.poses)
        return {
            "poses_mm_rad": [[p.x_m * 1e3, p.y_m * 1e3, p.phi_rad] for p in poses],
            **({"poses_z_mm": [p.z_m * 1e3 for p in poses if isinstance(p, TaskPose)]} if self.spatial else {}),
        }

    # ------------------------------------------------------------------------------------------- dataset

    @property
    def dataset(self) -> Any:
        """:meth:`to_xarray` (the name this result has had)."""
        return self.to_xarray()

    def to_xarray(self) -> Any:
        """The frequencies over designs x poses (:func:`fpm_sim.results.frequencies_dataset`): ``freq_hz`` with
        dimensions each varied field (a factorial study) or ``design`` (a list of designs), ``pose`` and
        ``mode``; ``status`` per design and pose; pose coordinates ``x_mm``, ``y_mm``, ``phi_rad``; variables
        ``in_plane_mode1``, ``singularity``, ``link_mass_kg``, ``moving_mass_kg``."""
        from fpm_sim.results import frequencies_dataset

        if self.joint_space:  # no task coordinates: NaN, the joint values as coordinates of their own
            nan = [math.nan] * len(self.poses)
            where, extra = {"x_mm": nan, "y_mm": nan, "phi_rad": nan}, self.pose_columns()
        else:
            poses: list[Any] = list(self.poses)
            where = {"x_mm": [p.x_m * 1e3 for p in poses], "y_mm": [p.y_m * 1e3 for p in poses]}
            where["phi_rad"] = [p.phi_rad for p in poses]
            extra = {"z_mm": [getattr(p, "z_m", 0.0) * 1e3 for p in poses]} if self.spatial else {}
        ds = frequencies_dataset(
            self.frequencies_hz,
            **where,
            status=self.status,
            leading={"design": np.arange(len(self.designs))},
            coords={
                **{f: ("design", np.array([d[f] for d in self.designs])) for f in self.fields},
                **{c: ("pose", v) for c, v in extra.items()},
            },
            data_vars={
                "in_plane_mode1": (("design", "pose"), self.in_plane),
                "singularity": (("design", "pose"), self.singularity),
                "link_mass_kg": ("design", self.link_mass_kg),
                "moving_mass_kg": ("design", self.moving_mass_kg),
            },
            attrs={
                "config": self.config.name,
                "f_min_hz": math.nan if self.f_min_hz is None else self.f_min_hz,
                "segments": int(self.options.segments or 0),
                "axial": int(self.options.axial),
                "fields": ",".join(self.fields),
            },
        )
        if self.factorial and self.fields:
            if len(self.fields) == 1:
                ds = ds.swap_dims({"design": self.fields[0]}).drop_vars("design")
            else:
                ds = ds.set_index(design=self.fields).unstack("design")
            ds = ds.transpose(*self.fields, "pose", "mode")
            for name in ("link_mass_kg", "moving_mass_kg"):
                ds[name] = ds[name].transpose(*self.fields)
        return ds

    # ------------------------------------------------------------------------------------------- output

    def tidy_rows(self) -> list[dict[str, Any]]:
        """One row per design and pose: the varied fields, ``x_mm, y_mm, phi_rad`` (posed in joint space: the joint
        values), ``status, singularity, f1_hz, ..., in_plane_mode1``."""
        rows = []
        cols = self.pose_columns()
        for d, values in enumerate(self.designs):
            for i in range(len(self.poses)):
                row: dict[str, Any] = dict(values)
                row.update(
                    {
                        **{c: v[i] for c, v in cols.items()},
                        "status": str(self.status[d, i]),
                        "singularity": float(self.singularity[d, i]),
                    }
                )
                for k in range(self.n_modes):
                    row[f"f{k + 1}_hz"] = float(self.frequencies_hz[d, i, k])
                row["in_plane_mode1"] = float(self.in_plane[d, i])
                rows.append(row)
        return rows

    def write(self, out_dir: str | Path, *, figures: bool = True) -> list[Path]:
        """Write ``design.nc`` (h5netcdf), ``design.csv`` (tidy), ``summary.csv`` and the figures."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = [out / "design.nc", out / "design.csv", out / "summary.csv"]
        write_netcdf(self.dataset, paths[0])
        _write_csv(paths[1], self.tidy_rows())
        _write_csv(paths[2], self.summary())
        if figures:
            import matplotlib.pyplot as plt

            for name, fig in (
                ("design_min_f1.png", self.plot()),
                ("design_maps.png", self.plot_maps()),
                ("design_tradeoff.png", self.plot_tradeoff()),
            ):
                if fig is None:
                    continue
                # tight: the maps keep their aspect ratio, which the constrained layout cannot fit to the height
                fig.savefig(out / name, dpi=110, bbox_inches="tight", pad_inches=0.08)
                plt.close(fig)
                paths.append(out / name)
        return paths

    # ------------------------------------------------------------------------------------------- figures

    def plot(self, ax: Any = None) -> Any:
        """Minimum f1 over the workspace against each varied field (one panel per field, one line per value
        of the other fields; solid: the ``ok`` poses, dotted: near-singular poses included); with ``ax`` only
        the first field, on that axes. Returns the ``Figure``."""
        import matplotlib.pyplot as plt
        from matplotlib.ticker import MaxNLocator

        rows = self.summary()
        fields = self.fields or ["design"]
        if ax is None:
            fig, axes = plt.subplots(1, len(fields), figsize=(5 * len(fields), 3.8), constrained_layout=True)
            axes = np.atleast_1d(axes)
        else:
            fig, axes = ax.figure, np.array([ax])
        for a, f in zip(axes, fields):
            others = [o for o in self.fields if o != f]
            groups: dict[tuple, list[dict[str, Any]]] = {}
            for i, r in enumerate(rows):
                groups.setdefault(tuple(r[o] for o in others), []).append({**r, "design": i})
            for key, grp in groups.items():
                grp = sorted(grp, key=lambda r: r[f])
                label = ", ".join(f"{o}={v:g}" for o, v in zip(others, key)) or None
                (line,) = a.plot([r[f] for r in grp], [r["min_f1_ok_hz"] for r in grp], "o-", label=label)
                a.plot([r[f] for r in grp], [r["min_f1_hz"] for r in grp], ".:", color=line.get_color(), lw=0.8)
            if self.f_min_hz is not None:
                a.axhline(self.f_min_hz, color="red", ls="--", lw=1, label=f"f_min {self.f_min_hz:g} Hz")
            a.set_xlabel(f)
            a.xaxis.set_major_locator(MaxNLocator(nbins=5))  # SI values of many digits (0.0045 m) stay apart
            a.set_ylabel("minimum f1 over the workspace (Hz)")
            a.plot([], [], "k.:", lw=0.8, label="dotted: near-singular poses included")
            a.grid(alpha=0.3)
            if any(line.get_label() and not line.get_label().startswith("_") for line in a.get_lines()):
                a.legend(fontsize=7)
        fig.suptitle(wrap_title(f"{self.config.name}: weakest pose per design", fig, 9), fontsize=9)
        return fig

    def plot_maps(self, max_designs: int = 12) -> Any:
        """Small multiples of the f1 map over the poses, one per design (the first ``max_designs``)."""
        import matplotlib.pyplot as plt

        n = min(len(self.designs), max_designs)
        if n == 0 or self.joint_space:  # joint values have no map (design.csv holds them)
            return None
        cols = min(n, 4)
        rows_n = math.ceil(n / cols)
        fig, axes = plt.subplots(
            rows_n, cols, figsize=(3.2 * cols, 3.0 * rows_n), squeeze=False, constrained_layout=True
        )
        where = self.pose_columns()
        x, y = np.array(where["x_mm"]), np.array(where["y_mm"])
        f1 = self.frequencies_hz[:n, :, 0]
        vmin, vmax = (np.nanmin(f1), np.nanmax(f1)) if np.isfinite(f1).any() else (0.0, 1.0)
        sc = None
        for d in range(rows_n * cols):
            a = axes.flat[d]
            if d >= n:
                a.axis("off")
                continue
            ok = np.isfinite(f1[d])
            sc = a.scatter(x[ok], y[ok], c=f1[d, ok], s=max(4.0, 2000.0 / max(len(x), 1)), vmin=vmin, vmax=vmax)
            a.scatter(x[~ok], y[~ok], marker="x", s=6, color="0.7")
            a.margins(0.1)  # the markers at the outermost poses whole, not cut by the axes
            a.set_title("\n".join(f"{k}={v:g}" for k, v in self.designs[d].items()) or "design", fontsize=7)
            a.set_aspect("equal")
            a.tick_params(labelsize=6)
            a.set_xlabel("x (mm)", fontsize=7)
            a.set_ylabel("y (mm)", fontsize=7)
        if sc is not None:
            fig.colorbar(sc, ax=axes, label="f1 (Hz)", shrink=0.8)
        shown = (
            f"designs 1-{n} of {len(self.designs)} (the rest in design.csv)"
            if n < len(self.designs)
            else (f"all {n} designs")
        )
        fig.suptitle(f"f1 over the poses, {shown}; small grey marks: no f1 (out of reach or failed)", fontsize=9)
        return fig

    def plot_tradeoff(self) -> Any:
        """Moving mass against the minimum f1, one point per design."""
        import matplotlib.pyplot as plt

        rows = self.summary()
        fig, ax = plt.subplots(figsize=(5, 4), constrained_layout=True)
        # the y axis is summary.csv's min_f1_ok_hz (the weakest pose away from singularities), as labelled
        ax.scatter([r["moving_mass_kg"] for r in rows], [r["min_f1_ok_hz"] for r in rows])
        ax.margins(0.12)  # room for the outermost points' labels
        for r in rows:
            ax.annotate(
                ", ".join(f"{r[f]:g}" for f in self.fields), (r["moving_mass_kg"], r["min_f1_ok_hz"]), fontsize=6
            )
        if self.f_min_hz is not None:
            ax.axhline(self.f_min_hz, color="red", ls="--", lw=1, label=f"f_min {self.f_min_hz:g} Hz")
            ax.legend(fontsize=7)
        ax.set_xlabel("moving mass (kg)")
        ax.set_ylabel("minimum f1 over the ok poses (Hz)")
        ax.set_title(
            f"trade-off; labels: {', '.join(self.fields)}\n(near-singular poses excluded: min_f1_ok_hz)", fontsize=8
        )
        ax.grid(alpha=0.3)
        return fig


def write_netcdf(ds: Any, path: Path) -> str:
    """Write ``ds`` with the ``h5netcdf`` engine (netCDF-4); without ``h5py`` (its writer) fall back to SciPy's
    netCDF-3 writer with a warning. Returns the engine used."""
    try:
        import h5py  # noqa: F401
    except ImportError:
        warnings.warn(
            f"h5py is not installed: {path} is written as netCDF-3 (scipy) instead of netCDF-4 (h5netcdf); "
            "pip install h5py for the netCDF-4 file",
            FpmSimWarning,
            stacklevel=3,
        )
        ds.to_netcdf(path, engine="scipy")
        return "scipy"
    ds.to_netcdf(path, engine="h5netcdf")
    return "h5netcdf"


def _fmt(v: Any) -> Any:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return v


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with open(path, "w", newline="") as fh:
        if not rows:
            return
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(v) for k, v in r.items()})


# ----------------------------------------------------------------------------------------------- the loop


def check_request(
    vary: Mapping[str, Sequence[float]] | None,
    designs: Sequence[Mapping[str, float]] | None,
    *,
    n_modes: int,
    f_min_hz: float | None,
    poses: Sequence[P],
) -> list[P]:
    """The checks of a design study's request (:func:`design_study`, :func:`fpm_sim.designs.robust.design_over_draws`):
    exactly one of ``vary``/``designs``, ``n_modes >= 1``, ``f_min_hz >= 0`` (when given), at least one pose.
    Returns the poses as a list."""
    if (vary is None) == (designs is None):
        raise DesignError(
            "give either vary (FIELD=SPEC items) or designs (rows of field values), not both or neither",
            parameter="vary",
        )
    if n_modes < 1:
        raise DesignError("must be >= 1", parameter="n_modes", value=n_modes)
    if f_min_hz is not None and not f_min_hz >= 0:
        raise DesignError("must be >= 0", parameter="f_min_hz", value=f_min_hz)
    out = list(poses)
    if not out:
        raise DesignError("no poses", parameter="poses", hint="give a grid or poses")
    return out


def _solve(
    config: Machine,
    configs: list[Any],
    poses: Sequence[Pose] | Sequence[TaskPose] | Sequence[JointPose],
    *,
    n_modes: int,
    options: ModelOptions,
    engine: EngineOptions,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(frequencies, in-plane share of mode 1, singularity, status)`` over designs x poses: the 3RRR's pose loop on
    the engine, a described architecture's (:func:`fpm_sim.designs.described.solve_descriptions`, on
    ``engine.workers`` processes) or an imported model's (:func:`fpm_sim.designs.imported.solve_imported`, its task
    poses solved to joint values once)."""
    if isinstance(config, ImportedDescription):
        if not (all(isinstance(p, TaskPose) for p in poses) or all(isinstance(p, Mapping) for p in poses)):
            raise DesignError(
                f"{config.name} takes poses as fpm_sim.architecture.TaskPose (where it names an [end_effector]) or "
                "as {joint: value} mappings, all of one kind",
                parameter="poses",
            )
        joint_poses = imported_joint_poses(config, poses)  # type: ignore[arg-type]
        return solve_imported(configs, joint_poses, n_modes=n_modes, options=options)
    wanted = TaskPose if isinstance(config, Description) else Pose
    wrong = next((p for p in poses if not isinstance(p, wanted)), None)
    if wrong is not None:
        raise DesignError(
            f"{config.name} takes poses as {wanted.__name__}, got a {type(wrong).__name__}",
            parameter="poses",
            hint="a described architecture's poses are in its task coordinates (fpm_sim.architecture.TaskPose)",
        )
    if isinstance(config, Description):
        return solve_descriptions(configs, poses, n_modes=n_modes, options=options, workers=engine.workers or 1)  # type: ignore[arg-type]
    merged = solve_configs(configs, poses, n_modes=n_modes, options=options, engine=engine)  # type: ignore[arg-type]
    return (
        np.stack([m.frequencies_hz for m in merged]),
        np.stack([m.in_plane[:, 0] for m in merged]),
        np.stack([m.singularity for m in merged]),
        np.array([m.status for m in merged], dtype=object),
    )


def _designs_of(
    config: Machine, vary: Mapping[str, Sequence[float]] | None, designs: Sequence[Mapping[str, float]] | None
) -> tuple[list[dict[str, float]], dict[str, list[float]], bool]:
    """``(designs, levels, factorial)``: the full factorial of ``vary`` (fields checked on ``config``), or the rows
    of ``designs`` with each field's distinct values as its levels."""
    if vary is not None:
        levels = {k: [float(v) for v in vals] for k, vals in vary.items()}
        for name, vals in levels.items():
            _check_field(config, name)
            if not vals:
                raise DesignError(f"{name}: no values", parameter="vary")
        return factorial(levels), levels, True
    design_list = [{k: float(v) for k, v in d.items()} for d in designs or []]
    if not design_list:
        raise DesignError("no designs", parameter="designs")
    return design_list, {k: sorted({d[k] for d in design_list}) for k in design_list[0]}, False


def design_study(
    config: Machine,
    *,
    poses: Sequence[Pose] | Sequence[TaskPose] | Sequence[JointPose],
    vary: Mapping[str, Sequence[float]] | None = None,
    designs: Sequence[Mapping[str, float]] | None = None,
    n_modes: int = 3,
    f_min_hz: float | None = None,
    options: ModelOptions | None = None,
    engine: EngineOptions | None = None,
) -> DesignResult:
    """Lowest ``n_modes`` frequencies for every design x pose.

    Parameters
    ----------
    config
        The base description: the 3RRR's (:class:`fpm_sim.config.Manipulator`), a described architecture
        (:class:`fpm_sim.architecture.Description`, read from its file) or an imported model
        (:class:`fpm_sim.architecture.imported.ImportedDescription`, read from its file).
    poses
        The poses (the same for every design; e.g. :func:`fpm_sim.study.sweep.dense_grid` or
        :func:`fpm_sim.batch.pose_loop.read_poses_csv`; a described architecture: task poses, e.g. its check poses,
        :func:`fpm_sim.batch.task_sweep.task_grid` or :func:`fpm_sim.batch.task_sweep.read_task_poses_csv`). A design
        that moves the workspace marks the poses it cannot reach. An imported model: task poses where it names an
        ``[end_effector]``, or ``{joint: value}`` poses (:func:`fpm_sim.batch.joint_sweep.read_joint_poses_csv`),
        the same joint values for every design (:mod:`fpm_sim.designs.imported`).
    vary
        ``{dotted field: values}``: the full factorial (SI units, as the field names say; a described architecture or
        an imported model: dotted paths into its file, ``sections.bar.height_m``).
    designs
        Instead of ``vary``: a list of ``{field: value}`` designs (e.g. :func:`read_designs_csv`).
    n_modes
        Modes per pose.
    f_min_hz
        Threshold of the summary's workspace share (Hz).
    options
        Discretisation (default :func:`fpm_sim.batch.pose_loop.fast_options`, as ``sweep``).
    engine
        Where the chunks run (default: a local Dask cluster sized to the machine; see
        :class:`fpm_sim.batch.engine.EngineOptions`; a described architecture: ``engine.workers`` processes, default
        one).

    Raises
    ------
    DesignError
        Unknown field, invalid value, both or neither of ``vary``/``designs``, no poses.
    """
    pose_list: list[Any] = check_request(vary, designs, n_modes=n_modes, f_min_hz=f_min_hz, poses=list(poses))
    design_list, levels, is_factorial = _designs_of(config, vary, designs)
    fields = list(levels)
    base: Any = config  # either form; apply_design keeps it
    configs = [apply_design(base, d) for d in design_list]
    opts = options or fast_options()
    eng = engine or EngineOptions()
    eng = dataclasses.replace(eng, desc="design x poses" if eng.desc == "poses" else eng.desc)
    t0 = time.perf_counter()
    freq, in_plane, singularity, status = _solve(config, configs, pose_list, n_modes=n_modes, options=opts, engine=eng)
    elapsed = time.perf_counter() - t0
    return DesignResult(
        config=config,
        fields=fields,
        designs=design_list,
        factorial=is_factorial,
        levels=levels,
        poses=pose_list,
        frequencies_hz=freq,
        in_plane=in_plane,
        singularity=singularity,
        status=status,
        f_min_hz=f_min_hz,
        link_mass_kg=np.array([link_mass_kg(c) for c in configs]),
        moving_mass_kg=np.array([moving_mass_kg(c) for c in configs]),
        elapsed_s=elapsed,
        options=opts,
    )
