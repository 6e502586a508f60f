"""fpm-sim calibrate: a tiny run writes posterior.nc (the shared format), config.toml and report.md; bad
priors, missing data and a resume without a checkpoint exit 2 with one error line."""

import json
import warnings

import pytest

from fpm_sim.cli.main import main
from tests.helpers.priors import height_and_discrepancy_priors

PRIORS = height_and_discrepancy_priors()
MEASURED = "x_mm,y_mm,phi_rad,f1_hz\n0,-50,0,54\n50,50,0,49\n-50,50,0,36\n"


@pytest.fixture
def files(tmp_path):
    (tmp_path / "p.toml").write_text(PRIORS)
    (tmp_path / "m.csv").write_text(MEASURED)
    return tmp_path


def _argv(d, *extra):
    return [
        "calibrate", "--measured", str(d / "m.csv"), "--priors", str(d / "p.toml"), "--free", "section-height",
        "--segments", "3", "--live-points", "6", "--dlogz", "10", "--sample", "unif", "--quiet",
        "--out", str(d / "out"), *extra,
    ]  # fmt: skip


@pytest.mark.slow  # a few s of CPU, but a minute of wall time on a shared machine (a spawn-free tiny sampling run)
def test_a_tiny_run_writes_the_three_outputs(files, capsys):
    assert main([*_argv(files), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["result"]["names"] == ["section.height_m", "likelihood.discrepancy_rel"]
    out = files / "out"
    for name in ("posterior.nc", "config.toml", "report.md", "corner.png", "predicted_vs_measured.png"):
        assert (out / name).stat().st_size > 0, name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az

    idata = az.from_netcdf(out / "posterior.nc")
    post = idata.posterior
    assert post.sizes["chain"] == 1
    assert post["section.height_m"].dtype == "float64"
    assert post.attrs["fpm_sim_free_groups"] == "section-height"
    assert int(post.attrs["fpm_sim_segments"]) == 3
    assert post.attrs["fpm_sim_base_config"].startswith("name = ")
    assert idata.observed_data["f_hz"].values.tolist() == [54.0, 49.0, 36.0]
    assert idata.posterior_predictive["f_hz"].shape == (1, post.sizes["draw"], 3)
    assert "log_evidence" in idata.sample_stats.attrs
    assert "identified: posterior median +- sd (fpm-sim calibrate, m.csv)" in (out / "config.toml").read_text()
    text = (out / "report.md").read_text()
    assert "log-evidence" in text
    assert "likelihood calls" in text
    # the leave-one-out summary once: the table under it does not repeat it
    assert text.count("leave-one-out (PSIS): ") == 1
    assert "datum" in text[text.index("## Leave-one-out predictions") :]
    # a finished run's outputs are rewritten from its saved result with --resume (no sampling)
    assert main([*_argv(files), "--resume"]) == 0


@pytest.mark.parametrize(
    ("priors", "needle"),
    [
        ('[parameters."section.height_m"]\ndist = "gamma"\nreason = "r"\n', "unknown distribution 'gamma'"),
        (
            '[parameters."geometry.base_radius_m"]\ndist = "uniform"\nlower = 0.1\nupper = 0.2\nreason = "r"\n',
            "base_radius",
        ),
        ("", "no prior for the free parameter(s) section.height_m"),
    ],
)
def test_bad_priors_exit_2_naming_the_key(files, capsys, priors, needle):
    (files / "p.toml").write_text(priors)
    assert main(_argv(files)) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ")
    assert needle in err
    assert not (files / "out" / "posterior.nc").exists()


def test_resume_without_a_checkpoint_and_no_data_exit_2(files, capsys):
    assert main([*_argv(files), "--resume"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    argv = [a for a in _argv(files) if a not in ("--measured", str(files / "m.csv"))]
    assert main(argv) == 2
    assert "no data" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "value", "line"),
    [
        ("--live-points", "1", "error: --live-points: must be >= 2, got 1"),
        ("--dlogz", "0", "error: --dlogz: must be > 0, got 0.0"),
        ("--walks", "1", "error: --walks: must be >= 2, got 1"),
        ("--draws", "0", "error: --draws: must be >= 1, got 0"),
        ("--max-calls", "3", "error: --max-calls: must be >= the number of live points (6), got 3; "),
    ],
)
def test_bad_sampler_settings_exit_2_naming_the_option(files, capsys, option, value, line):
    # the library names its parameter (live_points, max_calls, ...); the one error path shows the option
    argv = _argv(files)
    if option in argv:
        argv[argv.index(option) + 1] = value
    else:
        argv += [option, value]
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith(line)
    assert not (files / "out").exists()


@pytest.mark.slow  # samples (tiny), ~20 s of wall time on a shared machine
def test_fewer_data_than_free_parameters_warns_loudly(files, capsys):
    (files / "m.csv").write_text("x_mm,y_mm,phi_rad,f1_hz\n0,-50,0,54\n")
    text = PRIORS + "".join(
        f'\n[parameters."hardware.{n}.mass_kg"]\ndist = "loguniform"\nlower = 0.03\nupper = 6\nreason = "r"\n'
        for n in ("platform", "elbow_joint", "platform_joint")
    )
    (files / "p.toml").write_text(text)
    argv = _argv(files)
    argv[argv.index("section-height")] = "section-height,hardware"
    argv[argv.index("--dlogz") + 1] = "50"
    assert main(argv) == 0
    assert "warning: 1 data for 4 free parameters" in capsys.readouterr().err
