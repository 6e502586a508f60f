"""``fpm-sim sweep`` on described architectures: grids in their own task coordinates, poses files, refusals."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from fpm_sim.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"


def test_a_dense_five_bar_sweep_writes_its_map(tmp_path, capsys):
    out = tmp_path / "five"
    args = [
        "sweep",
        "--config",
        str(EXAMPLES / "five_bar.toml"),
        "--step-mm",
        "80",
        "--segments",
        "3",
        "--out",
        str(out),
    ]
    assert main([*args, "--json", "--workers", "1"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["task"] == ["x", "y"]
    assert {"ok", "unreachable"} <= set(payload["counts"])
    rows = list(csv.DictReader(open(out / "sweep_dense.csv")))
    assert set(rows[0]) >= {"x_mm", "y_mm", "status", "singularity_type1", "singularity_type2", "f1_hz"}
    assert "z_mm" not in rows[0]
    ok = [r for r in rows if r["status"] == "ok"]
    assert ok
    assert all(float(r["f1_hz"]) > 0 for r in ok)
    assert (out / "sweep_dense.png").stat().st_size > 0


def test_a_delta_sweep_reads_its_poses_file_in_x_y_z(tmp_path, capsys):
    poses = tmp_path / "poses.csv"
    poses.write_text("x_mm,y_mm,z_mm\n0,0,-300\n50,0,-320\n0,0,-1000\n")
    out = tmp_path / "delta"
    code = main(
        [
            "sweep",
            "--config",
            str(EXAMPLES / "delta.toml"),
            "--poses",
            str(poses),
            "--segments",
            "3",
            "--out",
            str(out),
            "--json",
            "--workers",
            "1",
        ]
    )
    assert code == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["status"] for r in rows] == ["ok", "ok", "unreachable"]
    assert rows[1]["z_mm"] == -320.0


@pytest.mark.parametrize(
    ("extra", "flag"),
    [
        (["--reading", "y-"], "--reading"),
        (["--thickness-mm", "5"], "--thickness-mm"),
        (["--grid", "paper"], "--grid paper"),
        (["--phi-rad", "0.1"], "--phi-rad"),
    ],
)
def test_the_study_s_options_are_refused_by_name(extra, flag, tmp_path, capsys):
    code = main(["sweep", "--config", str(EXAMPLES / "five_bar.toml"), "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert err[0].startswith(f"error: {flag}")
    assert not (tmp_path / "o").exists()


def test_the_jax_backend_on_the_delta_is_refused_by_the_joint_it_cannot_close(tmp_path, capsys):
    out = tmp_path / "o"
    code = main(["sweep", "--config", str(EXAMPLES / "delta.toml"), "--backend", "jax", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert err[0].startswith("error: --backend: chains[")
    assert "spherical" in err[0]
    assert not out.exists()
