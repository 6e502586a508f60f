"""The study's published numbers, packaged with fpm-sim (``fpm_sim/data/*.csv``).

Source: Segura, "Model reduction of a 3RRR flexible parallel manipulator with experimental
validation" (Ciência em Foco vol. V, c. 2021), restated in the project's ``docs/study.md``. Each CSV keeps
its provenance comments (lines starting with ``#``).

- :func:`subsystem_tests`: the single-link (free-free, cantilever) and two-link chain tests, measured
  and COMSOL first frequencies;
- :func:`comsol_table`: the full manipulator's first frequency predicted by COMSOL at the 25 grid
  points (18 given, 7 empty), keyed by the table's own ``(row_mm, col_mm)`` labels;
- :func:`mesh_convergence`: the study's COMSOL mesh convergence rows;
- :data:`STUDY_COMSOL_VS_EXPERIMENT`: the study's own error statistics of COMSOL against the
  measurements at the 18 poses (the measured values themselves are not published).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from importlib import resources

__all__ = [
    "STUDY_COMSOL_VS_EXPERIMENT",
    "STUDY_THICKNESS_M",
    "ComsolPoint",
    "MeasuredPoint",
    "SubsystemTest",
    "comsol_table",
    "measured_table",
    "mesh_convergence",
    "parse_subsystem_rows",
    "read_data_csv",
    "subsystem_tests",
    "withheld_cells",
]

STUDY_THICKNESS_M = 0.030
"""The in-plane thickness of the study's manipulator links (m): its COMSOL and measured tables are for these."""

STUDY_COMSOL_VS_EXPERIMENT = {
    "max_abs_hz": 6.96,
    "max_abs_pct": 12.9,
    "mean_abs_hz": 2.88,
    "mean_abs_pct": 5.84,
    "median_abs_hz": 2.11,
    "median_abs_pct": 5.43,
}
"""The study's error of its COMSOL model against its 18 measured manipulator frequencies."""


@dataclass(frozen=True)
class SubsystemTest:
    """One subsystem test: ``rig`` is ``free-free``, ``cantilever`` or ``chain`` (hinge ``angle_deg``)."""

    rig: str
    angle_deg: float
    experimental_hz: float
    comsol_hz: float
    label: str


@dataclass(frozen=True)
class ComsolPoint:
    """One cell of the study's Table 5: its own labels (mm) and COMSOL's first frequency (NaN = none)."""

    row_mm: float
    col_mm: float
    comsol_hz: float

    @property
    def has_value(self) -> bool:
        return math.isfinite(self.comsol_hz)


def read_data_csv(name: str) -> list[dict[str, str]]:
    """Rows of a packaged CSV (``fpm_sim/data/<name>``) as dicts, comment lines skipped."""
    text = resources.files("fpm_sim.data").joinpath(name).read_text()
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return list(csv.DictReader(io.StringIO("\n".join(lines))))


def _num(s: str) -> float:
    return float(s) if s.strip() else math.nan


def subsystem_tests() -> list[SubsystemTest]:
    """The five subsystem tests in the study's order (link free-free, cantilever, chain 60/90/180 deg)."""
    return parse_subsystem_rows(read_data_csv("subsystems.csv"))


def parse_subsystem_rows(rows: list[dict[str, str]]) -> list[SubsystemTest]:
    """Subsystem tests from CSV rows ``rig,setting,experimental_hz[,comsol_hz]`` (see ``subsystems.csv``)."""
    out = []
    for row in rows:
        setting = row["setting"].strip()
        if row["rig"] == "link":
            if setting not in ("free-free", "cantilever"):
                raise ValueError(f"link test setting {setting!r}: use free-free or cantilever")
            rig, angle = setting, 180.0
            label = f"link {setting}"
        elif row["rig"] == "chain":
            rig = "chain"
            angle = float(setting.split("angle")[1].split("deg")[0])
            label = f"chain {angle:g} deg"
        else:
            raise ValueError(f"rig {row['rig']!r}: use link or chain")
        comsol = _num(row.get("comsol_hz") or "")
        out.append(SubsystemTest(rig, angle, float(row["experimental_hz"]), comsol, label))
    return out


def comsol_table() -> list[ComsolPoint]:
    """The 25 cells of the study's Table 5, in the file's order (rows 100 .. -100, columns -100 .. 100)."""
    return [
        ComsolPoint(float(r["row_mm"]), float(r["col_mm"]), _num(r["comsol_hz"]))
        for r in read_data_csv("comsol_table5.csv")
    ]


def mesh_convergence() -> list[dict[str, str]]:
    """The study's mesh convergence rows (strings as in the file; empty = not given)."""
    return read_data_csv("mesh_convergence.csv")


@dataclass(frozen=True)
class MeasuredPoint:
    """One cell of the study's measured Table 4 as packaged: labels (mm), frequency (NaN if unreadable)."""

    row_mm: float
    col_mm: float
    measured_hz: float
    readable: bool


def measured_table() -> list[MeasuredPoint]:
    """The packaged measured table (``measured_table4_train.csv``): 12 readable poses and the 7 unreadable.

    The study's 6 other readable poses were withheld from the project (see the file's header): they are
    not here, and :func:`withheld_cells` names where they are.
    """
    out = []
    for r in read_data_csv("measured_table4_train.csv"):
        v = r["experimental_hz"].strip()
        readable = v.lower() != "unreadable"
        out.append(MeasuredPoint(float(r["row_mm"]), float(r["col_mm"]), float(v) if readable else math.nan, readable))
    return out


def withheld_cells() -> list[tuple[float, float]]:
    """``(row_mm, col_mm)`` of the study's readable poses whose measurement was withheld: those with a COMSOL
    value (readable in the study) that the packaged measured table does not hold."""
    known = {(m.row_mm, m.col_mm) for m in measured_table()}
    return [(c.row_mm, c.col_mm) for c in comsol_table() if c.has_value and (c.row_mm, c.col_mm) not in known]
