"""The example cell's frequency requirements as plain pytest tests (one per helper of fpm_sim.testing).

Run: ``python -m pytest examples/requirements -q`` (about ten seconds: 4 segments per link, a 50 mm grid).
The requirements in fpm-requirements.toml are collected beside these tests by the plugin (conftest.py).
"""

from pathlib import Path

import pytest

from fpm_sim.testing import (
    assert_frequencies_close,
    assert_matches_measurements,
    assert_min_frequency,
    assert_no_mode_in_band,
)

HERE = Path(__file__).parent
USABLE = {"grid": "dense", "step_mm": 50, "min_singularity": 0.2}
MACHINING_POSES = [(0, 0, 0.0), (50, 0, 0.0), (0, 50, 0.0), (-50, -50, 0.1)]  # x_mm, y_mm, phi_rad


@pytest.mark.fpm_requirement("f1 above 40 Hz, usable workspace, payload up to 1 kg")
def test_f1_above_40_hz_with_payload(fpm_config, fpm_sweep):
    assert_min_frequency(fpm_config, 40.0, grid=USABLE, payload_kg=(0.0, 1.0), segments=4, cache=fpm_sweep.cache)


def test_f1_above_40_hz_as_a_comparison(fpm_sweep):
    # the same sweep as above (shared by the session); a failure prints the worst pose, mode and margin
    assert fpm_sweep.mode(1, grid=USABLE, payload_kg=1.0) >= 40.0


def test_no_mode_in_spindle_band(fpm_config, fpm_sweep):
    assert_no_mode_in_band(
        fpm_config,
        160.0,
        175.0,
        poses=MACHINING_POSES,
        n_modes=4,
        payload_kg=(0.0, 1.0),
        segments=4,
        cache=fpm_sweep.cache,
    )


def test_matches_hammer_tests(fpm_config):
    assert_matches_measurements(fpm_config, HERE / "hammer.csv", tolerance_pct=5.0, segments=4)


def test_regression_against_last_release(fpm_sweep):
    # f1..f3 at the centre pose as recorded from this design (4 segments per link, the description's 0.5 kg
    # payload): a change of design.toml that moves one of them by more than 0.2 % fails here
    result = fpm_sweep.frequencies(poses=[(0, 0, 0.0)], n_modes=3)
    assert_frequencies_close(result, [126.5, 139.2, 139.2], rtol=0.002)


@pytest.mark.xfail(
    reason="near the singularity loci f1 falls to ~11 Hz: the whole reachable workspace is not usable", strict=True
)
def test_f1_above_40_hz_everywhere_reachable(fpm_config, fpm_sweep):
    assert_min_frequency(fpm_config, 40.0, grid={"grid": "dense", "step_mm": 50}, segments=4, cache=fpm_sweep.cache)
