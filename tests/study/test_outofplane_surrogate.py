import dataclasses

import numpy as np
import pytest
import scipy.linalg

from fpm_sim.batch.frequencies import pose_frequencies
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import LumpedMass, Section
from fpm_sim.kinematics import Pose, assemble_batch
from fpm_sim.study.identify.problem import IN_PLANE_THRESHOLD
from fpm_sim.study.outofplane_surrogate import OutofplaneArrays, _chains, outofplane_first_frequencies
from tests.helpers.truths import REFERENCE_GEOMETRY  # the geometry these tests measured their numbers on

POSES = [Pose.from_mm(x, y, 0.0) for x in (-100, 0, 100) for y in (-100, 0, 100)]


def _lowest_out_of_plane(cfg, segments):
    seg = pose_frequencies(cfg, POSES, n_modes=8, options=fast_options(segments=segments))
    return np.array([f[np.asarray(ip) <= IN_PLANE_THRESHOLD][0] for f, ip in zip(seg.frequencies_hz, seg.in_plane)])


@pytest.mark.parametrize("section", [Section(0.030, 0.008), Section(0.010, 0.030)])
def test_outofplane_surrogate_converges_with_the_segment_model(previous_default_manip, section):
    # The segment model refined from 4 to 8 segments a link comes down onto the surrogate (measured: ratio 0.979 ->
    # 0.996 at 8 mm, 0.986 -> 0.997 at 30 mm): the two agree where the segment model converges. The bound 2 % is the
    # surrogate's own reductions (one Hermite element a link, +0.5 % on a cantilever's first mode; the elbows
    # condensed statically, an upper bound) plus the 8-segment model's distance from its limit (~0.5 %).
    cfg = previous_default_manip.replace(section=section, geometry=REFERENCE_GEOMETRY)
    coarse, fine = _lowest_out_of_plane(cfg, 4), _lowest_out_of_plane(cfg, 8)
    sur = outofplane_first_frequencies(cfg, POSES)
    assert np.all(np.abs(sur / fine - 1.0) < np.abs(sur / coarse - 1.0))
    assert np.all(np.abs(sur / fine - 1.0) < 0.02)


def _full_and_condensed(arrays, xyphi):
    """The grillage's 12x12 stiffness and mass (3 elbows, then the platform) at each pose, from the surrogate's
    own blocks."""
    many = assemble_batch(arrays.geometry, xyphi[:, 0], xyphi[:, 1], xyphi[:, 2])
    blocks = _chains(arrays, many, len(xyphi))
    kbb, kbq, kqq, mbb, mbq, mqq = (np.moveaxis(np.array(b), (0, 1), (-2, -1)) for b in blocks)
    n = len(xyphi)  # one description
    out = []
    for blocks in ((kbb, kbq, kqq), (mbb, mbq, mqq)):
        bb, bq, qq = blocks
        full = np.zeros((n, 12, 12))
        for i in range(3):
            full[:, 3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = bb[:, i]
            full[:, 3 * i : 3 * i + 3, 9:] = bq[:, i]
            full[:, 9:, 3 * i : 3 * i + 3] = np.swapaxes(bq[:, i], -1, -2)
            full[:, 9:, 9:] += qq[:, i]
        out.append(full)
    plat = np.diag([arrays.platform_kg[0], arrays.platform_kg_m2[0], arrays.platform_kg_m2[0]])
    out[1][:, 9:, 9:] += plat
    return out


@pytest.mark.parametrize("elbow_kg", [0.05, 1.0])
def test_condensed_frequency_is_an_upper_bound_of_the_grillage(previous_default_manip, elbow_kg):
    # Guyan's condensation is a Rayleigh-Ritz reduction, so its lowest frequency bounds the full grillage's from
    # above; with a light elbow the two agree closely, with a heavy one the elbows' own modes come down (measured
    # on the study's priors: up to 28 % apart), which is why the calibration's emulator corrects the surrogate.
    hw = previous_default_manip.hardware
    cfg = previous_default_manip.replace(
        section=Section(0.030, 0.008), geometry=REFERENCE_GEOMETRY,
        hardware=dataclasses.replace(hw, elbow_joint=LumpedMass(elbow_kg, (1e-5, 1e-5, 1e-5))),
    )  # fmt: skip
    arrays = OutofplaneArrays.of(cfg)
    xyphi = np.array([[p.x_m, p.y_m, p.phi_rad] for p in POSES])
    k, m = _full_and_condensed(arrays, xyphi)
    full = np.array([np.sqrt(scipy.linalg.eigh(a, b, eigvals_only=True)[0]) / (2 * np.pi) for a, b in zip(k, m)])
    condensed = outofplane_first_frequencies(cfg, POSES)
    assert np.all(condensed >= full * (1.0 - 1e-9))
    if elbow_kg < 0.1:
        assert np.all(condensed < full * 1.02)


def test_outofplane_surrogate_marks_unreachable_poses(default_manip):
    f = outofplane_first_frequencies(default_manip, [Pose(0.0, 0.0, 0.0), Pose(0.9, 0.0, 0.0)])
    assert np.isfinite(f[0])
    assert f[0] > 0
    assert np.isnan(f[1])
