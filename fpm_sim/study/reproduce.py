"""Reproduce the study: subsystem tests, the 25 poses, error statistics (the computation).

Compute here (:func:`reproduce_study` returns a :class:`StudyReproduction`), write with
:mod:`fpm_sim.study.reproduce_report` (the methods :class:`StudyReproduction` inherits from it:
:meth:`~fpm_sim.study.reproduce_report.ReproductionReport.write` writes ``poses.csv``, ``report.md`` and the
PNG figures).

The pose loop is :func:`fpm_sim.batch.frequencies.pose_frequencies` (replaceable backend); the subsystem rigs
are :func:`fpm_sim.study.rigs.subsystem_frequencies`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import spearmanr

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import PoseFrequencies
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.poses import StudyPose, TableReading, study_poses
from fpm_sim.study.reproduce_report import ReproductionReport
from fpm_sim.study.rigs import SubsystemResult, subsystem_frequencies
from fpm_sim.study.sweep import WorkspaceSweep
from fpm_sim.study.tables import STUDY_THICKNESS_M, measured_table, withheld_cells

__all__ = ["StudyReproduction", "error_stats", "reproduce_study"]

COMPARABLE_THICKNESS_REL = 0.25
"""Links within this relative distance of the study's 30 mm are scored against its tables (an identified
31 mm is the study's manipulator; the 10 and 5 mm variants are other machines)."""
DEFAULT_IDENTIFICATION = "default_identification.json"
"""Packaged summary of the identification that produced the embedded default (its cross-validated errors)."""


def error_stats(ours: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """The study's error statistics of ``ours`` against ``reference`` where both are finite.

    Returns min, max, mean and median of ``|ours - reference|`` (Hz) and of the same relative to the
    reference (%), the signed mean (%), Spearman's rank correlation and the count.
    """
    o, r = np.asarray(ours, float), np.asarray(reference, float)
    ok = np.isfinite(o) & np.isfinite(r)
    if not np.any(ok):
        return {"n": 0}
    d = np.abs(o[ok] - r[ok])
    p = 100.0 * d / np.abs(r[ok])
    rho = float(spearmanr(o[ok], r[ok]).statistic) if ok.sum() > 2 else math.nan
    return {
        "n": int(ok.sum()),
        "min_abs_hz": float(d.min()),
        "max_abs_hz": float(d.max()),
        "mean_abs_hz": float(d.mean()),
        "median_abs_hz": float(np.median(d)),
        "min_abs_pct": float(p.min()),
        "max_abs_pct": float(p.max()),
        "mean_abs_pct": float(p.mean()),
        "median_abs_pct": float(np.median(p)),
        "mean_signed_pct": float(np.mean(100.0 * (o[ok] - r[ok]) / np.abs(r[ok]))),
        "spearman": rho,
    }


@dataclass
class StudyReproduction(ReproductionReport):
    """Everything the reproduce report shows."""

    config: Manipulator
    reading: TableReading
    poses: list[StudyPose]
    frequencies: PoseFrequencies
    subsystems: list[SubsystemResult]
    options: ModelOptions
    notes: list[str] = field(default_factory=list)
    readability: list[Any] = field(default_factory=list)
    """Mode-1 readability tables (:class:`fpm_sim.study.readability.ReadabilityTable`), one per hammer axis."""
    posterior: str | None = None
    """The Bayesian calibration whose bands come with the report, in words (the file, the draws used, the band
    files and their coverage: ``fpm-sim reproduce --posterior`` fills it), or ``None``: the numbers are one
    identified description's (a point estimate)."""

    @classmethod
    def from_sweep(cls, sweep: WorkspaceSweep, reading: TableReading | None = None) -> StudyReproduction:
        """The pose table of a ``grid="paper"`` sweep (read with ``reading``, as the sweep was), from the same
        frequencies: no subsystem rigs, no readability."""
        if sweep.grid != "paper":
            raise FpmSimError(
                f"a study reproduction needs the sweep of the study's poses (grid 'paper'), not {sweep.grid!r}"
            )
        rd = reading or TableReading()
        from fpm_sim.batch.pose_loop import fast_options

        return cls(sweep.config, rd, study_poses(rd), sweep.frequencies, [], sweep.options or fast_options())

    @property
    def comsol_hz(self) -> np.ndarray:
        return np.array([p.comsol_hz for p in self.poses])

    @property
    def measured_hz(self) -> np.ndarray:
        """The packaged measured first frequencies (NaN: unreadable in the study, or withheld)."""
        m = {(c.row_mm, c.col_mm): c.measured_hz for c in measured_table()}
        return np.array([m.get((p.row_mm, p.col_mm), math.nan) for p in self.poses])

    @property
    def withheld(self) -> np.ndarray:
        """True at the six readable poses whose measurement was withheld from the project."""
        w = set(withheld_cells())
        return np.array([(p.row_mm, p.col_mm) in w for p in self.poses])

    @property
    def comparable(self) -> bool:
        """Whether the study's tables (30 mm links) describe this manipulator's links (thickness within
        :data:`COMPARABLE_THICKNESS_REL` of 30 mm)."""
        return abs(self.config.section.thickness_m / STUDY_THICKNESS_M - 1.0) <= COMPARABLE_THICKNESS_REL

    def stats_vs_measured(self) -> dict[str, float]:
        """Error statistics of our f1 against the 12 packaged measured poses (in-sample for a description
        identified from them); ``{"n": 0}`` when not :attr:`comparable`."""
        if not self.comparable:
            return {"n": 0}
        return error_stats(self.f1_hz, self.measured_hz)

    def identification_summary(self) -> dict[str, Any] | None:
        """Cross-validated errors of the identification that produced the embedded default (None for
        any other description: run ``fpm-sim identify --folds K`` on it)."""
        import json
        from importlib import resources

        from fpm_sim.config import default_config

        try:
            if self.config != default_config():
                return None
            text = resources.files("fpm_sim.data").joinpath(DEFAULT_IDENTIFICATION).read_text()
        except FileNotFoundError:
            return None
        return json.loads(text)

    @property
    def f1_hz(self) -> np.ndarray:
        return self.frequencies.f1_hz

    def stats(self) -> dict[str, float]:
        """Error statistics of our f1 against COMSOL over the poses with a COMSOL value (``{"n": 0}`` when the
        links are not the study's 30 mm ones: the table does not describe them, see :attr:`comparable`)."""
        if not self.comparable:
            return {"n": 0}
        return error_stats(self.f1_hz, self.comsol_hz)

    def rows(self) -> list[dict[str, Any]]:
        """One dict per pose with the :data:`~fpm_sim.study.reproduce_report.POSES_CSV_COLUMNS`."""
        out = []
        f = self.frequencies.frequencies_hz
        for i, p in enumerate(self.poses):
            row: dict[str, Any] = {
                "row_mm": p.row_mm,
                "col_mm": p.col_mm,
                "x_mm": p.pose.x_m * 1e3,
                "y_mm": p.pose.y_m * 1e3,
                "phi_rad": p.pose.phi_rad,
            }
            for k in range(3):
                row[f"f{k + 1}_hz"] = float(f[i, k]) if k < f.shape[1] else math.nan
            row["comsol_hz"] = p.comsol_hz
            row["measured_hz"] = float(self.measured_hz[i])
            row["withheld"] = bool(self.withheld[i])
            out.append(row)
        return out

    def to_xarray(self) -> Any:
        """The frequencies over the study's poses (:func:`fpm_sim.results.frequencies_dataset`) with COMSOL's and
        the measured first frequency (``comsol_hz``, ``measured_hz``, Hz) and the table's cells (``row_mm``,
        ``col_mm``) on ``pose``."""
        ds = self.frequencies.to_xarray()
        ds["comsol_hz"] = ("pose", self.comsol_hz)
        ds["measured_hz"] = ("pose", self.measured_hz)
        ds = ds.assign_coords(
            row_mm=("pose", [p.row_mm for p in self.poses]), col_mm=("pose", [p.col_mm for p in self.poses])
        )
        ds.attrs.update(config=self.config.name, reading=self.reading.name)
        return ds

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: poses with f1..f3 (Hz) and COMSOL's value, statistics, subsystem tests, resolution."""
        from fpm_sim.model.options import resolution_summary

        return {
            "config": self.config.name,
            "reading": self.reading.name,
            "options": {"segments": self.options.segments, "axial": self.options.axial},
            "resolution": resolution_summary(self.options),
            "poses": self.rows(),
            "status": self.frequencies.status,
            "in_plane_fraction_mode1": self.frequencies.in_plane[:, 0].tolist(),
            "comparable_with_study_tables": self.comparable,
            "stats_vs_comsol": self.stats() if self.comparable else None,
            "stats_vs_measured": self.stats_vs_measured() if self.comparable else None,
            "withheld_predictions": [
                {"row_mm": r["row_mm"], "col_mm": r["col_mm"], "f1_hz": r["f1_hz"]}
                for r in self.rows()
                if r["withheld"]
            ],
            "subsystems": [
                {
                    "test": s.test.label,
                    "experimental_hz": s.test.experimental_hz,
                    "comsol_hz": s.test.comsol_hz,
                    "ours_hz": s.ours_hz,
                    "error_pct": s.error_pct,
                    "dominant": s.dominant,
                }
                for s in self.subsystems
            ],
        }


def reproduce_study(
    config: Manipulator,
    *,
    reading: TableReading | None = None,
    options: ModelOptions | None = None,
    backend: str = "cpu",
    workers: int = 1,
    progress: bool = False,
    subsystems: bool = True,
    readability: bool = True,
    engine: EngineOptions | None = None,
) -> StudyReproduction:
    """Run the study's subsystem tests and its 25 poses on ``config``.

    Parameters
    ----------
    config
        The manipulator (its ``rig`` table describes the test pieces).
    reading
        How the study's table maps to poses (default: rows are x, +0.2 rad).
    options
        Pose-loop discretisation (default :func:`fpm_sim.batch.pose_loop.fast_options`).
    backend, workers, progress, engine
        Passed to :func:`fpm_sim.batch.frequencies.pose_frequencies` (``engine``: where the ``cpu`` backend's
        chunks run, :class:`fpm_sim.batch.engine.EngineOptions`).
    subsystems
        Also solve the subsystem rigs (needs ``config.rig``).
    readability
        Also tabulate mode-1 readability for a driving-point hammer along z and along the in-plane
        normal of chain 0's distal link at mid-span (the study's set-up is not stated; both axes).
    """
    from fpm_sim.batch.pose_loop import fast_options

    rd = reading or TableReading()
    opts = options or fast_options()
    poses = study_poses(rd)
    freqs = pose_frequencies(
        config,
        [p.pose for p in poses],
        backend=backend,
        n_modes=3,
        options=opts,
        workers=workers,
        progress=progress,
        desc="study poses",
        engine=engine,
    )
    subs = subsystem_frequencies(config) if subsystems and config.rig is not None else []
    tables = []
    notes = []
    if readability:
        from fpm_sim.response import LinkPoint
        from fpm_sim.study.readability import readability_table

        for axis in ("z", "normal"):
            try:
                tables.append(
                    readability_table(
                        config, options=opts, poses=poses, point=LinkPoint("distal_0", 0.5, axis), progress=progress
                    )
                )
            except FpmSimError as exc:  # e.g. a study pose at a singularity of this geometry (a mechanism mode)
                notes.append(f"mode-1 readability along {axis!r} not tabulated: {exc}")
    return StudyReproduction(config, rd, poses, freqs, subs, opts, notes=notes, readability=tables)
