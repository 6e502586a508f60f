"""The lab road end to end through the *time domain*: ``fpm-sim impact --uff`` (nonlinear hammer rollouts of a
hidden truth) -> ``fpm-sim ema`` (sdypy-EMA LSCF) -> ``fpm-sim identify`` recovers the truth's section.

``tests/study/test_identify_uff.py`` drives the same road with the model's *modal* FRFs; here the FRFs are what a
lab measures: H1 estimates from simulated impacts (half-sine pulse, accelerometer noise, a finite record, the
exponential response window, zero padding), so the EMA's peak picking and pole fit meet leakage, noise and the
window's added damping. Every step is the command a user runs, in process through :func:`fpm_sim.cli.main.main`.

Cost (why these settings): 3 segments per link without axial springs is the coarsest flexible model; its
automatic timestep is 5 us (set by the stiffest spring hinge), so one 0.5 s impact record takes about 4 s of CPU.
The fit uses the same 3 segments (``--segments 3``) and the same gravity-free, inextensible model
(``fpm-sim impact --no-gravity``; the impact command's links are inextensible by default), so the test checks the
road, not the discretisation.
"""

import json

import numpy as np
import pytest

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.cli.main import main
from fpm_sim.config.schema import config_to_toml
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import FrequencyResponse
from fpm_sim.sim.impact import write_uff58
from fpm_sim.study.identify import read_measured_csv
from tests.helpers.truths import (  # the truth, poses and settings, shared with studies/impact_road_scatter.py
    AXES,
    NOISE_M_S2,
    POSES_MM,
    SEGMENTS,
    SIGMA_PCT,
    TRUTH_SECTION_M,
    reference_config,
)


def _cli(capsys, *argv: str):
    rc = main([*argv, "--json"])
    out = capsys.readouterr().out
    assert rc == 0, out
    return json.loads(out)


@pytest.mark.slow
def test_impact_uff_ema_identify_recovers_the_hidden_section(tmp_path, capsys):
    start = reference_config()
    truth = start.with_section(**TRUTH_SECTION_M)
    (tmp_path / "truth.toml").write_text(config_to_toml(truth))
    (tmp_path / "start.toml").write_text(config_to_toml(start))

    # 1. the virtual lab: one hammer impact per pose and axis on the nonlinear model of the truth, with noise
    uff = {axis: [] for axis in AXES}
    for seed, ((x, y, phi), axis) in enumerate((p, a) for p in POSES_MM for a in AXES):
        path = tmp_path / f"pose_{x:g}_{y:g}_{axis}.uff"
        where = ("--x-mm", str(x), "--y-mm", str(y), "--phi-rad", str(phi))
        model = ("--segments", str(SEGMENTS), "--no-gravity")
        test = ("--impacts", "1", "--record-s", "0.5", "--noise-m-s2", str(NOISE_M_S2), "--seed", str(seed))
        _cli(
            capsys,
            "impact",
            "--config",
            str(tmp_path / "truth.toml"),
            *where,
            *model,
            *test,
            "--impact-axis",
            axis,
            "--f-max-hz",
            "400",
            "--uff",
            str(path),
        )
        uff[axis].append(path)

    # 2. EMA, one call per kind of test, the kind written to the modes CSV's mode column
    csvs = []
    ema_f = {}
    for axis, kind in AXES.items():
        out = tmp_path / f"ema_{kind}"
        band = ("--f-lower-hz", "20", "--f-upper-hz", "400", "--n-modes", "1")
        d = _cli(capsys, "ema", *map(str, uff[axis]), *band, "--mode-label", kind, "--out", str(out))
        for e in d["estimates"]:
            assert e["mode_label"] == kind
            # the UFF record told the EMA the window: 1 % at the end of the record, 0.5 s to a whole number of
            # rollout samples (measured 0.499993 s)
            assert e["window_tau_s"] == pytest.approx(0.5 / np.log(100.0), rel=1e-4)
            ema_f[(tuple(e["pose_mm_rad"]), kind)] = e["freq_hz"][0]
        csvs.append(out / "modes.csv")

    # the EMA read the right peak: against the truth's first mode of each kind from the constrained eigen-solve
    # (not from the rollouts). The exponential window adds the decay rate 1/tau to every pole, which keeps the damped
    # frequency and raises |pole| (the natural frequency LSCF reports) by about (zeta_total^2 - zeta^2) / 2, 0.06 %
    # at 59 Hz (zeta 1.1 % own + 2.5 % window); the UFF records carry tau and fpm-sim ema removes it. Measured with
    # 0.01 m/s^2 noise on one impact (studies/impact_road_scatter.py --seeds 8, which runs the EMA with and without
    # the correction): window removed, in-plane -0.025..+0.119 %, out-of-plane -0.034..-0.001 %; window kept
    # +0.041..+0.195 % and -0.006..+0.031 % (17 earlier draws, window kept: up to +0.27 % and +0.08 %, so about
    # +0.20 % and +0.045 % with it removed). Bounds: about 2x those; a wrong peak is >= 25 Hz off.
    poses = [Pose.from_mm(*p) for p in POSES_MM]
    pf = pose_frequencies(truth, poses, n_modes=6, options=ModelOptions(segments=SEGMENTS, axial=False, gravity=False))
    errors = {}
    for i, pose_mm in enumerate(POSES_MM):
        in_plane = pf.in_plane[i] > 0.5
        for kind, mask in (("in_plane", in_plane), ("out_of_plane", ~in_plane)):
            errors[(pose_mm, kind)] = ema_f[(pose_mm, kind)] / pf.frequencies_hz[i][mask][0] - 1.0
    with capsys.disabled():  # the numbers behind the bounds, shown with pytest -s
        print("\nEMA f / model f - 1:", {f"{p} {k}": f"{100 * v:+.3f} %" for (p, k), v in errors.items()})
    for (pose_mm, kind), e in errors.items():
        assert abs(e) < (0.004 if kind == "in_plane" else 0.001), (pose_mm, kind, e)

    # 3. identify the section from the reference start, through the CLI, with the same model options
    argv = ["identify", "--config", str(tmp_path / "start.toml"), "--free", "section", "--global", "none"]
    for c in csvs:
        argv += ["--measured", f"{c},sigma_pct={SIGMA_PCT}"]
    argv += ["--segments", str(SEGMENTS), "--quiet", "--out", str(tmp_path / "ident")]
    res = _cli(capsys, *argv)["result"]["parameters"]
    # Measured over 8 noise draws with the window removed (studies/impact_road_scatter.py --seeds 8): thickness
    # +0.001..+0.055 %, height -0.015..-0.032 %, |error| / reported std up to 0.66 and 0.35; with the window kept
    # the thickness comes out +0.040..+0.093 % (24 earlier draws: up to +0.127 %), biased high by the window, as the
    # in-plane frequencies rise with it. Bounds: about 2x the worst relative error expected over more draws, and 2
    # reported std. The start is 7.5 % and 9.5 % away.
    rel_tol = {"thickness_m": 0.0015, "height_m": 0.0008}
    for name, value in TRUTH_SECTION_M.items():
        p = res[f"section.{name}"]
        with capsys.disabled():
            print(f"{name}: truth {value:.6g}, identified {p['value']:.6g} +- {p['std']:.3g} (start {p['start']:.6g})")
        assert abs(p["value"] / value - 1.0) < rel_tol[name], (name, p)
        assert abs(p["value"] - value) < 2.0 * p["std"], (name, p)
    # the identified description is what every other command takes
    assert (tmp_path / "ident" / "config.toml").is_file()


def test_ema_mode_label_reaches_identify(tmp_path, capsys):
    """``fpm-sim ema --mode-label`` writes the mode column, so identify matches the estimate to the first mode of
    that kind (an out-of-plane test's first peak is not the model's mode 1 when an in-plane mode is lower)."""
    f = np.arange(0.0, 300.0, 0.25)
    w = 2 * np.pi * f
    h = -(w**2) / ((2 * np.pi * 150.0) ** 2 - w**2 + 2j * 0.01 * 2 * np.pi * 150.0 * w)
    frf = FrequencyResponse(f, h, "accelerance", "m/s^2/N", "hammer", "accel")
    uff = write_uff58(frf, tmp_path / "z.uff", pose_mm_rad=(0.0, 0.0, 0.2))
    band = ("--f-lower-hz", "20", "--n-modes", "1")
    d = _cli(capsys, "ema", str(uff), *band, "--mode-label", "out_of_plane", "--out", str(tmp_path / "ema"))
    assert d["estimates"][0]["mode_label"] == "out_of_plane"
    (o,) = read_measured_csv(tmp_path / "ema" / "modes.csv").observations
    assert (o.label, o.mode) == ("out_of_plane", 1)
    assert o.freq_hz == pytest.approx(150.0, rel=1e-5)
    # without the option the row stays unlabelled (the K-th lowest mode overall), as before
    _cli(capsys, "ema", str(uff), *band, "--out", str(tmp_path / "e2"))
    (o,) = read_measured_csv(tmp_path / "e2" / "modes.csv").observations
    assert o.label is None
    assert main(["ema", str(uff), "--mode-label", "sideways", "--out", str(tmp_path / "e3")]) == 2
