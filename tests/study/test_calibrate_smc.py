"""The tempered SMC of the calibration (:mod:`fpm_sim.study.calibrate.smc`) on problems whose evidence and mode
weights are known in closed form."""

import math

import numpy as np
import pytest

from fpm_sim.study.calibrate import SamplerOptions
from fpm_sim.study.calibrate.problem import CalibrationError
from fpm_sim.study.calibrate.sampler import _init_worker, sample_classes
from fpm_sim.study.calibrate.smc import SmcSettings, two_stage
from tests.study.test_calibrate_runs import AMPLITUDE, HALF, PRIORS, Toy, _argv, _cheap_frequencies

D = 4
CENTRES = (np.full(D, 0.3), np.full(D, 0.7))
SD = 0.01
WEIGHTS = (0.3, 0.7)
"""A mixture of two narrow (sd 0.01), well-separated Gaussian modes with these weights in the unit cube: every
mode lies 30 sd inside it, so Z = 0.3 + 0.7 = 1 (ln Z = 0) and the posterior puts 0.3 on the first mode."""
SUPPORT = 0.9
"""The cheap stage's support: u_0 < 0.9 (prior mass 0.9), holding both modes."""


def _modes(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(log L, in the first mode)`` at the rows of ``u``."""
    norm = D * math.log(SD * math.sqrt(2 * math.pi))
    a, b = (math.log(w) - 0.5 * np.sum((u - c) ** 2, axis=1) / SD**2 - norm for w, c in zip(WEIGHTS, CENTRES))
    return np.logaddexp(a, b), a > b


def _cheap(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(len(u)), np.where(u[:, 0] < SUPPORT, 0.0, -np.inf)


def _full(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    _, c = _cheap(u)
    return c, np.where(np.isfinite(c), _modes(u)[0], -np.inf)


@pytest.fixture(scope="module")
def mixture_runs():
    one, two = SmcSettings(particles=500), SmcSettings(particles=1600)
    return [two_stage(_cheap, _full, D, one, two, np.random.default_rng(seed)) for seed in range(6)]


def test_two_stage_smc_finds_both_modes_with_their_weights_and_the_evidence(mixture_runs):
    for run in mixture_runs:
        # ln Z = 0: within 4 of the run's stated errors (a stated error that is honest makes a 4-sigma miss
        # a 1-in-15 000 event), and the stated error is that of a few hundred particles, not zero or huge
        assert abs(run.log_evidence) < 4 * run.log_evidence_err, (run.log_evidence, run.log_evidence_err)
        assert 0.03 < run.log_evidence_err < 0.5
        # both modes held, the first with weight 0.3: the modes' shares are carried by the resampled importance
        # weights, whose drift over ~12 steps makes the share's sd about 0.05 at 1600 particles (measured over 12
        # seeds: 0.094 at 400); 0.15 is 3 of those
        share = float(np.mean(_modes(run.u)[1]))
        assert abs(share - WEIGHTS[0]) < 0.15, share
    # the stated errors against the runs' own spread (each run independent): the spread of six values over the
    # stated error is within the chi-square's 0.1 % .. 99.9 % points for 5 degrees of freedom (0.21 .. 2.3)
    z = np.array([r.log_evidence for r in mixture_runs])
    s = np.sqrt(np.mean([r.log_evidence_err**2 for r in mixture_runs]))
    assert 0.21 < np.std(z, ddof=1) / s < 2.3, (z, s)
    # no bias: the mean of six runs within 3 of its standard error (mode-jumping moves with copies of the moved
    # particle in the population put it 0.2 above, 3-4 standard errors)
    assert abs(np.mean(z)) < 3 * s / math.sqrt(len(z)), z


def test_final_moves_keep_the_posterior_and_leave_the_evidence_as_it_was():
    one = SmcSettings(particles=500)
    plain, final = SmcSettings(particles=800), SmcSettings(particles=800, final_moves=20.0)
    a = two_stage(_cheap, _full, D, one, plain, np.random.default_rng(3))
    b = two_stage(_cheap, _full, D, one, final, np.random.default_rng(3))
    # the same random path up to the last tempering step: the evidence is that of the tempering, bit for bit
    assert b.log_evidence == a.log_evidence
    assert b.log_evidence_var == a.log_evidence_var
    assert b.n_calls >= a.n_calls + 20 * 800  # at least one call per accepted move
    assert np.mean(np.any(b.u != a.u, axis=1)) > 0.99  # every particle travelled
    first = _modes(b.u)[1]
    assert abs(float(np.mean(first)) - WEIGHTS[0]) < 0.15  # as the test above: the moves stay in their mode
    for inside, centre in ((first, CENTRES[0]), (~first, CENTRES[1])):
        # each mode's mean within 4 standard errors of a few hundred correlated draws (0.01 / sqrt(100)), its sd
        # within 25 % of 0.01 (the sd of an sd estimate from ~100 effective draws is ~7 %)
        np.testing.assert_allclose(np.mean(b.u[inside], axis=0), centre, atol=4e-3)
        np.testing.assert_allclose(np.std(b.u[inside], axis=0), SD, rtol=0.25)


def test_jumps_between_modes_give_each_run_the_modes_shares():
    # without jumps a mode's share is what the tempering's resampling left (sd 0.053 over 12 seeds at 1600
    # particles, measured); with a jump every other sweep, particles move between the modes by the target's own
    # ratio (sd 0.010 over the same 12 seeds, ln Z's sd 0.056 against 0.116): each of four runs within 0.04 (4 of
    # those sd) of 0.3
    shares = []
    for seed in range(4):
        run = two_stage(_cheap, _full, D, SmcSettings(particles=500), SmcSettings(particles=1600, jumps=0.5),
                        np.random.default_rng(seed))  # fmt: skip
        shares.append(float(np.mean(_modes(run.u)[1])))
        assert abs(run.log_evidence) < 4 * run.log_evidence_err  # the evidence is the tempering's, as without
    np.testing.assert_allclose(shares, WEIGHTS[0], atol=0.04)


def test_the_calibrations_smc_weights_the_classes_by_their_evidences():
    toy = Toy()
    _init_worker(toy)
    opts = SamplerOptions(sampler="smc", particles=200, cheap_particles=200, runs=3, seed=1, draws=2000,
                          probe_draws=200)  # fmt: skip
    comb, check, summaries, _ = sample_classes(toy, opts, None, checkpoint=None, resume=False, print_func=None)
    z = np.array(AMPLITUDE[:2]) / (2 * HALF) ** 2
    assert summaries[2].skipped
    for k in (0, 1):
        # ln Z_k exact within 4 of the merged runs' stated error
        assert abs(summaries[k].log_evidence - math.log(z[k])) < 4 * summaries[k].log_evidence_err + 1e-9
    assert comb.weights == pytest.approx(z / z.sum(), abs=0.08)
    assert check is not None
    assert check.passed, check.failures
    # the draws of class 1 centre on its mode (sd 1 per coordinate, 1000+ draws: the mean within 0.2)
    one = comb.draws[comb.klass == 1]
    assert np.mean(one, axis=0) == pytest.approx([4.0, 2.0], abs=0.2)


class Bimodal(Toy):
    """Toy's problem with class 0's likelihood two unit 2-D Gaussians of amplitudes 1 at (-4, 0) and 3 at (4, 2),
    one on either side of x = 0, and class 1's one of amplitude 2 at (4, 2) (class 2 impossible): Z_0 = 4 / (2
    HALF)^2, Z_1 = 2 / (2 HALF)^2, the classes weighted 2/3 and 1/3, and x < 0 holds 1/4 of class 0's posterior."""

    def log_likelihood(self, theta):
        k = round(theta[-1])
        if not self.possible(theta):
            return -math.inf
        x, y = theta[0], theta[1]
        left = -0.5 * ((x + 4) ** 2 + y**2)
        right = -0.5 * ((x - 4) ** 2 + (y - 2) ** 2)
        mix = np.logaddexp(left, math.log(3.0) + right) if k == 0 else math.log(2.0) + right
        return float(mix) - math.log(2 * math.pi)


def test_a_split_prior_weights_its_parts_by_their_evidences():
    toy = Bimodal()
    _init_worker(toy)
    opts = SamplerOptions(sampler="smc", particles=200, cheap_particles=200, runs=3, seed=1, draws=3000,
                          probe_draws=200, split=("x", 2))  # fmt: skip
    comb, check, summaries, _ = sample_classes(toy, opts, None, checkpoint=None, resume=False, print_func=None)
    z = np.array([4.0, 2.0]) / (2 * HALF) ** 2
    for k in (0, 1):
        # ln Z_k exact within 4 of the merged runs' stated error, and every run's within 4 of its own (~0.1)
        assert abs(summaries[k].log_evidence - math.log(z[k])) < 4 * summaries[k].log_evidence_err, summaries[k]
        assert summaries[k].log_evidence_err < 0.15
        assert np.all(np.abs(np.array(summaries[k].run_log_evidence) - math.log(z[k])) < 0.6)
    # the classes' weights within 3 of their propagated sd
    assert np.all(np.abs(comb.weights - z / z.sum()) <= 3 * comb.weights_sd + 1e-9)
    # class 0's share left of x = 0 is its parts' evidence ratio: with each part's ln Z to ~0.07 (three runs merged)
    # the share's sd is 1/4 * 3/4 * sqrt(2) * 0.07 = 0.019; 0.06 is 3 of those (the resampling of ~2000 draws adds
    # less than 0.01)
    zero = comb.draws[comb.klass == 0]
    assert abs(np.mean(zero[:, 0] < 0) - 0.25) < 0.06
    assert np.mean(zero[zero[:, 0] < 0], axis=0) == pytest.approx([-4.0, 0.0], abs=0.2)
    assert check is not None
    assert check.passed, check.failures


def test_a_split_of_an_unknown_parameter_or_into_one_part_is_refused():
    toy = Toy()
    _init_worker(toy)
    with pytest.raises(CalibrationError, match=r"split.*not a free continuous parameter"):
        sample_classes(toy, SamplerOptions(sampler="smc", split=("z", 2)), None, checkpoint=None, resume=False,
                       print_func=None)  # fmt: skip
    with pytest.raises(CalibrationError, match=r"split.*number of parts >= 2"):
        SamplerOptions(sampler="smc", split=("x", 1)).check()


def _study_surrogate(branch: tuple[int, int, int]):
    """The study's calibration problem (its data, priors and statements) on the in-plane surrogate, one elbow-branch
    class (as ``studies/calibration_runs_surrogate.py`` builds it)."""
    from fpm_sim.study.calibrate.problem import study_problem

    return study_problem(model="inplane", branch=branch)


@pytest.mark.slow
@pytest.mark.very_slow  # 31 s on the shared 2 cores (three runs of ~229 000 calls vectorised; 710 s one at a time)
def test_three_seeds_of_the_study_calibration_on_the_surrogate():
    """Issue 31: on the study's problem (the in-plane surrogate, class (-1, -1, -1)) nested sampling's runs found
    the statements' region, 12-13 nats up, in 2 of 3 runs at 100 live points and 0 of 3 at 250
    (docs/identification.md). Every run of the two-stage SMC must reach it; the between-run check is the target:
    its ln Z criterion passes, its quantiles' does not yet (the runs hold the region's parts in different
    shares), reported as an expected failure until it passes. Splitting the base rotation's prior at its sign
    (``SamplerOptions.split``) did not make it pass: one run in six reaches a compact-geometry region 4-8 nats up
    (docs/identification.md). Run by hand: python -m pytest -m very_slow -rx tests/study/test_calibrate_smc.py"""
    from fpm_sim.study.calibrate import run_calibration

    problem = _study_surrogate((-1, -1, -1))
    opts = SamplerOptions(sampler="smc", particles=200, cheap_particles=1000, runs=3, seed=0)
    cal = run_calibration(problem, opts, progress=False)
    check = cal.runs_check
    assert check is not None
    # every run in the statements' region: the plateau outside it, where nested sampling's runs that missed the
    # region ended, is at ln Z -87.2 .. -88.3
    assert np.all(check.log_evidence > -82.0), check.log_evidence
    if not check.passed:
        pytest.xfail("issue 31: the SMC runs reach the statements' region but disagree inside it:\n" + check.table())


@pytest.mark.slow
@pytest.mark.very_slow  # ~6 min with two workers (12 searches of ~50 s, three runs of ~40 s), ~12 min on one
def test_a_pooled_mode_search_puts_every_run_in_the_compact_region():
    """Issue 31, "The needle": with ``mode_starts = 12`` (differential evolution to convergence, particles spread
    over each optimum, kernels pooled over the runs) every run of the study's problem (surrogate, class (-1, -1, -1))
    holds the compact region (base radius < 0.16 m), which plain runs reach by chance, and ln Z agrees between the
    runs (measured -72.11 +- 0.32, -72.24 +- 0.49, -72.74 +- 0.29 at seed 0; plain runs -74.4 to -76.1). This holds
    where the search finds the region: seed 0's does in 2 of its 12 starts, seed 20's in none (docs/identification.md,
    "The needle": 4 of 36 starts), so the test pins seed 0 and guards the sampling after a successful search, not
    the search's reach. The quantiles' criterion does not pass yet (the plateau's share differs between runs): an
    expected failure.
    Run by hand: python -m pytest -m very_slow -rx tests/study/test_calibrate_smc.py"""
    from fpm_sim.study.calibrate import run_calibration

    problem = _study_surrogate((-1, -1, -1))
    opts = SamplerOptions(sampler="smc", particles=1000, cheap_particles=2000, runs=3, seed=0, mode_starts=12,
                          workers=2)  # fmt: skip
    cal = run_calibration(problem, opts, progress=False)
    check = cal.runs_check
    assert check is not None
    base = problem.names.index("geometry.base_radius_m")
    # every run's median in the compact region: its particles reached it (plain runs: no particle below 0.16 m)
    assert np.all(check.quantiles[:, base, 1] < 0.16), check.quantiles[:, base]
    # ln Z within the check's own criterion (3 sigma of the pair's combined error)
    assert not [f for f in check.failures if "ln Z" in f], check.failures
    if not check.passed:
        pytest.xfail("issue 31: the runs hold the compact region but the plateau's share differs:\n" + check.table())


@pytest.fixture
def cli_files(tmp_path, monkeypatch):
    """test_calibrate_runs.py's CLI problem (a stand-in for the segment model, the height free)."""
    monkeypatch.setattr("fpm_sim.study.calibrate.problem.predict_observations", _cheap_frequencies)
    (tmp_path / "p.toml").write_text(PRIORS)
    (tmp_path / "m.csv").write_text("x_mm,y_mm,phi_rad,f1_hz\n0,-50,0,54\n50,50,0,56\n-50,50,0,53\n")
    return tmp_path


def test_the_cli_runs_the_smc_sampler_and_refuses_nested_sampling_options(cli_files, capsys):
    import json

    from fpm_sim.cli.main import main

    argv = [*_argv(cli_files), "--sampler", "smc", "--particles", "60", "--cheap-particles", "60", "--json",
            "--ess-fraction", "0.7", "--moves", "4"]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["result"]["options"]["sampler"] == "smc"
    assert (doc["result"]["options"]["ess_fraction"], doc["result"]["options"]["moves"]) == (0.7, 4.0)
    assert doc["result"]["runs_check"]["seeds"] == [5, 6, 7]
    assert "two-stage tempered SMC (60 particles" in (cli_files / "out" / "report.md").read_text()
    # a finished calibration's outputs are rewritten on --resume without sampling (the runs' .done files kept)
    assert list((cli_files / "out").glob("checkpoint.dynesty.seed5.done"))
    assert main([*argv, "--resume"]) == 0
    capsys.readouterr()
    # nested sampling's call limit has no meaning here: exit 2 naming it, nothing written
    bad = [*_argv(cli_files), "--sampler", "smc", "--max-calls", "100", "--overwrite"]
    assert main(bad) == 2
    assert capsys.readouterr().err.startswith("error: --max-calls: is nested sampling's (dynesty's) limit")
    # too few particles: exit 2 naming the option
    assert main([*_argv(cli_files), "--sampler", "smc", "--particles", "3", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --particles: must be >= 10, got 3")
    # the tempering's settings out of range: exit 2 naming the option
    assert main([*_argv(cli_files), "--sampler", "smc", "--ess-fraction", "1.5", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --ess-fraction: must be between 0 and 1, got 1.5")
    assert main([*_argv(cli_files), "--sampler", "smc", "--moves", "0", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --moves: must be > 0, got 0")
    assert main([*_argv(cli_files), "--sampler", "smc", "--final-moves", "-1", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --final-moves: must be >= 0, got -1")
    assert main([*_argv(cli_files), "--sampler", "smc", "--jumps", "2", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --jumps: must be between 0 and 1, got 2")
    # the emulator is the SMC's: exit 2 naming it
    assert main([*_argv(cli_files), "--emulator", "100", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --emulator: is the smc sampler's")
    assert main([*_argv(cli_files), "--sampler", "smc", "--emulator", "10", "--overwrite"]) == 2
    assert capsys.readouterr().err.startswith("error: --emulator: must be 0 (off) or >= 50")
    # the mode search's proposals are the segment model's data stage's (Python API): with the emulator, refused,
    # not ignored
    with pytest.raises(CalibrationError, match="is not used by the emulated data stage") as err:
        SamplerOptions(sampler="smc", emulator=100, mode_starts=4).check()
    assert err.value.parameter == "mode_starts"
    # on a problem whose model is not the segment model (here the surrogate itself) it is refused before sampling
    from fpm_sim.study.calibrate import run_calibration

    with pytest.raises(CalibrationError, match="the emulator corrects the 3RRR's vectorised surrogates"):
        run_calibration(_study_surrogate((-1, -1, -1)), SamplerOptions(sampler="smc", emulator=100))
    # data labelled with a mode kind: the emulator's lower family is not the labelled one, refused, not mixed up
    import dataclasses

    from fpm_sim.study.calibrate.problem import study_problem

    seg = study_problem(model="segments", branch=(-1, -1, -1))
    labelled = dataclasses.replace(
        seg, observations=tuple(dataclasses.replace(o, label="in_plane") for o in seg.observations)
    )
    with pytest.raises(CalibrationError, match="unlabelled first frequencies only") as err:
        run_calibration(labelled, SamplerOptions(sampler="smc", emulator=100))
    assert err.value.parameter == "emulator"


def test_resuming_a_nested_sampling_calibration_with_the_smc_sampler_is_refused(cli_files, capsys):
    from fpm_sim.cli.main import main

    assert main(_argv(cli_files)) == 0  # nested sampling: its finished runs' .done files are dynesty's results
    (cli_files / "out" / "calibration.pkl").unlink()  # resume from the runs, not from the finished calibration
    capsys.readouterr()
    assert main([*_argv(cli_files), "--resume", "--sampler", "smc"]) == 2
    err = capsys.readouterr().err
    # one line naming the run's file and what to do
    assert err.startswith("error: "), err
    assert err.count("\n") == 1, err
    assert "checkpoint.dynesty.seed5.done: resume: the finished run there was sampled by dynesty, not smc" in err


def _needle_evaluators():
    """4-D: a broad Gaussian (weight 0.1, sd 0.15 at 0.3) and a needle (weight 0.9, sd 0.002 at 0.75), both normalised
    densities on the unit cube's prior, no cheap terms. The needle fills ~1e-9 of the cube: prior draws never land in
    it. Z = 0.1 * P(broad inside the cube) + 0.9."""
    from scipy.stats import multivariate_normal

    broad = multivariate_normal(np.full(4, 0.3), 0.15**2 * np.eye(4))
    needle = multivariate_normal(np.full(4, 0.75), 0.002**2 * np.eye(4))

    def cheap(u):
        return np.zeros(len(u)), np.zeros(len(u))

    def full(u):
        return np.zeros(len(u)), np.logaddexp(np.log(0.1) + broad.logpdf(u), np.log(0.9) + needle.logpdf(u))

    from scipy.stats import norm

    inside = (norm.cdf(0.7 / 0.15) - norm.cdf(-0.3 / 0.15)) ** 4
    return cheap, full, math.log(0.1 * inside + 0.9)


def test_a_mode_found_by_a_search_enters_the_data_stage_with_its_mass_counted():
    """The data stage started from a defensive mixture of stage 1's particles and draws around a found mode
    (smc.ModeProposal, twice the needle's width): every seed holds the needle with its weight (0.9 / Z) and gets ln Z
    within 3 of its stated sigma (plus the mode weight's sampling error); without the proposal no run finds it."""
    from fpm_sim.study.calibrate.smc import ModeProposal, SmcSettings, two_stage

    cheap, full, log_z = _needle_evaluators()
    modes = ModeProposal(np.full((1, 4), 0.75), (0.004**2 * np.eye(4))[None])
    s1, s2 = SmcSettings(particles=400, moves=3.0), SmcSettings(particles=400, moves=3.0)
    for seed in range(4):
        run = two_stage(cheap, full, 4, s1, s2, np.random.default_rng(seed), modes=modes, mode_particles=400)
        share = np.mean(np.all(np.abs(run.u - 0.75) < 0.02, axis=1))
        assert abs(share - 0.9 / math.exp(log_z)) < 0.1, (seed, share)  # ~4 sd of a 400-particle share
        assert abs(run.log_evidence - log_z) < 3 * run.log_evidence_err + 0.05, (seed, run.log_evidence, log_z)
        plain = two_stage(cheap, full, 4, s1, s2, np.random.default_rng(seed))
        assert plain.log_evidence < log_z - 1.5  # the broad mode only: ln(0.091) against ln(0.991)


def test_particles_spread_over_a_found_mode_cover_it_and_carry_its_mass():
    """A search's optimum at the needle (one point, as a converged search leaves it): ``spread_over_mode``'s moves at
    the posterior spread 256 particles over the needle with its width (sd 0.002 per coordinate; a factor of 1.6
    either side: 20 moves from copies jittered by 0.05 of its width, 256 draws; measured 0.0018-0.0022); kernels
    around them (``ModeProposal.around``) then give every seed the needle's share and ln Z, as the test above's
    hand-made one."""
    from fpm_sim.study.calibrate.smc import ModeProposal, SmcSettings, spread_over_mode, two_stage

    cheap, full, log_z = _needle_evaluators()
    s1, s2 = SmcSettings(particles=400, moves=3.0), SmcSettings(particles=400, moves=3.0)
    for seed in range(3):
        rng = np.random.default_rng(seed)
        u, log_l = spread_over_mode(np.full(4, 0.7501), full, 256, SmcSettings(moves=20.0, max_sweeps=200), rng)
        assert np.all(np.abs(u - 0.75) < 0.02), seed
        assert np.all((0.002 / 1.6 < u.std(axis=0)) & (u.std(axis=0) < 1.6 * 0.002)), (seed, u.std(axis=0))
        assert np.all(np.isfinite(log_l))
        modes = ModeProposal.around([u[:64]])
        run = two_stage(cheap, full, 4, s1, s2, rng, modes=modes, mode_particles=400)
        share = np.mean(np.all(np.abs(run.u - 0.75) < 0.02, axis=1))
        assert abs(share - 0.9 / math.exp(log_z)) < 0.1, (seed, share)  # ~4 sd of a 400-particle share
        assert abs(run.log_evidence - log_z) < 3 * run.log_evidence_err + 0.05, (seed, run.log_evidence, log_z)


def test_mode_proposal_density_is_the_mixture_of_its_gaussians():
    """``ModeProposal.log_density`` (blocks of rows, whitened once) against scipy's densities summed, at points near
    and far from the kernels, with a block smaller than the rows: equal to round-off (1e-10 relative on densities of
    sums of a few terms)."""
    from scipy.stats import multivariate_normal

    from fpm_sim.study.calibrate.smc import ModeProposal

    rng = np.random.default_rng(3)
    pops = [0.5 + 0.05 * rng.standard_normal((7, 3)), 0.2 + 0.01 * rng.standard_normal((5, 3))]
    modes = ModeProposal.around(pops)
    u = rng.random((11, 3))
    ref = np.log(np.mean([multivariate_normal(m, c).pdf(u) for m, c in zip(modes.means, modes.covs)], axis=0))
    np.testing.assert_allclose(modes.log_density(u, block=4), ref, rtol=1e-10)
    assert modes.sample(5, rng).shape == (5, 3)


def test_a_resumed_calibration_whose_runs_are_done_does_not_search_again(tmp_path, monkeypatch):
    """``mode_starts`` with ``resume``: where every run of a class saved its results, the mode search (a minute a
    start on the study) is not run again, and the resumed calibration gives the saved runs' ln Z exactly. The search
    is shrunk here (2 members a coordinate, 3 generations, 16 particles spread): what is tested is that it is
    skipped, not what it finds."""
    from fpm_sim.study.calibrate import run_calibration, sampler

    monkeypatch.setattr(sampler, "MODE_SEARCH", {"popsize": 2, "maxiter": 3, "tol": 1e-4})
    monkeypatch.setattr(sampler, "MODE_SPREAD", SmcSettings(particles=16, moves=1.0, max_sweeps=4))
    monkeypatch.setattr(sampler, "MODE_KERNELS", 8)
    problem = _study_surrogate((-1, -1, -1))
    opts = SamplerOptions(sampler="smc", particles=40, cheap_particles=80, runs=1, seed=0, mode_starts=1, draws=50)
    first = run_calibration(problem, opts, checkpoint=tmp_path / "ck", progress=False)

    def no_search(*args, **kwargs):
        raise AssertionError("the mode search ran again")

    monkeypatch.setattr(sampler, "search_modes", no_search)
    again = run_calibration(problem, opts, checkpoint=tmp_path / "ck", resume=True, progress=False)
    assert again.log_evidence == first.log_evidence


EMULATOR_SHIFT = 0.5 * SD
EMULATOR_SD = 1.5 * SD
EMULATOR_WEIGHTS = (1.0, 1.0)
"""An emulator of the mixture that is wrong in every way a fitted emulator can be: its modes shifted by half their
sd, 1.5 times as wide, weighted 1 : 1 instead of 0.3 : 0.7, and its evidence 2 instead of 1."""


def _emulated(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = _cheap(u)[1]
    norm = D * math.log(EMULATOR_SD * math.sqrt(2 * math.pi))
    a, b = (
        math.log(w) - 0.5 * np.sum((u - m - EMULATOR_SHIFT) ** 2, axis=1) / EMULATOR_SD**2 - norm
        for w, m in zip(EMULATOR_WEIGHTS, CENTRES)
    )
    return c, np.where(np.isfinite(c), np.logaddexp(a, b), -np.inf)


def test_a_data_stage_on_a_wrong_emulator_weighted_to_the_exact_likelihood_gives_the_exact_posterior():
    from fpm_sim.study.calibrate.emulator import importance_diagnostics
    from fpm_sim.study.calibrate.smc import emulated_two_stage

    trained_on: list[int] = []

    def train(u: np.ndarray):
        trained_on.append(len(u))
        return _emulated

    one, two = SmcSettings(particles=500), SmcSettings(particles=1600)
    for seed in range(4):
        run = emulated_two_stage(_cheap, train, _full, D, one, two, np.random.default_rng(seed))
        assert run.log_weights is not None
        w = np.exp(run.log_weights)
        # the importance weights make it exact: ln Z = 0 (the emulator's own is ln 2 = 0.69) within 4 of the stated
        # error (which counts the weights' importance-sampling variance), and the first mode's weighted share 0.3
        # (the emulator's: 0.5) within 0.15, as the plain two-stage SMC's test allows
        assert abs(run.log_evidence) < 4 * run.log_evidence_err, (run.log_evidence, run.log_evidence_err)
        assert run.log_evidence_err < 0.5
        assert abs(float(np.sum(w * _modes(run.u)[1])) - WEIGHTS[0]) < 0.15
        unweighted = float(np.mean(_modes(run.u)[1]))
        assert abs(unweighted - EMULATOR_WEIGHTS[0] / sum(EMULATOR_WEIGHTS)) < 0.15, unweighted  # what it corrects
        ess, k = importance_diagnostics(np.log(w))
        # the weights are usable: a 1.5x wider proposal of 4 dimensions keeps a fair share of effective draws
        assert 0.05 * len(w) < ess < len(w)
        assert k < 0.7
        assert math.isclose(float(np.sum(w)), 1.0)
        assert np.array_equal(run.log_b, _full(run.u)[1])  # the exact likelihood is reported, not the emulator's
    assert trained_on == [one.particles] * 4  # trained on stage 1's particles


def test_a_stage_whose_weights_are_heavy_is_sampled_again_on_the_refit_and_only_that_is_reported():
    """``again``: given the first weighted stage's log weights it returns a refitted emulator (here the exact
    likelihood, as a refit on enough runs would approach it); the data stage runs once more on it and the run reports
    that stage: equal weights, ln Z = 0 within 4 of its stated error, the first mode's share 0.3 within 0.15 (as the
    plain SMC's test), and its calls include both stages' and both weightings'. Returning ``None`` reports the first
    stage, as without ``again``: the same numbers from the same seed."""
    from fpm_sim.study.calibrate.smc import emulated_two_stage

    seen: list[np.ndarray] = []

    def again(log_w: np.ndarray):
        seen.append(log_w)
        return _full

    one, two = SmcSettings(particles=500), SmcSettings(particles=1600)
    for seed in range(2):
        run = emulated_two_stage(_cheap, lambda u: _emulated, _full, D, one, two, np.random.default_rng(seed),
                                 again=again)  # fmt: skip
        assert len(seen) == seed + 1
        assert np.any(seen[-1] != seen[-1][0])  # given the first stage's unequal weights
        assert run.log_weights is not None
        assert np.allclose(run.log_weights, -math.log(len(run.u)))
        assert abs(run.log_evidence) < 4 * run.log_evidence_err, (run.log_evidence, run.log_evidence_err)
        assert abs(float(np.mean(_modes(run.u)[1])) - WEIGHTS[0]) < 0.15
        plain = emulated_two_stage(_cheap, lambda u: _emulated, _full, D, one, two, np.random.default_rng(seed))
        kept = emulated_two_stage(_cheap, lambda u: _emulated, _full, D, one, two, np.random.default_rng(seed),
                                  again=lambda lw: None)  # fmt: skip
        assert kept.log_evidence == plain.log_evidence
        assert np.array_equal(kept.u, plain.u)
        assert run.n_calls > plain.n_calls + two.particles  # a second data stage and its weighting counted


@pytest.mark.slow  # ~15 s: some 300 segment-model runs
def test_an_emulated_calibration_of_the_study_reports_the_segment_models_posterior():
    """``SamplerOptions.emulator`` on the study's problem (segment model, one class): every draw's reported
    log-likelihood is the segment model's (not the emulator's), and the run's line states the emulator's error and
    its weights' effective sample size and Pareto k."""
    from fpm_sim.study.calibrate import run_calibration
    from fpm_sim.study.calibrate.problem import study_problem

    problem = study_problem(branch=(-1, -1, -1))
    lines: list[str] = []
    opts = SamplerOptions(sampler="smc", particles=100, cheap_particles=300, emulator=100, runs=1, draws=200)
    cal = run_calibration(problem, opts, print_func=lines.append)
    assert np.isfinite(cal.log_evidence)
    for i in range(0, 200, 40):
        assert cal.log_likelihood[i] == pytest.approx(problem.log_likelihood(cal.draws[i]), rel=1e-9, abs=1e-9)
    (line,) = [x for x in lines if "seed 0:" in x]
    import re

    assert re.search(r"emulator [0-9.]+ % rms on \d+ runs, weights ESS \d+/100, Pareto k -?[0-9.]+", line), line


def _banana(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A curved ridge in the first two coordinates (width 0.003 across it, sd 0.15 along it), the rest loose."""
    x0, x1 = u[:, 0] - 0.5, u[:, 1] - 0.5
    return np.zeros(len(u)), -0.5 * ((x1 - 4 * x0**2 + 0.1) / 0.003) ** 2 - 0.5 * (x0 / 0.15) ** 2


def test_moves_in_random_subspaces_let_loose_coordinates_travel_beside_a_curved_ridge():
    from fpm_sim.study.calibrate.smc import _move

    def correlation(crossover: bool, seed: int) -> float:
        rng = np.random.default_rng(seed)
        u = rng.random((1000, 14))
        x0 = np.clip(0.15 * rng.standard_normal(1000), -0.45, 0.45)
        u[:, 0], u[:, 1] = 0.5 + x0, 0.4 + 4 * x0**2 + 0.003 * rng.standard_normal(1000)
        la, lb = _banana(u)
        moved = _move(u, la, lb, 1.0, _banana, SmcSettings(moves=10.0, crossover=crossover), rng, 1.0)[0]
        return float(np.mean([np.corrcoef(u[:, j], moved[:, j])[0, 1] for j in range(2, 14)]))

    # 40 sweeps (the most) of all 14 coordinates at once: the ridge holds the step to its width, and the twelve
    # loose coordinates keep a correlation of 0.85-0.86 with where they started (measured over 3 seeds); each move in
    # a random subspace (DREAM's crossover), 0.20-0.21. Either estimate from 12 x 1000 pairs is within +- 0.03
    for seed in range(2):
        assert correlation(False, seed) > 0.7
        assert correlation(True, seed) < 0.35


def test_moves_in_random_subspaces_keep_the_evidence_and_the_modes_shares():
    for seed in range(2):
        run = two_stage(_cheap, _full, D, SmcSettings(particles=500), SmcSettings(particles=1600, crossover=True),
                        np.random.default_rng(seed))  # fmt: skip
        # as the plain runs' test: ln Z = 0 within 4 stated errors, the first mode's share 0.3 within 0.15
        assert abs(run.log_evidence) < 4 * run.log_evidence_err, (run.log_evidence, run.log_evidence_err)
        assert abs(float(np.mean(_modes(run.u)[1])) - WEIGHTS[0]) < 0.15
