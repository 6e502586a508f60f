"""The study reproduction's report: ``poses.csv``, ``report.md`` (the verdict, the error statistics, the
withheld poses' predictions, the identified parameters' provenance) and the figures.

:class:`ReproductionReport` is the output half of :class:`fpm_sim.study.reproduce.StudyReproduction` (which
computes; it inherits these methods): this module formats and draws, and computes nothing of its own. It does
not import :mod:`fpm_sim.study.reproduce` (no cycle): what it reads of the reproduction is declared below.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.batch.pose_loop import PoseFrequencies
from fpm_sim.config import Manipulator
from fpm_sim.figures import text_colour, wrap_title
from fpm_sim.model.options import ModelOptions, resolution_footer
from fpm_sim.study.poses import GRID_MM, StudyPose, TableReading
from fpm_sim.study.rigs import SubsystemResult
from fpm_sim.study.tables import STUDY_COMSOL_VS_EXPERIMENT, STUDY_THICKNESS_M

__all__ = ["DEFAULT_OPTIMA_SPREAD_PCT", "POSES_CSV_COLUMNS", "ReproductionReport", "determination"]

POSES_CSV_COLUMNS = (
    "row_mm",
    "col_mm",
    "x_mm",
    "y_mm",
    "phi_rad",
    "f1_hz",
    "f2_hz",
    "f3_hz",
    "comsol_hz",
    "measured_hz",
    "withheld",
)
DEFAULT_OPTIMA_SPREAD_PCT = {
    (100.0, -50.0): 1.5,
    (100.0, 100.0): 2.9,
    (50.0, 0.0): 1.7,
    (0.0, -100.0): 23.0,
    (-50.0, 100.0): 28.0,
    (-100.0, -50.0): 16.0,
}
"""For the embedded default only: at each withheld pose ``(row_mm, col_mm)``, the median |deviation| (%) of the
predicted f1 of the competing identified descriptions from their median (``studies/optima_predictions.py`` over
the thirteen identify folders of docs/identification.md, "What the competing optima agree on"). Small: the data
pin the prediction down whatever the layout; large: the prediction depends on which optimum the search found."""


class ReproductionReport:
    """Tables, report and figures of a study reproduction (inherited by
    :class:`~fpm_sim.study.reproduce.StudyReproduction`, which holds the data and the derived numbers declared
    here)."""

    config: Manipulator
    reading: TableReading
    poses: list[StudyPose]
    frequencies: PoseFrequencies
    subsystems: list[SubsystemResult]
    options: ModelOptions
    notes: list[str]
    readability: list[Any]
    posterior: str | None

    # -- what the computation provides (StudyReproduction)
    @property
    def comparable(self) -> bool:
        raise NotImplementedError

    @property
    def f1_hz(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def comsol_hz(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def measured_hz(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def withheld(self) -> np.ndarray:
        raise NotImplementedError

    def rows(self) -> list[dict[str, Any]]:
        raise NotImplementedError

    def stats(self) -> dict[str, float]:
        raise NotImplementedError

    def stats_vs_measured(self) -> dict[str, float]:
        raise NotImplementedError

    def identification_summary(self) -> dict[str, Any] | None:
        raise NotImplementedError

    # -- output
    def write_csv(self, path: Path) -> None:
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(POSES_CSV_COLUMNS)
            for row in self.rows():
                w.writerow([_fmt_csv(row[c]) for c in POSES_CSV_COLUMNS])

    def grid(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x_mm, y_mm, Z)`` with ``Z[iy, ix]`` the value at grid position (x, y) under the reading."""
        xs = np.array(GRID_MM)
        z = np.full((len(xs), len(xs)), np.nan)
        for p, v in zip(self.poses, values):
            ix = int(np.argmin(np.abs(xs - p.pose.x_m * 1e3)))
            iy = int(np.argmin(np.abs(xs - p.pose.y_m * 1e3)))
            z[iy, ix] = v
        return xs, xs, z

    def table(self) -> str:
        """Subsystem tests and the poses' first frequency (Hz) against COMSOL's, with the error statistics."""
        lines = [self.config.name, f"reading {self.reading.name}", ""]
        lines.append(f"{'test':<22}{'measured':>10}{'COMSOL':>10}{'fpm-sim':>10}{'err %':>8}")
        for s in self.subsystems:
            t = s.test
            lines.append(
                f"{t.label:<22}{t.experimental_hz:>10g}{t.comsol_hz:>10g}{s.ours_hz:>10.2f}{s.error_pct:>+8.2f}"
            )
        lines.append("")
        cmp_ = self.comparable
        head = f"{'row':>5}{'col':>6}{'x':>7}{'y':>7}{'phi':>6}{'f1 Hz':>9}"
        lines.append(head + (f"{'measured':>10}{'COMSOL':>9}{'diff %':>8}" if cmp_ else ""))
        for row in self.rows():
            c = row["comsol_hz"]
            text = (
                f"{row['row_mm']:>5g}{row['col_mm']:>6g}{row['x_mm']:>7g}{row['y_mm']:>7g}{row['phi_rad']:>6.1f}"
                f"{row['f1_hz']:>9.2f}"
            )
            if cmp_:
                meas = "withheld" if row["withheld"] else _f(row["measured_hz"])
                d = f"{100 * (row['f1_hz'] / c - 1):+8.1f}" if c == c else f"{'-':>8}"
                text += f"{meas:>10}{_f(c):>9}{d}"
            lines.append(text)
        lines.append("")
        lines += self.verdict_lines()
        lines.append(resolution_footer(self.options))
        return "\n".join(lines)

    def verdict_lines(self) -> list[str]:
        """The verdict in a few plain sentences: this description against the measurements (in-sample and
        cross-validated) and against COMSOL, beside the study's own COMSOL-vs-measured error."""
        ref = STUDY_COMSOL_VS_EXPERIMENT["mean_abs_pct"]
        if not self.comparable:
            return [
                f"Not compared with the study's tables: these links are {self.config.section.thickness_m * 1e3:g} mm "
                f"in-plane, the study's measured and COMSOL values are for {STUDY_THICKNESS_M * 1e3:g} mm links (a "
                "comparison would measure the thickness change, not the model)."
            ]
        sm, sc = self.stats_vs_measured(), self.stats()
        summ = self.identification_summary() or {}
        cv = summ.get("summary", {}).get("measured_table4_train.csv", {}).get("cross_validated", {})
        out = []
        if sm.get("n"):
            text = (
                f"vs measured ({sm['n']} poses): mean |err| {sm['mean_abs_pct']:.2f} % in-sample (the poses it was "
                "fitted to)"
            )
            if cv.get("n"):
                text += f", {cv['mean_abs_pct']:.2f} % cross-validated (poses predicted by fits that did not see them)"
            text += f"; the study's own COMSOL model: {ref:g} % against its 18 measured poses."
            out.append(text)
            pred = cv.get("mean_abs_pct", math.nan)
            if math.isfinite(pred) and pred > 1.2 * ref:
                out.append(
                    "Verdict: fits the data it was identified from about as well as the study's model does, but "
                    f"predicts unseen poses {pred / ref:.1f}x worse than the study's {ref:g} %: read predictions "
                    "away from the measured poses as uncertain."
                    if sm["mean_abs_pct"] <= 1.2 * ref
                    else f"Verdict: less accurate than the study's own model ({ref:g} %), in-sample and "
                    "cross-validated."
                )
            elif math.isfinite(pred):
                out.append(f"Verdict: as accurate as the study's own model ({ref:g} %), cross-validated.")
            else:
                out.append(
                    "Verdict: in-sample only (no cross-validation for this description; fpm-sim identify --folds K "
                    "gives one)."
                )
        if sc.get("n"):
            out.append(
                f"vs COMSOL ({sc['n']} poses): mean |err| {sc['mean_abs_pct']:.2f} %, "
                f"median {sc['median_abs_pct']:.2f} %, max {sc['max_abs_pct']:.2f} %, Spearman {sc['spearman']:.3f}."
            )
        return out

    def plot(self, ax: Any = None) -> Any:
        """The f1 heatmaps (ours, COMSOL's, difference); the ``Figure``. ``ax``: three axes to draw on, or one
        for our f1 alone."""
        return self.plot_heatmaps(ax if ax is None or np.iterable(ax) else [ax])

    def plot_heatmaps(self, axes: Any = None) -> Any:
        """Figure: our f1, COMSOL's, and their difference (%) over the grid (x, y under the reading)."""
        import matplotlib.pyplot as plt

        n_panels = 3 if self.comparable else 1  # COMSOL's table describes the study's 30 mm links only
        if axes is None:
            fig, axes = plt.subplots(1, n_panels, figsize=(14 if n_panels == 3 else 6, 4.6), constrained_layout=True)
        else:
            fig = np.atleast_1d(axes)[0].figure
        axes = np.atleast_1d(axes)
        diff = 100.0 * (self.f1_hz / self.comsol_hz - 1.0)
        lo = float(np.nanmin([np.nanmin(self.f1_hz), np.nanmin(self.comsol_hz)]))
        hi = float(np.nanmax([np.nanmax(self.f1_hz), np.nanmax(self.comsol_hz)]))
        lim = float(np.nanmax(np.abs(diff))) if np.any(np.isfinite(diff)) else 1.0
        panels = [
            (self.f1_hz, "fpm-sim f1 (Hz)", "viridis", lo, hi),
            (self.comsol_hz, "COMSOL f1 (Hz), study Table 5", "viridis", lo, hi),
            (diff, "fpm-sim / COMSOL - 1 (%)", "RdBu_r", -lim, lim),
        ][:n_panels]
        if n_panels == 1:
            own = (float(np.nanmin(self.f1_hz)), float(np.nanmax(self.f1_hz)))
            panels = [(self.f1_hz, "fpm-sim f1 (Hz)", "viridis", *own)]
        for ax, (vals, title, cmap, vmin, vmax) in zip(axes, panels):
            xs, ys, z = self.grid(vals)
            im = ax.imshow(z, origin="lower", extent=(-125, 125, -125, 125), cmap=cmap, vmin=vmin, vmax=vmax)
            for iy in range(z.shape[0]):
                for ix in range(z.shape[1]):
                    v = z[iy, ix]
                    txt = "-" if not np.isfinite(v) else f"{v:.1f}"
                    ax.text(xs[ix], ys[iy], txt, ha="center", va="center", fontsize=8, color=text_colour(im, v))
            ax.set_title(title, fontsize=10)
            ax.set_xlabel("x (mm)")
            ax.set_ylabel("y (mm)")
            ax.set_xticks(xs)
            ax.set_yticks(ys)
            fig.colorbar(im, ax=ax, shrink=0.85)
        title = f"{self.config.name}\ntable reading {self.reading.name}"
        if not self.comparable:
            title += (
                f"; links {self.config.section.thickness_m * 1e3:g} mm: not comparable with the study's "
                f"{STUDY_THICKNESS_M * 1e3:g} mm tables"
            )
        fig.suptitle(wrap_title(title, fig, 9), fontsize=9)
        return fig

    def plot_subsystems(self) -> Any:
        """Figure: subsystem first frequencies, measured vs COMSOL vs fpm-sim."""
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
        groups = [
            [s for s in self.subsystems if s.test.rig != "chain"],
            [s for s in self.subsystems if s.test.rig == "chain"],
        ]
        for ax, grp in zip(axes, groups):
            x = np.arange(len(grp))
            w = 0.27
            ax.bar(x - w, [s.test.experimental_hz for s in grp], w, label="measured (study)")
            ax.bar(x, [s.test.comsol_hz for s in grp], w, label="COMSOL (study)")
            ax.bar(x + w, [s.ours_hz for s in grp], w, label="fpm-sim")
            ax.set_xticks(x)
            ax.set_xticklabels([s.test.label for s in grp])
            ax.set_ylabel("first natural frequency (Hz)")
            ax.set_xlabel("subsystem test")
        fig.suptitle("subsystem tests: first natural frequency", fontsize=10)
        # one legend above the panels, outside the bars
        fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=3, fontsize=8)
        return fig

    def write(self, out_dir: str | Path) -> list[Path]:
        """Write ``poses.csv``, ``report.md``, ``heatmaps.png``, ``subsystems.png``; returns the paths."""
        import matplotlib.pyplot as plt

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = [out / "poses.csv", out / "report.md", out / "heatmaps.png", out / "subsystems.png"]
        self.write_csv(paths[0])
        fig = self.plot_heatmaps()
        fig.savefig(paths[2], dpi=110)
        plt.close(fig)
        fig = self.plot_subsystems()
        fig.savefig(paths[3], dpi=110)
        plt.close(fig)
        paths[1].write_text(self.markdown())
        return paths

    def _unclear_poses_section(self) -> list[str]:
        """Our model at the study's 7 poses without a COMSOL value (unreadable FRFs) vs the other 18."""
        has = np.isfinite(self.comsol_hz)
        if has.all() or not has.any():
            return []
        fr = self.frequencies
        rows = [
            ("mean first frequency (Hz)", np.nanmean(fr.f1_hz[~has]), np.nanmean(fr.f1_hz[has])),
            ("mean singularity measure", np.nanmean(fr.singularity[~has]), np.nanmean(fr.singularity[has])),
            ("min singularity measure", np.nanmin(fr.singularity[~has]), np.nanmin(fr.singularity[has])),
            ("mean in-plane share of mode 1", np.nanmean(fr.in_plane[~has, 0]), np.nanmean(fr.in_plane[has, 0])),
        ]
        out = [
            f"## The {int((~has).sum())} poses the study could not read",
            "",
            "The study's FRFs were unreadable at these poses; a model can say whether they sit nearer a singularity "
            "(low, pose-sensitive first frequency) than the others.",
            "",
            "| quantity | unreadable poses | poses with a COMSOL value |",
            "|---|---:|---:|",
        ]
        out += [f"| {name} | {a:.3f} | {b:.3f} |" for name, a, b in rows]
        out.append("")
        for table in self.readability:
            out += [
                f"### Mode-1 readability, virtual driving-point hammer test along {table.point.axis!r} "
                f"at {table.point.link} ({table.point.fraction:g} of its length)",
                "",
                "How strongly a hammer at the assumed accelerometer point excites mode 1 and how far its peak stands "
                "out in the FRF (`fpm-sim readability`; docs/frf_impact_atlas.md), against the study's seven "
                "unreadable poses:",
                "",
                table.to_markdown(),
                "",
            ]
        return out

    def _error_sections(self) -> list[str]:
        """Errors against the measured and the COMSOL values, in-sample and cross-validated, beside COMSOL's own;
        the predictions at the six withheld poses."""
        lines: list[str] = [""]
        if not self.comparable:
            lines += [
                "## No error statistics: not comparable",
                "",
                f"These links are {self.config.section.thickness_m * 1e3:g} mm in-plane; the study's measured and "
                f"COMSOL tables are for its {STUDY_THICKNESS_M * 1e3:g} mm links. Comparing them would measure the "
                "thickness change, not the model, so no error statistics are given.",
                "",
            ]
        else:
            lines += self._error_statistics_section() + self._cross_validated_section()
        return lines + self._withheld_section()

    def _error_statistics_section(self) -> list[str]:
        """The study-form error statistics against the measured and the COMSOL values, beside COMSOL's own."""
        ref = STUDY_COMSOL_VS_EXPERIMENT
        lines: list[str] = []
        sc, sm = self.stats(), self.stats_vs_measured()
        head = (
            "| comparison | n | min (Hz) | max (Hz) | mean (Hz) | median (Hz) | min (%) | max (%) | mean (%) "
            "| median (%) | Spearman |"
        )
        lines += [
            "## Error statistics",
            "",
            "In the study's form (absolute error; relative to the reference). *In-sample*: this description at "
            "the poses it was identified from; the packaged measured table holds 12 of the study's 18 readable "
            "poses (the other 6 are withheld from the project, see below).",
            "",
            head,
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for name, st in (("fpm-sim vs measured (12 poses, in-sample)", sm), ("fpm-sim vs COMSOL (18 poses)", sc)):
            if st.get("n", 0):
                lines.append(
                    f"| {name} | {st['n']} | {st['min_abs_hz']:.2f} | {st['max_abs_hz']:.2f} | "
                    f"{st['mean_abs_hz']:.2f} | {st['median_abs_hz']:.2f} | {st['min_abs_pct']:.2f} | "
                    f"{st['max_abs_pct']:.2f} | {st['mean_abs_pct']:.2f} | {st['median_abs_pct']:.2f} | "
                    f"{st['spearman']:.3f} |"
                )
        lines += [
            f"| COMSOL vs measured (the study's own, 18 poses) | 18 | - | {ref['max_abs_hz']} "
            f"| {ref['mean_abs_hz']} | {ref['median_abs_hz']} | - | {ref['max_abs_pct']} | {ref['mean_abs_pct']} "
            f"| {ref['median_abs_pct']} | - |",
            "",
        ]
        return lines

    def _cross_validated_section(self) -> list[str]:
        """The cross-validated errors of the identification that produced this description, where known."""
        lines: list[str] = []
        summ = self.identification_summary()
        if summ:
            lines += [
                "### Cross-validated (from the identification that produced this description)",
                "",
                "Identified by (its start description `out/identify_study_nominal_start.toml` is written by the "
                "script, so from a clone run `nice python scripts/identify_study.py --out out/identify_study "
                "--seed 0 --folds 4 --workers 2`, which runs this command):",
                "",
                f"`{summ.get('command', '')}`",
                "",
                "| data | n | in-sample mean (%) | cross-validated mean (%) | cross-validated max (%) "
                "| cross-validated Spearman |",
                "|---|---:|---:|---:|---:|---:|",
            ]
            for src, st in summ.get("summary", {}).items():
                i, c = st.get("in_sample", {}), st.get("cross_validated", {})
                if not c:
                    continue
                lines.append(
                    f"| {src} | {i.get('n', 0)} | {i.get('mean_abs_pct', math.nan):.2f} | "
                    f"{c.get('mean_abs_pct', math.nan):.2f} | {c.get('max_abs_pct', math.nan):.2f} | "
                    f"{c.get('spearman', math.nan):.3f} |"
                )
            lines += [
                "",
                "Cross-validated: each pose predicted by a fit that did not see it (k-fold over poses, every "
                "file's value at a held-out pose left out together; fitted model at the identification's "
                "resolution, which can differ slightly from this report's).",
                "",
            ]
        else:
            lines += [
                "Cross-validated errors: not available for this description (they come from "
                "`fpm-sim identify --folds K`, which writes them into its report).",
                "",
            ]
        return lines

    def _withheld_section(self) -> list[str]:
        """The predictions at the six withheld poses (with the competing optima's spread for the default)."""
        lines: list[str] = []
        w = self.withheld
        if w.any():
            lines += [
                "## Predictions at the six withheld poses",
                "",
                "The study measured these poses too, but their values were withheld from the project to judge "
                "the models identified from the rest. Predicted here, never fitted.",
                "",
            ]
            spread = DEFAULT_OPTIMA_SPREAD_PCT if self.identification_summary() else {}
            comsol_head = "COMSOL (Hz)"
            if not self.comparable:
                comsol_head = f"COMSOL, the study's {STUDY_THICKNESS_M * 1e3:g} mm links (Hz)"
            if spread:
                lines += [
                    "Last column: how far the competing optima of the identification (descriptions that fit the data "
                    "about equally well) predict apart here, median |deviation| from their median "
                    "(`studies/optima_predictions.py`, docs/identification.md): a few per cent, the data determine "
                    "the prediction; tens of per cent, they leave it open.",
                    "",
                ]
            lines += [
                f"| row (mm) | col (mm) | x (mm) | y (mm) | phi (rad) | predicted f1 (Hz) | {comsol_head} |"
                + (" competing optima spread (%) |" if spread else ""),
                "|---:|---:|---:|---:|---:|---:|---:|" + ("---:|" if spread else ""),
            ]
            for r, k in zip(self.rows(), w):
                if k:
                    sp = spread.get((r["row_mm"], r["col_mm"]), math.nan) if spread else None
                    lines.append(
                        f"| {r['row_mm']:g} | {r['col_mm']:g} | {r['x_mm']:g} | {r['y_mm']:g} | {r['phi_rad']:+.1f} | "
                        f"{_f(r['f1_hz'])} | {_f(r['comsol_hz'])} |" + (f" {_f(sp, '.1f')} |" if sp is not None else "")
                    )
            lines.append("")
        return lines

    def _verdict_section(self) -> list[str]:
        """The report's opening: the verdict, what the data determine and leave open, the bands."""
        lines = ["## Verdict", "", " ".join(self.verdict_lines()), ""]
        if self.comparable and self.identification_summary():
            agree = ", ".join(f"({r:g}, {c:g})" for (r, c), v in DEFAULT_OPTIMA_SPREAD_PCT.items() if v < 5.0)
            open_ = ", ".join(f"({r:g}, {c:g})" for (r, c), v in DEFAULT_OPTIMA_SPREAD_PCT.items() if v >= 5.0)
            lo_a = min(v for v in DEFAULT_OPTIMA_SPREAD_PCT.values() if v < 5.0)
            hi_a = max(v for v in DEFAULT_OPTIMA_SPREAD_PCT.values() if v < 5.0)
            lo_o = min(v for v in DEFAULT_OPTIMA_SPREAD_PCT.values() if v >= 5.0)
            hi_o = max(v for v in DEFAULT_OPTIMA_SPREAD_PCT.values() if v >= 5.0)
            sub_err = max((abs(x.error_pct) for x in self.subsystems), default=math.nan)
            lines += [
                "**What the data determine and what they leave open.** The subsystem tests pin down the links and the "
                f"test rigs (fitted within {sub_err:.2g} %). The manipulator's geometry and hardware masses are not "
                "pinned down: eleven identification searches from scratch ended in eight optima that fit the data "
                "about equally well and predict the unmeasured poses 2-4x apart (docs/identification.md). At the "
                f"withheld poses (row, col) {agree} the optima agree within {lo_a:g}-{hi_a:g} %, so the data decide "
                f"those predictions; at {open_} they disagree by {lo_o:g}-{hi_o:g} % (median), so there the "
                "prediction is one optimum's, not the data's (see the table of withheld poses). Parameters with a "
                "standard deviation larger than their value are flagged below.",
                "",
            ]
        elif self.comparable:
            lines += [
                "**What the data leave open.** Not assessed for this description: `fpm-sim identify` with "
                "`--refine-per-class K` lists its competing optima, and their spread at unmeasured poses says what "
                "the data leave open.",
                "",
            ]
        used = (
            f"a posterior was used ({self.posterior})"
            if self.posterior is not None
            else "no posterior was used: the numbers above are one identified description's, without bands"
        )
        lines += [
            "**Uncertainty bands.** Bayesian calibration (`fpm-sim calibrate`, `fpm-sim reproduce --posterior`) turns "
            f"the data's uncertainty into bands on every prediction; here {used}.",
            "",
        ]
        return lines

    def markdown(self) -> str:
        """The report (Markdown)."""
        ref_mm = f"the study's {STUDY_THICKNESS_M * 1e3:g} mm links (Hz)"  # the tables' links, not these
        lines = [
            "# fpm-sim reproduction of the study (Segura, c. 2021)",
            "",
            f"Configuration: **{self.config.name}**; link section {self.config.section.thickness_m * 1e3:g} mm "
            f"(in-plane) x {self.config.section.height_m * 1e3:g} mm (out-of-plane).",
            f"Table reading: **{self.reading.name}** (rows are {self.reading.row_is}; the poses written (x, 0) "
            f"turned {self.reading.phi_sign * 0.2:+.1f} rad).",
            f"Pose loop: constrained eigen-solve, gravity off, {self.options.segments} segments per link"
            f"{', axial springs' if self.options.axial else ', inextensible links'}. Near a singularity (singularity "
            "measure below 0.05) f1 is sensitive to gravity's prestress: `fpm-sim modes` (gravity on) gives a "
            "different value at those poses.",
            "",
            *self._verdict_section(),
            "## Subsystem tests (first natural frequency)",
            "",
            "| test | measured (Hz) | COMSOL (Hz) | fpm-sim (Hz) | fpm-sim vs measured | mode |",
            "|---|---:|---:|---:|---:|---|",
        ]
        for s in self.subsystems:
            lines.append(
                f"| {s.test.label} | {s.test.experimental_hz:g} | {s.test.comsol_hz:g} | {s.ours_hz:.2f} | "
                f"{s.error_pct:+.2f} % | {s.dominant} |"
            )
        lines += [
            "",
            "![subsystems](subsystems.png)",
            "",
            "## The 25 poses",
            "",
            "| row (mm) | col (mm) | x (mm) | y (mm) | phi (rad) | f1 (Hz) | f2 (Hz) | f3 (Hz) | "
            + ("measured (Hz) | COMSOL (Hz) " if self.comparable else f"measured, {ref_mm} | COMSOL, {ref_mm} ")
            + "| diff vs COMSOL (%) | in-plane share of mode 1 | singularity measure | status |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
        ]
        fr = self.frequencies
        for i, row in enumerate(self.rows()):
            c = row["comsol_hz"]
            d = 100.0 * (row["f1_hz"] / c - 1.0) if math.isfinite(c) and self.comparable else math.nan
            meas = "withheld" if row["withheld"] else _f(row["measured_hz"])
            lines.append(
                f"| {row['row_mm']:g} | {row['col_mm']:g} | {row['x_mm']:g} | {row['y_mm']:g} "
                f"| {row['phi_rad']:+.1f} | "
                f"{_f(row['f1_hz'])} | {_f(row['f2_hz'])} | {_f(row['f3_hz'])} | {meas} | {_f(c)} | {_f(d, '+.1f')} | "
                f"{_f(fr.in_plane[i, 0], '.2f')} | {_f(fr.singularity[i], '.3f')} | {fr.status[i]} |"
            )
        lines += self._error_sections()
        lines += ["![heatmaps](heatmaps.png)", ""]
        lines += self._unclear_poses_section()
        ident = {k: v for k, v in self.config.provenance.items() if v.startswith("identified")}
        if ident:
            lines += ["## Identified parameters (value; source, with +- one standard deviation)", ""]
            lines += [
                "A standard deviation as large as the value or larger means the data do not determine the parameter "
                "(other values fit about as well); 30 % or more, poorly determined.",
                "",
                "| parameter | value | determined by the data? | from |",
                "|---|---|---|---|",
            ]
            for k, v in sorted(ident.items()):
                lines.append(
                    f"| `{k}` | {_value_of(self.config, k)} | {determination(v)} | {v[len('identified: ') :]} |"
                )
            lines.append("")
        lines += ["## Parameters and their provenance", ""]
        lines += ["| parameter | source |", "|---|---|"]
        for k, v in sorted(self.config.provenance.items()):
            lines.append(f"| `{k}` | {v} |")
        if self.notes:
            lines += ["", "## Notes", ""] + [f"- {n}" for n in self.notes]
        return "\n".join(lines) + "\n"


def determination(provenance: str) -> str:
    """From ``... = VALUE +- SD unit`` in an identified value's provenance: whether the data determine it."""
    m = re.search(r"= (-?[0-9.eE+-]+) \+- ([0-9.eE+-]+)", provenance)
    if not m:
        return "as its mass" if "scaled with the identified mass" in provenance else "-"
    value, sd = float(m.group(1)), float(m.group(2))
    if provenance.rstrip().endswith("deg"):  # an angle's size is no scale for its SD: judged in degrees
        return f"poorly (sd {sd:g} deg)" if sd >= 10.0 else f"yes (sd {sd:g} deg)"
    rel = sd / abs(value) if value else math.inf
    if rel >= 1.0:
        return f"**no: not determined by the data** (sd {100 * rel:.0f} % of the value)"
    if rel >= 0.3:
        return f"poorly (sd {100 * rel:.0f} %)"
    return f"yes (sd {100 * rel:.0f} %)"


def _value_of(config: Manipulator, dotted: str) -> str:
    obj: Any = config
    for part in dotted.split("."):
        obj = getattr(obj, part.replace("_deg", "_rad"), None) if obj is not None else None
    if obj is None:
        return "-"
    if dotted.endswith("_deg"):
        return str([round(math.degrees(a), 3) for a in obj])
    return str(obj) if not isinstance(obj, float) else f"{obj:.6g}"


def _f(v: float, fmt: str = ".2f") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, fmt)


def _fmt_csv(v: Any) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(round(v, 6))
    return str(v)
