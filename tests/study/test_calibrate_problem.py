"""The calibration problem: it pickles, a spawn pool's workers compute the same log-likelihood as this
process, the likelihood is the stated Gaussian (checked with scipy.stats), impossible descriptions are -inf."""

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
