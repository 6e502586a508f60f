"""Issue 31, items 3 and 5: the report says whether the fit found the machine (noise-floor test, what the data
determine, troubled poses), and the local steps' exact frequency derivatives."""

import dataclasses
import math
import warnings

import numpy as np
import pytest

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import load_config
from fpm_sim.kinematics import Pose
from fpm_sim.study.identify import IdentifyOptions, Observation, Problem, identify, parameter_set, predict_observations
from fpm_sim.study.identify.diagnosis import UNDETERMINED_SD, determination, noise_floor
from fpm_sim.study.identify.sensitivity import observation_gradients
from tests.conftest import REFERENCE_CONFIG
from tests.helpers.jitter import JITTER_SEEDS, jitter

SEG = 2
MM_RAD = [(0, 0, 0.2), (50, -50, 0), (50, 50, 0), (0, -50, 0), (-40, 0, 0.1), (20, 30, -0.1)]
POSES = [Pose.from_mm(x, y, p) for x, y, p in MM_RAD]
NOISE = 0.005  # 0.5 % of each frequency, as the rich data


def _twin_data(truth, seed=0):
    """f1..f3 at POSES from ``truth`` with 0.5 % Gaussian noise (seeded), sigma the noise's."""
    obs = [Observation(p, k, 1.0, 1.0, None, "twin") for p in POSES for k in (1, 2, 3)]
    f = predict_observations(truth, obs, options=fast_options(segments=SEG))
    sig = NOISE * f
    meas = f + sig * np.random.default_rng(seed).standard_normal(len(f))
    return [dataclasses.replace(o, freq_hz=float(m), sigma_hz=float(s)) for o, m, s in zip(obs, meas, sig)]


def _start(truth):
    """A start with the three hardware masses 30-40 % off the truth's."""
    ps = parameter_set(truth, ["hardware"])
    return ps.apply(ps.x0 * np.array([1.3, 0.7, 1.4]))


OPTS = IdentifyOptions(segments=SEG, global_method="none", max_nfev=30)


def test_a_twin_fit_reports_the_noise_floor_and_a_misspecified_one_how_far_above_it():
    truth = load_config(REFERENCE_CONFIG)
    fit = identify(Problem(parameter_set(_start(truth), ["hardware"]), _twin_data(truth)), options=OPTS)
    d = fit.diagnosis
    # the model contains the truth: chi2 ~ chi2(15 dof); this seed's draw gives p ~ 0.6, far from the 1e-3 line
    assert d.floor.dof == 18 - 3
    assert d.floor.at_floor
    assert d.floor.p_value > 0.05, d.summary()
    assert d.summary().startswith("fit at the noise floor")
    assert all(d.determination.determined)
    # each mass within 4 posterior sd of the truth (the sd is with the stated sigmas, the noise's own)
    truth_x = parameter_set(truth, ["hardware"]).x0
    assert np.all(np.abs(fit.values - truth_x) < 4 * d.determination.posterior_sd)
    # the summary reaches the table and the dict (the facade's and --json's)
    assert "fit at the noise floor" in fit.table()
    assert fit.to_dict()["diagnosis"]["noise_floor"]["at_floor"] is True

    # the truth's proximal links 3 % longer, the fit holding them at the start's: outside the model family
    g = truth.geometry
    longer = truth.replace(geometry=dataclasses.replace(g, proximal_length_m=1.03 * g.proximal_length_m))
    bad = identify(Problem(parameter_set(_start(truth), ["hardware"]), _twin_data(longer)), options=OPTS)
    fb = bad.diagnosis.floor
    assert not fb.at_floor
    assert fb.ratio > 10, fb.summary()
    assert f"fit {fb.ratio:.3g} times above the noise floor: the model or the search is missing something" in (
        bad.table()
    )


def test_the_noise_floor_test_is_the_chi_squared_tail():
    # 100 residuals of exactly 1 sigma, 4 parameters: chi2 = 100 on 96 dof. For an even dof 2k the tail is the
    # closed form exp(-x/2) sum_{i<k} (x/2)^i / i! (a Poisson sum), independent of scipy's incomplete gamma
    f = noise_floor(np.ones(100), 4)
    assert (f.chi2, f.dof) == (100.0, 96)
    closed = math.exp(-50.0) * sum(50.0**i / math.factorial(i) for i in range(48))
    assert f.p_value == pytest.approx(closed, rel=1e-9)
    assert f.at_floor
    # twice the noise in every residual: chi2/dof = 4.17, p ~ 1e-40
    g = noise_floor(2 * np.ones(100), 4)
    assert not g.at_floor
    assert g.ratio == pytest.approx(400 / 96)


@pytest.mark.parametrize("seed", [None, *JITTER_SEEDS])
def test_a_jacobian_with_a_null_direction_names_the_parameters_that_trade_off(seed):
    # four parameters, bounds' widths 2, 0.5, 1, 3; the data see the first two only through z_a - z_b
    # (a platform mass against its joints' masses, in bound-normalised units); the other two directly.
    names = ["platform", "joint", "length", "angle"]
    width = np.array([2.0, 0.5, 1.0, 3.0])
    rng = np.random.default_rng(7)
    jz = np.zeros((20, 4))
    jz[:, 0] = rng.standard_normal(20) * 30
    jz[:, 1] = -jz[:, 0]  # in z: only z_platform - z_joint is seen
    jz[:, 2] = rng.standard_normal(20) * 30
    jz[:, 3] = rng.standard_normal(20) * 30 + 0.5 * jz[:, 2]
    jx = jz / width[None, :]  # the Jacobian in the parameters' units
    if seed is not None:
        jx = jitter(jx, seed)
    det = determination(jx, width, names)
    assert det.determined == [False, False, True, True]
    assert len(det.undetermined_directions) == 1
    d = det.undetermined_directions[0]
    # the null direction is (1, 1, 0, 0)/sqrt(2) in z: equal weights of the same sign, sd >> the threshold
    assert set(d["weights"]) == {"platform", "joint"}
    np.testing.assert_allclose(list(d["weights"].values()), [2**-0.5, 2**-0.5], atol=1e-3)
    assert d["sd_fraction"] > 1e6 * UNDETERMINED_SD
    # the determined parameters' sd: ~1/(30 sqrt(20)) of their widths, far below the threshold
    assert np.all(det.posterior_sd[2:] / width[2:] < 0.05)


def _central_differences(ps, x, obs, opts, rel=1e-5):
    """The frequencies' central differences, step ``rel`` of each bound width (a second, independent method)."""
    out = np.zeros((len(obs), len(x)))
    for k in range(len(x)):
        h = rel * ps.width[k]
        lo, hi = x.copy(), x.copy()
        lo[k], hi[k] = x[k] - h, x[k] + h
        fl = predict_observations(ps.apply(lo), obs, options=opts)
        fh = predict_observations(ps.apply(hi), obs, options=opts)
        out[:, k] = (fh - fl) / (2 * h)
    return out


@pytest.mark.parametrize("labelled", [False, True])
def test_the_eigen_sensitivities_match_central_differences_of_the_frequencies_geometry_included(labelled):
    ref = load_config(REFERENCE_CONFIG)
    ps = parameter_set(ref, ["geometry", "hardware", "section"])
    x = ps.x0 * (1 + 0.02 * np.sin(np.arange(len(ps.x0)) + 1.0))  # off the start: no special point
    x = np.clip(x, ps.lower, ps.upper)
    kinds = [("in_plane", 1), ("in_plane", 2), ("out_of_plane", 1)] if labelled else [(None, 1), (None, 2), (None, 3)]
    obs = [Observation(p, k, 1.0, 1.0, lab, "t") for p in POSES for lab, k in kinds]
    opts = fast_options(segments=SEG)
    exact = observation_gradients(ps, x, list(range(len(x))), obs, opts)
    cd = _central_differences(ps, x, obs, opts)
    # compared per datum on the scale of its largest derivative times the bound width (a frequency change in Hz
    # over the whole range). The central differences truncate at O(step^2): measured, the largest difference is
    # 1.5e-3, 1.5e-5 and 4e-7 at steps of 1e-3, 1e-4 and 1e-5 of the width (the h^2 law down to the exact value;
    # the worst column the platform-joint rotation, whose 120-deg range curves the frequencies most). At 1e-5 the
    # eigen-solves' round-off adds ~1e-13 / 1e-5 = 1e-8 and the matrices' forward step (1e-7 of the width)
    # ~1e-7. 1e-5 leaves 20x for another machine's round-off; a missing constraint term (-2 mu' dG x) puts the
    # geometry columns off by O(1).
    scaled = lambda g: g * ps.width[None, :]  # noqa: E731
    scale = np.abs(scaled(cd)).max(axis=1, keepdims=True)
    err = np.abs(scaled(exact) - scaled(cd)) / scale
    assert err.max() < 1e-5, (ps.names, err.max(axis=0))


def test_the_exact_jacobian_refinement_reaches_the_noise_floor_with_fewer_evaluations():
    truth = load_config(REFERENCE_CONFIG)
    problem = Problem(parameter_set(_start(truth), ["hardware"]), _twin_data(truth))
    fd = identify(problem, options=OPTS)
    ex = identify(problem, options=dataclasses.replace(OPTS, jacobian="exact"))
    assert ex.diagnosis.floor.at_floor
    # the same optimum: the costs agree to the fd Jacobian's own accuracy (its steps end within ~1e-3 of a sd)
    assert ex.cost == pytest.approx(fd.cost, rel=1e-3)
    np.testing.assert_allclose(ex.values, fd.values, atol=1e-2 * ex.diagnosis.determination.posterior_sd.max())
    # the exact path was taken: its Jacobian solves no frequency per parameter (the evaluations count whole
    # frequency computations; its matrix steps are not counted), the fd Jacobian one per parameter
    assert ex.history[-1].evaluations < fd.history[-1].evaluations


def test_cli_exact_jacobian_writes_the_verdict_to_the_report_the_json_and_stdout(tmp_path, capsys):
    import json

    from fpm_sim.cli.main import main

    truth = load_config(REFERENCE_CONFIG)
    obs = _twin_data(truth)
    meas = tmp_path / "meas.csv"
    rows = {}
    for o in obs:
        rows.setdefault((o.pose.x_m, o.pose.y_m, o.pose.phi_rad), []).append(o.freq_hz)
    meas.write_text(
        "x_mm,y_mm,phi_rad,f1_hz,f2_hz,f3_hz\n"
        + "".join(
            f"{x * 1e3:g},{y * 1e3:g},{p:g},{','.join(f'{f:.6f}' for f in fs)}\n" for (x, y, p), fs in rows.items()
        )
    )
    ws = tmp_path / "ws.csv"
    ws.write_text("x_mm,y_mm,phi_rad\n0,0,0\n")  # the workspace prior's rows go through the fd part of the Jacobian
    out = tmp_path / "id"
    argv = ["identify", "--config", str(REFERENCE_CONFIG), "--measured", f"{meas},sigma_pct=0.5", "--free", "hardware"]
    argv += ["--global", "none", "--segments", str(SEG), "--max-nfev", "20", "--quiet", "--jacobian", "exact"]
    assert main([*argv, "--workspace", str(ws), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    verdict = printed["result"]["diagnosis"]["summary"]
    assert verdict.startswith("fit at the noise floor"), verdict
    assert json.loads((out / "identify.json").read_text())["result"]["diagnosis"]["summary"] == verdict
    report = (out / "report.md").read_text()
    assert "## Did the fit find the machine?" in report
    assert f"**{verdict}**" in report
    assert "exact Jacobian of the frequencies" in report


def test_pairing_by_frequency_survives_a_mode_the_file_did_not_measure():
    # the file measured the model's 1st, 3rd and 4th modes at each pose (the 2nd crossed into the band unseen) and
    # numbered them f1, f2, f3. By order, f2 and f3 are paired with the wrong modes; by frequency (the assignment
    # problem), each with its own, and the derivatives follow the same pairing.
    truth = load_config(REFERENCE_CONFIG)
    opts = fast_options(segments=SEG)
    # not the symmetric first pose: its 3rd and 4th modes are a repeated pair (only their sum has a derivative)
    full = [Observation(p, k, 1.0, 1.0, None, "f") for p in POSES[1:] for k in (1, 2, 3, 4)]
    f = predict_observations(truth, full, options=opts)
    seen = [o for o in full if o.mode != 2]
    renumbered = [
        dataclasses.replace(o, mode={1: 1, 3: 2, 4: 3}[o.mode], freq_hz=float(v), sigma_hz=NOISE * float(v))
        for o, v in zip(full, f)
        if o.mode != 2
    ]
    want = np.array([v for o, v in zip(full, f) if o.mode != 2])
    by_order = predict_observations(truth, renumbered, options=opts)
    by_freq = predict_observations(truth, renumbered, options=opts, pairing="frequency")
    assert np.max(np.abs(by_order / want - 1)) > 0.05  # the wrong modes: off by far more than the noise
    # the same modes, from a solve asked for more of them (the pairing's margin): equal to round-off
    np.testing.assert_allclose(by_freq, want, rtol=1e-10)
    ps = parameter_set(truth, ["geometry", "hardware"])
    exact = observation_gradients(ps, ps.x0, list(range(len(ps.x0))), renumbered, opts, pairing="frequency")
    direct = observation_gradients(ps, ps.x0, list(range(len(ps.x0))), seen, opts)  # the modes by their own number
    scale = np.abs(direct * ps.width).max()
    np.testing.assert_allclose(exact * ps.width, direct * ps.width, rtol=0, atol=1e-8 * scale)


def test_frequency_pairing_and_the_exact_jacobian_carry_into_cross_validation_and_predictions():
    from fpm_sim.study.identify import cross_validate, predict_with_std

    truth = load_config(REFERENCE_CONFIG)
    opts = dataclasses.replace(OPTS, jacobian="exact", pairing="frequency")
    fit = identify(Problem(parameter_set(_start(truth), ["hardware"]), _twin_data(truth)), options=opts)
    assert fit.diagnosis.floor.at_floor
    cv = cross_validate(fit, folds=2, max_nfev=10)
    # held-out poses predicted by a 3-mass fit of half the poses: measured 0.95 % at most (0.5 % noise); 2 %
    # leaves 2x. The masses move f1..f3 by 35-53 % over their bounds, and a wrong pairing would be off by the
    # gap to a neighbouring mode, 4.8 % at least here
    assert np.nanmax(np.abs(cv.error_pct())) < 2
    # predictions at a pose without measured values (NaN placeholders) fall back to pairing by order
    new = [Observation(Pose.from_mm(10, -10, 0.05), k, float("nan"), float("nan"), None, "new") for k in (1, 2, 3)]
    f, sd = predict_with_std(fit, new)
    np.testing.assert_allclose(f, predict_observations(fit.config, new, options=fast_options(segments=SEG)))
    assert np.all(sd > 0)


def test_a_described_architecture_fit_says_whether_it_found_the_machine(tmp_path):
    from fpm_sim.architecture import load_description
    from fpm_sim.study.identify.described import identify_description, parse_free_paths, read_task_measured_csv
    from tests.architecture.test_architecture_identify import COARSE, FIVE_BAR, _measured

    desc = load_description(FIVE_BAR)
    # noise-free twin data stated at 0.5 % (at the default 2 % the held fit below, 2.2 % off on average, is
    # within the noise: chi2 = 12.3 for 8 dof, p = 0.14, rightly "at the noise floor")
    data = read_task_measured_csv(_measured(tmp_path), desc, sigma_pct=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        both = identify_description(
            desc, data, parse_free_paths("sections.bar.height_m,lumps.end_effector.mass_kg=0.1:0.5", desc),
            options=COARSE,
        )  # fmt: skip
        held = identify_description(desc, data, parse_free_paths("sections.bar.height_m", desc), options=COARSE)
    # the truth's two edits freed: the residuals vanish (chi2 ~1e-20), p = 1
    assert both.diagnosis["summary"].startswith("fit at the noise floor")
    assert all(d["determined"] for d in both.diagnosis["determination"]["parameters"].values())
    # the end effector's mass held at the file's 0.25 kg instead of the truth's 0.3: measured 24.7 times above the
    # floor, p = 2e-38
    assert not held.diagnosis["noise_floor"]["at_floor"]
    assert "times above the noise floor: the model or the search is missing something" in held.table()
    assert held.to_dict()["diagnosis"]["summary"] == held.diagnosis["summary"]
