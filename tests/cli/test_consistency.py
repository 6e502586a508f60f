"""One resolution policy: at their defaults, every command that reports the first natural frequency at
(0, 0, 0) reports the same one (issue: 72.88 / 73.50 / 74.58 Hz from 12 / 6 / 4 segment defaults before).

Measured with the shared default (fidelity standard, 12 segments per link): modes 72.880135 Hz
(transitionFD, gravity, axial springs), sweep/reduce/frf/atlas/impact 72.880210 Hz (constrained or the
pose loop, gravity off or inextensible): the methods differ by 1.0e-6 relative, gravity's prestress and
the axial springs by < 1e-5 (measured: 73.50239 vs 73.50263 Hz at 6 segments over all eight combinations).
The 0.1 % asked for is 100 times the largest of these; a different segment count moves f1 by 0.85 %
(6 vs 12), so the test fails if any command gets its own resolution default back.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fpm_sim.cli.main import main

AGREEMENT = 1e-5  # measured spread 1.0e-6 (method, gravity, axial springs) times a margin of 10; the issue asks 1e-3


def run_json(capsys, *argv: str) -> dict:
    code = main([*argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_defaults_agree_on_f1(capsys, tmp_path):
    f1 = {}
    res = {}
    d = run_json(capsys, "modes", "--n-modes", "1")
    f1["modes"], res["modes"] = d["modes"][0]["frequency_hz"], d["resolution"]
    d = run_json(capsys, "reduce", "--modes", "1")
    f1["reduce"], res["reduce"] = d["frequencies_hz"][0], d["resolution"]
    d = run_json(capsys, "frf", "--f-max-hz", "100", "--df-hz", "1")
    f1["frf"], res["frf"] = d["modal_freq_hz"][0], d["resolution"]
    # the grid step does not change the model; 50 mm keeps the grid small and holds (0, 0)
    d = run_json(capsys, "sweep", "--step-mm", "50", "--workers", "1", "--out", str(tmp_path / "sweep"))
    (row,) = [r for r in d["rows"] if r["x_mm"] == 0 and r["y_mm"] == 0]
    f1["sweep"], res["sweep"] = row["f1_hz"], d["resolution"]
    atlas = tmp_path / "a.npz"
    run_json(capsys, "atlas", "build", "--x-mm", "-50", "0", "50", "--y-mm", "-50", "0", "50", "--modes", "2",
             "--out", str(atlas))
    d = run_json(capsys, "atlas", "query", str(atlas))
    f1["atlas query"], res["atlas query"] = d["frequencies_hz"][0], d["resolution"]
    values = np.array(list(f1.values()))
    spread = values.max() / values.min() - 1.0
    assert spread < AGREEMENT, f1
    # every result states the same resolution and its error estimate (0.41 / 12^2 = 0.28 %)
    for name, r in res.items():
        assert r["segments"] == 12, (name, r)
        assert r["link_model"] == "segments", (name, r)
        assert r["f1_error_estimate"] == pytest.approx(0.41 / 144), (name, r)


@pytest.mark.slow
def test_impact_modal_f1_agrees_with_modes(capsys):
    """The impact command at the shared default (a short record keeps it to minutes: its rollouts need
    0.27 us steps at 12 segments per link, measured)."""
    d = run_json(capsys, "impact", "--impacts", "1", "--record-s", "0.02")
    m = run_json(capsys, "modes", "--n-modes", "1")
    assert d["resolution"]["segments"] == m["resolution"]["segments"] == 12
    assert abs(d["modal_f1_hz"] / m["modes"][0]["frequency_hz"] - 1.0) < AGREEMENT
