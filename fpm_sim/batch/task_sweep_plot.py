"""The figure of a :class:`fpm_sim.batch.task_sweep.TaskSweep`: f1 over x and y, with the singularity loci.

It takes the sweep as ``Any``: importing its class here would close an import cycle (task_sweep calls this lazily)."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from fpm_sim.figures import wrap_title
from fpm_sim.kinematics import NEAR_SINGULAR_WARN

__all__ = ["plot_task_sweep"]


def _field(sweep: Any, values: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    z = np.full((len(ys), len(xs)), np.nan)
    for p, v in zip(sweep.poses, values):
        z[np.searchsorted(ys, round(p.y_m * 1e3, 9)), np.searchsorted(xs, round(p.x_m * 1e3, 9))] = v
    return z


def plot_task_sweep(sweep: Any, ax: Any = None) -> Any:
    """Heatmap of f1 (a grid) or coloured points (a pose list), singular and near-singular poses marked, and on a
    grid the two singularity measures' contours at :data:`fpm_sim.kinematics.NEAR_SINGULAR_WARN`, the boundary of
    the near-singular regions around the loci; the ``Figure``."""
    import matplotlib.pyplot as plt

    xs = np.array(sorted({round(p.x_m * 1e3, 9) for p in sweep.poses}))
    ys = np.array(sorted({round(p.y_m * 1e3, 9) for p in sweep.poses}))
    if ax is None:
        fig, ax = plt.subplots(figsize=(7, 6), constrained_layout=True)
    else:
        fig = ax.figure
    f1 = sweep.freq_hz[:, 0]
    if sweep.grid == "dense" and sweep.step_mm:
        step = sweep.step_mm
        extent = (xs[0] - step / 2, xs[-1] + step / 2, ys[0] - step / 2, ys[-1] + step / 2)
        im = ax.imshow(_field(sweep, f1, xs, ys), origin="lower", extent=extent, cmap="viridis")
        level = NEAR_SINGULAR_WARN  # the near-singular region's boundary
        loci = (
            (sweep.type2, "red", "solid", f"type-2 (parallel) singularity measure {level:g}"),
            (sweep.type1, "black", "dashed", f"type-1 (serial) singularity measure {level:g}"),
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for values, colour, style, label in loci:
                field = _field(sweep, values, xs, ys)
                if np.isfinite(field).sum() > 4 and np.nanmin(field) < level < np.nanmax(field):
                    ax.contour(xs, ys, field, levels=[level], colors=colour, linewidths=1.8, linestyles=style, zorder=4)
                    ax.plot([], [], color=colour, ls=style, label=label)
        reached = [(p.x_m * 1e3, p.y_m * 1e3) for p, s in zip(sweep.poses, sweep.status) if s != "unreachable"]
        if reached:  # the workspace, not the box searched for it
            rx, ry = np.array(reached).T
            ax.set_xlim(rx.min() - step, rx.max() + step)
            ax.set_ylim(ry.min() - step, ry.max() + step)
    else:
        im = ax.scatter([p.x_m * 1e3 for p in sweep.poses], [p.y_m * 1e3 for p in sweep.poses], c=f1, s=120)
    fig.colorbar(im, ax=ax, label="first natural frequency (Hz)")
    marks = {"singular": ("x", "red"), "near_singular": ("o", "orange")}
    for status, (marker, colour) in marks.items():
        pts = [(p.x_m * 1e3, p.y_m * 1e3) for p, s in zip(sweep.poses, sweep.status) if s == status]
        if pts:
            label = status.replace("_", " ") + (" (not computed)" if status == "singular" else "")
            look: dict[str, str] = {"facecolors": "none", "edgecolors": colour} if marker == "o" else {"color": colour}
            ax.scatter(*zip(*pts), marker=marker, s=9, linewidths=0.8, label=label, zorder=3, **look)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=2)
    nb = "\u00a0"  # a held coordinate is not broken across lines
    held = [
        f"z{nb}={nb}{sweep.poses[0].z_m * 1e3:g}{nb}mm"
        if c == "z"
        else f"phi{nb}={nb}{sweep.poses[0].phi_rad:g}{nb}rad"
        for c in sweep.task
        if c in ("z", "phi")
    ]
    title = f"{sweep.name}: first natural frequency" + (f" at {', '.join(held)}" if held else "")
    ax.set_title(wrap_title(title, fig, 9, fraction=0.7), fontsize=9)
    return fig
