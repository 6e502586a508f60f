"""``--posterior PATH [--draws N]`` on modes, sweep and reproduce: bands printed, in the JSON, written; bad
posterior files exit 2 with one error line. The posterior is the synthetic one of
tests/helpers/posterior.py (six draws of the default description, 4 segments)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.cli.main import main
from tests.helpers.posterior import write_posterior


@pytest.fixture(scope="module")
def post(tmp_path_factory):
    return str(write_posterior(tmp_path_factory.mktemp("cli_post") / "posterior.nc"))


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_modes_prints_bands_of_each_frequency(post, capsys, tmp_path):
    code, out, _ = run(capsys, "modes", "--posterior", post, "--n-modes", "2", "--plot", str(tmp_path / "b.png"))
    assert code == 0
    assert "6 of 6 draws" in out
    assert "5-95 % Hz" in out
    assert "4 segments" in out  # the likelihood's resolution by default
    assert (tmp_path / "b.png").stat().st_size > 0
    code, out, _ = run(capsys, "modes", "--posterior", post, "--n-modes", "2", "--draws", "4", "--json")
    assert code == 0
    d = json.loads(out)
    assert d["n_draws"] == 4
    row = d["bands"][0]
    f1 = np.array(d["frequencies_hz"])[:, 0, 0].astype(float)
    # the predictive median (parameters + the posterior's model discrepancy), near the draws' median
    assert row["f1_q50_hz"] == pytest.approx(np.median(f1), rel=0.05)
    assert row["f1_q05_hz"] <= row["f1_q25_hz"] <= row["f1_q50_hz"] <= row["f1_q75_hz"] <= row["f1_q95_hz"]
    assert d["posterior"]["free_groups"] == ["section-height", "hardware"]


def test_sweep_prints_bands_and_names_where_to_measure_next(post, capsys, tmp_path):
    out_dir = tmp_path / "S"
    code, out, _ = run(capsys, "sweep", "--posterior", post, "--grid", "paper", "--out", str(out_dir), "--json")
    assert code == 0
    d = json.loads(out)
    assert len(d["bands"]) == 25
    assert d["bands"][0]["label"] == "100,-100"
    assert {p.name for p in out_dir.iterdir()} == {"bands.nc", "bands.csv", "bands.png", "bands_map.png"}
    import xarray as xr

    with xr.open_dataset(out_dir / "bands.nc") as ds:
        assert ds["freq_hz"].dims == ("draw", "pose", "mode")
        assert ds["freq_hz"].shape == (6, 25, 3)
        all_ok = (ds["status"] == "ok").all("draw").values
    # measure here next: the widest relative 90 % band among the poses every draw reaches as ok
    width = np.array(
        [(r["f1_q95_hz"] - r["f1_q05_hz"]) / r["f1_q50_hz"] if r["f1_q50_hz"] else np.nan for r in d["bands"]]
    )
    assert all_ok.sum() >= 15
    assert d["measure_here_next"]["relative_width"] == pytest.approx(np.nanmax(width[all_ok]), rel=1e-12)
    assert all_ok[d["measure_here_next"]["pose"]]
    poses = tmp_path / "my_poses.csv"
    poses.write_text("x_mm,y_mm,phi_rad\n0,0,0\n30,-20,0.1\n")
    code, out, _ = run(capsys, "sweep", "--posterior", post, "--poses", str(poses), "--out", str(tmp_path / "P"))
    assert code == 0
    assert "(30, -20) mm, 0.1 rad" in out
    assert "6/6" in out
    code, out, _ = run(capsys, "sweep", "--posterior", post, "--step-mm", "60", "--out", str(tmp_path / "D"))
    assert code == 0
    assert "measure here next" in out
    assert "90 % band width / median" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["modes", "--posterior", "nope.nc"], "error: --posterior: file not found, got 'nope.nc'"),
        (["modes", "--posterior", "{junk}"], "junk.nc: not an ArviZ InferenceData"),
        (["modes", "--posterior", "{post}", "--config", "x.toml"], "--config and --posterior"),
        (["sweep", "--posterior", "{post}", "--thickness-mm", "10"], "--thickness-mm and --posterior"),
        (["modes", "--posterior", "{post}", "--draws", "0"], "--draws must be in"),
        (["sweep", "--posterior", "{noattr}"], "lacks the attribute(s) fpm_sim_base_config"),
    ],
)
def test_bad_posterior_exits_2_with_one_line(post, tmp_path, capsys, argv, message):
    junk = tmp_path / "junk.nc"
    junk.write_text("no")
    noattr = write_posterior(tmp_path / "noattr.nc", attrs={"fpm_sim_base_config": None})
    argv = [a.format(post=post, junk=junk, noattr=noattr) for a in argv]
    code, _, err = run(capsys, *argv, "--out", str(tmp_path / "o")) if argv[0] == "sweep" else run(capsys, *argv)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
    assert err.startswith("error: ")


def test_reproduce_uses_the_shipped_posterior_or_says_none_is_shipped(post, monkeypatch):
    from fpm_sim.cli import bands
    from fpm_sim.study import posterior as study_posterior

    args = argparse.Namespace(posterior=None, config=None, thickness_mm=None)
    monkeypatch.setattr(study_posterior, "default_posterior_path", lambda: None)
    found, note = bands.reproduce_posterior(args)
    assert found is None
    assert note.startswith("no posterior shipped")
    monkeypatch.setattr(study_posterior, "default_posterior_path", lambda: Path(post))
    found, note = bands.reproduce_posterior(args)
    assert found is not None
    assert found.n_draws == 6
    # a description of the user's own is not the default's: its posterior is not used
    own = argparse.Namespace(posterior=None, config=Path("x.toml"), thickness_mm=None)
    found, note = bands.reproduce_posterior(own)
    assert found is None
    assert note == ""


@pytest.mark.slow
def test_reproduce_with_a_posterior_writes_bands_and_coverage(post, capsys, tmp_path):
    # ~25 s: the whole reproduction (subsystem tests, 25 poses, readability) at 4 segments, then the bands
    out_dir = tmp_path / "R"
    code, out, _ = run(capsys, "reproduce", "--posterior", post, "--segments", "4", "--out", str(out_dir), "--json")
    assert code == 0
    d = json.loads(out)
    cov = d["bands"]["coverage"]
    assert cov["measured_poses"] == 12
    rows = d["bands"]["poses"]
    assert [r["withheld"] for r in rows] == [False] * 12 + [True] * 6
    assert all(r["measured_hz"] is None for r in rows[12:])
    inside = np.mean([r["f1_q05_hz"] <= r["measured_hz"] <= r["f1_q95_hz"] for r in rows[:12]])
    assert cov["in_90_band"] == inside
    assert {"bands.nc", "bands.csv", "bands.png", "poses.csv"} <= {p.name for p in out_dir.iterdir()}
    # the report's verdict says a posterior was used and where its bands are
    report = (out_dir / "report.md").read_text()
    verdict = report[report.index("**Uncertainty bands.**") :].split("\n")[0]
    assert "a posterior was used (posterior.nc, 6 of 6 draws" in verdict
    assert "bands.nc, bands.csv, bands.png" in verdict
    assert f"{100 * inside:.0f} % of the 12 measured f1 inside the 90 % band" in verdict


def test_the_reports_pointer_names_the_file_the_draws_the_band_files_and_the_coverage(post):
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.batch.pose_loop import fast_options
    from fpm_sim.cli.bands import reproduce_pointer
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.posterior import Posterior, StudyBands, predict_bands

    posterior = Posterior.from_netcdf(post)
    poses = [Pose.from_mm(0, 0, 0), Pose.from_mm(40, -30, 0.1)]
    bands = predict_bands(
        posterior, poses, n_draws=2, n_modes=1, options=fast_options(segments=3), engine=EngineOptions(workers=1)
    )
    q = bands.quantiles_hz[:, :, 0]
    measured_hz = np.array([q[2, 0], 2 * q[4, 1]])  # the median at the first pose (inside), far above at the second
    sb = StudyBands(bands=bands, measured_hz=measured_hz, withheld=np.array([False, False]), reading="x+")
    line = reproduce_pointer(posterior, sb, ["bands.nc", "bands.csv", "bands.png"])
    assert line == (
        "posterior.nc, 2 of 6 draws, free groups section-height,hardware; the bands of f1 at the measured and "
        "withheld poses are in bands.nc, bands.csv, bands.png; 50 % of the 2 measured f1 inside the 90 % band"
    )


def test_the_embedded_default_s_frequencies_say_that_bands_exist(capsys):
    """Issue 32, item 2: a user running modes on the embedded default learns that the shipped posterior gives bands
    (the line names the option and the file); on a description of their own there is no such posterior."""
    from fpm_sim.cli.main import main
    from fpm_sim.study.posterior import default_posterior_path

    assert main(["modes", "--fidelity", "fast", "--n-modes", "2"]) == 0
    out = capsys.readouterr().out
    assert f"'fpm-sim modes --posterior {default_posterior_path()}'" in out
    five_bar = Path(__file__).resolve().parents[2] / "examples" / "architectures" / "five_bar.toml"
    assert main(["modes", "--fidelity", "fast", "--n-modes", "2", "--config", str(five_bar)]) == 0
    assert "bands exist" not in capsys.readouterr().out


def test_the_embedded_default_s_design_study_says_that_bands_exist(tmp_path, capsys):
    """Issue 32, item 2: ``design`` on the embedded default names the posterior that gives each design's band."""
    from fpm_sim.cli.main import main
    from fpm_sim.study.posterior import default_posterior_path

    argv = ["design", "--vary", "section.thickness_m=0.02,0.03", "--grid", "paper", "--segments", "2"]
    assert main([*argv, "--n-modes", "2", "--out", str(tmp_path / "d")]) == 0
    assert f"'fpm-sim design --posterior {default_posterior_path()}'" in capsys.readouterr().out
