"""The calibration's cyclic orbits of elbow-branch classes and its periodic angles (issue 31): relabelling the 3RRR's
chains turns both joint layouts by 120 deg and shifts the branch pattern, so one class of each orbit, with both
rotations over a whole turn (wrapped by the samplers), holds every machine of its orbit."""

import math

import numpy as np
import pytest

from fpm_sim.study.calibrate.priors import PriorError, read_priors
from fpm_sim.study.calibrate.smc import SmcSettings, two_stage
from fpm_sim.study.identify.problem import ELBOW_BRANCHES, cyclic_branch_orbits


def test_the_orbits_partition_the_eight_classes():
    orbits = cyclic_branch_orbits()
    assert sum(orbits.values()) == len(ELBOW_BRANCHES)
    assert sorted(orbits.values()) == [1, 1, 3, 3]
    for k in orbits:
        rolled = {tuple(int(x) for x in np.roll(ELBOW_BRANCHES[k], r)) for r in range(3)}
        assert len(rolled) == orbits[k]


@pytest.mark.slow  # ~1 s: 8 segment-model likelihoods
def test_a_relabelled_machine_has_the_same_likelihood_on_the_segment_model():
    """The symmetry the orbits rest on, on the reported model (its MuJoCo models, the statements, the data): class
    ``k`` at rotations ``(a, b)`` is class ``roll(k, -1)`` at ``(a + 120, b + 120)`` deg; the wrong direction is
    not."""
    from fpm_sim.study.calibrate.problem import study_problem

    p = study_problem(model="segments")
    base, plat = p.names.index("geometry.base_rotation_deg"), p.names.index("geometry.platform_rotation_deg")
    rng = np.random.default_rng(3)
    checked = 0
    for u in rng.random((400, p.ndim)):
        theta = p.prior_transform(u)
        if not math.isfinite(p.cheap_log_likelihood(theta)):
            continue
        ll = p.log_likelihood(theta)
        for turn, roll, same in ((120.0, -1, True), (120.0, 1, False)):
            other = theta.copy()
            for i in (base, plat):
                other[i] = (theta[i] + turn + 180.0) % 360.0 - 180.0
            other[-1] = ELBOW_BRANCHES.index(tuple(int(x) for x in np.roll(ELBOW_BRANCHES[int(theta[-1])], roll)))
            # the same machine, its chains built in another order: equal to the eigen-solve's and the assembly's
            # round-off (1e-9 relative is far below any difference a real change of machine makes, ~1e-2)
            if same:
                assert p.log_likelihood(other) == pytest.approx(ll, rel=1e-9, abs=1e-7)
            elif ELBOW_BRANCHES[int(theta[-1])] not in ((1, 1, 1), (-1, -1, -1)):
                assert p.log_likelihood(other) != pytest.approx(ll, rel=1e-6)
        checked += 1
        if checked == 3:
            break
    assert checked == 3


PRIORS = """
[parameters."geometry.base_rotation_deg"]
dist = "uniform"
lower = {lower}
upper = {upper}
reason = "assumed: test"

[parameters."geometry.platform_rotation_deg"]
dist = "uniform"
lower = -180
upper = 180
reason = "assumed: test"

[parameters."geometry.elbow_branch"]
dist = "branches"
relabel = "cyclic"
reason = "assumed: test"
"""


def test_cyclic_relabelling_needs_both_rotations_over_a_whole_turn():
    free = ["geometry.base_rotation_deg", "geometry.platform_rotation_deg"]
    ok = read_priors("p.toml", free, text=PRIORS.format(lower=-180, upper=180))
    assert ok.branch_relabel
    assert ok.periodic == (0, 1)
    with pytest.raises(PriorError, match=r'relabel: "cyclic".*geometry.base_rotation_deg is not: give it lower = -180'):
        read_priors("p.toml", free, text=PRIORS.format(lower=-60, upper=60))
    with pytest.raises(PriorError, match=r"relabel: 'sideways'"):
        read_priors("p.toml", free, text=PRIORS.format(lower=-180, upper=180).replace('"cyclic"', '"sideways"'))


SD = 0.04
"""A mode across the seam of a periodic coordinate: a Gaussian of sd 0.04 about ``u_0 = 0`` (wrapped, so half of it
lies near 1) and ``u_1 = 0.5``; on the torus it integrates to 1 (the wrapped tails beyond one turn: ~e^-78)."""


def _seam(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d0 = np.mod(u[:, 0] + 0.5, 1.0) - 0.5
    log_l = -0.5 * (d0**2 + (u[:, 1] - 0.5) ** 2) / SD**2 - 2 * math.log(SD * math.sqrt(2 * math.pi))
    return np.zeros(len(u)), log_l


def test_smc_wraps_a_periodic_coordinate_and_keeps_a_mode_across_its_seam_whole():
    stage = SmcSettings(particles=800, periodic=(0,))
    for seed in range(3):
        run = two_stage(
            lambda u: (np.zeros(len(u)), np.zeros(len(u))), lambda u: _seam(u), 2, stage, stage,
            np.random.default_rng(seed),
        )  # fmt: skip
        # ln Z = 0 within 4 of its stated error; the two halves of the mode each hold half of it (binomial sd
        # 0.5 / sqrt(ESS), ESS >= 100 of 800 resampled-and-moved particles: 0.05; 0.15 is 3 of those)
        assert abs(run.log_evidence) < 4 * run.log_evidence_err + 0.05, (run.log_evidence, run.log_evidence_err)
        assert abs(float(np.mean(run.u[:, 0] < 0.5)) - 0.5) < 0.15
        assert np.all((run.u >= 0) & (run.u <= 1))
