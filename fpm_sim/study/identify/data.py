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
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.study.poses import TableReading
from fpm_sim.study.tables import SubsystemTest, parse_subsystem_rows

__all__ = [
    "DEFAULT_SIGMA_PCT",
    "MODE_LABELS",
    "DataError",
    "DataSet",
    "Observation",
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


def _rows(path: Path) -> list[dict[str, str]]:
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise DataError(f"measured-data file not found: {path} (--measured)") from exc
    except IsADirectoryError as exc:
        raise DataError(f"--measured {path} is a folder; give a CSV file") from exc
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise DataError(f"{path}: no data rows (only comments or empty)")
    return list(csv.DictReader(io.StringIO("\n".join(lines))))


def _float(text: str | None, path: Path, i: int, col: str) -> float:
    if text is None or not text.strip():
        return math.nan
    try:
        return float(text)
    except ValueError as exc:
        raise DataError(f"{path}, data row {i + 1}, column '{col}': {text!r} is not a number") from exc


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
        Naming the file, row and column of anything unreadable.
    """
    p = Path(path)
    if not (math.isfinite(sigma_pct) and sigma_pct > 0):
        raise DataError(f"{p}: sigma_pct must be > 0, got {sigma_pct!r}")
    rows = _rows(p)
    cols = set(rows[0])
    ds = DataSet(source=p.name, sigma_pct=sigma_pct)
    if {"x_mm", "y_mm"} <= cols:
        fcols = sorted((c for c in cols if c.startswith("f") and c.endswith("_hz")), key=lambda c: int(c[1:-3]))
        for c in fcols:
            if not c[1:-3].isdigit():
                raise DataError(f"{p}: column {c!r} not understood; frequency columns are f1_hz, f2_hz, ...")
        if not fcols:
            raise DataError(f"{p}: no frequency column; expected f1_hz, f2_hz, ... beside x_mm,y_mm,phi_rad")
        for i, r in enumerate(rows):
            x, y = _float(r["x_mm"], p, i, "x_mm"), _float(r["y_mm"], p, i, "y_mm")
            phi = _float(r.get("phi_rad", "0") or "0", p, i, "phi_rad")
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(phi)):
                raise DataError(f"{p}, data row {i + 1}: x_mm, y_mm and phi_rad must be finite numbers")
            label = (r.get("mode") or "").strip() or None
            if label is not None and label not in MODE_LABELS:
                raise DataError(f"{p}, data row {i + 1}, column 'mode': {label!r}; use in_plane or out_of_plane")
            sig = _float(r.get("sigma_hz"), p, i, "sigma_hz")
            for c in fcols:
                f = _float(r[c], p, i, c)
                if math.isnan(f):
                    continue
                if not f > 0:
                    raise DataError(f"{p}, data row {i + 1}, column '{c}': frequency must be > 0, got {f}")
                s = sig if math.isfinite(sig) else f * sigma_pct / 100.0
                if not s > 0:
                    raise DataError(f"{p}, data row {i + 1}, column 'sigma_hz': must be > 0, got {s}")
                ds.observations.append(Observation(Pose.from_mm(x, y, phi), int(c[1:-3]), f, s, label, p.name))
        return ds
    if {"row_mm", "col_mm"} <= cols:
        if reading is None:
            raise DataError(
                f"{p} uses the study's row_mm,col_mm labels: say how to read them with --reading x+|x-|y+|y-"
            )
        fcol = next((c for c in ("experimental_hz", "comsol_hz", "f1_hz") if c in cols), None)
        if fcol is None:
            raise DataError(f"{p}: no frequency column; expected experimental_hz, comsol_hz or f1_hz")
        for i, r in enumerate(rows):
            v = (r[fcol] or "").strip()
            if not v or v.lower() == "unreadable":
                continue
            f = _float(v, p, i, fcol)
            rm, cm = _float(r["row_mm"], p, i, "row_mm"), _float(r["col_mm"], p, i, "col_mm")
            ds.observations.append(Observation(reading.pose(rm, cm), 1, f, f * sigma_pct / 100.0, None, p.name, rm, cm))
        return ds
    raise DataError(
        f"{p}: columns {sorted(cols)} not understood; expected x_mm,y_mm,phi_rad,f1_hz,... or row_mm,col_mm"
    )


def read_subsystems_csv(path: str | Path) -> list[SubsystemTest]:
    """Rig tests in the shape of the study's ``subsystems.csv`` (``rig,setting,experimental_hz``)."""
    p = Path(path)
    rows = _rows(p)
    try:
        return parse_subsystem_rows(rows)
    except (KeyError, ValueError, IndexError) as exc:
        raise DataError(
            f"{p}: not a subsystem-test table (columns rig,setting,experimental_hz; rig 'link' with setting "
            f"free-free or cantilever, or 'chain' with setting 'joint angle N deg'): {exc}"
        ) from exc
