"""``calibrate`` on a described architecture (:mod:`fpm_sim.study.calibrate.described`).

Truth: (1) a second method: three_rrr.toml is the study's 3RRR written as a description, so its likelihood at the same
parameter values is the 3RRR path's (``sections.links.height_m`` is the 3RRR's ``section.height_m``); (2) a synthetic
truth: data from a known perturbed five-bar with 1 % noise put the truth inside the posterior's 90 % interval; (3) bad
input is one error line naming the path, the column or the row, and nothing written."""

from __future__ import annotations

import json
import math
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import TaskPose, description_value, load_description, with_description_value
from fpm_sim.batch.task_sweep import sweep_task_many
from fpm_sim.cli.main import main
from fpm_sim.config import default_config
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.results import to_jsonable
from fpm_sim.study.calibrate import CalibrationProblem, SamplerOptions, read_priors, run_calibration
from fpm_sim.study.calibrate.described import DescribedCalibrationProblem, described_priors, described_problem
from fpm_sim.study.identify import Observation, parameter_set
from fpm_sim.study.identify.described import read_task_measured_csv
from tests.helpers.priors import height_and_discrepancy_priors

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = EXAMPLES / "five_bar.toml"
MASS = "lumps.end_effector.mass_kg"
POSES_3RRR = ((0.0, 0.0, 0.0), (50.0, -50.0, 0.1), (-40.0, 80.0, -0.2))
MEASURED_3RRR = ((50.0, 80.0), (49.0, 79.0), (48.0, 78.0))


def test_the_3rrr_as_a_description_has_the_3rrr_s_likelihood(tmp_path):
    """three_rrr.toml with a prior on ``sections.links.height_m`` and the 3RRR with one on ``section.height_m``, the
    same f1 and f2 at three poses (the 3RRR's unlabelled observations are its K-th lowest modes, as a description's
    fK_hz): the same predicted frequencies to the round-off of the inverse kinematics and of the finite-difference
    stiffness (1e-8, as tests/architecture/test_architecture_design.py; measured 1e-11), so the same log L to the
    change those errors make in it, ``sum |f - y| / s^2 * df`` (computed below)."""
    desc = load_description(EXAMPLES / "three_rrr.toml")
    rows = "".join(f"{x},{y},{p},{a},{b}\n" for (x, y, p), (a, b) in zip(POSES_3RRR, MEASURED_3RRR))
    (tmp_path / "m.csv").write_text("x_mm,y_mm,phi_rad,f1_hz,f2_hz\n" + rows)
    data = read_task_measured_csv(tmp_path / "m.csv", desc, sigma_pct=2.0)
    text = height_and_discrepancy_priors("sections.links.height_m")
    described = DescribedCalibrationProblem(desc, described_priors(desc, "p.toml", text=text), data, segments=2)
    manip = default_config()
    obs = tuple(
        Observation(Pose.from_mm(x, y, p), k, f, 0.02 * f, None, "m.csv")
        for (x, y, p), fk in zip(POSES_3RRR, MEASURED_3RRR)
        for k, f in enumerate(fk, 1)
    )
    names = parameter_set(manip, ["section-height"]).names
    assert names == ["section.height_m"]
    priors = read_priors("p.toml", names, text=height_and_discrepancy_priors(names[0]))
    study = CalibrationProblem(manip, ("section-height",), priors, obs, segments=2)
    np.testing.assert_array_equal(described.measured, study.measured)
    np.testing.assert_array_equal(described.sigma, study.sigma)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for theta in (np.array([0.012, 0.03]), np.array([0.02, 0.1])):
            f_desc, f_study = described.predict(theta), study.predict(theta)
            np.testing.assert_allclose(f_desc, f_study, rtol=1e-8)
            s2 = described.noise_sd(f_study, theta[1]) ** 2
            tol = float(np.sum(np.abs(f_study - study.measured) / s2 * 1e-8 * f_study)) + 1e-9
            assert described.log_likelihood(theta) == pytest.approx(study.log_likelihood(theta), abs=tol)
        assert described.predict(np.array([0.02, 0.1]))[0] > 1.5 * described.predict(np.array([0.012, 0.1]))[0]
    again = pickle.loads(pickle.dumps(described))  # what a spawn pool's workers receive
    assert again.log_likelihood(np.array([0.02, 0.1])) == described.log_likelihood(np.array([0.02, 0.1]))
    assert described.notes()["working_mode"].startswith("one class")
    assert described.branch_classes == (None,)


NOISE = np.random.default_rng(3).standard_normal((6, 2))
"""The synthetic data's standard normal noise: four of its twelve values beyond 2 sd (2.04, -2.56, -2.02, 3.32), the
others within 0.9 sd."""


def _synthetic(tmp_path: Path, mass_kg: float = 0.35, noise: float = 0.01) -> Path:
    """The five-bar with its end-effector lump at ``mass_kg`` (the file: 0.25 kg) at its six check poses, f1 and f2
    with ``noise`` relative Gaussian noise (:data:`NOISE`), as a measured file."""
    desc = with_description_value(load_description(FIVE_BAR), MASS, mass_kg)
    poses = [TaskPose(p["x"], p["y"]) for p in desc.check_poses]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (sw,) = sweep_task_many([desc], poses, options=ModelOptions(segments=2), n_modes=2)
    f = sw.freq_hz * (1.0 + noise * NOISE)
    lines = ["x_mm,y_mm,f1_hz,f2_hz"] + [
        f"{p.x_m * 1e3:g},{p.y_m * 1e3:g},{a!r},{b!r}" for p, (a, b) in zip(poses, f.tolist())
    ]
    path = tmp_path / "measured.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.slow  # ~1000 likelihood calls of 6 poses: ~60 s on a shared 2-core machine
def test_a_synthetic_five_bar_puts_the_truth_inside_the_90_interval(tmp_path):
    """The end-effector mass 0.35 kg (the file's 0.25), 12 frequencies with 1 % noise, a uniform prior 0.05-1 kg:
    the posterior's 5-95 % interval holds 0.35 and excludes the file's 0.25 (the data move the mass by ~40 %, far
    beyond their 1 % noise); a measured value lies outside its 90 % predictive band exactly where its noise was beyond
    1.645 sd (:data:`NOISE`: every value is 0.7 sd or more from that edge, more than the mass's uncertainty moves
    it)."""
    desc = load_description(FIVE_BAR)
    data = read_task_measured_csv(_synthetic(tmp_path), desc, sigma_pct=1.0)
    problem = described_problem(desc, data, priors=None, free=f"{MASS}=0.05:1.0", segments=2)
    opts = SamplerOptions(live_points=20, sample="unif", runs=1, draws=300, probe_draws=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = run_calibration(problem, opts, progress=False)
    lo, med, hi = cal.quantiles()[0]
    assert lo < 0.35 < hi
    assert not lo < 0.25 < hi
    assert abs(med - 0.35) < 0.05
    np.testing.assert_array_equal(cal.coverage(0.9), np.abs(NOISE.ravel()) < 1.645)
    doc = cal.to_dict()
    assert doc["compared"].startswith("each measured fK_hz")
    assert doc["classes"][0]["branches"] == "the file's working modes"
    assert json.dumps(to_jsonable(doc))


def _files(tmp_path: Path, priors: str, measured: str) -> list[str]:
    (tmp_path / "p.toml").write_text(priors)
    (tmp_path / "m.csv").write_text(measured)
    return [
        "calibrate", "--config", str(FIVE_BAR), "--measured", str(tmp_path / "m.csv"), "--priors",
        str(tmp_path / "p.toml"), "--segments", "1", "--live-points", "4", "--max-calls", "8", "--runs", "1",
        "--sample", "unif", "--draws", "20", "--quiet", "--out", str(tmp_path / "out"),
    ]  # fmt: skip


MASS_PRIOR = f'[parameters."{MASS}"]\ndist = "uniform"\nlower = 0.05\nupper = 1.0\nreason = "assumed: wide"\n'
GOOD = "x_mm,y_mm,f1_hz\n0,250,35\n-60,220,38\n"


@pytest.mark.parametrize(
    ("priors", "measured", "extra", "needle"),
    [
        (MASS_PRIOR.replace("end_effector", "hand"), GOOD, [], "lumps.hand.mass_kg"),
        (MASS_PRIOR.replace("0.05", "-0.1"), GOOD, [], "the prior reaches -0.1"),
        (MASS_PRIOR, "x_mm,f1_hz\n0,35\n", [], "missing column(s) y_mm"),
        (MASS_PRIOR, GOOD + "0,900,30\n", [], "row 4"),
        (MASS_PRIOR, GOOD, ["--free", "geometry,hardware"], "the 3RRR's parameter groups"),
        (MASS_PRIOR, GOOD, ["--free", "sections.bar.height_m"], "no prior for the free path sections.bar.height_m"),
        (MASS_PRIOR + '[statements.measured_poses_clear]\nreason = "r"\n', GOOD, [], "the study's statements"),
    ],
    ids=[
        "missing-path",
        "negative-bound",
        "missing-column",
        "unreachable-pose",
        "3rrr-groups",
        "no-prior",
        "3rrr-only",
    ],
)
def test_bad_input_is_one_error_line_and_nothing_written(tmp_path, capsys, priors, measured, extra, needle):
    argv = _files(tmp_path, priors, measured)
    assert main([*argv, *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error:")
    assert needle in err[0]
    assert not (tmp_path / "out").exists()


def test_a_tiny_command_run_writes_the_posterior_and_the_median_file(tmp_path, capsys):
    """The wiring of the command (a handful of likelihood calls: not a posterior worth reading): posterior.nc with
    the file as its base and the free path, description.toml at the median that reads back, the report saying what
    is compared and that there is one class."""
    argv = _files(tmp_path, MASS_PRIOR, GOOD)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)["result"]
    assert doc["names"] == [MASS]
    assert "K-th lowest elastic" in doc["compared"]
    assert doc["working_mode"].startswith("one class")
    assert doc["classes"][0]["branches"] == "the file's working modes"
    out = tmp_path / "out"
    for name in ("posterior.nc", "description.toml", "report.md", "corner.png", "predicted_vs_measured.png"):
        assert (out / name).stat().st_size > 0, name
    median = load_description(out / "description.toml")
    value = doc["parameters"][MASS]["median"]
    assert description_value(median, MASS) == pytest.approx(value)
    assert median.provenance[MASS].startswith("identified: posterior median")
    report = (out / "report.md").read_text()
    assert "Free paths: lumps.end_effector.mass_kg" in report
    assert "Working mode: one class" in report
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az

    idata = az.from_netcdf(out / "posterior.nc")
    assert idata.posterior.attrs["fpm_sim_free_groups"] == MASS
    assert idata.posterior.attrs["fpm_sim_base_config"].lstrip().startswith("name = ")
    assert idata.observed_data["mode"].values.tolist() == [1, 1]


def test_the_facade_takes_a_description_and_refuses_the_3rrr_s_options(tmp_path):
    desc = load_description(FIVE_BAR)
    (tmp_path / "m.csv").write_text(GOOD)
    kw = {"measured": [tmp_path / "m.csv"], "free": [f"{MASS}=0.05:1.0"], "segments": 1}
    with pytest.raises(FpmSimError, match="subsystems"):
        fs.calibrate(desc, subsystems=tmp_path / "m.csv", **kw)
    with pytest.raises(FpmSimError, match="measured"):
        fs.calibrate(desc, **{**kw, "measured": []})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = fs.calibrate(
            desc, sampler=SamplerOptions(live_points=4, max_calls=8, runs=1, sample="unif", draws=10), **kw
        )
    assert cal.names == [MASS]
    assert math.isfinite(cal.log_evidence)
    assert isinstance(cal.problem, DescribedCalibrationProblem)
