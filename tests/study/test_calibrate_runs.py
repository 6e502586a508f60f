"""The elbow-branch classes enumerated and weighted by their evidences, several runs merged, and the
between-run check (:mod:`fpm_sim.study.calibrate.runs`), on a toy problem whose evidences are known."""

import math
from dataclasses import dataclass

import numpy as np
import pytest

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate.problem import FrequencyLikelihood
from fpm_sim.study.calibrate.runs import (
    ClassResult,
    allocate,
    between_run_check,
    combine_classes,
    combine_parts,
    evidence_weights,
)
from fpm_sim.study.calibrate.sampler import _init_worker, sample_classes
from tests.helpers.priors import height_and_discrepancy_priors

HALF = 10.0
"""The continuous prior: uniform on [-HALF, HALF]^2 (density 1 / (2 HALF)^2)."""
AMPLITUDE = (1.0, 3.0, 0.0)
"""Class k's likelihood: AMPLITUDE[k] times a unit 2-D Gaussian density (far inside the box), so
Z_k = AMPLITUDE[k] / (2 HALF)^2 exactly and the weights are 1/4, 3/4 and 0 (class 2 is impossible)."""
CENTRES = ((-4.0, 0.0), (4.0, 2.0), (0.0, 0.0))


@dataclass(frozen=True)
class Toy(FrequencyLikelihood):
    """A problem for :func:`sample_classes`: coordinates (x, y, class), three classes (its class labels and
    per-worker preparation the base's)."""

    parameters: object = None
    names = ("x", "y", "geometry.elbow_branch")
    ndim = 3
    branch_classes = (0, 1, 2)

    def prior_transform(self, u):
        u = np.asarray(u, float)
        return np.array([2 * HALF * u[0] - HALF, 2 * HALF * u[1] - HALF, float(min(int(3 * u[2]), 2))])

    def possible(self, theta):
        return round(theta[-1]) != 2

    def log_likelihood(self, theta):
        k = round(theta[-1])
        if not self.possible(theta):
            return -math.inf
        r2 = (theta[0] - CENTRES[k][0]) ** 2 + (theta[1] - CENTRES[k][1]) ** 2
        return math.log(AMPLITUDE[k]) - 0.5 * r2 - math.log(2 * math.pi)


@pytest.fixture(scope="module")
def toy_result():
    toy = Toy()
    _init_worker(toy)
    opts = SamplerOptions(live_points=80, dlogz=0.1, sample="unif", runs=3, seed=4, draws=2000, probe_draws=200)
    return sample_classes(toy, opts, None, checkpoint=None, resume=False, print_func=None)


def test_classes_are_weighted_by_their_evidences(toy_result):
    comb, check, summaries, _ = toy_result
    z = np.array(AMPLITUDE[:2]) / (2 * HALF) ** 2
    # the impossible class is skipped and reported, not sampled
    assert summaries[2].skipped
    assert summaries[2].weight == 0.0
    assert "skipped" in summaries[2].line()
    assert comb.classes == [0, 1]
    # nested sampling states its ln Z errors (~0.1 for 3 x 80 live points here): the weights must agree with
    # the analytic 1/4, 3/4 within 3 of their propagated sd, and the total evidence within 3 of its error
    assert np.all(np.abs(comb.weights - z / z.sum()) <= 3 * comb.weights_sd)
    assert comb.weights_sd[1] < 0.1
    assert abs(comb.log_evidence - math.log(z.sum() / 3)) <= 3 * comb.log_evidence_err
    for k in (0, 1):
        assert abs(summaries[k].log_evidence - math.log(z[k])) <= 3 * summaries[k].log_evidence_err + 1e-9
    # the draws carry their class, in the proportion of the weights (largest remainder: within one draw)
    n = len(comb.draws)
    assert n == 2000
    for j, k in enumerate(comb.classes):
        mine = comb.klass == k
        assert abs(mine.sum() - comb.weights[j] * n) <= 1
        # and each class's draws are its own posterior (the unit Gaussian at its centre: mean within 4 SE)
        assert np.allclose(comb.draws[mine].mean(axis=0), CENTRES[k], atol=4 / math.sqrt(mine.sum()) + 0.05)
    # in random order: the first draws (what a thinned file or a figure takes) hold both classes
    assert set(comb.klass[:50].tolist()) == {0, 1}
    assert check is not None
    assert check.passed, check.failures


def test_weights_and_their_errors_are_the_first_order_propagation():
    # two classes, equal evidences, ln Z errors 0.1 and 0.2: w = 1/2 each and
    # var ln w_0 = (1/2)^2 0.1^2 + (1/2)^2 0.2^2 (from d ln w_k / d ln Z_j = delta_kj - w_j)
    w, sd = evidence_weights(np.array([-3.0, -3.0]), np.array([0.1, 0.2]))
    assert np.allclose(w, [0.5, 0.5])
    assert np.allclose(sd, 0.5 * math.sqrt(0.25 * 0.01 + 0.25 * 0.04))
    assert allocate(np.array([0.2, 0.3, 0.5]), 7).tolist() == [1, 2, 4]
    assert allocate(np.array([1 / 3] * 3), 10).sum() == 10


def test_parts_of_equal_prior_mass_combine_into_their_class():
    # two parts (prior mass 1/2 each) with evidences 0.1 and 0.3 of their own priors: the class's Z = (0.1 + 0.3)
    # / 2, the parts weighted 1/4 and 3/4, the error sqrt((1/4)^2 0.2^2 + (3/4)^2 0.1^2); a nil part adds nothing
    def run(z, err, x):
        return {"samples": np.full((4, 1), x), "logwt": np.full(4, math.log(z / 4)), "logl": np.zeros(4),
                "logz": np.array([math.log(z)]), "logzerr": np.array([err]), "ncall": np.array([10]),
                "niter": 2}  # fmt: skip

    out = combine_parts([run(0.1, 0.2, -1.0), run(0.3, 0.1, 1.0)])
    assert float(out["logz"][-1]) == pytest.approx(math.log(0.2))
    assert float(out["logzerr"][-1]) == pytest.approx(math.sqrt((0.25 * 0.2) ** 2 + (0.75 * 0.1) ** 2))
    w = np.exp(out["logwt"])
    assert float(w.sum()) == pytest.approx(0.2)
    assert float(w[out["samples"][:, 0] < 0].sum() / w.sum()) == pytest.approx(0.25)
    assert out["ncall"].tolist() == [20]
    nil = {"samples": np.empty((0, 1)), "logwt": np.empty(0), "logl": np.empty(0), "logz": np.array([-math.inf]),
           "logzerr": np.array([0.0]), "ncall": np.array([5]), "niter": 1}  # fmt: skip
    out = combine_parts([run(0.3, 0.1, 1.0), nil])
    assert float(out["logz"][-1]) == pytest.approx(math.log(0.15))
    assert float(out["logzerr"][-1]) == pytest.approx(0.1)


def _equal_run(klass, draws, log_z, err):
    """A 'run' of equal-weight samples (each carrying 1/n of the evidence)."""
    n = len(draws)
    return ClassResult(klass, draws, np.full(n, log_z - math.log(n)), np.zeros(n), log_z, err)


def test_the_check_passes_for_agreeing_runs_and_names_a_disagreeing_parameter():
    rng = np.random.default_rng(0)
    n = 4000

    def run(shift_b, log_z):
        d = rng.standard_normal((n, 2))
        d[:, 1] += shift_b
        return [_equal_run(0, d, log_z, 0.1)]

    def check(per_run):
        merged = combine_classes([_equal_run(0, np.concatenate([r[0].samples for r in per_run]), 0.0, 0.1)], 1, n, rng)
        return between_run_check(per_run, merged, [0, 1, 2], ["a", "b"], n_classes=1, n_draws=n, rng=rng)

    # three draws of the same posterior: quantile spreads ~0.1 sd (sampling), far below the 0.5 sd tolerance
    same = check([run(0.0, 0.0), run(0.0, 0.05), run(0.0, -0.05)])
    assert same.passed, same.failures
    assert "PASSED" in same.table()
    # one run with b moved by 2 sd and ln Z 2 away (14 sigma): flagged, naming b and not a
    bad = check([run(0.0, 0.0), run(2.0, 2.0), run(0.0, 0.0)])
    assert not bad.passed
    assert bad.bad_parameters == ["b"]
    assert any("ln Z differs" in f for f in bad.failures)
    assert "runs disagree" in bad.table()
    assert bad.to_dict()["bad_parameters"] == ["b"]


PRIORS = height_and_discrepancy_priors()


def _cheap_frequencies(config, observations, *, options=None, workers=1):
    """A stand-in for the segment model (the CLI's wiring is tested, not the model): f grows as h^1.5."""
    h = config.section.height_m
    return np.array([55.0 * (h / 0.01) ** 1.5 * (1 + 0.01 * o.pose.x_m) for o in observations])


@pytest.fixture
def cli_files(tmp_path, monkeypatch):
    monkeypatch.setattr("fpm_sim.study.calibrate.problem.predict_observations", _cheap_frequencies)
    (tmp_path / "p.toml").write_text(PRIORS)
    (tmp_path / "m.csv").write_text("x_mm,y_mm,phi_rad,f1_hz\n0,-50,0,54\n50,50,0,56\n-50,50,0,53\n")
    return tmp_path


def _argv(d, *extra):
    return [
        "calibrate", "--measured", str(d / "m.csv"), "--priors", str(d / "p.toml"), "--free", "section-height",
        "--live-points", "30", "--sample", "unif", "--workers", "1", "--runs", "3", "--seed", "5", "--quiet",
        "--out", str(d / "out"), *extra,
    ]  # fmt: skip


def test_the_cli_prints_the_between_run_check(cli_files, capsys):
    import json
    import warnings

    from fpm_sim.cli.main import main

    assert main(_argv(cli_files)) == 0
    out = capsys.readouterr().out
    assert "between-run check (3 runs, seeds 5, 6, 7): PASSED" in out
    assert "section.height_m" in out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    stats = az.from_netcdf(cli_files / "out" / "posterior.nc").sample_stats.attrs
    assert stats["runs_check_passed"] == 1
    assert json.loads(stats["classes"])[0]["run_log_evidence"].__len__() == 3
    text = (cli_files / "out" / "report.md").read_text()
    assert "## Independent runs (between-run check)" in text
    assert "| ln Z |" in text
    assert "seed 7" in text
    assert main([*_argv(cli_files), "--overwrite", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["result"]["runs_check"]["passed"] is True
    assert doc["result"]["runs_check"]["seeds"] == [5, 6, 7]
    assert doc["result"]["options"]["runs"] == 3


def test_the_cli_warns_loudly_naming_the_parameters_when_runs_disagree(cli_files, capsys, monkeypatch):
    from fpm_sim.cli.main import main
    from fpm_sim.study.calibrate import sampler

    real = sampler.between_run_check
    # tolerances no finite sample meets (the runs' quantiles and ln Z necessarily differ by more): the check fails
    strict = {"quantile_tol": 1e-9, "nsigma": 1e-9}
    monkeypatch.setattr(sampler, "between_run_check", lambda *a, **k: real(*a, **{**k, **strict}))
    assert main(_argv(cli_files)) == 0
    cap = capsys.readouterr()
    assert "FAILED" in cap.out
    assert "runs disagree" in cap.out
    assert "warning: the 3 independent runs DISAGREE" in cap.err
    assert "Parameters whose quantiles disagree: section.height_m, likelihood.discrepancy_rel" in cap.err
    assert "**disagree**" in (cli_files / "out" / "report.md").read_text()


def test_runs_below_one_exit_2_naming_the_option(cli_files, capsys):
    from fpm_sim.cli.main import main

    argv = _argv(cli_files)
    argv[argv.index("--runs") + 1] = "0"
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith("error: --runs: must be >= 1, got 0")
    assert not (cli_files / "out").exists()


@pytest.mark.slow  # ~60 s of wall time on the shared 2-core machine (two runs of the segment model, 2 workers)
def test_two_seeds_of_a_small_study_calibration_pass_the_check(tmp_path, capsys):
    """A positive control on the real model and the study's data: the section height and the discrepancy
    (the study's priors for them; the base's branches), 30 live points, seeds 0 and 1, each run on its own
    worker. A 2-dimensional posterior this well sampled must pass the check (measured: the largest quantile
    difference is half of what the check allows). The whole study (11 dimensions, 8 classes) does not pass at
    settings that fit a test's time: see the report of issue 31."""
    import json
    from importlib.resources import files

    from fpm_sim.cli.main import main

    study = files("fpm_sim.data").joinpath("study_priors.toml").read_text()
    keep = study[study.index('[parameters."section.height_m"]') : study.index("[likelihood.mode_read]")]
    (tmp_path / "p.toml").write_text(keep)
    measured = files("fpm_sim.data").joinpath("measured_table4_train.csv")
    argv = ["calibrate", "--measured", f"{measured},reading=x+", "--priors", str(tmp_path / "p.toml"),
            "--free", "section-height", "--segments", "2", "--live-points", "30", "--sample", "unif",
            "--runs", "2", "--workers", "2", "--seed", "0", "--quiet", "--json",
            "--out", str(tmp_path / "out")]  # fmt: skip
    assert main(argv) == 0
    check = json.loads(capsys.readouterr().out)["result"]["runs_check"]
    assert check["seeds"] == [0, 1]
    assert check["passed"], check["failures"]
