"""``fpm-sim reduce``: export, round trip through the .mat file, errors."""

import json

import numpy as np
import pytest

from fpm_sim.cli.main import main
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.reduction import load_reduced_model, reduce_model


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_reduce_mat_round_trip(capsys, tmp_path):
    out = tmp_path / "rom.mat"
    args = ["--x-mm", "50", "--y-mm", "-50", "--phi-rad", "0.1", "--segments", "3", "--no-axial"]
    code, text, _ = run(capsys, "reduce", *args, "--modes", "6", "--out", str(out), "--json")
    assert code == 0
    payload = json.loads(text)
    assert payload["n_modes"] == 6
    assert payload["pose"] == {"x_m": 0.05, "y_m": -0.05, "phi_rad": 0.1}
    back = load_reduced_model(out)
    # the same reduction through the API gives the same matrices as the file holds
    built = build_manipulator(default_config(), Pose(0.05, -0.05, 0.1), ModelOptions(segments=3, axial=False))
    rom = reduce_model(built, n_modes=6)
    for name in ("a", "b", "c", "d"):
        assert np.array_equal(getattr(back, name), getattr(rom, name)), name
    assert back.input_names == ["force_x", "force_y", "moment_z"]
    assert back.output_names[:3] == ["disp_x", "disp_y", "rot_z"]
    assert np.allclose(back.frequencies_hz, rom.frequencies_hz)


def test_reduce_table_and_band(capsys):
    code, text, _ = run(capsys, "reduce", "--segments", "3", "--no-axial", "--band-hz", "300")
    assert code == 0
    assert "freq (Hz)" in text
    assert "force_x (N)" in text
    assert "acc_distal_0 (m/s^2)" in text


def test_reduce_servo_motors_add_torque_inputs(capsys):
    code, text, _ = run(
        capsys,
        "reduce",
        "--segments",
        "3",
        "--no-axial",
        "--modes",
        "4",
        "--motors",
        "servo",
        "--servo-stiffness-nm-per-rad",
        "500",
        "--json",
    )
    assert code == 0
    assert json.loads(text)["inputs"][3:] == ["motor_torque_0 (N m)", "motor_torque_1 (N m)", "motor_torque_2 (N m)"]


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--modes", "0"], "--modes"),
        (["--modes", "2", "--out", "rom.txt"], ".mat or .npz"),
        (["--error-bound", "3"], "--error-bound"),
        (["--modes", "2", "--motors", "servo"], "--servo-stiffness-nm-per-rad"),
    ],
)
def test_reduce_errors(capsys, argv, match):
    code, _, err = run(capsys, "reduce", "--segments", "3", "--no-axial", *argv)
    assert code == 2
    assert match in err
