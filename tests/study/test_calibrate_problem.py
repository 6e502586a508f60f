"""The calibration problem: it pickles, a spawn pool's workers compute the same log-likelihood as this
process, the likelihood is the stated Gaussian (checked with scipy.stats), impossible descriptions are -inf."""

import dataclasses
import math
import multiprocessing
import pickle

import numpy as np
import pytest
from scipy import stats

from fpm_sim.kinematics import Pose
from fpm_sim.study.calibrate import CalibrationError, CalibrationProblem, read_priors
from fpm_sim.study.calibrate.sampler import _init_worker, _worker_log_likelihood
from fpm_sim.study.identify import Observation, parameter_set

PRIORS = """
[parameters."section.height_m"]
dist = "loguniform"
lower = 0.005
upper = 0.03
reason = "assumed: bar stock"

[parameters."hardware.platform.mass_kg"]
dist = "loguniform"
lower = 0.2
upper = 6.0
reason = "assumed: a plate"

[likelihood.discrepancy_rel]
dist = "loguniform"
lower = 0.005
upper = 0.5
reason = "assumed: model error"
"""
GROUPS = ("section-height", "hardware")


def _problem(manip, model="segments", poses=((0.0, -50.0, 0.0), (50.0, 50.0, 0.0), (-50.0, 50.0, 0.0))):
    names = parameter_set(manip, list(GROUPS)).names
    text = PRIORS.replace("hardware.platform.mass_kg", "PLATFORM")
    extra = "".join(
        f'\n[parameters."{n}"]\ndist = "loguniform"\nlower = 0.03\nupper = 1.0\nreason = "assumed: hinge"\n'
        for n in names
        if n.startswith("hardware.") and n != "hardware.platform.mass_kg"
    )
    pr = read_priors("p.toml", names, text=text.replace("PLATFORM", "hardware.platform.mass_kg") + extra)
    obs = tuple(
        Observation(Pose.from_mm(x, y, p), 1, f, 0.02 * f, None, "syn") for (x, y, p), f in zip(poses, (50, 45, 40))
    )
    return CalibrationProblem(manip, GROUPS, pr, obs, segments=3, model=model)


def test_the_likelihood_is_the_stated_gaussian(default_manip):
    prob = _problem(default_manip)
    theta = prob.prior_transform(np.full(prob.ndim, 0.5))
    f = prob.predict(theta)
    d = theta[prob.names.index("likelihood.discrepancy_rel")]
    sd = np.sqrt(prob.sigma**2 + (d * f) ** 2)
    expected = float(np.sum(stats.norm.logpdf(prob.measured, loc=f, scale=sd)))
    assert prob.log_likelihood(theta) == pytest.approx(expected, rel=1e-12)


@pytest.mark.slow  # ~20 s on a shared machine: a fresh interpreter imports MuJoCo
def test_it_pickles_and_a_spawn_pool_agrees_with_this_process(default_manip):
    prob = _problem(default_manip)
    clone = pickle.loads(pickle.dumps(prob))
    rng = np.random.default_rng(1)
    thetas = [prob.prior_transform(rng.random(prob.ndim)) for _ in range(3)]
    here = [prob.log_likelihood(t) for t in thetas]
    assert [clone.log_likelihood(t) for t in thetas] == here
    with multiprocessing.get_context("spawn").Pool(1, initializer=_init_worker, initargs=(prob,)) as pool:
        there = pool.map(_worker_log_likelihood, thetas)
    # the same model in a fresh interpreter: equal to the last bit (same code, same inputs, one thread)
    assert there == here
    assert all(math.isfinite(v) for v in here)


def test_an_unreachable_measured_pose_is_impossible(default_manip):
    prob = _problem(default_manip, poses=((0.0, 0.0, 0.0), (900.0, 0.0, 0.0), (0.0, 50.0, 0.0)))
    theta = prob.prior_transform(np.full(prob.ndim, 0.5))
    assert prob.log_likelihood(theta) == -math.inf


def test_the_inplane_surrogate_refuses_what_it_cannot_give(default_manip):
    prob = _problem(default_manip, model="inplane")
    theta = prob.prior_transform(np.full(prob.ndim, 0.5))
    assert math.isfinite(prob.log_likelihood(theta))
    with pytest.raises(CalibrationError, match="model must be one of"):
        CalibrationProblem(default_manip, GROUPS, prob.priors, prob.observations, model="fem")


def test_priors_that_do_not_match_the_free_groups_are_refused(default_manip):
    prob = _problem(default_manip)
    with pytest.raises(CalibrationError, match="do not match the free parameters"):
        CalibrationProblem(default_manip, ("section-height",), prob.priors, prob.observations)


def test_the_statements_terms_follow_their_stated_formula(default_manip):
    from fpm_sim.kinematics import inverse_kinematics
    from fpm_sim.study.calibrate.priors import MeasuredPosesClear, SingularAtPhi0

    prob = _problem(default_manip)
    a, b = SingularAtPhi0(reason="r"), MeasuredPosesClear(reason="r")
    priors = dataclasses.replace(prob.priors, singular_at_phi0=a, measured_poses_clear=b)
    with_statements = dataclasses.replace(prob, priors=priors)
    g = default_manip.geometry

    def soft(z, eps):
        return math.log(eps + (1 - eps) / (1 + math.exp(-z)))

    expected = 0.0
    for x, y in a.poses_mm:  # pose by pose through the single-pose kinematics (not the vectorised call)
        m0 = inverse_kinematics(g, Pose.from_mm(x, y, 0.0), check_singularity=False).singularity
        mt = inverse_kinematics(g, Pose.from_mm(x, y, a.turn_rad), check_singularity=False).singularity
        expected += soft(min(a.near - m0.parallel, min(mt.serial, mt.parallel) - a.near) / a.width, a.eps)
    for o in prob.observations:
        m = inverse_kinematics(g, o.pose, check_singularity=False).singularity
        expected += soft((min(m.serial, m.parallel) - b.min_measure) / b.width, b.eps)
    got = with_statements.statements_log_likelihood(default_manip)
    assert got == pytest.approx(expected, rel=1e-9)
    # the shipped default contradicts statement (a) at some (x, 0) pose (issue 23): the term is far below 0
    assert got < -5.0
    assert prob.statements_log_likelihood(default_manip) == 0.0  # none enabled


def test_a_gaussian_process_discrepancy_is_the_stated_multivariate_normal(default_manip):
    """With [likelihood.length_scale_m] the poses' errors are jointly normal with covariance
    diag(sigma^2) + d^2 diag(f) K diag(f), K the squared-exponential correlation of (x, y, 0.1 m x phi)."""
    names = parameter_set(default_manip, list(GROUPS)).names
    base = _problem(default_manip)
    gp_text = base.priors.text + (
        '\n[likelihood.length_scale_m]\ndist = "loguniform"\nlower = 0.02\nupper = 1.0\nreason = "assumed: r"\n'
    )
    prob = dataclasses.replace(base, priors=read_priors("p.toml", names, text=gp_text))
    assert prob.names[-1] == "likelihood.length_scale_m"
    theta = prob.prior_transform(np.full(prob.ndim, 0.5))
    f = prob.predict(theta)
    d, ell = theta[-2], theta[-1]
    xyz = np.array([[o.pose.x_m, o.pose.y_m, 0.1 * o.pose.phi_rad] for o in prob.observations])
    k = np.exp(-0.5 * np.sum((xyz[:, None] - xyz[None]) ** 2, axis=-1) / ell**2)
    cov = np.diag(prob.sigma**2) + d**2 * np.outer(f, f) * k
    expected = stats.multivariate_normal(f, cov).logpdf(prob.measured)
    assert prob.log_likelihood(theta) == pytest.approx(expected, rel=1e-12)
    # the same problem without a correlation length: the independent likelihood, which differs here
    assert base.log_likelihood(theta[:-1]) != pytest.approx(expected, rel=1e-3)
