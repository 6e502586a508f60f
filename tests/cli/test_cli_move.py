"""``fpm-sim move`` and the time-stepping options of the time-domain commands: outputs, JSON, errors."""

import json

import numpy as np
import pytest

from fpm_sim.cli.main import main


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_parser_mirrors_agree_with_the_library():
    from fpm_sim.cli import move as cli_move
    from fpm_sim.cli import rollout as cli_rollout
    from fpm_sim.sim import stepping, trajectory

    assert cli_rollout.INTEGRATORS == stepping.INTEGRATORS
    assert cli_rollout.INTEGRATORS[0] == stepping.DEFAULT_INTEGRATOR
    assert cli_rollout.BAND_F1_MULTIPLE == stepping.BAND_F1_MULTIPLE
    assert cli_rollout.MAX_NUMERICAL_DAMPING == stepping.MAX_NUMERICAL_DAMPING
    assert cli_move.PROFILES == trajectory.PROFILES
    assert cli_move.SHAPERS == trajectory.SHAPERS
    assert cli_move.DEFAULT_SETTLE_TOL_MM == pytest.approx(trajectory.DEFAULT_SETTLE_TOL_M * 1e3)


def test_move_json_csv_and_plot(capsys, tmp_path):
    csv, png = tmp_path / "m.csv", tmp_path / "m.png"
    argv = ["move", "--segments", "3", "--to-x-mm", "5", "--move-s", "0.1", "--settle-s", "0.1", "--json"]
    code, out, err = run(capsys, *argv, "--out", str(csv), "--plot", str(png), "--shaper", "zv")
    assert code == 0, err
    d = json.loads(out)
    assert d["shaper"] == "zv"
    assert len(d["shaper_impulses"]["times_s"]) == 2
    assert d["stepping"]["integrator"] == "discrete"
    assert d["stepping"]["numerical_damping_at_band_top"] <= 0.02
    assert d["residual"]["modal_f1_hz"] > 0
    table = np.genfromtxt(csv, delimiter=",", names=True)
    assert table["command_x_m"][-1] == pytest.approx(5e-3)
    assert png.stat().st_size > 1000


def test_move_path_csv(capsys, tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("t_s,x_mm,y_mm,phi_rad\n0,0,0,0\n0.05,2,1,0\n0.1,4,1,0\n")
    code, out, err = run(capsys, "move", "--segments", "3", "--path-csv", str(path), "--settle-s", "0.1", "--json")
    assert code == 0, err
    assert json.loads(out)["parameters"]["profile"] == "csv"


@pytest.mark.parametrize(
    ("extra", "option"),
    [
        (["--move-s", "0"], "--move-s"),
        (["--settle-s", "-1"], "--settle-s"),
        (["--to-x-mm", "nan"], "--to-x-mm"),
        (["--to-phi-rad", "4"], "--to-phi-rad"),
        (["--band-hz", "-5"], "--band-hz"),
        (["--path-csv", "nowhere.csv"], "--path-csv"),
        (["--out", "m.txt"], "--out"),
    ],
)
def test_move_errors_name_the_option(capsys, extra, option):
    code, _, err = run(capsys, "move", "--segments", "3", *extra)
    assert code == 2
    assert err.startswith("error: ")
    assert option in err


def test_move_path_csv_errors_name_the_file_and_row(capsys, tmp_path):
    bad = tmp_path / "path.csv"
    bad.write_text("t_s,x_mm,y_mm,phi_rad\n0,0,0,0\n0.1,nan,0,0\n")
    code, _, err = run(capsys, "move", "--segments", "3", "--path-csv", str(bad))
    assert code == 2
    assert err.splitlines()[-1] == f"error: {bad}: row 3: path_csv: every value must be finite, got '0.1,nan,0,0'"
    bad.write_text("t_s,x_mm,y_mm,phi_rad\n0,0,0,0\n0.1,1,0,0\n")  # a good path cannot be shaped
    code, _, err = run(capsys, "move", "--segments", "3", "--path-csv", str(bad), "--shaper", "zv")
    assert code == 2
    assert err.splitlines()[-1].startswith("error: --shaper: a shaper shapes a profile move")


def test_rollout_integrator_option(capsys):
    base = ["rollout", "--segments", "3", "--no-axial", "--thickness-mm", "5", "--duration-s", "0.003", "--json"]
    code, out, err = run(capsys, *base, "--force-x-n", "1", "--integrator", "explicit")
    assert code == 0, err
    explicit = json.loads(out)
    code, out, err = run(capsys, *base, "--force-x-n", "1", "--band-hz", "500")
    assert code == 0, err
    discrete = json.loads(out)
    assert explicit["stepping"]["integrator"] == "explicit"
    assert explicit["stepping"]["numerical_damping_at_band_top"] == 0.0
    assert discrete["stepping"]["integrator"] == "discrete"
    assert discrete["stepping"]["band_hz"] == 500.0
    assert discrete["stepping"]["step_s"] > explicit["stepping"]["step_s"]
    # --timestep-s with the discrete integrator sets its step (the model keeps its own for the welds)
    code, out, err = run(capsys, *base, "--timestep-s", "5e-5")
    assert code == 0, err
    assert json.loads(out)["stepping"]["step_s"] == 5e-5
    code, _, err = run(capsys, *base, "--band-hz", "1e6")
    assert code == 2
    line = err.splitlines()[-1]
    assert line.startswith("error: --band-hz: the discrete step from it, ")
    assert line.endswith(", got 1000000.0; use the explicit integrator, or a lower band")
    code, _, err = run(capsys, *base, "--timestep-s", "1e-9")  # the discrete step itself
    assert code == 2
    assert err.splitlines()[-1].startswith("error: --timestep-s: the discrete step from it, 1e-09 s, is below the ")


def test_transient_and_impact_integrator_options(capsys):
    argv = ["transient", "--study", "--segments", "3", "--duration-s", "0.01", "--json", "--step-band-hz", "300"]
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    d = json.loads(out)
    assert d["stepping"]["band_hz"] == 300.0
    assert d["stepping"]["band_source"] == "given"
    # the stepping's band is transient's --step-band-hz (its --band-hz is the reduced model's band)
    code, _, err = run(capsys, *argv[:-2], "--step-band-hz", "1e6")
    assert code == 2
    assert err.splitlines()[-1].startswith("error: --step-band-hz: the discrete step from it, ")
    code, _, err = run(capsys, "impact", "--segments", "3", "--integrator", "explicit", "--implicit-step-s", "1e-5")
    assert code == 2
    assert "--implicit-step-s" in err
