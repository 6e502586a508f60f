"""The k-fold plumbing of fpm-sim identify, data readers, parameter groups and the CLI's written folder."""

import dataclasses
import json
import math
import tomllib

import numpy as np
import pytest

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import LumpedMass, default_config, load_config
from fpm_sim.kinematics import Pose
from fpm_sim.study.identify import (
    DataError,
    IdentifyOptions,
    Observation,
    ParameterError,
    Problem,
    cross_validate,
    fold_assignment,
    identify,
    parameter_set,
    predict_observations,
    read_measured_csv,
)
from fpm_sim.study.poses import parse_reading

SEG = 2
POSES = [
    Pose.from_mm(x, y, p)
    for x, y, p in [(0, 0, 0.2), (50, -50, 0), (-50, 50, 0), (50, 50, 0), (-50, -50, 0), (0, -50, 0)]
]


def _with_platform_mass(cfg, m):
    hw = cfg.hardware
    r = m / hw.platform.mass_kg
    return cfg.replace(
        hardware=dataclasses.replace(hw, platform=LumpedMass(m, tuple(v * r for v in hw.platform.inertia_kg_m2)))
    )


def test_fold_assignment_partitions_the_poses():
    f = fold_assignment(12, 4, seed=3)
    assert sorted(np.bincount(f)) == [3, 3, 3, 3]
    assert np.array_equal(f, fold_assignment(12, 4, seed=3))  # reproducible
    assert not np.array_equal(f, fold_assignment(12, 4, seed=4))
    assert sorted(np.bincount(fold_assignment(7, 3, seed=0))) == [2, 2, 3]
    with pytest.raises(ValueError, match=r"^folds: "):
        fold_assignment(5, 6, seed=0)


def test_a_held_out_pose_is_predicted_by_a_fit_that_never_saw_it():
    truth = _with_platform_mass(default_config(), 3.0)
    obs = [Observation(p, 1, 1.0, 1.0, None, "synthetic") for p in POSES]
    f_true = predict_observations(truth, obs, options=fast_options(segments=SEG))
    corrupt = 2  # this pose's value is wrong by +30 %: only the fits that see it are pulled by it
    meas = f_true.copy()
    meas[corrupt] *= 1.3
    obs = [dataclasses.replace(o, freq_hz=float(m), sigma_hz=0.01 * float(m)) for o, m in zip(obs, meas)]
    ps = parameter_set(default_config(), ["hardware"])
    ps.parameters = [p for p in ps.parameters if p.name == "hardware.platform.mass_kg"]
    opts = IdentifyOptions(segments=SEG, global_method="none", max_nfev=30)
    res = identify(Problem(ps, obs), options=opts)
    cv = cross_validate(res, folds=3, max_nfev=30)
    # the fold that holds the corrupted pose out fits the clean poses only: it predicts the truth there
    # (noise-free data, same model; the least squares stops within ~1e-4 relative)
    assert cv.predicted[corrupt] == pytest.approx(f_true[corrupt], rel=1e-3)
    # the in-sample fit is pulled towards the corrupted value
    assert res.predicted[corrupt] > f_true[corrupt] * 1.01
    # every observation gets exactly one cross-validated prediction
    assert np.all(np.isfinite(cv.predicted))
    assert cv.mean_abs_pct("synthetic") > 0


def test_measured_csv_forms(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("# comment\nx_mm,y_mm,phi_rad,f1_hz,f2_hz,sigma_hz,mode\n0,0,0.2,50,,0.5,in_plane\n10,-20,0,40,80,,\n")
    ds = read_measured_csv(p, sigma_pct=2.0)
    assert [(o.mode, o.freq_hz, o.sigma_hz, o.label) for o in ds.observations] == [
        (1, 50.0, 0.5, "in_plane"),
        (1, 40.0, 0.8, None),
        (2, 80.0, 1.6, None),
    ]
    p.write_text("row_mm,col_mm,experimental_hz\n100,0,47\n50,50,unreadable\n")
    with pytest.raises(DataError, match=r"^reading: "):
        read_measured_csv(p)
    (o,) = read_measured_csv(p, reading=parse_reading("y-")).observations
    assert (o.pose.x_m, o.pose.y_m, o.pose.phi_rad) == (0.0, 0.1, -0.2)
    p.write_text("x_mm,y_mm,phi_rad,f1_hz,mode\n0,0,0,50,sideways\n")
    with pytest.raises(DataError, match="row 2: mode: unknown mode kind, got 'sideways'"):
        read_measured_csv(p)
    p.write_text("x_mm,y_mm,phi_rad,f1_hz\n0,0,0,abc\n")
    with pytest.raises(DataError, match="f1_hz"):
        read_measured_csv(p)


def test_labelled_matching_picks_the_kind_not_the_rank():
    cfg = default_config()
    pose = Pose.from_mm(0, 0, 0.2)
    from fpm_sim.batch.frequencies import pose_frequencies

    pf = pose_frequencies(cfg, [pose], n_modes=6, options=fast_options(segments=SEG))
    frac = pf.in_plane[0]
    first_in = pf.frequencies_hz[0][frac > 0.5][0]
    first_out = pf.frequencies_hz[0][frac <= 0.5][0]
    obs = [
        Observation(pose, 1, 1.0, 1.0, "in_plane", "x"),
        Observation(pose, 1, 1.0, 1.0, "out_of_plane", "x"),
        Observation(pose, 1, 1.0, 1.0, None, "x"),
    ]
    got = predict_observations(cfg, obs, options=fast_options(segments=SEG))
    # the solves ask for 5 and 6 eigenpairs: LAPACK's subset solve differs at ~1e-12 relative
    assert got[0] == pytest.approx(first_in, rel=1e-9)
    assert got[1] == pytest.approx(first_out, rel=1e-9)
    assert got[2] == pytest.approx(min(first_in, first_out), rel=1e-9)
    assert first_in != first_out


def test_parameter_groups_and_errors():
    cfg = default_config()
    ps = parameter_set(cfg, ["geometry-per-chain"])
    assert len(ps.parameters) == 18
    x = ps.x0.copy()
    x[ps.names.index("geometry.proximal_length_m[1]")] *= 1.05
    g = ps.apply(x).geometry
    assert g.proximal_length_per_chain[1] == pytest.approx(cfg.geometry.proximal_length_m * 1.05)
    assert g.proximal_length_per_chain[0] == cfg.geometry.proximal_length_m
    ps = parameter_set(cfg, ["offsets"])
    assert ps.names == ["geometry.distal_offset_m", "geometry.platform_offset_m"]
    assert list(ps.lower) == [0.0, 0.0]
    assert list(ps.upper) == [0.06, 0.06]
    assert list(ps.x0) == [0.03, 0.03]  # a coplanar start begins mid-range (0 is a stationary point)
    g = ps.apply([0.03, 0.01]).geometry
    assert g.distal_offset_per_chain == (0.03, 0.03, 0.03)
    assert g.platform_offset_per_chain == (0.01, 0.01, 0.01)
    stacked = cfg.replace(geometry=dataclasses.replace(cfg.geometry, distal_offset_m=(0.01, 0.02, 0.03)))
    ps = parameter_set(stacked, ["offsets"])
    assert ps.x0[0] == pytest.approx(0.02)  # a per-chain start: its mean, the differences kept
    assert ps.apply([0.03, 0.0]).geometry.distal_offset_per_chain == pytest.approx((0.02, 0.03, 0.04))
    with pytest.raises(ParameterError, match="unknown parameter group"):
        parameter_set(cfg, ["geometery"])
    ps = parameter_set(cfg, ["geometry", "compliance"])
    g2 = ps.apply(ps.x0).geometry
    assert g2 == cfg.geometry  # the start values reproduce the start
    assert math.isclose(ps.apply(ps.x0).compliance.passive_joint_tilt_nm_per_rad, 1e7)
    assert [n for n in ps.names if n.startswith("compliance.")] == [
        "compliance.log10_passive_joint_tilt_nm_per_rad",
        "compliance.log10_motor_clamp_nm_per_rad",
        "compliance.log10_motor_mount_tilt_nm_per_rad",
    ]
    assert math.isclose(ps.apply(ps.x0).compliance.motor_mount_tilt_nm_per_rad, 1e7)


def test_offsets_group_recovers_stacked_layers_from_synthetic_frequencies():
    # synthetic truth: the default with 40 mm / 15 mm layers, three modes at four poses, noise-free
    cfg = default_config()
    truth = cfg.replace(geometry=dataclasses.replace(cfg.geometry, distal_offset_m=0.04, platform_offset_m=0.015))
    obs = [Observation(p, m, 1.0, 1.0, None, "synthetic") for p in POSES[:4] for m in (1, 2, 3)]
    f = predict_observations(truth, obs, options=fast_options(segments=SEG))
    obs = [dataclasses.replace(o, freq_hz=float(v), sigma_hz=0.01 * float(v)) for o, v in zip(obs, f)]
    opts = IdentifyOptions(segments=SEG, global_method="none", max_nfev=40)
    ps = parameter_set(cfg, ["offsets"])
    res = identify(Problem(ps, obs), options=opts)
    # noise-free data, same model: the fit lands on the truth (measured 4e-13 m off)
    np.testing.assert_allclose(res.values, [0.04, 0.015], rtol=0, atol=1e-6)
    # why a coplanar description does not start at 0: the fit stays there (every gradient vanishes)
    ps.parameters = [dataclasses.replace(p, start=0.0) for p in ps.parameters]
    stuck = identify(Problem(ps, obs), options=opts)
    assert np.all(stuck.values < 1e-3)
    assert stuck.cost > 1e6 * res.cost


def test_cli_identify_writes_a_complete_folder_usable_with_config(tmp_path):
    from fpm_sim.cli.main import main

    truth = _with_platform_mass(default_config(), 3.0)
    obs = [Observation(p, 1, 1.0, 1.0, None, "x") for p in POSES[:4]]
    f = predict_observations(truth, obs, options=fast_options(segments=SEG))
    csv = tmp_path / "meas.csv"
    csv.write_text(
        "x_mm,y_mm,phi_rad,f1_hz\n"
        + "".join(f"{o.pose.x_m * 1e3:g},{o.pose.y_m * 1e3:g},{o.pose.phi_rad:g},{v:.6f}\n" for o, v in zip(obs, f))
    )
    out = tmp_path / "id"
    rc = main(
        [
            "identify",
            "--measured",
            f"{csv},sigma_pct=1",
            "--free",
            "hardware",
            "--global",
            "none",
            "--segments",
            str(SEG),
            "--folds",
            "2",
            "--cv-max-nfev",
            "3",
            "--max-nfev",
            "20",
            "--quiet",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    assert {p.name for p in out.iterdir()} >= {
        "config.toml",
        "identify.json",
        "report.md",
        "measured_vs_predicted.png",
        "residuals_workspace.png",
    }
    cfg = load_config(out / "config.toml")
    src = cfg.provenance["hardware.platform.mass_kg"]
    assert src.startswith("identified: meas.csv")
    assert "+-" in src
    doc = json.loads((out / "identify.json").read_text())
    assert doc["cross_validation"]["folds"] == 2
    # the command recorded is the one main() was given (not the test runner's sys.argv)
    assert doc["command"].startswith(f"fpm-sim identify --measured {csv},sigma_pct=1 --free hardware")
    assert f"Command: `fpm-sim identify --measured {csv},sigma_pct=1" in (out / "report.md").read_text()
    assert tomllib.loads((out / "config.toml").read_text())["hardware"]["platform"]["mass_kg"]["value"] > 0
    # a second run into the same folder is refused without --overwrite, before any computation
    assert main(["identify", "--measured", str(csv), "--free", "hardware", "--out", str(out)]) == 2
    assert not list(tmp_path.glob(".id.tmp-*"))


@pytest.mark.parametrize(
    ("flag", "value"), [("--refine", "0"), ("--refine-per-class", "0"), ("--generations", "0"), ("--workers", "0")]
)
def test_cli_identify_refuses_counts_below_one_naming_the_option(tmp_path, capsys, flag, value):
    from fpm_sim.cli.main import main

    csv = tmp_path / "meas.csv"
    csv.write_text("x_mm,y_mm,phi_rad,f1_hz\n0,0,0,40\n")
    rc = main(["identify", "--measured", str(csv), "--free", "hardware", flag, value, "--out", str(tmp_path / "id")])
    assert rc == 2
    assert flag in capsys.readouterr().err
    assert not (tmp_path / "id").exists()
