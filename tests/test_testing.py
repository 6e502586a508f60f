"""fpm_sim.testing and fpm_sim.study.requirements: each helper's verdict against the pose loop called directly,
each failure message (requirement, pose, mode, margin, resolution), the payload-range argument, the reader's
errors, the shared sweeps and the JUnit XML. Tiny models: 3 spring locations per link, 2-3 poses."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.study.requirements import (
    RequirementError,
    SweepCache,
    check_requirements,
    load_requirements,
    pose_text,
    with_payload,
)
from fpm_sim.testing import (
    assert_frequencies_close,
    assert_matches_measurements,
    assert_min_frequency,
    assert_no_mode_in_band,
)

SEG = 3
POSES_MM = [(0.0, 0.0, 0.0), (50.0, 0.0, 0.0), (0.0, 50.0, 0.0)]
POSES = [Pose.from_mm(*p) for p in POSES_MM]


def truth(config, payload_kg=None, n_modes=3) -> np.ndarray:
    """The pose loop called directly, as the independent reference of the helpers' verdicts."""
    cfg = config if payload_kg is None else with_payload(config, payload_kg)
    return pose_frequencies(cfg, POSES, n_modes=n_modes, options=fast_options(segments=SEG)).frequencies_hz


# --------------------------------------------------------------------------------------------- min_frequency


def test_min_frequency_passes_just_below_the_worst_pose_and_fails_just_above(default_manip):
    f1 = truth(default_manip)[:, 0]
    worst = int(np.argmin(f1))
    assert_min_frequency(default_manip, f1[worst] - 0.01, poses=POSES_MM, segments=SEG)
    with pytest.raises(AssertionError) as exc:
        assert_min_frequency(default_manip, f1[worst] + 0.5, poses=POSES_MM, segments=SEG, name="stiff enough")
    msg = str(exc.value)
    assert "requirement 'stiff enough'" in msg
    assert f"mode 1 at pose {pose_text(POSES[worst])}" in msg
    assert f"{f1[worst]:.3f} Hz, short by 0.500 Hz" in msg
    assert f"({100 * 0.5 / (f1[worst] + 0.5):.2f} % of" in msg
    assert "1 of 3 poses fail" in msg
    assert "resolution: 3 segments per link" in msg


def test_min_frequency_of_a_higher_mode_names_that_mode(default_manip):
    f2 = truth(default_manip)[:, 1]
    with pytest.raises(AssertionError, match=r"worst mode 2 at pose .*3 of 3 poses fail"):
        assert_min_frequency(default_manip, f2.max() + 1.0, poses=POSES_MM, mode=2, segments=SEG)


def test_every_frequency_falls_with_the_payload_so_the_range_ends_suffice(default_manip):
    """The Courant-Fischer argument of the module docstring, checked: every mode at every pose is non-increasing
    in the payload mass (0 .. 2 kg in five steps), so a payload between the ends lies between the end values."""
    masses = [0.0, 0.25, 0.5, 1.0, 2.0]
    f = np.stack([truth(default_manip, m, n_modes=4) for m in masses])
    # round-off of the eigen-solve: 1e-9 relative (the mode 3 of pose 3 hardly moves: 99.58 -> 99.57 Hz)
    assert np.all(np.diff(f, axis=0) <= 1e-9 * f[:-1])
    assert np.all(f[0] - f[-1] >= -1e-9 * f[0])


def test_min_frequency_over_a_payload_range_is_decided_at_its_heavy_end(default_manip):
    heavy = truth(default_manip, 1.0)[:, 0]
    light = truth(default_manip, 0.0)[:, 0]
    bound = (heavy.min() + light.min()) / 2  # met without payload, missed with 1 kg
    assert_min_frequency(default_manip, bound, poses=POSES_MM, payload_kg=0.0, segments=SEG)
    with pytest.raises(AssertionError, match=r"with payload 1 kg: "):
        assert_min_frequency(default_manip, bound, poses=POSES_MM, payload_kg=(0.0, 1.0), segments=SEG)


# --------------------------------------------------------------------------------------------- band_exclusion


def test_band_exclusion_passes_outside_and_names_the_mode_inside(default_manip):
    f = truth(default_manip, n_modes=3)
    lo, hi = f[:, 0].max() + 0.5, f[:, 1].min() - 0.5  # between modes 1 and 2 at every pose
    assert lo < hi
    assert_no_mode_in_band(default_manip, lo, hi, poses=POSES_MM, n_modes=3, segments=SEG)
    # a band around mode 2 at pose 0 only
    band = (f[0, 1] - 0.2, f[0, 1] + 0.1)
    with pytest.raises(AssertionError) as exc:
        assert_no_mode_in_band(default_manip, *band, poses=POSES_MM, n_modes=3, segments=SEG, name="spindle")
    msg = str(exc.value)
    assert "requirement 'spindle' (band_exclusion" in msg
    assert f"worst mode 2 at pose {pose_text(POSES[0])}" in msg
    assert "inside" in msg
    assert "by 0.100 Hz" in msg  # the smallest shift that clears the band: 0.1 Hz up
    assert "resolution: 3 segments per link" in msg


def test_band_crossed_between_the_payload_ends_fails_though_both_ends_are_outside(default_manip):
    """Mode 1 at pose 0 sweeps [f(1 kg), f(0 kg)]; a band strictly inside that interval holds at neither end,
    yet the mode passes through it at some payload in between (continuity): the requirement must fail."""
    a, b = truth(default_manip, 0.0)[0, 0], truth(default_manip, 1.0)[0, 0]
    lo, hi = b + 0.4 * (a - b), b + 0.6 * (a - b)
    for m in (0.0, 1.0):  # each end alone is outside the band
        assert_no_mode_in_band(default_manip, lo, hi, poses=POSES_MM[:1], n_modes=1, payload_kg=m, segments=SEG)
    with pytest.raises(AssertionError, match=r"worst mode 1 at pose .*inside"):
        assert_no_mode_in_band(default_manip, lo, hi, poses=POSES_MM[:1], n_modes=1, payload_kg=(0, 1), segments=SEG)


# --------------------------------------------------------------------------------------------- match_measurements


def write_measured(path: Path, values_hz) -> Path:
    lines = ["x_mm,y_mm,phi_rad,f1_hz"] + [f"{x},{y},{p},{float(f)!r}" for (x, y, p), f in zip(POSES_MM, values_hz)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_matches_measurements_within_and_beyond_the_tolerance(default_manip, tmp_path):
    model = truth(default_manip)[:, 0]
    # synthetic measurements the model is 2 %, -3 % and 1 % away from (error = model / measured - 1)
    errors = np.array([0.02, -0.03, 0.01])
    assert_matches_measurements(default_manip, write_measured(tmp_path / "ok.csv", model / (1 + errors)), segments=SEG)
    errors[1] = -0.08
    csv = write_measured(tmp_path / "hammer.csv", model / (1 + errors))
    with pytest.raises(AssertionError) as exc:
        assert_matches_measurements(default_manip, csv, tolerance_pct=5.0, segments=SEG)
    msg = str(exc.value)
    assert "requirement 'within 5 % of hammer.csv'" in msg
    assert f"mode 1 at pose {pose_text(POSES[1])}" in msg
    assert "(-8.00 %)" in msg
    assert "margin -3.00 % of the 5 % tolerance" in msg
    assert "1 of 3 measured frequencies fail" in msg


def test_measured_pose_outside_the_workspace_is_bad_input(default_manip, tmp_path):
    csv = tmp_path / "far.csv"
    csv.write_text("x_mm,y_mm,phi_rad,f1_hz\n900,0,0,50\n")
    with pytest.raises(FpmSimError, match=r"measured_csv: pose \(x=900.0 mm.*unreachable"):
        assert_matches_measurements(default_manip, csv, segments=SEG)


# --------------------------------------------------------------------------------------------- frequencies close


def test_frequencies_close_on_a_pose_loop_result(default_manip):
    pf = pose_frequencies(default_manip, POSES, n_modes=2, options=fast_options(segments=SEG))
    assert_frequencies_close(pf, pf.frequencies_hz * (1 + 0.009), rtol=0.01)
    expected = pf.frequencies_hz.copy()
    expected[2, 1] *= 1.05
    with pytest.raises(AssertionError) as exc:
        assert_frequencies_close(pf, expected, rtol=0.01)
    msg = str(exc.value)
    assert f"worst mode 2 at pose {pose_text(POSES[2])}" in msg
    assert f"({100 * (1 / 1.05 - 1):+.3f} %)" in msg
    assert "1 of 6 values fail" in msg


def test_frequencies_close_on_arrays_and_shape_errors():
    assert_frequencies_close([[60.0, 80.0]], [60.3, 80.0], rtol=0.01)
    with pytest.raises(AssertionError, match=r"worst mode 1 at row 0: 60.0000 Hz vs expected 61.0000 Hz"):
        assert_frequencies_close([[60.0, 80.0]], [61.0, 80.0], rtol=0.001)
    with pytest.raises(AssertionError, match=r"mode 1 at row 0: nan Hz vs expected 60.0000 Hz"):
        assert_frequencies_close([[math.nan]], [60.0])
    with pytest.raises(FpmSimError, match="3 modes, the result only 2"):
        assert_frequencies_close([[60.0, 80.0]], [1.0, 2.0, 3.0])


# --------------------------------------------------------------------------------------------- bad input


def test_probability_needs_a_posterior_and_a_probability(default_manip):
    with pytest.raises(FpmSimError, match=r"probability= needs a posterior \(fpm-sim calibrate\)"):
        assert_min_frequency(default_manip, 40.0, poses=POSES_MM, probability=0.95)
    for p in (None, 1.0, 0.0):
        with pytest.raises(FpmSimError, match="probability"):
            assert_min_frequency(default_manip, 40.0, poses=POSES_MM, probability=p, posterior="post.nc")


def test_min_frequency_with_a_posterior_probability(default_manip, tmp_path):
    """The posterior probability against a Monte Carlo of the predictive model the calibration states (each
    draw's f (1 + d z), z independent per pose), and the pass/fail verdicts either side of it."""
    from fpm_sim.study.posterior import Posterior
    from fpm_sim.testing import _min_frequency_probability
    from tests.helpers.posterior import write_posterior

    post = Posterior.from_netcdf(write_posterior(tmp_path / "post.nc"))
    poses = [fs.Pose.from_mm(*p) for p in POSES_MM]
    _, _, bands = _min_frequency_probability(post, poses, 1.0, 1, 4)
    level = 0.97 * float(np.median(bands.frequencies_hz[:, :, 0], axis=0).min())  # inside the predictive spread
    prob, _, bands = _min_frequency_probability(post, poses, level, 1, 4)
    rng = np.random.default_rng(1)
    f = bands.frequencies_hz[:, :, 0]
    d = np.asarray(bands.discrepancy_rel)[:, None, None]
    z = rng.standard_normal((*f.shape, 20_000))
    meets = (f[:, :, None] * (1 + d * z) >= level).all(axis=1)  # (draw, sample)
    assert prob == pytest.approx(meets.mean(), abs=0.01)  # Monte Carlo error ~0.002
    assert 0.05 < prob < 0.95  # the level sits inside the predictive spread (else the check is empty)
    assert_min_frequency(default_manip, level, poses=POSES_MM, probability=prob * 0.9, posterior=post, segments=4)
    with pytest.raises(AssertionError, match=r"FAILED: the probability is .* over 6 draws at 3 poses; least likely"):
        assert_min_frequency(default_manip, level, poses=POSES_MM, probability=min(0.99, prob * 1.1 + 0.01),
                             posterior=post, segments=4)  # fmt: skip


def test_unreachable_and_empty_pose_sets_are_errors_not_failures(default_manip):
    with pytest.raises(FpmSimError, match=r"requirement 'f1 >= 40 Hz'.poses: pose \(x=900.0 mm.* is unreachable"):
        assert_min_frequency(default_manip, 40.0, poses=[(900, 0, 0)], segments=SEG)
    with pytest.raises(FpmSimError, match=r"pose set .* is empty"):
        assert_min_frequency(default_manip, 40.0, poses=[], segments=SEG)
    with pytest.raises(FpmSimError, match="payload_kg must be a mass >= 0"):
        assert_min_frequency(default_manip, 40.0, poses=POSES_MM, payload_kg=-1.0)


REQ_FILE = """
[settings]
segments = 3

[[requirement]]
name = "f1"
kind = "min_frequency"
at_least_hz = {f1}
poses = {{ list = {poses} }}

[[requirement]]
name = "f2"
kind = "min_frequency"
mode = 2
at_least_hz = 1.0
poses = {{ list = {poses} }}

[[requirement]]
name = "band"
kind = "band_exclusion"
band_hz = [1.0, 2.0]
n_modes = 3
poses = {{ list = {poses} }}

[[requirement]]
name = "f1 with payload"
kind = "min_frequency"
at_least_hz = 1.0
payload_kg = [0.0, 0.5]
poses = {{ list = {poses} }}
"""


def write_reqs(tmp_path: Path, f1: float = 1.0) -> Path:
    path = tmp_path / "fpm-requirements.toml"
    path.write_text(REQ_FILE.format(f1=f1, poses=[list(p) for p in POSES_MM]))
    return path


def test_requirements_sharing_poses_and_payload_share_one_sweep(default_manip, tmp_path):
    cache = SweepCache()
    report = check_requirements(load_requirements(write_reqs(tmp_path)), default_manip, cache=cache)
    assert report.passed
    # f1, f2 and band share (poses, description's payload, 3 segments); "f1 with payload" needs 0.5 kg
    assert report.sweeps == 2
    again = check_requirements(load_requirements(write_reqs(tmp_path)), default_manip, cache=cache)
    assert again.sweeps == 0


def test_report_contract_and_junit_xml(default_manip, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    f1 = truth(default_manip)[:, 0]
    report = check_requirements(load_requirements(write_reqs(tmp_path, f1=f1.min() + 1.0)), default_manip)
    assert not report.passed
    d = report.to_dict()
    assert [r["passed"] for r in d["requirements"]] == [False, True, True, True]
    assert d["requirements"][0]["margin_hz"] == pytest.approx(-1.0, abs=1e-9)
    assert "FAIL" in report.table()
    assert isinstance(report.plot(), Figure)
    path = report.write_junit(tmp_path / "out" / "junit.xml")
    suite = ET.parse(path).getroot().find("testsuite")
    assert suite is not None
    assert suite.get("tests") == "4"
    assert suite.get("failures") == "1"
    cases = suite.findall("testcase")
    assert [c.get("name") for c in cases] == ["f1", "f2", "band", "f1 with payload"]
    failure = cases[0].find("failure")
    assert failure is not None
    assert "requirement 'f1'" in failure.get("message", "")
    assert pose_text(POSES[int(np.argmin(f1))]) in failure.get("message", "")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[[requirement]\nname = 1", "is not valid TOML"),
        ('[[requirement]]\nname = "a"\nkind = "max_frequency"', "requirement 'a': unknown kind 'max_frequency'"),
        ('[[requirement]]\nname = "a"\nkind = "min_frequency"\nat_least_hz = 1\nspeed = 2', r"unknown key\(s\) speed"),
        ('[[requirement]]\nname = "a"\nkind = "min_frequency"', "missing 'at_least_hz'"),
        ('[[requirement]]\nname = "a"\nkind = "min_frequency"\nat_least_hz = 1\nposes = { grid = "hex" }', "grid"),
        ('[[requirement]]\nname = "a"\nkind = "min_frequency"\nat_least_hz = 1\npayload_kg = [-1, 2]', "payload_kg"),
        ('[[requirement]]\nname = "a"\nkind = "band_exclusion"\nband_hz = [5, 1]', "band_hz must satisfy"),
        ('[[requirement]]\nname = "a"\nkind = "match_measurements"\nmeasured_csv = "m.csv"', "tolerance_pct"),
        ('[[requirement]]\nname = "a"\nkind = "min_frequency"\nat_least_hz = 1\n' * 2, "used twice"),
        ("[settings]\nsegments = 3", "no requirement"),
    ],
)
def test_reader_errors_name_the_requirement_and_key(tmp_path, text, match):
    path = tmp_path / "r.toml"
    path.write_text(text)
    with pytest.raises(RequirementError, match=match):
        load_requirements(path)


def test_workspace_pose_set_is_the_pose_loops_computable_grid_points(default_manip):
    """The vectorised workspace filter keeps exactly the grid points the pose loop computes (ok, near_singular)."""
    from fpm_sim.batch.pose_loop import pose_assembly
    from fpm_sim.study.requirements import PoseSpec
    from fpm_sim.study.sweep import dense_grid

    grid = dense_grid(default_manip, step_mm=50.0)
    statuses = [pose_assembly(default_manip, p) for p in grid]
    expected = [p for p, (_, _, s) in zip(grid, statuses) if s in ("ok", "near_singular")]
    assert PoseSpec(step_mm=50.0).resolve(default_manip, "w") == expected
    assert 0 < len(expected) < len(grid)  # the grid's square holds unreachable corners
    far = [p for p, (_, m, s) in zip(grid, statuses) if s in ("ok", "near_singular") and m >= 0.3]
    assert PoseSpec(step_mm=50.0, min_singularity=0.3).resolve(default_manip, "w") == far
    assert len(far) < len(expected)


def test_assert_requirement_on_a_requirement_and_on_an_outcome(default_manip):
    from fpm_sim.study.requirements import PoseSpec, Requirement, evaluate
    from fpm_sim.testing import assert_requirement

    spec = PoseSpec(kind="list", points=tuple(POSES_MM))
    req = Requirement("f1 > 1 kHz", "min_frequency", spec, segments=SEG, at_least_hz=1000.0)
    with pytest.raises(AssertionError, match=r"requirement 'f1 > 1 kHz' .*FAILED: worst mode 1 at pose"):
        assert_requirement(req, default_manip)
    ok = evaluate(Requirement("f1 > 1 Hz", "min_frequency", spec, segments=SEG, at_least_hz=1.0), default_manip)
    assert ok.passed
    assert_requirement(ok)
    with pytest.raises(FpmSimError, match="give the description"):
        assert_requirement(req)


def test_pose_file_and_paper_pose_sets(default_manip, tmp_path):
    (tmp_path / "poses.csv").write_text("x_mm,y_mm,phi_rad\n0,0,0\n50,0,0\n")
    (tmp_path / "far.csv").write_text("x_mm,y_mm,phi_rad\n0,0,0\n900,0,0\n")
    path = tmp_path / "fpm-requirements.toml"
    body = '[[requirement]]\nname = "{n}"\nkind = "min_frequency"\nat_least_hz = 1\nposes = {p}\n'
    path.write_text(
        body.format(n="file", p='{ file = "poses.csv" }')
        + body.format(n="paper", p='{ grid = "paper", reading = "y-" }')
        + body.format(n="far", p='{ file = "far.csv" }')
    )
    reqs = load_requirements(path)
    assert reqs["file"].poses.resolve(default_manip, "r") == POSES[:2]
    from fpm_sim.study.poses import parse_reading, study_poses

    assert reqs["paper"].poses.resolve(default_manip, "r") == [sp.pose for sp in study_poses(parse_reading("y-"))]
    with pytest.raises(FpmSimError, match=r"r.poses: pose \(x=900.0 mm, y=0.0 mm, phi=0.000 rad\) is unreachable"):
        reqs["far"].poses.resolve(default_manip, "r")
    with pytest.raises(RequirementError, match="no requirement named 'nope'"):
        reqs["nope"]
