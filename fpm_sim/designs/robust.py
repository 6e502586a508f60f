"""Design studies over a posterior: every design applied to every posterior draw, and the probability that the
design meets its frequency target.

A description identified from a dozen measured frequencies is uncertain (``docs/identification.md``); a design
chosen on one optimum may miss its target on the machine actually built. :func:`design_over_draws` applies each
design (dotted field values, as :func:`fpm_sim.designs.design_study`) to each draw of the posterior (the draws'
descriptions, e.g. :meth:`fpm_sim.study.posterior.Posterior.configs`) and runs the pose loop over designs x
draws x poses on the engine (:func:`fpm_sim.batch.pose_loop.solve_configs`). Per design and draw the weakest
``ok`` pose gives ``min f1``; the probability that the design meets ``f_min_hz`` is the share of the draws
whose ``min f1`` reaches it.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import STATUS_OK, STATUS_UNREACHABLE, fast_options, solve_configs
from fpm_sim.config import Manipulator
from fpm_sim.designs.study import DesignError, apply_design, check_request, factorial
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions, resolution_summary

__all__ = ["DesignBands", "design_over_draws"]


@dataclass
class DesignBands:
    """Frequencies over designs x posterior draws x poses (:func:`design_over_draws`).

    Attributes
    ----------
    fields
        The varied dotted fields.
    designs
        One ``{field: value}`` per design.
    poses
        The poses.
    f_min_hz
        The frequency target (Hz).
    frequencies_hz
        ``(n_designs, n_draws, n_poses, n_modes)``; NaN where not computed.
    status
        ``(n_designs, n_draws, n_poses)``.
    options
        The pose loop's model options.
    elapsed_s
        Wall time.
    """

    fields: list[str]
    designs: list[dict[str, float]]
    poses: list[Pose]
    f_min_hz: float
    frequencies_hz: np.ndarray
    status: np.ndarray
    options: ModelOptions = field(default_factory=fast_options)
    elapsed_s: float = 0.0

    @property
    def n_draws(self) -> int:
        return int(self.frequencies_hz.shape[1])

    @property
    def min_f1_ok_hz(self) -> np.ndarray:
        """``(n_designs, n_draws)`` lowest f1 over the ``ok`` poses (NaN: no ``ok`` pose)."""
        f1 = np.where(self.status == STATUS_OK, self.frequencies_hz[..., 0], np.nan)
        out = np.full(f1.shape[:2], np.nan)
        has = np.isfinite(f1).any(axis=2)
        out[has] = np.nanmin(f1[has], axis=1)
        return out

    @property
    def probability_meets(self) -> np.ndarray:
        """``(n_designs,)`` share of the draws whose lowest f1 over the ``ok`` poses is at least ``f_min_hz``
        (a draw without an ``ok`` pose does not meet it)."""
        m = self.min_f1_ok_hz
        return np.mean(np.where(np.isfinite(m), m, -np.inf) >= self.f_min_hz, axis=1)

    @property
    def mean_share_above(self) -> np.ndarray:
        """``(n_designs,)`` mean over the draws of the share of the reachable poses with ``f1 >= f_min_hz`` (the
        design summary's share, averaged over the posterior)."""
        f1 = np.where(np.isfinite(self.frequencies_hz[..., 0]), self.frequencies_hz[..., 0], -np.inf)
        reachable = self.status != STATUS_UNREACHABLE
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.sum((f1 >= self.f_min_hz) & reachable, axis=2) / np.sum(reachable, axis=2)
        return np.nanmean(share, axis=1) if np.isfinite(share).any() else np.full(len(self.designs), math.nan)

    def summary(self) -> list[dict[str, Any]]:
        """Per design: P(min f1 >= f_min), the mean workspace share above f_min, and the median and 5/95 %
        quantiles of min f1 over the draws."""
        m = self.min_f1_ok_hz
        p, share = self.probability_meets, self.mean_share_above
        rows = []
        for d, values in enumerate(self.designs):
            ok = m[d][np.isfinite(m[d])]
            q = np.quantile(ok, (0.05, 0.5, 0.95)) if ok.size else np.full(3, math.nan)
            row: dict[str, Any] = dict(values)
            row.update(
                {
                    "p_meets_f_min": float(p[d]),
                    "mean_share_above_f_min": float(share[d]),
                    "min_f1_ok_q05_hz": float(q[0]),
                    "min_f1_ok_q50_hz": float(q[1]),
                    "min_f1_ok_q95_hz": float(q[2]),
                    "draws": self.n_draws,
                }
            )
            rows.append(row)
        return rows

    def table(self) -> str:
        """The summary as a text table."""
        heads = [*self.fields, f"P(min f1>={self.f_min_hz:g}Hz)", "mean share", "min f1 median Hz", "5-95 % Hz"]
        width = [max(len(h), 12) for h in heads]
        lines = ["  ".join(h.rjust(w) for h, w in zip(heads, width))]
        for r in self.summary():
            cells = [f"{r[f]:.6g}" for f in self.fields] + [
                f"{100 * r['p_meets_f_min']:.0f} %",
                "-" if math.isnan(r["mean_share_above_f_min"]) else f"{100 * r['mean_share_above_f_min']:.1f} %",
                f"{r['min_f1_ok_q50_hz']:.2f}",
                f"{r['min_f1_ok_q05_hz']:.2f} .. {r['min_f1_ok_q95_hz']:.2f}",
            ]
            lines.append("  ".join(c.rjust(w) for c, w in zip(cells, width)))
        lines.append(
            f"over {self.n_draws} posterior draws and {len(self.poses)} poses; min f1 over the ok poses (away from "
            "singularities) of each draw"
        )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: fields, designs, the target, the summary and each design's min f1 per draw."""
        m = self.min_f1_ok_hz
        return {
            "fields": list(self.fields),
            "f_min_hz": self.f_min_hz,
            "n_draws": self.n_draws,
            "summary": self.summary(),
            "min_f1_ok_hz": np.where(np.isfinite(m), m, np.array(None)).tolist(),
            "resolution": resolution_summary(self.options),
            "elapsed_s": self.elapsed_s,
        }

    def write(self, out_dir: str | Path) -> list[Path]:
        """Write ``design_bands.csv`` (:meth:`summary`), ``design_bands.json`` (:meth:`to_dict`) and
        ``design_bands.png`` (:meth:`plot`); returns the paths."""
        import matplotlib.pyplot as plt

        from fpm_sim.results import to_jsonable

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = [out / "design_bands.csv", out / "design_bands.json", out / "design_bands.png"]
        rows = self.summary()
        with open(paths[0], "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(
                {k: "" if isinstance(v, float) and not math.isfinite(v) else v for k, v in r.items()} for r in rows
            )
        paths[1].write_text(json.dumps(to_jsonable(self.to_dict()), indent=1))
        fig = self.plot()
        fig.savefig(paths[2], dpi=110)
        plt.close(fig)
        return paths

    def plot(self, ax: Any = None) -> Any:
        """P(min f1 >= f_min) per design (bars) with the median and 5-95 % of min f1 on a second axis."""
        import matplotlib.pyplot as plt

        if ax is None:
            fig, ax = plt.subplots(figsize=(max(5.0, 0.6 * len(self.designs) + 2), 3.8), constrained_layout=True)
        else:
            fig = ax.figure
        x = np.arange(len(self.designs))
        ax.bar(x, 100 * self.probability_meets, color="C0", alpha=0.5, label=f"P(min f1 >= {self.f_min_hz:g} Hz)")
        ax.set_ylabel("probability over the posterior (%)")
        ax.set_ylim(0, 105)
        ax.set_xticks(x, [", ".join(f"{v:g}" for v in d.values()) for d in self.designs], rotation=45, ha="right")
        ax.set_xlabel(", ".join(self.fields))
        ax2 = ax.twinx()
        rows = self.summary()
        med = np.array([r["min_f1_ok_q50_hz"] for r in rows])
        lo = np.array([r["min_f1_ok_q05_hz"] for r in rows])
        hi = np.array([r["min_f1_ok_q95_hz"] for r in rows])
        ax2.errorbar(x, med, yerr=[med - lo, hi - med], fmt="o", color="C1", capsize=3, label="min f1: median, 5-95 %")
        ax2.axhline(self.f_min_hz, color="red", ls="--", lw=1, label=f"target f_min {self.f_min_hz:g} Hz")
        ax2.set_ylabel("min f1 over the ok poses (Hz)")
        handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
        ax.legend(handles=handles, fontsize=7, loc="lower right")
        ax.set_title(f"designs over {self.n_draws} posterior draws", fontsize=8)
        return fig


def design_over_draws(
    draws: Sequence[Manipulator],
    *,
    poses: Sequence[Pose],
    f_min_hz: float,
    vary: Mapping[str, Sequence[float]] | None = None,
    designs: Sequence[Mapping[str, float]] | None = None,
    n_modes: int = 1,
    options: ModelOptions | None = None,
    engine: EngineOptions | None = None,
) -> DesignBands:
    """Every design (the factorial of ``vary``, or ``designs``) applied to every description in ``draws``
    (e.g. a posterior's), the lowest ``n_modes`` frequencies at ``poses``, and P(min f1 >= ``f_min_hz``).

    Raises
    ------
    DesignError
        Both or neither of ``vary``/``designs``, no draws, no poses, a bad target or a design value a draw
        cannot take.
    """
    poses = check_request(vary, designs, n_modes=n_modes, f_min_hz=f_min_hz, poses=poses)
    draws = list(draws)
    if not draws:
        raise DesignError("no posterior draws", parameter="draws", hint="give at least one draw's description")
    design_list = factorial(vary) if vary is not None else [dict(d) for d in designs or []]
    if not design_list:
        raise DesignError("no designs", parameter="vary" if vary is not None else "designs")
    fields = list(design_list[0])
    configs = [apply_design(c, d) for d in design_list for c in draws]
    opts = options or fast_options()
    eng = engine or EngineOptions()
    eng = dataclasses.replace(eng, desc="design x draws x poses" if eng.desc == "poses" else eng.desc)
    t0 = time.perf_counter()
    parts = solve_configs(configs, poses, n_modes=n_modes, options=opts, engine=eng)
    shape = (len(design_list), len(draws), len(poses))
    return DesignBands(
        fields=fields,
        designs=[{k: float(v) for k, v in d.items()} for d in design_list],
        poses=poses,
        f_min_hz=f_min_hz,
        frequencies_hz=np.stack([p.frequencies_hz for p in parts]).reshape((*shape, n_modes)),
        status=np.array([p.status for p in parts], dtype=object).reshape(shape),
        options=opts,
        elapsed_s=time.perf_counter() - t0,
    )
