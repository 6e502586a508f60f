"""First natural frequencies over the reachable workspace, with the singularity loci.

:func:`sweep_workspace` evaluates a grid of positions at one platform rotation (``dense``: every
``step_mm`` over the square that holds the reachable workspace; ``paper``: the study's 25 poses
under a table reading). Every grid point is kept and given a status (``ok``, ``near_singular``,
``singular``, ``unreachable``): nothing is dropped silently.

The singularity loci drawn on the heatmap are the zero level sets, on a finer grid, of
``det(Jx)`` (parallel singularity: the distal link lines concurrent) and of each chain's
``cross(w_i, u_i)`` (serial: chain ``i`` stretched or folded).
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import PoseFrequencies, fast_options
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.figures import text_colour, wrap_title, write_table_and_figure
from fpm_sim.kinematics import Pose, assemble_many
from fpm_sim.model.options import ModelOptions, resolution_footer
from fpm_sim.study.poses import TableReading, study_poses

__all__ = ["SWEEP_CSV_COLUMNS", "WorkspaceSweep", "dense_grid", "singularity_fields", "sweep_workspace"]

SWEEP_CSV_COLUMNS = ("x_mm", "y_mm", "phi_rad", "f1_hz", "f2_hz", "f3_hz", "in_plane_mode1", "singularity", "status")


def _reach_half_width(config: Manipulator) -> float:
    """Half-width (m) of a square centred on the base centre that holds every reachable position."""
    g = config.geometry
    return (
        max(g.proximal_length_per_chain)
        + max(g.distal_length_per_chain)
        + max(g.platform_radius_per_chain)
        - min(g.base_radius_per_chain) / 2.0
        + 1e-9
    )


def dense_grid(config: Manipulator, *, step_mm: float, phi_rad: float = 0.0) -> list[Pose]:
    """Positions every ``step_mm`` (aligned on the origin) over the square holding the workspace.

    Rows of the square with no reachable point are trimmed away; inside the kept bounding box every
    point is returned (reachable or not).
    """
    if not step_mm > 0:
        raise FpmSimError("must be > 0", parameter="step_mm", value=step_mm)
    half = _reach_half_width(config)
    n = math.floor(half * 1e3 / step_mm)
    ticks = np.arange(-n, n + 1) * step_mm
    if ticks.size > 401:
        raise FpmSimError(
            f"gives {ticks.size} x {ticks.size} points", parameter="step_mm", value=step_mm, hint="use a larger step"
        )
    xx, yy = np.meshgrid(ticks * 1e-3, ticks * 1e-3)
    reach = assemble_many(config.geometry, xx.ravel(), yy.ravel(), phi_rad).reachable.reshape(xx.shape)
    if not reach.any():
        raise FpmSimError(f"no reachable position with step {step_mm} mm", parameter="phi_rad", value=phi_rad)
    rows, cols = np.where(reach.any(axis=1))[0], np.where(reach.any(axis=0))[0]
    ys, xs = ticks[rows.min() : rows.max() + 1], ticks[cols.min() : cols.max() + 1]
    return [Pose.from_mm(float(x), float(y), phi_rad) for y in ys for x in xs]


def singularity_fields(
    config: Manipulator, x_mm: np.ndarray, y_mm: np.ndarray, phi_rad: float
) -> tuple[np.ndarray, np.ndarray]:
    """``det(Jx)`` (rotation column over the characteristic length) and ``min_i |cross(w_i, u_i)|`` on the
    grid ``y_mm x x_mm`` (NaN where unreachable), from :func:`fpm_sim.kinematics.assemble_many`."""
    xx, yy = np.meshgrid(np.asarray(x_mm, float) * 1e-3, np.asarray(y_mm, float) * 1e-3)
    many = assemble_many(config.geometry, xx.ravel(), yy.ravel(), phi_rad)
    return many.det_jx.reshape(xx.shape), many.serial.reshape(xx.shape)


@dataclass
class WorkspaceSweep:
    """Result of :func:`sweep_workspace`."""

    config: Manipulator
    grid: str
    phi_rad: float
    step_mm: float
    frequencies: PoseFrequencies
    options: ModelOptions | None = None
    """The pose loop's model options (resolution), when known."""

    def rows(self) -> list[dict[str, Any]]:
        fr = self.frequencies
        out = []
        for i, p in enumerate(fr.poses):
            f = fr.frequencies_hz[i]
            out.append(
                {
                    "x_mm": round(p.x_m * 1e3, 6),
                    "y_mm": round(p.y_m * 1e3, 6),
                    "phi_rad": p.phi_rad,
                    "f1_hz": float(f[0]),
                    "f2_hz": float(f[1]) if f.size > 1 else math.nan,
                    "f3_hz": float(f[2]) if f.size > 2 else math.nan,
                    "in_plane_mode1": float(fr.in_plane[i, 0]),
                    "singularity": float(fr.singularity[i]),
                    "status": fr.status[i],
                }
            )
        return out

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for s in self.frequencies.status:
            out[s] = out.get(s, 0) + 1
        return out

    def write_csv(self, path: Path) -> None:
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(SWEEP_CSV_COLUMNS)
            for r in self.rows():
                w.writerow(
                    ["" if isinstance(r[c], float) and not math.isfinite(r[c]) else r[c] for c in SWEEP_CSV_COLUMNS]
                )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: grid, status counts, one row per point (x, y mm; phi rad; f1..f3 Hz), resolution."""
        from fpm_sim.model.options import resolution_summary

        return {
            "config": self.config.name,
            "grid": self.grid,
            "step_mm": self.step_mm,
            "phi_rad": self.phi_rad,
            "counts": self.counts(),
            "rows": self.rows(),
            "resolution": resolution_summary(self.options) if self.options is not None else {},
        }

    def to_xarray(self) -> Any:
        """The frequencies over poses (:meth:`fpm_sim.batch.pose_loop.PoseFrequencies.to_xarray`), with the grid."""
        ds = self.frequencies.to_xarray()
        ds.attrs.update(config=self.config.name, grid=self.grid, step_mm=self.step_mm, grid_phi_rad=self.phi_rad)
        return ds

    def table(self) -> str:
        """Counts by status and the f1 range (Hz)."""
        f1 = self.frequencies.f1_hz
        ok = f1[np.isfinite(f1)]
        lines = [
            f"{self.config.name}: grid {self.grid}, {len(f1)} points ("
            + ", ".join(f"{k} {v}" for k, v in sorted(self.counts().items()))
            + ")"
        ]
        if ok.size:
            lines.append(f"f1 range: {ok.min():.2f} .. {ok.max():.2f} Hz")
        footer = resolution_footer(self.options)
        return "\n".join([*lines, footer] if footer else lines)

    def plot(self, ax: Any = None) -> Any:
        """Heatmap of f1 with unreachable/singular points marked and the singularity loci drawn; the ``Figure``."""
        import matplotlib.pyplot as plt

        rows = self.rows()
        xs = np.array(sorted({r["x_mm"] for r in rows}))
        ys = np.array(sorted({r["y_mm"] for r in rows}))
        if ax is None:
            fig, ax = plt.subplots(figsize=(7, 6), constrained_layout=True)
        else:
            fig = ax.figure
        if self.grid == "dense":
            z = np.full((len(ys), len(xs)), np.nan)
            for r in rows:
                z[np.searchsorted(ys, r["y_mm"]), np.searchsorted(xs, r["x_mm"])] = r["f1_hz"]
            step = self.step_mm
            im = ax.imshow(
                z,
                origin="lower",
                extent=(xs[0] - step / 2, xs[-1] + step / 2, ys[0] - step / 2, ys[-1] + step / 2),
                cmap="viridis",
            )
        else:
            im = ax.scatter([r["x_mm"] for r in rows], [r["y_mm"] for r in rows], c=[r["f1_hz"] for r in rows], s=400)
            for r in rows:
                colour = text_colour(im, r["f1_hz"])
                ax.text(r["x_mm"], r["y_mm"], f"{r['f1_hz']:.1f}", ha="center", va="center", fontsize=7, color=colour)
        fig.colorbar(im, ax=ax, label="first natural frequency (Hz)")
        marks = {"unreachable": ("x", "0.5"), "singular": ("s", "red"), "near_singular": ("o", "orange")}
        for status, (marker, color) in marks.items():
            pts = [(r["x_mm"], r["y_mm"]) for r in rows if r["status"] == status]
            if pts:
                label = status.replace("_", " ")
                if self.grid == "dense" or marker == "x":
                    ax.scatter(*zip(*pts), marker=marker, s=12, color=color, label=label, zorder=3)
                else:  # a ring around the pose's disc: its number stays readable
                    ax.scatter(*zip(*pts), marker=marker, s=620, facecolors="none", edgecolors=color, lw=2, zorder=3)
                    ax.scatter([], [], marker=marker, s=40, facecolors="none", edgecolors=color, lw=1.5, label=label)
        pad = 20.0
        fx = np.linspace(xs[0] - pad, xs[-1] + pad, 241)
        fy = np.linspace(ys[0] - pad, ys[-1] + pad, 241)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            det, ser = singularity_fields(self.config, fx, fy, self.phi_rad)
            if np.nanmin(det) < 0 < np.nanmax(det):
                ax.contour(fx, fy, det, levels=[0.0], colors="red", linewidths=1.5)
            ax.contour(fx, fy, ser, levels=[0.02], colors="black", linewidths=1.0, linestyles="dashed")
        ax.plot([], [], color="red", label="parallel singularity (det Jx = 0)")
        ax.plot([], [], color="black", ls="--", label="serial singularity (chain straight/folded)")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=2)  # below: covers no point
        phis = sorted({round(float(r["phi_rad"]), 9) for r in rows})
        if len(phis) == 1:
            phi_text = f"phi = {phis[0]:g} rad"
        else:  # e.g. the paper grid: its (x, 0) poses are turned 0.2 rad
            count = {v: sum(round(float(r["phi_rad"]), 9) == v for r in rows) for v in phis}
            phi_text = "phi = " + ", ".join(f"{v:g} rad at {n} poses" for v, n in count.items())
            phi_text += f" (singularity loci drawn at {self.phi_rad:g} rad)"
        title = f"{self.config.name}\n{phi_text}, grid {self.grid}"
        ax.set_title(wrap_title(title, fig, 9, fraction=0.7), fontsize=9)
        return fig

    def write(self, out_dir: str | Path) -> list[Path]:
        """``sweep_<grid>.csv`` and ``sweep_<grid>.png`` in ``out_dir``."""
        paths: list[Path] = write_table_and_figure(self, out_dir, f"sweep_{self.grid}")
        return paths


def sweep_workspace(
    config: Manipulator,
    *,
    grid: str = "dense",
    step_mm: float = 10.0,
    phi_rad: float = 0.0,
    reading: TableReading | None = None,
    poses: Sequence[Pose] | None = None,
    options: ModelOptions | None = None,
    backend: str = "cpu",
    workers: int = 2,
    progress: bool = False,
    engine: EngineOptions | None = None,
) -> WorkspaceSweep:
    """First three frequencies over the workspace (``grid="dense"``), at the study's poses (``"paper"``) or at
    given ``poses`` (``"poses"``; written to ``sweep_poses.csv``). ``engine`` says where the ``cpu`` backend
    runs (:class:`fpm_sim.batch.engine.EngineOptions`)."""
    if grid == "poses":
        if not poses:
            raise FpmSimError("grid='poses' needs poses (x_mm,y_mm,phi_rad)", parameter="poses")
        poses = list(poses)
    elif poses is not None:
        raise FpmSimError("poses are given: use grid='poses'", parameter="grid", value=grid)
    elif grid == "dense":
        poses = dense_grid(config, step_mm=step_mm, phi_rad=phi_rad)
    elif grid == "paper":
        poses = [p.pose for p in study_poses(reading)]
        step_mm = 50.0
    else:
        raise FpmSimError("must be 'paper', 'dense' or 'poses'", parameter="grid", value=grid)
    opts = options or fast_options()
    fr = pose_frequencies(
        config,
        poses,
        backend=backend,
        n_modes=3,
        options=opts,
        workers=workers,
        progress=progress,
        desc="sweep",
        engine=engine,
    )
    return WorkspaceSweep(config, grid, phi_rad, step_mm, fr, opts)
