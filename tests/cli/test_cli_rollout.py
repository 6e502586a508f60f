"""``fpm-sim rollout``: files written, servo torques, and errors naming the option."""

import json

import numpy as np

from fpm_sim.cli.main import main


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


BASE = ["rollout", "--segments", "3", "--no-axial", "--thickness-mm", "5", "--duration-s", "0.003"]


def test_rollout_csv_and_plot(capsys, tmp_path):
    csv, png = tmp_path / "r.csv", tmp_path / "r.png"
    code, text, _ = run(capsys, *BASE, "--force-y-n", "5", "--out", str(csv), "--plot", str(png))
    assert code == 0
    assert "disp y (mm)" in text
    table = np.genfromtxt(csv, delimiter=",", names=True)
    assert len(table) == 31
    assert table["disp_y_m"][-1] > 0
    assert np.allclose(table["load_fy_n"], 5.0)
    assert "acc_distal_0_p2_x_m_s2" in table.dtype.names
    assert png.stat().st_size > 1000


def test_rollout_servo_torque_json(capsys):
    code, text, _ = run(
        capsys,
        *BASE,
        "--motors",
        "servo",
        "--servo-stiffness-nm-per-rad",
        "500",
        "--motor-torque-nm",
        "1",
        "0",
        "0",
        "--json",
    )
    assert code == 0
    payload = json.loads(text)
    assert payload["parameters"]["motors"]["mode"] == "servo"
    assert payload["peak_abs_disp"]["x_m"] > 0


def test_rollout_errors(capsys):
    code, _, err = run(capsys, *BASE, "--motor-torque-nm", "1", "0", "0")
    assert code == 2
    assert "motors.mode = 'servo'" in err
    code, _, err = run(capsys, *BASE, "--motors", "servo")
    assert code == 2
    assert "--servo-stiffness-nm-per-rad" in err
    code, _, err = run(capsys, *BASE, "--out", "x.txt")
    assert code == 2
    assert "--out" in err
