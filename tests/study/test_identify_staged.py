"""Issue 31, items 3-4: the staged continuation with multi-start (``global_method="staged"``, the default for rich
data), the pairs of parameters that trade off, and the proof: as-built machines identified to the noise floor from
data of an independent, finer model, with predictions at other poses checked against the truth."""

import dataclasses
import math
import warnings

import numpy as np
import pytest

from fpm_sim.config import default_config, load_config
from fpm_sim.kinematics import assemble_many
from fpm_sim.study.identify import IdentificationError, IdentifyOptions, Observation, Problem, identify, parameter_set
from fpm_sim.study.identify.diagnosis import CORRELATED, determination
from fpm_sim.study.identify.engine import predict_with_std, resolve_global_method
from fpm_sim.study.identify.objective import Objective
from fpm_sim.study.identify.strategies.staged import prior_starts, stages
from fpm_sim.study.poses import study_poses
from tests.conftest import REFERENCE_CONFIG
from tests.helpers.asbuilt import FIT_SEGMENTS, as_built, check_poses, rich_data, truth_frequencies, truth_vector

OPTS = IdentifyOptions(segments=2, global_method="staged", max_nfev=30, staged_starts=1, staged_max_nfev=30)


def _objective(groups, n_obs=6):
    cfg = default_config()
    obs = [Observation(study_poses()[0].pose, 1, 10.0, 0.1, None, "t")] * n_obs
    return Objective(Problem(parameter_set(cfg, groups), obs), IdentifyOptions(segments=2))


def test_the_stages_free_masses_first_then_the_collective_geometry_then_each_chain():
    obj = _objective(["geometry-per-chain", "hardware"])
    names = obj.ps.names
    plan = stages(obj)
    assert [s.name for s in plan] == ["physical", "geometry", "per-chain"]
    assert [s.basis.shape[1] for s in plan] == [3, 3 + 6, 21]  # 3 masses; + 6 fields tied over 3 chains; all
    assert [names[i] for i in plan[0].columns] == [n for n in names if n.startswith("hardware.")]
    # every tied direction moves one field of all three chains by the same step (in bound-normalised units)
    for col in plan[1].basis.T[3:]:
        moved = [names[i] for i in np.flatnonzero(col)]
        assert len(moved) == 3
        assert len({n.split("[")[0] for n in moved}) == 1
    np.testing.assert_array_equal(plan[2].basis, np.eye(len(names)))
    # geometry (collective) with the masses: stage 2 frees everything, so there is no third
    assert [s.name for s in stages(_objective(["geometry", "hardware"]))] == ["physical", "geometry"]
    assert [s.name for s in stages(_objective(["hardware"]))] == ["physical"]


def test_the_prior_samples_are_seeded_the_start_first_geometry_near_it_masses_anywhere():
    obj = _objective(["geometry-per-chain", "hardware"])
    a = prior_starts(obj, 5, 0.3, seed=4)
    b = prior_starts(obj, 5, 0.3, seed=4)
    z0 = obj.z(obj.ps.x0)
    assert a[0][1] == "start description"
    np.testing.assert_array_equal(a[0][0], z0)
    for (za, _), (zb, _) in zip(a, b):
        np.testing.assert_array_equal(za, zb)
    geo = np.array([p.group == "geometry-per-chain" for p in obj.ps.parameters])
    z = np.array([s[0] for s in a[1:]])
    assert np.all(np.abs(z[:, geo] - z0[geo]) <= 0.15 + 1e-12)
    assert np.ptp(z[:, ~geo]) > 0.3  # four uniform draws over the bounds spread the masses


def test_a_pair_that_trades_off_is_named_with_its_correlation():
    # columns a and a + 0.2 b (a, b orthonormal), a third column orthogonal to both: J'J = [[1, 1], [1, 1.04]]
    # on the pair, so their posterior correlation is -1 / sqrt(1.04) = -0.9806 (closed form); the third is
    # uncorrelated with them
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.standard_normal((30, 3)))
    a, b, c = q.T
    width = np.array([2.0, 0.5, 1.0])
    jz = np.column_stack([a, a + 0.2 * b, c]) * 40.0
    det = determination(jz / width[None, :], width, ["platform", "joint", "length"])
    assert det.correlated == [
        {"a": "platform", "b": "joint", "correlation": pytest.approx(-1 / math.sqrt(1.04), abs=1e-4)}
    ]
    assert all(det.determined)
    assert any("platform ~ joint (-0.981)" in line for line in det.lines())
    assert det.to_dict()["correlated"] == det.correlated
    # a weaker pair (0.9 in magnitude is the threshold) is not named
    jz = np.column_stack([a, a + 0.6 * b, c])
    assert abs(-1 / math.sqrt(1.36)) < CORRELATED
    assert determination(jz / width[None, :], width, ["p", "j", "l"]).correlated == []


def test_auto_runs_staged_for_rich_data_and_de_otherwise():
    obj = _objective(["hardware"], n_obs=9)
    assert resolve_global_method(obj.problem, IdentifyOptions())[0] == "staged"  # 9 data for 3 parameters
    thin = dataclasses.replace(obj.problem, observations=obj.problem.observations[:8])
    method, why = resolve_global_method(thin, IdentifyOptions())
    assert method == "de"
    assert "8 data for 3 free parameters" in why
    assert resolve_global_method(obj.problem, IdentifyOptions(global_method="de"))[0] == "de"  # still selectable


@pytest.mark.parametrize(("option", "value"), [("staged_starts", 0), ("staged_spread", 1.5), ("staged_max_nfev", 0)])
def test_staged_settings_out_of_range_are_refused_by_name(option, value, tmp_path, capsys):
    obj = _objective(["hardware"], n_obs=9)
    with pytest.raises(IdentificationError) as e:
        identify(obj.problem, options=IdentifyOptions(**{option: value}))
    assert option in str(e.value)


def test_cli_refuses_no_staged_start_in_one_line(tmp_path, capsys):
    from importlib.resources import files

    from fpm_sim.cli.main import main

    measured = files("fpm_sim.data").joinpath("measured_table4_train.csv")
    argv = ["identify", "--measured", f"{measured},reading=x+", "--free", "hardware", "--staged-starts", "0"]
    assert main([*argv, "--out", str(tmp_path / "id")]) == 2
    assert "--staged-starts must be >= 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "id").exists()


def test_staged_reaches_the_noise_floor_from_masses_far_from_the_start():
    # twin data (the fit's own model, 0.5 % noise) of the reference machine; the start's three masses 2.5x, 0.4x
    # and 2.5x the truth's and its links' sections 20 % off: the continuation fits masses and sections first
    from tests.study.test_identify_floor import _twin_data

    truth = load_config(REFERENCE_CONFIG)
    data = _twin_data(truth)
    ps = parameter_set(truth, ["hardware", "section"])
    start = ps.apply(ps.x0 * np.array([2.5, 0.4, 2.5, 1.2, 0.8]))
    fit = identify(Problem(parameter_set(start, ["hardware", "section"]), data), options=OPTS)
    assert fit.options.global_method == "staged"
    assert fit.diagnosis.floor.at_floor, fit.diagnosis.summary()
    assert fit.cost / len(data) < 2
    assert any("cost per datum by stage: physical" in h.note for h in fit.history)
    # the truth within 4 posterior sd (the stated sigmas are the noise's)
    sd = fit.diagnosis.determination.posterior_sd
    assert np.all(np.abs(fit.values - ps.x0) < 4 * sd), (fit.values, ps.x0, sd)


# ----------------------------------------------------------------------------------------------- the proof
FREE = ["geometry-per-chain", "hardware"]
NEAR_SINGULAR = 0.1
"""Check poses with a singularity measure below this (under the identified machine) are held to their stated
uncertainty instead of the 1 % / 3 % bounds: the frequencies' sensitivity to the geometry grows without bound
towards a singularity (tests/study/test_identify_blind.py measured 2-3.5 % at 0.05-0.17 and 22 % at 0.02)."""


# CI's slow set runs the machine whose masses are far from the start (the hardest); the other two are very_slow
# (python -m pytest -m very_slow): 150-220 s each on the shared cores, and CI keeps under its hour
@pytest.mark.slow
@pytest.mark.parametrize(
    ("seed", "far"),
    [
        pytest.param(1, False, marks=pytest.mark.very_slow),
        pytest.param(2, False, marks=pytest.mark.very_slow),
        (3, True),
    ],
)
def test_as_built_machines_are_identified_to_the_noise_floor_and_predict_other_poses(seed, far):
    truth, start = as_built(seed, far_masses=far), default_config()
    data = rich_data(truth, seed)
    assert len(data) == 75
    ps = parameter_set(start, FREE)
    opts = IdentifyOptions(segments=FIT_SEGMENTS, jacobian="exact")  # global_method "auto": 75 data for 23
    fit = identify(Problem(ps, data), options=opts)
    assert fit.options.global_method == "staged"
    # the noise floor: chi2 ~ chi2(52) (75 data, 23 parameters) plus the model-form error (FIT_SEGMENTS
    # inextensible segments against the data's 12 with axial springs: 0.35 % before the fit, a stiffening
    # that the masses and radii mostly absorb). Measured 0.71 per datum (seed 3); <= 2 is the target
    per_datum = fit.cost / len(data)
    assert per_datum <= 2.0, (per_datum, [h.note for h in fit.history])
    # every parameter within 4 posterior sd of the truth: the sd is the noise's; the model-form error biases the
    # radii (measured up to 2.7 sd, all base radii long and platform radii short: the discretisation's stiffening)
    z = (fit.values - truth_vector(ps.names, truth, start)) / fit.std
    assert np.max(np.abs(z)) < 4.0, dict(zip(ps.names, np.round(z, 2)))

    # 20 other poses (seeded, in the data's square, reachable): f1..f3 against the truth's own model
    other = check_poses(truth, seed)
    f_true, _ = truth_frequencies(truth, other)
    check = [Observation(p, k + 1, math.nan, math.nan, None, "check") for p in other for k in range(3)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pred, sd = predict_with_std(fit, check)
    err = np.abs(pred / f_true.ravel() - 1.0)
    measure = assemble_many(
        fit.config.geometry, [p.x_m for p in other], [p.y_m for p in other], [p.phi_rad for p in other]
    ).singularity
    near = np.repeat(~(measure >= NEAR_SINGULAR), 3)
    # away from singularities: the 1 % on average and 3 % at most (measured 0.22 % and 0.67 %, seed 3)
    assert np.mean(err[~near]) < 0.01, np.mean(err[~near])
    assert np.max(err[~near]) < 0.03, np.max(err[~near])
    # near one: the stated uncertainty (predict_with_std's delta-method sd, which grows with the frequencies'
    # sensitivity to the geometry there) covers the error at 3 sd. Measured (seed 2, a check pose at measure
    # 0.039): f1 0.84 % off, stated sd 2.0 %
    assert np.all(err[near] < 3 * (sd / pred)[near]), (err[near], (sd / pred)[near])


def test_cli_default_runs_staged_on_rich_data_and_reports_the_masses_that_trade_off(tmp_path):
    from importlib.resources import files

    from fpm_sim.cli.main import main

    measured = files("fpm_sim.data").joinpath("measured_table4_train.csv")
    out = tmp_path / "id"
    argv = ["identify", "--measured", f"{measured},reading=x+", "--free", "hardware", "--segments", "2"]
    assert main([*argv, "--staged-starts", "2", "--out", str(out), "--quiet"]) == 0
    report = (out / "report.md").read_text()
    assert "Search: global `staged` (seed 0; 2 starts" in report
    assert "auto: staged (12 data for 3 free parameters" in report
    # the study's f1..f3 at four poses see the platform and its joints mostly through their sum (measured -0.96)
    assert "hardware.platform.mass_kg ~ hardware.platform_joint.mass_kg (-0.9" in report
