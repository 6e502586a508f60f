"""Measured modal data as :func:`fpm_sim.study.identify.identify` takes it.

Two shapes of CSV (``#`` lines are comments):

- pose form: ``x_mm,y_mm,phi_rad`` and any of ``f1_hz,f2_hz,...`` (blank = not measured), optional
  ``sigma_hz`` (one standard deviation of every frequency on that row) and optional ``mode``
  (``in_plane`` / ``out_of_plane``: then ``fK_hz`` is the K-th lowest mode *of that kind*, matched by
  the model's strain-energy split, not by sorted order);
- the study's table form: ``row_mm,col_mm`` and one frequency column (``experimental_hz``,
  ``comsol_hz`` or ``f1_hz``); a :class:`~fpm_sim.study.poses.TableReading` turns the labels into
  poses. Cells reading ``unreadable`` or blank are skipped.

Each file carries a relative standard deviation used when a row has no ``sigma_hz``
(:data:`DEFAULT_SIGMA_PCT`, or the value given with the file).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

from fpm_sim.errors import FpmSimError, read_text_input
from fpm_sim.kinematics import Pose, PoseValueError, checked_pose_mm
from fpm_sim.study.poses import TableReading
from fpm_sim.study.tables import SubsystemTest, parse_subsystem_rows

__all__ = [
    "DEFAULT_SIGMA_PCT",
    "MODE_LABELS",
    "DataError",
    "DataSet",
    "Observation",
    "read_cell",
    "read_csv_rows",
    "read_measured_csv",
    "read_subsystems_csv",
]

DEFAULT_SIGMA_PCT = 2.0
"""Relative standard deviation (%) of a measured frequency when the file states none: a hammer-test
FRF peak read to +-0.5 Hz at 30-75 Hz (uniform: 0.3-1 %) plus the peak's scatter between impacts."""

MODE_LABELS = ("in_plane", "out_of_plane")


class DataError(FpmSimError):
    """A measured-data file cannot be read; the message names the file, row and column."""


@dataclass(frozen=True)
class Observation:
    """One measured natural frequency.

    ``mode``: 1-based index among the model's lowest modes (``label`` None) or among the modes of
    kind ``label``. ``sigma_hz``: one standard deviation. ``row_mm``/``col_mm``: the study table's
    labels where the data came in that form (NaN otherwise).
    """

    pose: Pose
    mode: int
    freq_hz: float
    sigma_hz: float
    label: str | None
    source: str
    row_mm: float = math.nan
    col_mm: float = math.nan
    line: int | None = None
    """The row's line number in its file (for messages about this observation)."""

    def describe(self) -> str:
        kind = f" {self.label}" if self.label else ""
        where = f"({self.pose.x_m * 1e3:g}, {self.pose.y_m * 1e3:g}, {self.pose.phi_rad:g})"
        return f"{self.source} {where} f{self.mode}{kind}"


@dataclass
class DataSet:
    """Observations read from one file, with the file's name and its default relative sigma."""

    source: str
    observations: list[Observation] = field(default_factory=list)
    sigma_pct: float = DEFAULT_SIGMA_PCT


def read_csv_rows(path: Path, parameter: str = "measured") -> list[tuple[int, dict[str, str]]]:
    """``(line number, row)`` of every data row (``#`` comments and blank lines skipped); UTF-8 with or without
    a byte-order mark, any line ending; header names stripped."""
    try:
        text = read_text_input(path, error=DataError, parameter=parameter, kind="a CSV file", hint="give a CSV file")
    except FileNotFoundError as exc:
        raise DataError(f"file not found: {path}", parameter=parameter) from exc
    except IsADirectoryError as exc:
        raise DataError(f"{path} is a folder", parameter=parameter, hint="give a CSV file") from exc
    lines = [
        (n, ln) for n, ln in enumerate(text.splitlines(), start=1) if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not lines:
        raise DataError("no data rows (only comments or empty)", file=path)
    header = [h.strip() for h in next(csv.reader([lines[0][1]]))]
    if len(lines) == 1:
        raise DataError(f"only a header ({', '.join(header)}), no data rows", file=path, row=lines[0][0])
    out: list[tuple[int, dict[str, str]]] = []
    for n, ln in lines[1:]:
        cells = next(csv.reader([ln]))
        if len(cells) > len(header):
            raise DataError(f"{len(cells)} cells for {len(header)} columns", file=path, row=n)
        out.append((n, dict(zip(header, [c.strip() for c in cells] + [""] * (len(header) - len(cells))))))
    return out


def read_cell(text: str | None, path: Path, line: int, col: str) -> float:
    """The number in a cell, NaN for a blank one; anything else (``n/a``, ``inf``, ``nan``) is refused."""
    if text is None or not text.strip():
        return math.nan
    try:
        v = float(text)
    except ValueError:
        raise DataError("not a number", parameter=col, value=text, file=path, row=line) from None
    if not math.isfinite(v):
        raise DataError(
            "must be finite (leave the cell blank if not measured)", parameter=col, value=text, file=path, row=line
        )
    return v


def read_measured_csv(
    path: str | Path,
    *,
    reading: TableReading | None = None,
    sigma_pct: float = DEFAULT_SIGMA_PCT,
) -> DataSet:
    """Read a measured-frequency CSV (see module docstring).

    Parameters
    ----------
    path
        The CSV file.
    reading
        Needed for the study's ``row_mm,col_mm`` form: how the labels map to poses.
    sigma_pct
        Relative standard deviation (%) of the file's frequencies where a row has no ``sigma_hz``.

    Raises
    ------
    DataError
        Naming the file, row (its line number in the file) and column of anything unreadable.
    """
    p = Path(path)
    if not (math.isfinite(sigma_pct) and sigma_pct > 0):
        raise DataError("must be > 0", parameter="sigma_pct", value=sigma_pct)
    rows = read_csv_rows(p)
    cols = set(rows[0][1])
    ds = DataSet(source=p.name, sigma_pct=sigma_pct)
    if {"x_mm", "y_mm"} <= cols:
        fcols = _frequency_columns(p, cols)
        for line, r in rows:
            ds.observations += _pose_row_observations(p, line, r, fcols, sigma_pct)
        return ds
    if {"row_mm", "col_mm"} <= cols:
        if reading is None:
            raise DataError(
                f"{p} uses the study's row_mm,col_mm labels: say how to read them",
                parameter="reading",
                hint="x+, x-, y+ or y-",
            )
        fcol = next((c for c in ("experimental_hz", "comsol_hz", "f1_hz") if c in cols), None)
        if fcol is None:
            raise DataError("no frequency column", file=p, hint="expected experimental_hz, comsol_hz or f1_hz")
        for line, r in rows:
            obs = _table_row_observation(p, line, r, fcol, reading, sigma_pct)
            if obs is not None:
                ds.observations.append(obs)
        return ds
    raise DataError(
        f"columns {sorted(cols)} not understood", file=p, hint="expected x_mm,y_mm,phi_rad,f1_hz,... or row_mm,col_mm"
    )


def _frequency_columns(p: Path, cols: set[str]) -> list[str]:
    """The pose form's ``fK_hz`` columns, by ``K``."""
    fcols = [c for c in cols if c.startswith("f") and c.endswith("_hz")]
    for c in fcols:
        if not c[1:-3].isdigit():
            raise DataError(f"column {c!r} not understood", file=p, hint="frequency columns are f1_hz, f2_hz, ...")
    fcols.sort(key=lambda c: int(c[1:-3]))
    if not fcols:
        raise DataError("no frequency column", file=p, hint="expected f1_hz, f2_hz, ... beside x_mm,y_mm,phi_rad")
    return fcols


def _pose_row_observations(
    p: Path, line: int, r: dict[str, str], fcols: list[str], sigma_pct: float
) -> list[Observation]:
    """The observations of one pose-form row (its pose checked, blank frequencies skipped)."""
    try:
        pose = checked_pose_mm(r["x_mm"], r["y_mm"], r.get("phi_rad") or "0", file=p, row=line)
    except PoseValueError as e:
        raise DataError(e.message, parameter=e.parameter, value=e.value, hint=e.hint, file=p, row=line) from None
    label = (r.get("mode") or "").strip() or None
    if label is not None and label not in MODE_LABELS:
        raise DataError(
            "unknown mode kind", parameter="mode", value=label, hint="use in_plane or out_of_plane", file=p, row=line
        )
    sig = read_cell(r.get("sigma_hz"), p, line, "sigma_hz")
    out = []
    for c in fcols:
        f = read_cell(r[c], p, line, c)
        if math.isnan(f):
            continue
        if not f > 0:
            raise DataError("a frequency must be > 0", parameter=c, value=f, file=p, row=line)
        s = sig if math.isfinite(sig) else f * sigma_pct / 100.0
        if not s > 0:
            raise DataError("must be > 0", parameter="sigma_hz", value=s, file=p, row=line)
        out.append(Observation(pose, int(c[1:-3]), f, s, label, p.name, line=line))
    return out


def _table_row_observation(
    p: Path, line: int, r: dict[str, str], fcol: str, reading: TableReading, sigma_pct: float
) -> Observation | None:
    """The observation of one table-form row (``None``: blank or ``unreadable``)."""
    v = (r[fcol] or "").strip()
    if not v or v.lower() == "unreadable":
        return None
    f = read_cell(v, p, line, fcol)
    if not f > 0:
        raise DataError("a frequency must be > 0", parameter=fcol, value=f, file=p, row=line)
    rm, cm = read_cell(r["row_mm"], p, line, "row_mm"), read_cell(r["col_mm"], p, line, "col_mm")
    if math.isnan(rm) or math.isnan(cm):
        raise DataError("row_mm and col_mm must both be given", file=p, row=line)
    return Observation(reading.pose(rm, cm), 1, f, f * sigma_pct / 100.0, None, p.name, rm, cm, line=line)


def read_subsystems_csv(path: str | Path) -> list[SubsystemTest]:
    """Rig tests in the shape of the study's ``subsystems.csv`` (``rig,setting,experimental_hz``)."""
    p = Path(path)
    rows = [r for _, r in read_csv_rows(p, "subsystems")]
    try:
        return parse_subsystem_rows(rows)
    except (KeyError, ValueError, IndexError) as exc:
        raise DataError(
            f"{p}: not a subsystem-test table (columns rig,setting,experimental_hz; rig 'link' with setting "
            f"free-free or cantilever, or 'chain' with setting 'joint angle N deg'): {exc}"
        ) from exc
