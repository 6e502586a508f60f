"""The workspace prior of fpm-sim identify (``Problem.workspace``, ``--workspace``): poses the machine is known to
work at penalise descriptions under which they are unreachable or near a singularity."""

import dataclasses
import json

import numpy as np
import pytest

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import load_config
from fpm_sim.kinematics import Pose, inverse_kinematics
from fpm_sim.study.identify import (
    IdentifyOptions,
    Observation,
    Problem,
    identify,
    parameter_set,
    predict_observations,
    workspace_residuals,
)
from fpm_sim.study.identify.problem import PENALTY_SIGMAS
from tests.conftest import REFERENCE_CONFIG

SEG = 2
DATA_POSES = [Pose.from_mm(x, y, p) for x, y, p in [(0, 0, 0.2), (50, -50, 0), (50, 50, 0), (0, -50, 0)]]
W = Pose.from_mm(-50, 50, 0)  # measure 0.070 under the reference description


def _measure(cfg, pose):
    # the per-pose inverse kinematics' measure (the prior evaluates the vectorised one)
    return inverse_kinematics(cfg.geometry, pose, check_singularity=False).singularity.value


def test_the_hinge_zero_above_the_threshold_linear_below_penalty_when_unreachable():
    ref = load_config(REFERENCE_CONFIG)
    ps = parameter_set(ref, ["geometry"])
    m = np.array([_measure(ref, p) for p in [*DATA_POSES, W]])
    far = Pose.from_mm(1000, 0, 0)  # outside every link's reach
    ws = [*DATA_POSES, W, far]
    r = workspace_residuals(Problem(ps, [], workspace=ws, min_singularity=0.5 * m.min()), ref)
    np.testing.assert_array_equal(r[:-1], 0.0)
    assert r[-1] == PENALTY_SIGMAS
    # the threshold at twice W's measure: W half-way, a residual of half the penalty
    r = workspace_residuals(Problem(ps, [], workspace=[W], min_singularity=2 * m[-1]), ref)
    np.testing.assert_allclose(r, [0.5 * PENALTY_SIGMAS], rtol=1e-9)


def _proximal_only(cfg):
    ps = parameter_set(cfg, ["geometry"])
    ps.parameters = [p for p in ps.parameters if p.name == "geometry.proximal_length_m"]
    return ps


@pytest.fixture(scope="module")
def synthetic():
    ref = load_config(REFERENCE_CONFIG)
    obs = [Observation(p, k, 1.0, 1.0, None, "synthetic") for p in DATA_POSES for k in (1, 2)]
    f = predict_observations(ref, obs, options=fast_options(segments=SEG))
    obs = [dataclasses.replace(o, freq_hz=float(v), sigma_hz=0.01 * float(v)) for o, v in zip(obs, f)]
    return ref, obs


def test_the_prior_moves_a_fit_away_from_a_near_singular_workspace_pose_and_is_not_counted_as_data(synthetic):
    ref, obs = synthetic
    opts = IdentifyOptions(segments=SEG, global_method="none", max_nfev=20)
    m_truth = _measure(ref, W)
    free = identify(Problem(_proximal_only(ref), obs), options=opts)
    assert free.cost < 1e-8  # noise-free data, the start is the truth
    # a threshold below the truth's measure changes nothing
    loose = identify(
        Problem(_proximal_only(ref), obs, workspace=[W], min_singularity=0.9 * m_truth),
        options=opts,
    )
    np.testing.assert_array_equal(loose.values, free.values)
    # a threshold at twice the truth's measure: the truth now costs (PENALTY/2)^2; the fit trades data misfit
    # for distance from the singularity and ends cheaper than the truth, with W's measure raised
    tight = identify(
        Problem(_proximal_only(ref), obs, workspace=[W], min_singularity=2 * m_truth),
        options=opts,
    )
    assert 0.0 < tight.cost < (0.5 * PENALTY_SIGMAS) ** 2
    assert _measure(tight.config, W) > m_truth
    assert tight.dof == free.dof == len(obs) - 1  # the prior's residual is not a degree of freedom


def test_cli_workspace_file_reported_and_bad_values_refused(tmp_path, synthetic):
    from fpm_sim.cli.main import main

    _, obs = synthetic
    meas = tmp_path / "meas.csv"
    meas.write_text(
        "x_mm,y_mm,phi_rad,f1_hz\n"
        + "".join(f"{o.pose.x_m * 1e3:g},{o.pose.y_m * 1e3:g},{o.pose.phi_rad:g},{o.freq_hz:.6f}\n" for o in obs[::2])
    )
    ws = tmp_path / "ws.csv"
    ws.write_text("x_mm,y_mm,phi_rad\n-50,50,0\n1000,0,0\n")
    base = ["identify", "--config", str(REFERENCE_CONFIG), "--measured", f"{meas},sigma_pct=1", "--free", "hardware"]
    base += ["--global", "none", "--segments", str(SEG), "--max-nfev", "2", "--quiet"]
    out = tmp_path / "id"
    assert main([*base, "--workspace", str(ws), "--out", str(out)]) == 0
    doc = json.loads((out / "identify.json").read_text())
    assert doc["workspace"]["poses"] == 2
    assert doc["workspace"]["unreachable"] == 1
    assert "(x=1000.0 mm, y=0.0 mm, phi=0.000 rad)" in doc["workspace"]["below_threshold"]
    assert "Workspace prior: 2 poses" in (out / "report.md").read_text()
    for bad in (["--workspace", str(tmp_path / "nowhere.csv")], ["--workspace", str(ws), "--min-singularity", "0"]):
        assert main([*base, *bad, "--out", str(tmp_path / "refused")]) == 2
        assert not (tmp_path / "refused").exists()
