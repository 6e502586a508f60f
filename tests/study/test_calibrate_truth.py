"""Calibration against truths the sampler never sees.

- Simulation-based calibration (Talts et al. 2018) on the in-plane surrogate (cheap): for each replica a truth
  is drawn from the prior, data are simulated from it with the likelihood's own noise, the posterior is
  sampled, and the truth's rank among the posterior draws is recorded. With a correct sampler and likelihood
  the ranks are uniform; a chi-square test of the rank histogram must not reject uniformity.
- Blind truth on the segment model: a hidden description (the default with its masses, link height and rig
  perturbed inside the priors), 12 first frequencies at study poses and the 5 rig tests with 1.5 % noise;
  the truth must lie inside its 95 % marginals and the 90 % predictive band must cover the truth's f1 at
  >= 16 of 20 other poses.

Each test has a full case (marked ``very_slow``: ``python -m pytest -m very_slow``, docs/identification.md gives
its last figures) and a smaller case that CI's slow set runs (``-m "slow and not very_slow"``, .ci/run).
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.kinematics import Pose
from fpm_sim.study.calibrate import CalibrationProblem, SamplerOptions, read_priors, run_calibration
from fpm_sim.study.identify import Observation, parameter_set, predict_observations
from tests.helpers.priors import HARDWARE_PRIORS

SBC_POSES = [(0, -50, 0), (50, 50, 0), (-50, 50, 0), (100, -100, 0), (-100, -100, 0), (50, -100, 0)]
SIGMA_HZ = 1.0  # fixed, known noise sd: the data-generating process is exactly the likelihood's


def _rank_histogram_p(ranks: np.ndarray, n_draws: int, bins: int) -> float:
    """p-value of a chi-square test that ranks in 0..n_draws are uniform, in ``bins`` equal bins."""
    counts = np.histogram(ranks, bins=bins, range=(-0.5, n_draws + 0.5))[0]
    return float(stats.chisquare(counts).pvalue)


# (replicas, bins). The chi-square test of a rank histogram holds when every bin expects enough ranks (>= 5; here
# replicas / bins = 12.5 in both cases), so the smaller case halves the replicas and the bins together: its test is
# as valid, with less power (4 bins of 10 ranks out of 40 see a pile at the ends or the middle, not finer shapes).
# Full: 446 s on the shared machine; CI's case: 347 s on the 2 cores at a load average of 8-9 (3 Dec 2026).
SBC_CASES = [
    pytest.param((100, 8), marks=pytest.mark.very_slow, id="full"),
    pytest.param((50, 4), id="ci"),
]


@pytest.mark.slow
@pytest.mark.parametrize("size", SBC_CASES)
def test_simulation_based_calibration_of_the_sampler(default_manip, size):
    names = parameter_set(default_manip, ["hardware"]).names
    priors = read_priors("sbc.toml", names, text=HARDWARE_PRIORS)
    rng = np.random.default_rng(20261202)
    (replicas, bins), n_draws = size, 39
    ranks = np.zeros((replicas, len(names)), int)
    proto = [Observation(Pose.from_mm(x, y, p), 1, 1.0, SIGMA_HZ, None, "sbc") for x, y, p in SBC_POSES]
    base = CalibrationProblem(default_manip, ("hardware",), priors, tuple(proto), model="inplane")
    for r in range(replicas):
        truth = base.prior_transform(rng.random(base.ndim))
        f = base.predict(truth)
        y = f + SIGMA_HZ * rng.standard_normal(len(f))
        obs = tuple(dataclasses.replace(o, freq_hz=float(v)) for o, v in zip(proto, y))
        prob = dataclasses.replace(base, observations=obs)
        cal = run_calibration(
            prob,
            # one run per replica, as timed (each replica's draws are one run's: what SBC checks)
            SamplerOptions(live_points=30, dlogz=0.5, seed=r, sample="unif", draws=n_draws, runs=1),
            progress=False,
        )
        ranks[r] = np.sum(cal.draws[:, : len(names)] < truth[None, :], axis=0)
    for j, n in enumerate(names):
        p = _rank_histogram_p(ranks[:, j], n_draws, bins=bins)
        # 3 tests at 1 %: a correct sampler fails one ~3 % of the time; a biased or overconfident one
        # piles ranks at the ends or the middle and fails far more often
        assert p > 0.01, (n, p, np.histogram(ranks[:, j], bins=bins, range=(-0.5, n_draws + 0.5))[0])


BLIND_PRIORS_MANIPULATOR = """
[parameters."hardware.platform.mass_kg"]
dist = "loguniform"
lower = 0.2
upper = 6.0
reason = "assumed: test"
[parameters."hardware.elbow_joint.mass_kg"]
dist = "loguniform"
lower = 0.03
upper = 1.0
reason = "assumed: test"
[parameters."hardware.platform_joint.mass_kg"]
dist = "loguniform"
lower = 0.03
upper = 1.0
reason = "assumed: test"
[parameters."section.height_m"]
dist = "loguniform"
lower = 0.005
upper = 0.03
reason = "assumed: test"
"""
BLIND_PRIORS_RIG = """
[parameters."rig.length_m"]
dist = "uniform"
lower = 0.15
upper = 0.30
reason = "assumed: test"
[parameters."rig.clamped_length_m"]
dist = "uniform"
lower = 0.0
upper = 0.08
reason = "assumed: test"
[parameters."rig.section.height_m"]
dist = "loguniform"
lower = 0.004
upper = 0.02
reason = "assumed: test"
[parameters."rig.chain_hinge.mass_kg"]
dist = "uniform"
lower = 0.05
upper = 1.5
reason = "assumed: test"
"""
BLIND_PRIORS_LIKELIHOOD = """
[likelihood.discrepancy_rel]
dist = "loguniform"
lower = 0.002
upper = 0.5
reason = "assumed: test"
"""


@dataclasses.dataclass(frozen=True)
class BlindCase:
    groups: tuple[str, ...]
    priors: str
    rig_tests: bool


BLIND_CASES = [
    # 8 parameters, seen through 12 poses and the 5 rig tests: 2468 s on 2 cores shared with four other processes
    # (~35 min of CPU; about 18 min alone). A likelihood call is ~87 ms of CPU, ~73 of them the five rigs.
    pytest.param(
        BlindCase(
            ("hardware", "section-height", "rig"),
            BLIND_PRIORS_MANIPULATOR + BLIND_PRIORS_RIG + BLIND_PRIORS_LIKELIHOOD,
            rig_tests=True,
        ),
        marks=pytest.mark.very_slow,
        id="full",
    ),
    # CI: the manipulator alone (masses and link height, 4 parameters, the same 12 poses, no rigs: ~15 ms a call,
    # and fewer dimensions to sample). Same sampler settings, same 20 other poses and 150 band draws, so the same
    # bounds hold (see below); what it leaves out is the rigs' part of the likelihood and the rig parameters.
    # 545 s on the 2 cores at a load average of 8-9 (3 Dec 2026).
    pytest.param(
        BlindCase(("hardware", "section-height"), BLIND_PRIORS_MANIPULATOR + BLIND_PRIORS_LIKELIHOOD, rig_tests=False),
        id="ci",
    ),
]


@pytest.mark.slow
@pytest.mark.parametrize("case", BLIND_CASES)
def test_blind_truth_inside_the_marginals_and_bands_cover_other_poses(default_manip, case):
    from fpm_sim.study.poses import study_poses
    from fpm_sim.study.tables import subsystem_tests

    groups = case.groups
    ps = parameter_set(default_manip, list(groups))
    priors = read_priors("blind.toml", ps.names, text=case.priors)
    rng = np.random.default_rng(7)
    # the hidden truth: each value moved 10-30 % from the default, inside its prior
    x_true = ps.x0 * (1.0 + rng.choice([-1, 1], len(ps.x0)) * rng.uniform(0.1, 0.3, len(ps.x0)))
    truth = ps.apply(x_true)
    poses = [sp.pose for sp in study_poses()]
    fit_poses, other = poses[:12], poses[12:]
    obs0 = tuple(Observation(p, 1, 1.0, 1.0, None, "blind") for p in fit_poses)
    tests = tuple(subsystem_tests()) if case.rig_tests else ()
    # the rigs at 4 segments (the truth and the fit share the model, so the resolution does not bias the test;
    # at 8 a call costs 2.5x more)
    dummy = CalibrationProblem(default_manip, groups, priors, obs0, tests, segments=3, subsystem_segments=4)
    theta_true = np.concatenate([x_true, [0.01]])
    f_true = dummy.predict(theta_true, truth)
    assert np.all(np.isfinite(f_true))
    noisy = f_true * (1.0 + 0.015 * rng.standard_normal(len(f_true)))
    obs = tuple(dataclasses.replace(o, freq_hz=float(v), sigma_hz=0.015 * float(v)) for o, v in zip(obs0, noisy))
    rigs = tuple(dataclasses.replace(t, experimental_hz=float(v)) for t, v in zip(tests, noisy[len(obs) :]))
    prob = dataclasses.replace(
        dummy, observations=obs, rig_tests=rigs, priors=dataclasses.replace(priors, rig_sigma_pct=1.5)
    )
    # one run, as timed (the between-run check on hidden truths is issue 31's part 2)
    opts = SamplerOptions(live_points=60, dlogz=0.5, seed=3, workers=2, walks=20, runs=1)
    cal = run_calibration(prob, opts, progress=False)
    # each parameter's truth inside its 95 % marginal: a per-parameter bound, the same at any number of parameters
    # (a calibrated posterior passes all k of them with probability >= 1 - 0.05 k: 0.6 for the full case's 8, 0.8
    # for CI's 4; the seeds are fixed, so a pass is reproducible)
    lo, hi = np.quantile(cal.draws, [0.025, 0.975], axis=0)
    for i, n in enumerate(ps.names):
        assert lo[i] <= x_true[i] <= hi[i], (n, lo[i], x_true[i], hi[i])
    # predictions at 13 other study poses plus 7 off-grid ones (20): the truth's f1 inside the 90 % band
    extra = [
        Pose.from_mm(x, y, 0.0)
        for x, y in ((25, 25), (-25, 75), (75, -25), (-75, -75), (25, -75), (75, 75), (-25, -25))
    ]
    targets = (other + extra)[:20]
    other_obs = [Observation(p, 1, 1.0, 1.0, None, "other") for p in targets]

    def f1(cfg):
        return predict_observations(cfg, other_obs, options=fast_options(segments=prob.segments))

    f_truth = f1(truth)
    idx = np.random.default_rng(0).choice(len(cal.draws), size=min(150, len(cal.draws)), replace=False)
    preds = np.array([f1(prob.config(cal.draws[k])) for k in idx])
    ok = np.all(np.isfinite(preds), axis=0) & np.isfinite(f_truth)
    band_lo, band_hi = np.quantile(preds[:, ok], 0.05, axis=0), np.quantile(preds[:, ok], 0.95, axis=0)
    covered = int(np.sum((f_truth[ok] >= band_lo) & (f_truth[ok] <= band_hi)))
    # a calibrated 90 % band covers n poses ~ Binomial(n, 0.9) times: >= ceil(0.8 n) with probability 0.96 at n = 20
    # (0.90 at n = 18), in both cases (the same 20 poses)
    assert ok.sum() >= 18
    assert covered >= math.ceil(0.8 * ok.sum()), (covered, int(ok.sum()))
