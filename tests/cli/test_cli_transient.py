"""``fpm-sim transient``: the study's command writes the CSV with the agreed columns."""

import json

from fpm_sim.cli.main import main


def test_transient_command(capsys, tmp_path):
    code = main(["transient", "--study", "--segments", "3", "--duration-s", "0.01", "--out", str(tmp_path), "--json"])
    out = capsys.readouterr().out
    assert code == 0
    payload = json.loads(out)
    assert set(payload["cases"]) == {"x", "y"}
    assert payload["parameters"]["thickness_m"] == 0.005
    assert payload["parameters"]["motors"] == "locked"
    assert (tmp_path / "transient.csv").read_text().splitlines()[0] == "t_s,load_axis,disp_full_m,disp_rom_m"
    assert (tmp_path / "transient.png").exists()
    assert (tmp_path / "summary.json").exists()


def test_transient_errors(capsys):
    code = main(["transient", "--study", "--segments", "3", "--force-n", "-1"])
    assert code == 2
    assert "--force-n" in capsys.readouterr().err
