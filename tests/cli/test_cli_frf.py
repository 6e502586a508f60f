"""The frf, impact, readability and atlas commands: JSON payloads, files written, user errors (exit 2)."""

import json

import numpy as np
import pytest
from conftest import SYMMETRIC_CONFIG

from fpm_sim.cli.main import main
from fpm_sim.rom.reduction import load_reduced_model


def run(capsys, *argv):
    # every command runs on the symmetric test fixture, not the identified default
    code = main([*argv, "--config", str(SYMMETRIC_CONFIG)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_frf_json_csv_and_plot(capsys, tmp_path):
    csv, png = tmp_path / "frf.csv", tmp_path / "frf.png"
    code, text, _ = run(
        capsys, "frf", "--segments", "3", "--no-axial", "--x-mm", "50", "--f-max-hz", "300",
        "--csv", str(csv), "--plot", str(png), "--json",
    )  # fmt: skip
    assert code == 0
    d = json.loads(text)
    assert d["excitation"] == "distal_0@0.5/z"
    assert d["response"] == "distal_0@0.5/z"
    # the first FRF peak is the first mode (driving point, 1 % damping)
    assert d["peaks"][0]["freq_hz"] == pytest.approx(d["modal_freq_hz"][0], rel=1e-3)
    raw = np.loadtxt(csv, delimiter=",", skiprows=2)
    assert raw.shape[1] == 6
    assert raw[-1, 0] == pytest.approx(300.0)
    assert png.stat().st_size > 1000


def test_frf_table_with_user_damping(capsys):
    code, text, _ = run(
        capsys, "frf", "--segments", "3", "--no-axial", "--damping-ratio", "0.03", "--output-link", "distal_2",
        "--output-axis", "z", "--quantity", "mobility",
    )  # fmt: skip
    assert code == 0
    assert "mobility (m/s/N) from distal_0@0.5/z to distal_2@0.5/z" in text
    assert "0.0300" in text


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--input-link", "distal_5"], "unknown link"),
        (["--input-fraction", "2"], "fraction"),
        (["--damping-ratio", "1.5"], "damping"),
        (["--f-max-hz", "0"], "--f-max-hz"),
        (["--csv", "x.txt"], ".csv"),
        (["--link-model", "rigid"], "flexible links"),
    ],
)
def test_frf_errors(capsys, argv, match):
    code, _, err = run(capsys, "frf", "--segments", "3", "--no-axial", *argv)
    assert code == 2
    assert match in err


def test_impact_json(capsys, tmp_path):
    csv = tmp_path / "h1.csv"
    code, text, _ = run(
        capsys, "impact", "--segments", "3", "--record-s", "0.1", "--impacts", "2", "--csv", str(csv), "--json",
    )  # fmt: skip
    assert code == 0
    d = json.loads(text)
    assert {"first_peak_hz", "modal_f1_hz", "relative_error"} <= d.keys()
    assert len(d["impacts"]) == 2
    assert d["setup"]["impact"] == "distal_0@0.5/z"
    # a 0.1 s record still puts the first peak within 2 % (the line spacing comes from the zero padding)
    assert abs(d["relative_error"]) < 0.02
    assert "coherence" in csv.read_text().splitlines()[1]


def test_impact_errors(capsys):
    code, _, err = run(capsys, "impact", "--segments", "3", "--impacts", "0")
    assert code == 2
    assert "--impacts" in err  # the CLI names its option for the parameter n_impacts
    code, _, err = run(capsys, "impact", "--segments", "1")
    assert code == 2
    assert "--segments" in err


def test_readability_markdown(capsys, tmp_path):
    md, png = tmp_path / "readability.md", tmp_path / "readability.png"
    code, text, _ = run(
        capsys, "readability", "--segments", "3", "--markdown", str(md), "--plot", str(png), "--json"
    )  # fmt: skip
    assert code == 0
    d = json.loads(text)
    assert len(d["rows"]) == 25
    assert sum(r["study_unreadable"] for r in d["rows"]) == 7
    assert len(d["agreement"]) == 3
    assert md.read_text().count("\n| (") == 25
    assert png.stat().st_size > 1000


def test_atlas_build_and_query(capsys, tmp_path):
    atlas, rom, png = tmp_path / "atlas.npz", tmp_path / "rom.mat", tmp_path / "atlas.png"
    code, text, _ = run(
        capsys, "atlas", "build", "--segments", "3", "--x-mm", "-50", "0", "50", "--y-mm", "0", "50",
        "--modes", "4", "--out", str(atlas), "--plot", str(png),
    )  # fmt: skip
    assert code == 0
    assert "mode 4" in text
    assert atlas.exists()
    assert "weak links" in text
    assert png.stat().st_size > 1000
    code, text, _ = run(
        capsys, "atlas", "query", str(atlas), "--x-mm", "25", "--y-mm", "25", "--direct", "--out", str(rom), "--json",
    )  # fmt: skip
    assert code == 0
    d = json.loads(text)
    # linear interpolation (3 x 2 grid) across 50 mm: f1..f3 within 2 % (the target; measured 0.33 %).
    # Mode 4 changes character between these grid poses (the build reports weak links there), so it is not
    # held to that
    assert np.max(np.abs(d["relative_difference"][:3])) < 0.02
    assert d["direct_mode_index"][:3] == [1, 2, 3]
    assert min(d["mac"][:3]) > 0.99
    assert load_reduced_model(rom).n_modes == 4


def test_atlas_errors(capsys, tmp_path):
    code, _, err = run(capsys, "atlas", "query", str(tmp_path / "none.npz"))
    assert code == 2
    assert "not found" in err
    code, _, err = run(capsys, "atlas", "build", "--segments", "3", "--out", str(tmp_path / "a.txt"))
    assert code == 2
    assert ".npz" in err
    code, _, err = run(
        capsys, "atlas", "build", "--segments", "3", "--x-mm", "0", "--y-mm", "0", "--modes", "2",
        "--out", str(tmp_path / "a.npz"),
    )  # fmt: skip
    assert code == 0
    code, _, err = run(capsys, "atlas", "query", str(tmp_path / "a.npz"), "--x-mm", "10")
    assert code == 2
    assert "single value" in err
