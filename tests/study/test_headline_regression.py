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
        44.0088233118, 46.6523252396, 47.9719184847, 48.6149774883, 46.7753557810,
        47.0931350019, 51.7904534200, 55.1423516425, 61.0887358053, 52.8722063435,
        49.9071565533, 57.4798136700, 62.8047351355, 57.3734292825, 38.7788481508,
        53.6503416494, 63.1191990714, 55.8398416983, 34.4816705948, 11.9805029771,
        60.1585411276, 53.6544618825, 25.0527090325, 0.6841171000, 34.6370587772,
    ]
)  # fmt: skip
"""f1 at the 25 study poses (default reading: rows are x, +0.2 rad; the default resolution, 12 segments,
gravity off), measured 2026-12-01 on the default re-identified by `fpm-sim identify --global de` with a
surrogate-seeded first population (issue 12). The pose at 0.68 Hz sits next to a parallel singularity of the
identified geometry (docs/identification.md)."""

SHIPPED_STATS = {
    "n": 18,
    "mean_abs_pct": 16.220486479430683,
    "median_abs_pct": 9.077739995149141,
    "max_abs_pct": 83.88782812560193,
    "min_abs_pct": 0.38332050882693125,
    "mean_signed_pct": -0.5477922987087458,
    "spearman": 0.7440660474716203,
}

SHIPPED_SUBSYSTEMS_HZ = {
    ("free-free", 180.0): 985.0503307326507,
    ("cantilever", 180.0): 220.5603676830371,
    ("chain", 60.0): 78.99482403144052,
    ("chain", 90.0): 87.74260283786214,
    ("chain", 180.0): 80.91334247134208,
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
    # Round-off of an eigenvalue grows as w_max^2 / w^2: at the pose next to a singularity (0.68 Hz, measure
    # 0.0052) two LAPACK drivers (all eigenpairs vs the lowest few) differ by 1.4e-6 relative (measured on the
    # previous default, 0.59 Hz); 1e-5 there, 1e-7 elsewhere.
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
