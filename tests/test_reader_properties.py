"""Property-based tests (hypothesis, ``tests/test_properties.py`` style) of the readers where user files and
options enter: identify's measured CSV, design's ``--vary`` items and ``--designs`` CSV.

Each property states independently what the reader must do with any input: read exactly the valid values,
or refuse with an :class:`FpmSimError` that names the parameter and, for files, the first bad row's line
number. Derandomised, few examples, no model is built: the file runs in a second or two.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fpm_sim.config import default_config
from fpm_sim.designs import DesignError, parse_vary, read_designs_csv
from fpm_sim.study.identify.data import DataError, read_measured_csv

FAST = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
BASE = default_config()

# a cell: a number (any float, as Python writes it), a blank, or text a user might type
cell = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-400, 400).map(lambda v: f"{v:g}"),
    st.sampled_from(["", "n/a", "inf", "-inf", "nan", "abc", "3.1416", "-3.1416", "30", "0", "50", "-5"]),
)


def _number(text: str) -> float | None:
    """The finite number a cell holds, else None (the reader's rule, written out independently)."""
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _expected_measured(rows: list[tuple[str, str, str, str]]) -> tuple[int | None, list[tuple[float, ...]]]:
    """(index of the first bad row or None, the (x, y, phi, f) of the good rows with a frequency)."""
    good = []
    for i, (x, y, phi, f) in enumerate(rows):
        xv, yv = _number(x), _number(y)
        pv = 0.0 if not phi.strip() else _number(phi)
        if xv is None or yv is None or pv is None or abs(pv) > math.pi:
            return i, []
        if f.strip():
            fv = _number(f)
            if fv is None or not fv > 0:
                return i, []
            good.append((xv, yv, pv, fv))
    return None, good


@FAST
@given(
    rows=st.lists(st.tuples(cell, cell, cell, cell), min_size=0, max_size=5),
    bom=st.booleans(),
    crlf=st.booleans(),
    comment=st.booleans(),
)
def test_measured_csv_reads_exactly_the_valid_rows_or_names_the_first_bad_row(rows, bom, crlf, comment):
    lines = (["# measured on the rig"] if comment else []) + ["x_mm,y_mm,phi_rad,f1_hz"]
    lines += [",".join(r) for r in rows]
    text = ("\r\n" if crlf else "\n").join(lines) + "\n"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.csv"
        path.write_bytes(("\ufeff" if bom else "").encode() + text.encode())
        header_line = 2 if comment else 1
        bad, good = _expected_measured(rows)
        if not rows:
            with pytest.raises(DataError, match="only a header") as exc:
                read_measured_csv(path)
            assert exc.value.row == header_line
            return
        if bad is not None:
            with pytest.raises(DataError) as exc:
                read_measured_csv(path)
            assert exc.value.file == str(path)
            assert exc.value.row == header_line + 1 + bad
            assert exc.value.parameter in ("x_mm", "y_mm", "phi_rad", "f1_hz")
            return
        obs = read_measured_csv(path).observations
    assert [(o.pose.x_m, o.pose.y_m, o.pose.phi_rad, o.freq_hz) for o in obs] == [
        (x * 1e-3, y * 1e-3, p, f) for x, y, p, f in good
    ]
    assert all(o.mode == 1 and o.sigma_hz == pytest.approx(0.02 * o.freq_hz) for o in obs)


SETTABLE = ["section.thickness_m", "section.height_m", "material.young_pa", "hardware.payload.mass_kg"]
NOT_SETTABLE = ["section.area_m2", "section.width_m", "geometry", "name", "nope.field", ""]
spec = st.one_of(
    st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=4).map(lambda v: ",".join(repr(x) for x in v)),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.integers(-1, 5)).map(lambda t: f"{t[0]!r}:{t[1]!r}:{t[2]}"),
    st.sampled_from(["", "nan", "1,inf", "a,b", "1:2", "1:2:x", "1:2:3:4", ",", "0.01"]),
)


def _expected_spec(text: str) -> list[float] | None:
    parts = text.strip().split(":")
    if len(parts) == 3:
        try:
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            return None
        values = list(np.linspace(start, stop, count)) if count >= 1 else []
    elif len(parts) == 1:
        try:
            values = [float(v) for v in text.split(",") if v.strip()]
        except ValueError:
            return None
    else:
        return None
    return values if values and all(math.isfinite(v) for v in values) else None


@FAST
@given(items=st.lists(st.tuples(st.sampled_from(SETTABLE + NOT_SETTABLE), spec), min_size=1, max_size=3))
def test_vary_items_are_read_or_refused_naming_vary(items):
    argv = [f"{name}={s}" for name, s in items]
    names = [n for n, _ in items]
    ok = all(n in SETTABLE for n in names) and len(set(names)) == len(names)
    expected = {n: _expected_spec(s) for n, s in items}
    if ok and all(v is not None for v in expected.values()):
        assert parse_vary(argv, BASE) == expected  # the same arithmetic (np.linspace): exact
    else:
        with pytest.raises(DesignError) as exc:
            parse_vary(argv, BASE)
        assert exc.value.parameter == "vary"


@FAST
@given(
    header=st.lists(st.sampled_from(SETTABLE + NOT_SETTABLE[:2]), min_size=1, max_size=3),
    rows=st.lists(st.lists(cell, min_size=1, max_size=3), min_size=0, max_size=4),
)
def test_designs_csv_is_read_or_refused_naming_designs(header, rows):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "d.csv"
        path.write_text("\n".join([",".join(header)] + [",".join(r) for r in rows]) + "\n")
        kept = [r for r in rows if any(c.strip() for c in r)]  # blank lines are skipped
        ok = (
            len(set(header)) == len(header)
            and all(h in SETTABLE for h in header)
            and kept
            and all(len(r) == len(header) and all(_number(c) is not None for c in r) for r in kept)
        )
        if ok:
            assert read_designs_csv(path, BASE) == [{h: float(c) for h, c in zip(header, r)} for r in kept]
        else:
            with pytest.raises(DesignError) as exc:
                read_designs_csv(path, BASE)
            assert exc.value.parameter == "designs"
