import csv
import json
import math

import numpy as np
import pytest

from fpm_sim.cli import main
from fpm_sim.study_comparison import POSES_CSV_COLUMNS, error_stats


def test_error_stats_in_the_studys_form():
    st = error_stats(np.array([110.0, 90.0, np.nan, 50.0]), np.array([100.0, 100.0, 20.0, np.nan]))
    assert st["n"] == 2
    assert st["max_abs_hz"] == 10.0 and st["mean_abs_pct"] == 10.0 and st["median_abs_hz"] == 10.0
    assert st["mean_signed_pct"] == 0.0


def test_reproduce_writes_csv_report_and_figures(tmp_path, capsys):
    out = tmp_path / "rep"
    code = main(["reproduce", "--segments", "2", "--workers", "1", "--out", str(out), "--reading", "y-", "--json"])
    assert code == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["reading"] == "row=y,phi=-0.2"
    with open(out / "poses.csv") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == POSES_CSV_COLUMNS
    assert len(rows) == 26
    data = [dict(zip(rows[0], r)) for r in rows[1:]]
    assert sum(r["comsol_hz"] == "" for r in data) == 7
    for r in data:
        assert float(r["x_mm"]) == float(r["col_mm"]) and float(r["y_mm"]) == float(r["row_mm"])  # rows are y
        assert float(r["phi_rad"]) == (-0.2 if float(r["col_mm"]) == 0 else 0.0)
        assert all(math.isfinite(float(r[f"f{k}_hz"])) for k in (1, 2, 3))
    report = (out / "report.md").read_text()
    for needle in ("Subsystem tests", "The 25 poses", "Error statistics", "provenance"):
        assert needle in report
    assert (out / "heatmaps.png").stat().st_size > 0 and (out / "subsystems.png").stat().st_size > 0


def test_sweep_keeps_every_point_with_a_status(tmp_path, capsys):
    code = main(
        ["sweep", "--grid", "dense", "--step-mm", "100", "--segments", "2", "--workers", "1", "--out", str(tmp_path)]
    )
    assert code == 0
    with open(tmp_path / "sweep_dense.csv") as fh:
        rows = list(csv.DictReader(fh))
    statuses = {r["status"] for r in rows}
    assert "ok" in statuses and "unreachable" in statuses
    for r in rows:
        assert (r["f1_hz"] == "") == (r["status"] in ("unreachable", "singular"))
    assert (tmp_path / "sweep_dense.png").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["reproduce", "--reading", "q+"], "x+, x-"),
        (["reproduce", "--thickness-mm", "-5"], "--thickness-mm"),
        (["sweep", "--step-mm", "0"], "--step-mm"),
        (["reproduce", "--backend", "gpu-dream"], "--backend"),
        (["reproduce", "--segments", "0"], "--segments"),
    ],
)
def test_bad_input_is_named(capsys, argv, message, tmp_path):
    code = main([*argv, "--out", str(tmp_path)])
    assert code == 2
    assert message in capsys.readouterr().err


def test_singularity_fields_match_the_kinematics_module(default_manip):
    from fpm_sim.kinematics import Pose, UnreachablePoseError, inverse_kinematics
    from fpm_sim.workspace_sweep import singularity_fields

    xs, ys = np.array([-120.0, 0.0, 90.0, 400.0]), np.array([-80.0, 0.0, 60.0])
    det, ser = singularity_fields(default_manip, xs, ys, 0.1)
    for iy, y in enumerate(ys):
        for ix, x in enumerate(xs):
            try:
                asm = inverse_kinematics(default_manip.geometry, Pose.from_mm(x, y, 0.1), check_singularity=False)
            except UnreachablePoseError:
                assert np.isnan(det[iy, ix]) and np.isnan(ser[iy, ix])
                continue
            assert ser[iy, ix] == pytest.approx(asm.singularity.serial, abs=1e-12)
            assert np.isfinite(det[iy, ix])
