"""The elbow-branch classes enumerated and weighted by their evidences, several runs merged, and the
between-run check (:mod:`fpm_sim.study.calibrate.runs`), on a toy problem whose evidences are known."""

import math
from dataclasses import dataclass

import numpy as np
import pytest

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate.problem import FrequencyLikelihood
from fpm_sim.study.calibrate.runs import (
    QUANTILES,
    ClassResult,
    allocate,
    between_run_check,
    class_weights_cdf_var,
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


def _two_class_runs(rng, shares, err, n=4000):
    """Runs of a posterior of two classes far apart in ``a`` (N(0, 1) and N(6, 1)), class 1 with these shares."""
    return [
        [_equal_run(0, rng.standard_normal((n, 1)), math.log(1 - w), err),
         _equal_run(1, rng.standard_normal((n, 1)) + 6.0, math.log(w), err)]
        for w in shares
    ]  # fmt: skip


def _check_two_classes(per_run, rng, n=4000):
    merged = combine_classes(
        [_equal_run(k, np.concatenate([r[k].samples for r in per_run]),
                    math.log(np.mean([math.exp(r[k].log_evidence) for r in per_run])), 0.3) for k in (0, 1)],
        2, n, rng,
    )  # fmt: skip
    return between_run_check(per_run, merged, [0, 1, 2], ["a"], n_classes=2, n_draws=n, rng=rng)


def test_the_class_weights_error_of_a_quantile_is_the_spread_of_the_mixtures_cdf():
    """class_weights_cdf_var against a Monte Carlo of it: ln Z_k drawn with their stated errors, the mixture's CDF
    at the run's quantile recomputed from the exact class CDFs each time."""
    from scipy.stats import norm

    rng = np.random.default_rng(3)
    run = combine_classes(_two_class_runs(rng, [0.1], 0.4, n=20000)[0], 2, 20000, rng)
    quant = np.quantile(run.draws, QUANTILES, axis=0).T  # (1, 3)
    got = class_weights_cdf_var(run, quant, np.array([0.4, 0.4]), rng)
    lz = np.log([0.9, 0.1]) + 0.4 * rng.standard_normal((200_000, 2))
    w = np.exp(lz) / np.exp(lz).sum(axis=1, keepdims=True)
    cdf = w[:, :1] * norm.cdf(quant[0]) + w[:, 1:] * norm.cdf(quant[0] - 6.0)  # (m, 3)
    # both Monte Carlo (2e4 and 2e5 draws: a variance's relative sd ~ sqrt(2 / m) times its kurtosis, ~2 %), the
    # function's on the run's empirical class CDFs (2e4 draws: ~1e-3 off the exact ones); the first order,
    # sum_k w_k^2 s_k^2 (F_k - q)^2, is below both: by 6 % at the 5 % point (class 0's CDF there is close to q),
    # 15-28 % at the median and the 95 % point (measured)
    np.testing.assert_allclose(got[0], np.var(cdf, axis=0), rtol=0.08)
    first = sum((w0 * 0.4) ** 2 * (norm.cdf(quant[0] - c) - np.array(QUANTILES)) ** 2 for w0, c in ((0.9, 0), (0.1, 6)))
    assert np.all(got[0, 1:] > 1.1 * first[1:])


def test_quantiles_moved_by_class_weights_within_their_stated_errors_agree_and_beyond_them_do_not():
    rng = np.random.default_rng(4)
    shares = [0.15, 0.05, 0.10]  # class 1's ln Z 1.1 apart between the first two runs
    # stated ln Z errors of 0.5: 1.6 sigma apart, so the 95 % points' spread (the class weights') is allowed
    ok = _check_two_classes(_two_class_runs(rng, shares, 0.5), rng)
    assert ok.passed, ok.failures
    # the same spread of weights with ln Z errors of 0.02 is not Monte Carlo error: both criteria say so
    bad = _check_two_classes(_two_class_runs(rng, shares, 0.02), rng)
    assert bad.bad_parameters == ["a"]
    assert any("ln Z differs" in f for f in bad.failures)


def test_a_quantile_in_the_gap_between_two_classes_is_compared_in_probability():
    """The 95 % point of a posterior with about 5 % of its mass 6 sd away lies in the gap between the classes for one
    run and inside the far class for another (a 0.015 change of the weights moves it by ~2 sd). Their CDFs at each
    other's quantiles differ by ~0.01, within the draws' and the weights' error (ln Z errors of 0.2); the delta
    method's error of the quantile, taken from the merged draws' density, is no measure of that move. A check saved
    before the comparison in probability keeps the delta method's."""
    import dataclasses

    rng = np.random.default_rng(5)
    chk = _check_two_classes(_two_class_runs(rng, [0.045, 0.06, 0.052], 0.2, n=3000), rng, n=3000)
    assert np.ptp(chk.quantiles[:, 0, 2]) > 0.5 * chk.merged_sd[0]  # apart by more than the sd tolerance
    assert chk.cdf_at is not None
    assert np.max(np.abs(chk.cdf_at[..., 0, 2] - 0.95)) < 0.03
    assert chk.passed, chk.failures
    saved = dataclasses.replace(chk, cdf_at=None, cdf_sd=None)
    assert saved.excess().shape == (1, 3)


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
