"""Regression of the headline numbers as shipped (the embedded default description, `fpm-sim reproduce`'s
pose loop and subsystem rigs): the subsystems within 0.3 % of the measurements, and the 25-pose error
statistics against the study's COMSOL table.

What moves these numbers, and so the tolerances: the pose loop (gravity off, at ``qpos0``) has no iterative
solver: M from ``mj_fullM``, K the exact joint-spring diagonal, an SVD null space and a dense symmetric
eigen-solve, so only round-off and LAPACK/BLAS builds move f1 (1e-12..1e-10 relative); the clamped subsystem
rigs add the centred finite-difference stiffness (round-off ~1e-9 relative). 1e-7 relative (f1, subsystems) and
1e-5 percentage points (statistics) are 100-1000x those and catch any change of the model, the description or
the study's table. A deliberate change of the default description must update the values here, with its
reason in the commit.
"""

import numpy as np
import pytest

from fpm_sim.config import default_config
from fpm_sim.study.reproduce import reproduce_study

SHIPPED_F1_HZ = np.array(
    [
        43.7081976915, 46.4974721003, 47.9307626379, 49.2053395092, 46.8285240360,
        46.7875064001, 51.7090272347, 55.2211483020, 61.1973500600, 52.5302502730,
        49.6686932229, 57.5746971211, 63.0750583367, 57.5378409235, 38.9110076612,
        53.7443017680, 63.6252124746, 55.7789578536, 34.4054340863, 12.8073667635,
        61.2201949530, 52.2185194909, 24.6048657879, 0.5862964483, 34.6704668177,
    ]
)  # fmt: skip
"""f1 at the 25 study poses (default reading: rows are x, +0.2 rad; the default resolution, 12 segments,
gravity off), measured 2026-12-01 on the default re-identified by `fpm-sim identify --global de` (issue 12). The pose
at 0.59 Hz sits next to a parallel singularity of the identified geometry (docs/identification.md)."""

SHIPPED_STATS = {
    "n": 18,
    "mean_abs_pct": 16.050982817572166,
    "median_abs_pct": 9.1654252721175,
    "max_abs_pct": 83.009186525112,
    "min_abs_pct": 0.16138016404367567,
    "mean_signed_pct": -0.536224056870526,
    "spearman": 0.7254901960784313,
}

SHIPPED_SUBSYSTEMS_HZ = {
    ("free-free", 180.0): 985.0503306592504,
    ("cantilever", 180.0): 220.560367702428,
    ("chain", 60.0): 78.99482402938015,
    ("chain", 90.0): 87.7426028383071,
    ("chain", 180.0): 80.91334246192663,
}


@pytest.fixture(scope="module")
def shipped():
    return reproduce_study(default_config(), readability=False)


def test_subsystems_within_the_headline_0p3_percent(shipped):
    assert len(shipped.subsystems) == 5
    for s in shipped.subsystems:
        # the headline: every subsystem within 0.3 % of the experiment (measured -0.292 % .. +0.005 % at the
        # default 12 segments; the identification fitted them at 4 segments to 0.05 %, docs/identification.md)
        assert abs(s.error_pct) < 0.3, (s.test.rig, s.test.angle_deg, s.error_pct)
        assert s.ours_hz == pytest.approx(SHIPPED_SUBSYSTEMS_HZ[(s.test.rig, s.test.angle_deg)], rel=1e-7)


def test_pose_frequencies_as_shipped(shipped):
    # Round-off of an eigenvalue grows as w_max^2 / w^2: at the pose next to a singularity (0.59 Hz, measure
    # 0.0045) two LAPACK drivers (all eigenpairs vs the lowest few) differ by 1.4e-6 relative, measured; 1e-5
    # there, 1e-7 elsewhere.
    near = shipped.frequencies.singularity < 0.01
    np.testing.assert_allclose(shipped.f1_hz[~near], SHIPPED_F1_HZ[~near], rtol=1e-7)
    np.testing.assert_allclose(shipped.f1_hz[near], SHIPPED_F1_HZ[near], rtol=1e-5)
    assert near.sum() == 1


def test_error_statistics_against_comsol_as_shipped(shipped):
    stats = shipped.stats()
    assert stats["n"] == SHIPPED_STATS["n"]
    for key, value in SHIPPED_STATS.items():
        if key == "n":
            continue
        # percentages: 1e-5 points; Spearman's rho is a rank statistic and changes only in steps of ~1e-3
        assert stats[key] == pytest.approx(value, abs=1e-5), key
