import json

import pytest

from fpm_sim.cli.main import main


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_modes_json(capsys):
    code, out, _ = run(capsys, "modes", "--x-mm", "20", "--y-mm", "-10", "--segments", "3", "--n-modes", "4", "--json")
    assert code == 0
    data = json.loads(out)
    freqs = [m["frequency_hz"] for m in data["modes"]]
    assert len(freqs) == 4
    assert freqs == sorted(freqs)
    assert all("damping_ratio" in m for m in data["modes"])
    assert data["parameters"]["pose"] == {"x_m": 0.02, "y_m": -0.01, "phi_rad": 0.0}
    assert data["parameters"]["options"]["segments"] == 3


def test_modes_shapes_and_plot(capsys, tmp_path):
    png = tmp_path / "m.png"
    code, out, _ = run(capsys, "modes", "--segments", "2", "--n-modes", "2", "--json", "--shapes", "--plot", str(png))
    assert code == 0
    assert png.stat().st_size > 1000
    data = json.loads(out)
    pts = data["modes"][0]["points_displacement"]
    assert len(pts["distal_1"]) == 4  # 2 segments -> 3 pieces -> 4 points
    peak = max(sum(c * c for c in p) ** 0.5 for link in pts.values() for p in link)
    assert abs(peak - 1.0) < 1e-12


def test_modes_table_both_methods(capsys):
    code, out, _ = run(capsys, "modes", "--segments", "3", "--n-modes", "3", "--method", "both")
    assert code == 0
    assert "transitionFD" in out
    assert "constrained" in out


def test_rig_json(capsys):
    code, out, _ = run(
        capsys,
        "rig",
        "chain",
        "--angle-deg",
        "90",
        "--segments",
        "4",
        "--n-modes",
        "2",
        "--json",
        "--thickness-mm",
        "12",
    )
    assert code == 0
    data = json.loads(out)
    assert data["parameters"]["rig"]["angle_deg"] == 90.0
    assert data["parameters"]["piece"]["section"]["thickness_m"] == 0.012


def test_config_template_round_trips(tmp_path, capsys):
    code, out, _ = run(capsys, "config")
    assert code == 0
    path = tmp_path / "c.toml"
    path.write_text(out)
    code, out, _ = run(capsys, "config", "--config", str(path))
    assert code == 0
    assert "geometry.base_radius_m" in out
    assert "assumed:" in out
    code, out, _ = run(capsys, "config", "--json")
    data = json.loads(out)
    assert data["compliance"]["motor_clamp_nm_per_rad"] == "inf"
    assert data["provenance"]["section.thickness_m"].startswith(("study", "assumed", "identified"))


def test_export_mjcf(tmp_path, capsys):
    out_file = tmp_path / "m.xml"
    code, _out, _ = run(capsys, "export-mjcf", "manipulator", "--segments", "2", "--out", str(out_file))
    assert code == 0
    assert out_file.read_text().startswith("<mujoco")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["modes", "--link-model", "noodle"], "--link-model"),
        (["modes", "--x-mm", "600"], "unreachable"),
        (["modes", "--segments", "0"], "--segments"),
        (["rig", "chain", "--angle-deg", "300"], "--angle-deg"),
        (["rig", "cantilever", "--clamped-length-mm", "1000"], "--clamped-length-mm: must be shorter than"),
        (["rig", "cantilever", "--poisson", "0.7"], "--poisson: must lie in (-1, 0.5), got 0.7"),
        (["modes", "--config", "/nonexistent.toml"], "not found"),
    ],
)
def test_errors_are_clear(capsys, argv, message):
    code, _, err = run(capsys, *argv)
    assert code == 2
    assert message in err
