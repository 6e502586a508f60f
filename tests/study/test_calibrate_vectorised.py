"""The vectorised likelihoods (fpm_sim.study.calibrate.vectorised) give, row by row, what the calibration problem
gives one description at a time: the same support (-inf where it is -inf) and the same values to round-off."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fpm_sim.config import default_config
from fpm_sim.study.calibrate.problem import study_problem
from fpm_sim.study.calibrate.vectorised import (
    cheap_log_likelihood_batch,
    family_frequencies_batch,
    inplane_log_likelihood_batch,
    supports,
)
from fpm_sim.study.identify import parameter_set
from fpm_sim.study.identify.parameters import GROUPS, ParameterError, apply_parameters, apply_parameters_batch
from fpm_sim.study.inplane_surrogate import inplane_first_frequencies
from fpm_sim.study.outofplane_surrogate import outofplane_first_frequencies


def _field(cfg, spec) -> np.ndarray:
    *owners, leaf = spec.path.split(".")
    owner = cfg
    for name in owners:
        owner = getattr(owner, name)
    if spec.kind in ("chain_mean", "chain_item", "chain_scale"):
        return np.asarray(getattr(owner, f"{leaf[:-2]}_per_chain"), float)
    if spec.kind == "lump_mass":
        lump = getattr(owner, leaf)
        return np.array([lump.mass_kg, *lump.inertia_kg_m2])
    return np.asarray(getattr(owner, leaf), float)


@pytest.mark.parametrize("groups", [[g] for g in GROUPS if g != "rig"] + [["as-built", "geometry", "hardware"]])
def test_batch_parameters_are_the_one_at_a_time_fields(groups):
    start = default_config()
    # unequal chains: chain_mean shifts each chain, chain_item keeps the others
    start = start.replace(geometry=dataclasses.replace(start.geometry, proximal_length_m=(0.25, 0.26, 0.24)))
    specs = parameter_set(start, groups).parameters
    rng = np.random.default_rng(0)
    lo, hi = np.array([s.lower for s in specs]), np.array([s.upper for s in specs])
    x = lo + (hi - lo) * rng.random((20, len(specs)))
    batch = apply_parameters_batch(start, specs, x)
    for i, row in enumerate(x):
        cfg = apply_parameters(start, specs, row)
        for spec in specs:
            # the same formulas in the same order: equal to a few ulps (np.radians against math.radians)
            np.testing.assert_allclose(batch[spec.path][i], _field(cfg, spec), rtol=1e-14, atol=0, err_msg=spec.name)


def test_the_cheap_and_surrogate_likelihoods_are_the_problems_row_by_row():
    prob = study_problem(model="inplane")
    assert supports(prob)
    u = np.random.default_rng(1).random((600, prob.ndim))
    thetas = prob.prior_transform(u)
    np.testing.assert_array_equal(thetas, np.array([prob.prior_transform(r) for r in u]))
    cheap = cheap_log_likelihood_batch(prob, thetas)
    full = inplane_log_likelihood_batch(prob, thetas)
    one_cheap = np.array([prob.cheap_log_likelihood(t) for t in thetas])
    one_full = np.array([prob.log_likelihood(t) for t in thetas])
    for batch, one in ((cheap, one_cheap), (full, one_full)):
        np.testing.assert_array_equal(np.isfinite(batch), np.isfinite(one))
        ok = np.isfinite(one)
        assert 0.2 < ok.mean() < 0.9  # both the support and its complement are exercised
        # sums of tens of terms of order 1-1e3 in another order: round-off of order 1e-13 of the largest term
        np.testing.assert_allclose(batch[ok], one[ok], rtol=1e-10, atol=1e-9)


def test_the_segment_model_has_no_vectorised_likelihood_but_its_cheap_part():
    prob = study_problem(model="segments")
    assert supports(prob)  # the surrogate stands in for it as an intermediate target, never as its result
    u = np.random.default_rng(2).random((50, prob.ndim))
    thetas = prob.prior_transform(u)
    one = np.array([prob.cheap_log_likelihood(t) for t in thetas])
    batch = cheap_log_likelihood_batch(prob, thetas)
    np.testing.assert_array_equal(np.isfinite(batch), np.isfinite(one))
    np.testing.assert_allclose(batch[np.isfinite(one)], one[np.isfinite(one)], rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("as_built", [None, (1.0, 0.01)])
def test_the_two_families_surrogates_are_each_descriptions_row_by_row(as_built):
    prob = study_problem(model="segments", as_built=as_built)
    u = np.random.default_rng(4).random((200, prob.ndim))
    thetas = prob.prior_transform(u)
    f, cheap = family_frequencies_batch(prob, thetas)
    poses = [o.pose for o in prob.observations]
    ok = np.isfinite(cheap)
    assert 0.2 < ok.mean() < 0.9
    assert np.all(np.isnan(f[~ok]))
    for i in np.flatnonzero(ok)[:40]:
        cfg = prob.config(thetas[i])
        one = np.stack([inplane_first_frequencies(cfg, poses), outofplane_first_frequencies(cfg, poses)])
        # the same formulas on the same kinematics, the section's and hardware's fields built another way
        np.testing.assert_allclose(f[i], one, rtol=1e-10)


def test_as_built_deviations_come_after_the_layout_whatever_the_order_given():
    start = default_config()
    ps = parameter_set(start, ["as-built", "geometry"])
    assert [s.group for s in ps.parameters] == ["geometry"] * 6 + ["as-built"] * 12
    x = np.array([s.start for s in ps.parameters])
    x[ps.names.index("geometry.base_rotation_deg")] = 10.0
    x[ps.names.index("geometry.base_angle_dev_deg[1]")] = 1.5
    x[ps.names.index("geometry.proximal_length_m")] = 0.3
    x[ps.names.index("geometry.proximal_length_dev_rel[2]")] = 0.02
    g, g0 = ps.apply(x).geometry, start.geometry
    # the deviation adds to the layout's rotation rather than replacing it, and scales the mean length
    np.testing.assert_allclose(
        np.degrees(np.subtract(g.base_angles_rad, g0.base_angles_rad)), [10.0, 11.5, 10.0], rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(g.proximal_length_per_chain, [0.3, 0.3, 0.306], rtol=1e-14)
    with pytest.raises(ParameterError, match="overlap"):
        parameter_set(start, ["geometry-per-chain", "as-built"])


@pytest.mark.parametrize(("klass", "part"), [(0, None), (5, (3, 2, 1)), (7, (0, 4, 0))])
def test_the_samplers_vectorised_coordinates_are_its_one_at_a_time_ones(klass, part):
    from fpm_sim.study.calibrate import sampler

    prob = study_problem(model="inplane")
    sampler._init_worker(prob)
    u = np.random.default_rng(3).random((40, prob.ndim - 1))
    one = np.array([sampler._with_class(sampler._class_prior_transform(x, klass, part), klass) for x in u])
    np.testing.assert_array_equal(sampler._class_thetas(u, klass, part), one)
