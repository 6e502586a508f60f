"""FRFs of the linear model: static limit against the nonlinear static solution, reciprocity, the
modal-damping sum against a direct frequency-domain solve with the full damping matrix, the damping
option against the half-power bandwidth, peak picking, point location and errors."""

import math
import re

import mujoco
import numpy as np
import pytest
import scipy.linalg

from fpm_sim.kinematics import Pose
from fpm_sim.linear.equilibrium import equality_jacobian, static_equilibrium
from fpm_sim.linear.matrices import damping_matrix, mass_matrix, stiffness_matrix
from fpm_sim.linear.nullspace import NULLSPACE_RCOND
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import FrfError, LinkPoint, half_power_damping, locate, modal_frf, pick_peaks, point_row
from fpm_sim.rom.reduction import modal_system

POSE = Pose(0.05, -0.05, 0.1)  # off-centre and rotated: no symmetry to hide errors behind
HIT = LinkPoint("distal_0", 0.5, "z")
SIDE = LinkPoint("distal_1", 0.3, "z")  # out of plane, like HIT: the planar structure decouples the planes
IN_A = LinkPoint("distal_0", 0.5, "normal")
IN_B = LinkPoint("proximal_2", 0.7, "normal")


@pytest.fixture(scope="module")
def system(symmetric_manip):
    built = build_manipulator(symmetric_manip, POSE, ModelOptions(segments=3, axial=False))
    return modal_system(built)


@pytest.fixture(scope="module")
def system_no_gravity(symmetric_manip):
    built = build_manipulator(symmetric_manip, POSE, ModelOptions(segments=3, axial=False, gravity=False))
    return modal_system(built)


def test_locate_follows_the_link(system):
    built = system.built
    data = mujoco.MjData(built.model)
    data.qpos[:] = system.qpos
    mujoco.mj_forward(built.model, data)
    sites = built.links["distal_2"]
    start, end = data.site(sites[0]).xpos, data.site(sites[-1]).xpos
    _, p0, _ = locate(built, data, LinkPoint("distal_2", 0.0, "normal"))
    _, p1, _ = locate(built, data, LinkPoint("distal_2", 1.0, "normal"))
    _, pm, e = locate(built, data, LinkPoint("distal_2", 0.5, "normal"))
    # the link is straight but for its gravity sag (micrometres): the mid-point lies halfway
    np.testing.assert_allclose(p0, start, atol=1e-9)
    np.testing.assert_allclose(p1, end, atol=1e-9)
    np.testing.assert_allclose(pm, 0.5 * (start + end), atol=1e-5)
    # 'normal' is in the base plane and perpendicular to the link
    assert abs(e[2]) < 1e-12
    assert abs(e @ (end - start)) < 1e-4 * np.linalg.norm(end - start)


@pytest.mark.parametrize(("hit", "seen"), [(HIT, SIDE), (IN_A, IN_B)], ids=["out-of-plane", "in-plane"])
def test_static_limit_matches_the_nonlinear_static_deflection(system_no_gravity, hit, seen):
    """Receptance at 0 Hz (sum of all modes) = the static deflection under a small point force, found by
    Newton's method on the full MuJoCo model (gravity off: the equilibrium is the assembly, qpos0)."""
    s = system_no_gravity
    model = s.built.model
    frf = modal_frf(s, excitation=hit, response=seen, freq_hz=np.array([0.0]), quantity="receptance")
    force_n = 0.05  # small: sub-micrometre deflections, linear
    data = mujoco.MjData(model)
    data.qfrc_applied[:] = point_row(s.built, model.qpos0, hit) * force_n
    q = static_equilibrium(model, data, rtol=1e-10)
    c = point_row(s.built, model.qpos0, seen)
    static = c @ (q - model.qpos0) / force_n
    assert abs(static) > 1e-9  # m/N: a real transfer, not two zeros agreeing
    # the weld loop closures are stiff but not rigid (solref = 2 h) in the MuJoCo solution and rigid in the
    # modal null space, and Newton stops at a residual: measured agreement ~1e-7; 1e-4 still flags any wrong
    # Jacobian, sign or point (those are O(1) errors)
    assert frf.h[0].real == pytest.approx(static, rel=1e-4)
    # the modal sum over all modes also equals the directly solved constrained flexibility (exact identity)
    assert frf.h[0].real == pytest.approx(c @ s.flexibility @ point_row(s.built, model.qpos0, hit), rel=1e-8)


def test_in_plane_force_does_not_reach_out_of_plane(system_no_gravity):
    """The structure is symmetric about its plane: without gravity sag the planes decouple exactly."""
    f = np.linspace(1.0, 400.0, 200)
    cross = modal_frf(system_no_gravity, excitation=IN_A, response=HIT, freq_hz=f).magnitude
    direct = modal_frf(system_no_gravity, excitation=HIT, response=HIT, freq_hz=f).magnitude
    assert cross.max() < 1e-6 * direct.max()


@pytest.mark.parametrize(("a", "b"), [(HIT, SIDE), (IN_A, IN_B), (HIT, IN_B)])
def test_reciprocity(system, a, b):
    f = np.linspace(1.0, 400.0, 300)
    h_ab = modal_frf(system, excitation=a, response=b, freq_hz=f).h
    h_ba = modal_frf(system, excitation=b, response=a, freq_hz=f).h
    assert np.abs(h_ab).max() > 0
    np.testing.assert_allclose(h_ab, h_ba, rtol=1e-9, atol=1e-12 * np.abs(h_ab).max())


def test_modal_sum_against_direct_solve_with_the_full_damping_matrix(system):
    """Direct: ``c Z (Kr - w^2 Mr + j w Cr)^-1 Z' b`` in the loop-closure null space, with the joint-damper
    matrix as it is (not diagonalised). The modal FRF drops only the off-diagonal modal damping."""
    built = system.built
    model = built.model
    data = mujoco.MjData(model)
    k = stiffness_matrix(model, data, system.qpos)
    data.qpos[:] = system.qpos
    mujoco.mj_forward(model, data)
    m = mass_matrix(model, data)
    z = scipy.linalg.null_space(equality_jacobian(model, data), rcond=NULLSPACE_RCOND)
    kr, mr, cr = z.T @ k @ z, z.T @ m @ z, z.T @ damping_matrix(model) @ z
    b = z.T @ point_row(built, system.qpos, HIT)
    c = point_row(built, system.qpos, HIT) @ z
    f = np.linspace(20.0, 400.0, 1500)
    direct = np.array([-(w**2) * c @ np.linalg.solve(kr - w**2 * mr + 1j * w * cr, b) for w in 2 * np.pi * f])
    modal = modal_frf(system, excitation=HIT, response=HIT, freq_hz=f).h
    # stiffness-proportional damping is diagonal in the modes of the spring stiffness; the tangent stiffness
    # adds the (tiny) gravity prestress, so the modal damping matrix has small off-diagonal terms: measured
    # max difference 2e-8 of the peak; 1e-5 leaves room for that coupling and still flags any wrong residue,
    # frequency or damping ratio (those move the peak by percents)
    assert np.max(np.abs(modal - direct)) / np.max(np.abs(direct)) < 1e-5
    pk_d = pick_peaks(f, np.abs(direct))
    pk_m = pick_peaks(f, np.abs(modal))
    assert len(pk_d) == len(pk_m) >= 2
    for a, b_ in zip(pk_d, pk_m):
        assert a.freq_hz == pytest.approx(b_.freq_hz, rel=1e-3)


def test_user_damping_is_what_the_half_power_bandwidth_reads(system):
    zeta = 0.02
    f1 = system.frequencies_hz[0]
    f = np.linspace(0.7 * f1, 1.3 * f1, 6001)
    frf = modal_frf(system, excitation=HIT, response=HIT, freq_hz=f, damping_ratio=zeta, quantity="receptance")
    assert np.allclose(frf.damping_ratios, zeta)
    peak = frf.peaks()[0]
    # a single-mode receptance has its half-power points at w1 (1 -+ zeta) to O(zeta^2); the neighbouring
    # modes (> 30 % away) bend the skirts slightly: measured 0.5 % of zeta
    assert half_power_damping(f, frf.magnitude, peak.freq_hz) == pytest.approx(zeta, rel=0.05)
    # receptance peak of a single mode at w1 sqrt(1 - 2 zeta^2); measured within 0.09 % (neighbours)
    assert peak.freq_hz == pytest.approx(f1 * math.sqrt(1 - 2 * zeta**2), rel=2e-3)


def test_model_damping_is_the_modal_projection(system):
    frf = modal_frf(system, excitation=HIT, response=HIT, freq_hz=np.array([10.0]))
    np.testing.assert_allclose(frf.damping_ratios, np.diag(system.xi) / (2 * system.omega_rad_s))


def test_pick_peaks_refines_between_samples():
    f = np.arange(0.0, 200.0, 1.0)
    fn, z = 73.4, 0.01
    mag = 1.0 / np.abs(fn**2 - f**2 + 2j * z * fn * f)
    peaks = pick_peaks(f, mag)
    assert len(peaks) == 1
    # a 1 Hz grid; the parabola through three dB samples lands within a tenth of a bin here
    assert peaks[0].freq_hz == pytest.approx(fn, abs=0.1)
    assert pick_peaks(f, mag, min_prominence_db=200.0) == []


@pytest.mark.parametrize(
    ("point", "message"),
    [
        (LinkPoint("distal_7", 0.5, "z"), "unknown link"),
        (LinkPoint("distal_0", 1.5, "z"), "fraction"),
        (LinkPoint("distal_0", 0.5, "sideways"), "axis"),
        (LinkPoint("platform", 0.5, "normal"), "platform"),
    ],
)
def test_bad_points_name_the_problem(system, point, message):
    with pytest.raises(FrfError, match=message):
        modal_frf(system, excitation=point, response=HIT, freq_hz=np.array([10.0]))


def test_bad_options(system):
    with pytest.raises(FrfError, match="quantity"):
        modal_frf(system, excitation=HIT, response=HIT, freq_hz=np.array([10.0]), quantity="velocity")
    with pytest.raises(FrfError, match="damping"):
        modal_frf(system, excitation=HIT, response=HIT, freq_hz=np.array([10.0]), damping_ratio=1.5)
    with pytest.raises(FrfError, match="freq_hz"):
        modal_frf(system, excitation=HIT, response=HIT, freq_hz=np.array([-1.0]))


def test_csv_round_trip(system, tmp_path):
    f = np.linspace(1.0, 300.0, 50)
    frf = modal_frf(system, excitation=HIT, response=SIDE, freq_hz=f)
    p = frf.save_csv(tmp_path / "frf.csv")
    raw = np.loadtxt(p, delimiter=",", skiprows=2)
    np.testing.assert_allclose(raw[:, 0], f)
    np.testing.assert_allclose(raw[:, 1] + 1j * raw[:, 2], frf.h, rtol=1e-8)
    with pytest.raises(FrfError, match=re.escape(".csv")):
        frf.save_csv(tmp_path / "frf.txt")
