"""The full-model differential evolution (``global_method="de"``): it finds the elbow branches and the geometry
of a synthetic truth from a start on other branches, where a local search from the start cannot."""

import dataclasses

import numpy as np
import pytest

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import load_config
from fpm_sim.kinematics import Pose
from fpm_sim.study.identify import IdentifyOptions, Observation, Problem, identify, parameter_set, predict_observations
from tests.conftest import REFERENCE_CONFIG

SEG = 2
POSES = [Pose.from_mm(x, y, p) for x, y, p in [(0, 0, 0.2), (50, -50, 0), (0, -50, 0), (50, 50, 0), (-50, -50, 0)]]


def _geometry_only(start):
    ps = parameter_set(start, ["geometry"])
    keep = ("geometry.proximal_length_m", "geometry.base_rotation_deg")
    ps.parameters = [p for p in ps.parameters if p.name in keep]
    return ps


def _synthetic_problem():
    """The truth: another elbow-branch combination, proximal links 8 % longer, layout turned 12 deg; its f1..f3
    at 5 poses (1 % sigma, noise-free). The start: the reference's own branches, nominal geometry."""
    ref = load_config(REFERENCE_CONFIG)
    g = ref.geometry
    truth_start = ref.replace(geometry=dataclasses.replace(g, elbow_branch=(1, -1, 1)))
    truth_ps = _geometry_only(truth_start)
    x_true = np.array([g.proximal_length_m * 1.08, 12.0])
    truth = truth_ps.apply(x_true)
    obs = [Observation(p, k, 1.0, 1.0, None, "synthetic") for p in POSES for k in (1, 2, 3)]
    f = predict_observations(truth, obs, options=fast_options(segments=SEG))
    assert np.all(np.isfinite(f))
    obs = [dataclasses.replace(o, freq_hz=float(v), sigma_hz=0.01 * float(v)) for o, v in zip(obs, f)]
    return Problem(_geometry_only(ref), obs), x_true


@pytest.mark.parametrize("strategy", ["best1bin", "rand1bin"])
def test_de_finds_the_branches_and_geometry_a_local_search_misses(strategy):
    problem, x_true = _synthetic_problem()
    local = identify(problem, options=IdentifyOptions(segments=SEG, global_method="none", max_nfev=30))
    opts = IdentifyOptions(
        segments=SEG, global_method="de", generations=15, popsize=6, n_refine=2, de_strategy=strategy
    )
    de = identify(problem, options=opts)
    # noise-free data from the same model: the global search lands in the truth's basin and the local
    # refinement converges there (measured: cost ~1e-9); the local search from the start cannot change
    # the branches and stays far (measured cost > 100)
    assert de.config.geometry.elbow_branch == (1, -1, 1)
    np.testing.assert_allclose(de.values, x_true, rtol=1e-3, atol=1e-2)
    assert de.cost < 1e-3
    assert local.cost > 1e3 * max(de.cost, 1e-6)
    # reproducible with the seed, and the same when the population is scored in two processes
    again = identify(problem, options=dataclasses.replace(opts, workers=2))
    np.testing.assert_array_equal(again.values, de.values)


def test_first_population_is_sobol_with_surrogate_seeds_per_branch(monkeypatch):
    from fpm_sim.study.identify import objective, problem
    from fpm_sim.study.identify.strategies import de

    ref = load_config(REFERENCE_CONFIG)
    ps = parameter_set(ref, ["geometry", "hardware"])
    obs = [Observation(p, 1, 40.0, 0.4, None, "synthetic") for p in POSES]
    obj = objective.Objective(Problem(ps, obs), IdentifyOptions(segments=SEG))
    free = np.array(obj.man_idx, dtype=int)
    geo = [j for j, i in enumerate(free) if ps.parameters[i].group == "geometry"]
    assert 0 < len(geo) < len(free)
    branches = list(problem.ELBOW_BRANCHES)
    # a stand-in surrogate: each branch's "optimum" a distinct, recognisable geometry (the order is its ranking)
    ranked = branches[::-1]
    fake = []
    for k, b in enumerate(ranked):
        z = np.full(len(ps.parameters), 0.5)
        z[free[geo]] = 0.01 * (k + 1)
        fake.append((z, f"fake {b}", b))
    calls = []
    monkeypatch.setattr(de, "surrogate_starts", lambda o, opts, br: calls.append(list(br)) or fake)

    d = len(free) + 1
    plain = de.initial_population(
        obj, IdentifyOptions(segments=SEG, popsize=5, surrogate_seeds=0), free, branches
    )
    assert calls == []  # no surrogate run when no seed is asked for
    n = plain.shape[0]
    assert plain.shape == (n, d)
    assert n >= 5 * d
    assert n & (n - 1) == 0  # scipy's Sobol size: a power of two
    assert np.all((plain[:, :-1] >= 0) & (plain[:, :-1] <= 1))
    assert np.all((plain[:, -1] >= 0) & (plain[:, -1] <= len(branches) - 1))

    seeded = de.initial_population(
        obj, IdentifyOptions(segments=SEG, popsize=5, surrogate_seeds=2), free, branches
    )
    assert calls == [branches]  # every combination, not the surrogate-de's own six
    for k, b in enumerate(ranked):
        for row in (2 * k, 2 * k + 1):
            np.testing.assert_array_equal(seeded[row, geo], 0.01 * (k + 1))
            assert seeded[row, -1] == branches.index(b)
    rest = [j for j in range(len(free)) if j not in geo]
    # the seeds' other parameters, and every later member, are the Sobol population's own
    np.testing.assert_array_equal(seeded[:, rest], plain[:, rest])
    np.testing.assert_array_equal(seeded[2 * len(branches) :], plain[2 * len(branches) :])


def test_refinement_candidates_are_class_leaders_first_then_runners_up():
    problem, _ = _synthetic_problem()
    opts = IdentifyOptions(
        segments=SEG, global_method="de", generations=2, popsize=6, n_refine=100, refine_per_class=2, max_nfev=1
    )
    result = identify(problem, options=opts)
    notes = [c.origin for c in result.candidates]
    leaders = [n for n in notes if ", best of its final population" in n]
    runners_up = [n for n in notes if ", no. 2 of its final population" in n]
    # every candidate is refined (n_refine is larger): the classes' best, then their second best, then the start
    assert notes == [*leaders, *runners_up, "start description"]
    branches = [n.split("elbow branches ")[1] for n in leaders]
    assert len(set(branches)) == len(branches) > 1
    assert {n.split("elbow branches ")[1] for n in runners_up} <= set(branches)
    # one candidate per class unless asked for more
    one = identify(problem, options=dataclasses.replace(opts, refine_per_class=1)).candidates
    assert [c.origin for c in one] == [*leaders, "start description"]

    # the report lists every end, best first, its cost above the optimum's in units of s^2
    from fpm_sim.study.identify.report import competing_optima_lines

    rows = [r for r in competing_optima_lines(result) if r.startswith("| ") and not r.startswith("| cost")]
    assert len(rows) == len(result.candidates)
    costs = [float(r.split(" | ")[0][2:]) for r in rows]
    assert costs == sorted(costs)
    assert costs[0] == pytest.approx(result.cost, rel=1e-3)
    deltas = [float(r.split(" | ")[1]) for r in rows]
    s2 = max(result.chi2_per_dof, 1.0)
    np.testing.assert_allclose(deltas, (np.array(costs) - result.cost) / s2, atol=0.01 + 1e-3 * max(costs) / s2)
