"""The latent-mode model of a measured first frequency (fpm_sim.study.readout): the modal constants against
the FRF path's (a second method: the full linearisation and the modal FRF's residues), the read probabilities
and the mixture likelihood against their definitions written out."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.response import LinkPoint, modal_frf
from fpm_sim.rom.reduction import modal_system
from fpm_sim.study.readout import ModeRead, mixture_log_likelihood, read_probabilities, sensor_residues


@pytest.mark.parametrize("axis", ["normal", "z"])
def test_modal_constants_equal_the_modal_frfs_residues(default_manip, axis):
    """(c v_k)^2 from the re-posed pose-loop model equals the driving-point residue of the FRF built from the full
    linearisation (transitionFD, static equilibrium without gravity) at the same pose and point."""
    pose = Pose.from_mm(30.0, -40.0, 0.1)
    point = LinkPoint("distal_1", 0.5, axis)
    opts = fast_options(segments=3)
    freq, res = sensor_residues(default_manip, [pose], n_modes=4, points=[point], options=opts)
    built = build_manipulator(default_manip, pose, opts)
    system = modal_system(built)
    frf = modal_frf(system, excitation=point, response=point, freq_hz=np.array([1.0, 2.0]))
    np.testing.assert_allclose(freq[0], system.frequencies_hz[:4], rtol=1e-6)  # two linearisations, same modes
    # the material point is located the same way; the residues agree to the linearisations' agreement
    np.testing.assert_allclose(res[0, 0], np.abs(frf.residues[:4]), rtol=1e-5, atol=1e-9 * np.max(res))


def test_read_probabilities_follow_the_first_clear_peak_rule():
    read = ModeRead(modes=3, height_db=-20.0, width_db=3.0)
    # mode 1 as high as any: read with probability sigmoid(20/3) ~ 0.9987
    p = read_probabilities(np.array([1.0, 0.5, 0.2, 0.1, 0.1, 0.1]), read)
    v1 = 1 / (1 + math.exp(-20 / 3))
    assert p[0] > v1 - 2e-3
    # mode 1 at -40 dB (a node near the sensor): the first clear peak is mode 2
    p = read_probabilities(np.array([1e-2, 1.0, 0.3, 0.1, 0.1, 0.1]), read)
    assert p[1] > 0.99
    assert p[0] == pytest.approx(1 / (1 + math.exp(20 / 3)), rel=0.01)
    # written out: P(k) = v_k prod_{j<k} (1 - v_j), renormalised over the three lowest
    r = np.array([0.08, 0.1, 1.0, 0.5, 0.2, 0.1])
    h = 20 * np.log10(r[:3] / r.max())
    v = 1 / (1 + np.exp(-(h + 20) / 3))
    raw = np.array([v[0], (1 - v[0]) * v[1], (1 - v[0]) * (1 - v[1]) * v[2]])
    np.testing.assert_allclose(read_probabilities(r, read), raw / raw.sum(), rtol=1e-12)


def test_mixture_likelihood_is_the_average_over_setups_of_the_per_pose_mixtures():
    rng = np.random.default_rng(4)
    y = np.array([50.0, 62.0, 35.0])
    sig = 0.02 * y
    f = rng.uniform(30, 80, (3, 3))
    probs = rng.dirichlet(np.ones(3), size=(2, 3))  # (setups, poses, modes)
    d = 0.07
    s = np.sqrt(sig[:, None] ** 2 + (d * f) ** 2)
    dens = stats.norm.pdf(y[:, None], f, s)
    expected = math.log(np.mean([np.prod(np.sum(probs[k] * dens, axis=1)) for k in range(2)]))
    assert mixture_log_likelihood(y, sig, f, probs, d) == pytest.approx(expected, rel=1e-12)
    # one setup reading mode 1 everywhere: the independent Gaussian likelihood of mode 1
    one = np.zeros((1, 3, 3))
    one[0, :, 0] = 1.0
    assert mixture_log_likelihood(y, sig, f, one, d) == pytest.approx(
        float(np.sum(stats.norm.logpdf(y, f[:, 0], s[:, 0]))), rel=1e-12
    )


def test_components_weigh_setups_by_the_data_and_leave_each_datum_out():
    """components(): written out for two setups, three poses, two modes."""
    from fpm_sim.study.readout import components, responsibilities, setup_weights

    rng = np.random.default_rng(5)
    y = np.array([50.0, 40.0, 60.0])
    sig = 0.02 * y
    f = rng.uniform(35, 70, (3, 2))
    probs = rng.dirichlet(np.ones(2), size=(2, 3))
    d = 0.1
    s = np.sqrt(sig[:, None] ** 2 + (d * f) ** 2)
    dens = stats.norm.pdf(y[:, None], f, s)  # (n, modes)
    per = np.einsum("snk,nk->sn", probs, dens)  # (setups, n)
    w_all = per.prod(axis=1) / per.prod(axis=1).sum()
    np.testing.assert_allclose(setup_weights(y, sig, f, probs, d), w_all, rtol=1e-10)
    mu, sd, w = components(y, sig, f, probs, d, leave_out=True)
    for i in range(3):
        rest = np.delete(per, i, axis=1).prod(axis=1)
        expect = (rest / rest.sum())[:, None] * probs[:, i, :]  # (setups, modes)
        np.testing.assert_allclose(w[i], expect.ravel(), rtol=1e-10)
        np.testing.assert_allclose(mu[i], np.tile(f[i], 2))
        np.testing.assert_allclose(sd[i], np.tile(s[i], 2))
    resp = responsibilities(y, sig, f, probs, d)
    expect = np.einsum("s,snk->nk", w_all, probs * dens[None] / per[:, :, None])
    np.testing.assert_allclose(resp, expect, rtol=1e-10)
