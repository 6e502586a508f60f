import csv
import json
import math

import numpy as np
import pytest

from fpm_sim.cli.main import main
from fpm_sim.study.reproduce import error_stats
from fpm_sim.study.reproduce_report import POSES_CSV_COLUMNS


def test_error_stats_in_the_studys_form():
    st = error_stats(np.array([110.0, 90.0, np.nan, 50.0]), np.array([100.0, 100.0, 20.0, np.nan]))
    assert st["n"] == 2
    assert st["max_abs_hz"] == 10.0
    assert st["mean_abs_pct"] == 10.0
    assert st["median_abs_hz"] == 10.0
    assert st["mean_signed_pct"] == 0.0


def test_reproduce_writes_csv_report_and_figures(tmp_path, capsys):
    # a fixed description (the default before its identify re-run), so that the reading's mechanics are
    # tested on a geometry whose study poses are all away from singularities under every reading
    import re

    from fpm_sim.config import config_to_toml, default_config

    text = config_to_toml(default_config())
    for key, value in (
        ("base_radius_m", "0.1526"),
        ("base_angles_deg", "[150.8546, -89.1454, 30.8546]"),
        ("proximal_length_m", "0.1515"),
        ("distal_length_m", "0.1535"),
        ("platform_radius_m", "0.0874"),
        ("platform_angles_deg", "[-178.6021, -58.6021, 61.3979]"),
        ("elbow_branch", "[-1, -1, -1]"),
    ):
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    cfg = tmp_path / "ref.toml"
    cfg.write_text(text)
    out = tmp_path / "rep"
    code = main(
        [
            "reproduce",
            "--config",
            str(cfg),
            "--segments",
            "2",
            "--workers",
            "1",
            "--out",
            str(out),
            "--reading",
            "y-",
            "--json",
        ]
    )
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
        assert float(r["x_mm"]) == float(r["col_mm"])
        assert float(r["y_mm"]) == float(r["row_mm"])
        assert float(r["phi_rad"]) == (-0.2 if float(r["col_mm"]) == 0 else 0.0)
        assert all(math.isfinite(float(r[f"f{k}_hz"])) for k in (1, 2, 3))
    report = (out / "report.md").read_text()
    for needle in ("Subsystem tests", "The 25 poses", "Error statistics", "provenance", "Mode-1 readability"):
        assert needle in report
    assert (out / "heatmaps.png").stat().st_size > 0
    assert (out / "subsystems.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["reproduce", "--reading", "q+"], "--reading"),
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
