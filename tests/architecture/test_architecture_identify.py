"""``identify`` on a described architecture: dotted paths fitted to frequencies at poses in its task coordinates.

Truth is a twin experiment: the file's machine with known edits computes the "measured" frequencies; the fit from the
file's own values must return the edits, and the fitted file it writes must read back to the fitted machine."""

from __future__ import annotations

import json
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.architecture import (
    TaskPose,
    description_toml,
    description_value,
    load_description,
    parse_description,
    settable_paths,
    with_description_value,
)
from fpm_sim.batch.task_sweep import sweep_task_many
from fpm_sim.cli.main import main
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.identify.described import identify_description, parse_free_paths, read_task_measured_csv

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = EXAMPLES / "five_bar.toml"
COARSE = ModelOptions(segments=2, gravity=False, axial=False)  # the twin and the fit share it: any resolution will do
TRUTH = {"sections.bar.height_m": 0.0068, "lumps.end_effector.mass_kg": 0.3}


def _measured(tmp_path: Path) -> Path:
    """The five-bar with TRUTH's edits at its first three check poses, as a measured file (f1..f3)."""
    desc = load_description(FIVE_BAR)
    for path, value in TRUTH.items():
        desc = with_description_value(desc, path, value)
    poses = [TaskPose(p["x"], p["y"]) for p in desc.check_poses[:3]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (sw,) = sweep_task_many([desc], poses, options=COARSE, n_modes=3)
    lines = ["x_mm,y_mm,f1_hz,f2_hz,f3_hz"]
    for p, row in zip(poses, sw.freq_hz):
        lines.append(f"{p.x_m * 1e3:g},{p.y_m * 1e3:g}," + ",".join(repr(float(f)) for f in row))
    path = tmp_path / "measured.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_twin_experiment_returns_the_edits():
    """Noise-free data from known edits: bounded least squares from the file's values returns them (the residual's
    minimum is exact; 1e-6 is the solver's tolerance with a finite-difference Jacobian, measured 2e-14)."""
    desc = load_description(FIVE_BAR)
    with tempfile.TemporaryDirectory() as tmp:
        data = read_task_measured_csv(_measured(Path(tmp)), desc)
    free = parse_free_paths("sections.bar.height_m,lumps.end_effector.mass_kg=0.1:0.5", desc)
    assert free["sections.bar.height_m"] == (0.0015, 0.024)  # a factor of 4 either side by default
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify_description(desc, data, free, options=COARSE)
    np.testing.assert_allclose(result.values, list(TRUTH.values()), rtol=1e-6)
    assert all(abs(r["error_pct"]) < 1e-4 for r in result.rows())
    assert np.all(np.isfinite(result.std))
    assert np.all(result.std > 0)
    assert description_value(result.fitted, "sections.bar.height_m") == pytest.approx(0.0068, rel=1e-6)
    assert result.fitted.provenance["sections.bar.height_m"].startswith("identified: measured.csv")
    assert json.dumps(result.to_dict())


def test_the_command_writes_a_fitted_file_that_reads_back(tmp_path, capsys):
    measured = _measured(tmp_path)
    out = tmp_path / "id"
    argv = ["identify", "--config", str(FIVE_BAR), "--measured", str(measured), "--free", "sections.bar.height_m"]
    assert main([*argv, "--segments", "2", "--out", str(out), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    (param,) = payload["result"]["parameters"]
    assert param["path"] == "sections.bar.height_m"
    assert 0.006 < param["value"] < 0.0068  # the end effector's mass is held at 0.25 kg: the height takes up some of it
    fitted = load_description(out / "description.toml")
    assert description_value(fitted, "sections.bar.height_m") == param["value"]
    assert fitted.provenance["sections.bar.height_m"].startswith("identified: measured.csv")
    assert (out / "identify.json").is_file()
    assert (out / "identify.png").stat().st_size > 0


@pytest.mark.parametrize("name", ["five_bar", "delta", "three_prr", "serial_arm", "three_rrr"])
def test_a_written_description_reads_back_to_the_same_machine(name):
    """description_toml after an edit: the same machine, the same provenance, the same mapping."""
    import tomllib

    desc = load_description(EXAMPLES / f"{name}.toml")
    path = settable_paths(desc)[0]
    edited = with_description_value(desc, path, 1.01 * description_value(desc, path))
    text = description_toml(edited, header="a header\nof two lines")
    back = parse_description(tomllib.loads(text))
    assert back == edited
    assert back.provenance == edited.provenance
    assert tomllib.loads(text) == edited.data


@pytest.mark.parametrize(
    ("extra", "start"),
    [
        ([], "error: --free geometry,hardware: the 3RRR's parameter groups"),
        (["--free", "sections.bars.height_m"], "error: --free: field 'sections.bars.height_m': unknown"),
        (["--free", "sections.bar.height_m=0.007:0.009"], "error: --free: sections.bar.height_m: bounds must hold"),
        (["--free", "sections.bar.height_m", "--folds", "3"], "error: --folds: an option of the 3RRR's"),
        (["--free", "sections.bar.height_m", "--global", "none"], "error: --global: an option of the 3RRR's"),
    ],
)
def test_the_3rrr_s_groups_an_unknown_path_and_its_options_are_one_error_line(extra, start, tmp_path, capsys):
    (tmp_path / "m.csv").write_text("x_mm,y_mm,f1_hz\n0,250,30\n")
    argv = ["identify", "--config", str(FIVE_BAR), "--measured", str(tmp_path / "m.csv"), "--out", str(tmp_path / "o")]
    code = main([*argv, *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1, err
    assert err[0].startswith(start), err[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x_mm,f1_hz\n0,30\n", r"m\.csv: missing column\(s\) y_mm"),
        ("x_mm,y_mm,f1_hz\n0,250,-3\n", r"m\.csv: row 2: f1_hz: must be > 0"),
        ("x_mm,y_mm,f1_hz\n0,900,30\n", r"m\.csv: row 2: .*computes no f1 at this pose"),
    ],
)
def test_a_bad_measured_file_names_its_row(text, message, tmp_path, capsys):
    (tmp_path / "m.csv").write_text(text)
    argv = ["identify", "--config", str(FIVE_BAR), "--measured", str(tmp_path / "m.csv"), "--free",
            "sections.bar.height_m", "--segments", "2", "--out", str(tmp_path / "o")]  # fmt: skip
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1, err
    assert err[0].startswith("error: "), err
    assert re.search(message, err[0]), err[0]
