"""The study's full-vs-reduced transient: error per load axis, files, and the full study run (slow)."""

import numpy as np
import pytest

from fpm_sim.study.transient import ANISOTROPY_TOL, STUDY_FORCE_N, nrms_error, study_transient


@pytest.fixture(scope="module")
def short(default_manip):
    """The study's setup on a coarse 3-segment discretisation and a 40 ms window (fast)."""
    return study_transient(default_manip, segments=3, duration_s=0.04)


def test_reduced_model_follows_the_nonlinear_rollout(short):
    assert [c.axis for c in short.cases] == ["x", "y"]
    for c in short.cases:
        # the target is 5 %; at 10 N the gap is geometric nonlinearity (measured ~1 to 2 %)
        assert c.nrms <= 0.05
        assert c.force_n == STUDY_FORCE_N
        assert len(c.t_s) == 401
        assert np.allclose(np.diff(c.t_s), 1e-4)
        # the response is a deflection along the load, of the order of the static compliance
        assert c.disp_full_m.max() > 1e-4
    s = short.summary()
    x, y = short.case("x"), short.case("y")
    ratio = y.peak_full_m / x.peak_full_m
    assert s["y_over_x_peak_full"] == pytest.approx(ratio, rel=1e-12)
    assert s["y_larger_than_x"] == (ratio > 1.0)
    # the verdict states what the peaks show (the study: y larger than x), not merely some text
    expected = "y larger" if ratio > 1 + ANISOTROPY_TOL else "x larger" if ratio < 1 - ANISOTROPY_TOL else "equal"
    assert expected in s["anisotropy_verdict"]
    # the reduced model sees the same anisotropy as the full rollout (both within the 5 % nrms above)
    assert s["y_over_x_peak_rom"] == pytest.approx(ratio, rel=0.05)
    assert s["wall_full_s"] > 0
    assert s["wall_rom_total_s"] > 0


def test_nrms_error():
    t = np.linspace(0, 1, 1001)
    a = np.sin(2 * np.pi * t)
    assert nrms_error(a, a) == 0.0
    assert nrms_error(a, 1.1 * a) == pytest.approx(0.1)


def test_files(short, tmp_path):
    files = short.save(tmp_path / "out")
    lines = files["csv"].read_text().splitlines()
    assert lines[0] == "t_s,load_axis,disp_full_m,disp_rom_m"
    assert len(lines) == 1 + 2 * 401
    assert lines[1].split(",")[1] == "x"
    assert lines[-1].split(",")[1] == "y"
    assert files["plot"].stat().st_size > 1000
    assert "wall time" in files["summary_txt"].read_text()


@pytest.mark.slow
def test_study_transient(default_manip):
    """The study's transient as shipped (12 segments, discrete integrator, 0.2 s at 0.1 ms): about 18 s."""
    res = study_transient(default_manip)
    assert res.parameters["segments"] == 12
    assert res.stepping.integrator == "discrete"
    for c in res.cases:
        assert c.nrms <= 0.05  # the target; measured 1.3 % (x) and 1.7 % (y)
        assert len(c.t_s) == 2001


def test_discrete_and_explicit_agree_at_3_segments(default_manip):
    """The default (discrete) full model against the explicit reference, 3 segments, 40 ms (fast)."""
    runs = [study_transient(default_manip, segments=3, duration_s=0.04, integrator=i) for i in ("explicit", "discrete")]
    assert runs[1].stepping.step_s > 5 * runs[0].stepping.step_s
    for a in ("x", "y"):
        # measured 0.14 % (x) and 0.13 % (y); 1 % is the bound at 12 segments
        assert nrms_error(runs[0].case(a).disp_full_m, runs[1].case(a).disp_full_m) <= 0.01


@pytest.mark.slow
def test_discrete_matches_the_explicit_reference_at_12_segments(default_manip):
    """The issue's check: the study transient at the standard 12 segments, discrete (default band 5 x f1: the
    0.1 ms output step) against the explicit reference (0.81 us steps; 4-12 min a load axis on the shared
    machine), NRMS <= 1 % on both axes. Measured 0.473 % (x) and 0.451 % (y), 192x faster
    (scripts/benchmark_integrators.py)."""
    runs = [study_transient(default_manip, integrator=i) for i in ("explicit", "discrete")]
    for a in ("x", "y"):
        assert nrms_error(runs[0].case(a).disp_full_m, runs[1].case(a).disp_full_m) <= 0.01
