"""Virtual impact test: the first peak of the H1 FRF from nonlinear rollouts against the modal f1 of the
same model; H1 on synthetic signals; the accelerometer kinematics; errors."""

import math

import mujoco
import numpy as np
import pytest

from fpm_sim.errors import FpmSimWarning
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import FrfError, LinkPoint, locate, modal_frf
from fpm_sim.rom.reduction import modal_system
from fpm_sim.sim.impact import ImpactRecord, ImpactSetup, h1_estimate, point_acceleration, virtual_impact_test
from fpm_sim.sim.stepping import numerical_damping

FIRST_PEAK_TOL = 0.005
"""The first FRF peak against the modal f1 (the issue's target is 2 %). Sources of difference: the FFT line
spacing after zero padding (0.125 Hz at 8 s, refined by a parabola: up to ~0.2 % at 60-80 Hz), the
accelerance peak sitting at f1 / sqrt(1 - 2 zeta^2) (+0.01 % at 1 %), the neighbouring modes' skirts, the
discrete integrator's period error ((omega h)^2 / 3 ~ 2e-5) and the soft welds (~1e-4). Measured -0.1 to -0.25 %
at the study poses; in the noisy 3-impact fast test -0.37 % (explicit reference) and -0.48 / -0.49 % (discrete at
10 / 16.7 us: the wider, numerically damped peak reads 0.1 % lower on the 0.125 Hz lines; the EMA reads the
two within 0.004 %, test_discrete_step_is_removed_by_the_ema). 0.5 % is what the line spacing alone can move."""


def test_first_peak_matches_modal_f1_with_noise(symmetric_manip):
    """Pose (0, 0, 0), the coarsest flexible model, three impacts with accelerometer noise."""
    built = build_manipulator(symmetric_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, axial=False))
    setup = ImpactSetup(record_s=0.2, noise_m_s2=0.05, seed=3)
    res = virtual_impact_test(built, setup)
    assert len(res.records) == 3
    assert len({r.peak_force_n for r in res.records}) == 3  # three different impacts
    assert abs(res.relative_error) < FIRST_PEAK_TOL
    assert res.first_peak_mode == 1
    # the exponential window adds known damping; what is left is the model's own (1.2 % at f1 from the
    # configured stiffness-proportional damping, beta omega / 2); the half-power read of a 0.2 s record
    # with 0.125 Hz lines resolves it to a few tenths of a percent of damping
    model_zeta = symmetric_manip.damping.stiffness_proportional_s * 2 * math.pi * res.modal_f1_hz / 2
    assert res.identified_damping_ratio == pytest.approx(model_zeta, abs=4e-3)
    # noise lowers the coherence below 1 somewhere in the band, but not at the resonance
    band = (res.frf.freq_hz > 5) & (res.frf.freq_hz < 1000)
    assert res.frf.coherence[band].min() < 0.999
    at_peak = np.argmin(np.abs(res.frf.freq_hz - res.first_peak_hz))
    assert res.frf.coherence[at_peak] > 0.99
    d = res.to_dict()
    assert d["first_peak_hz"] == res.first_peak_hz
    assert d["modal_f1_hz"] == res.modal_f1_hz
    # end to end: the H1 of the nonlinear rollouts against the linear modal FRF of the same model, with the
    # window's damping 1 / (tau omega_r) added to every mode (exact for a sum of decaying modes). Left over:
    # leakage from truncating a 0.2 s record, the neighbouring modes, noise and nonlinearity: measured 2.6 %
    # of the peak at worst over 20-400 Hz (median 0.7 %); a wrong point, axis, sign or scale is O(1)
    system = modal_system(built)
    tau = res.records[0].t_s[-1] / math.log(1.0 / setup.window_end)
    # ... and the discrete integrator's numerical damping (exact per mode, fpm_sim.sim.stepping; ~2 % at the
    # default band's top, 359 Hz here: without it the peaks near 400 Hz come out 20 % high)
    numerical = numerical_damping(system.omega_rad_s / (2 * math.pi), res.discrete_step_s)
    zeta = np.diag(system.xi) / (2 * system.omega_rad_s) + 1.0 / (tau * system.omega_rad_s) + numerical
    zeta = np.minimum(zeta, 0.99)
    band = (res.frf.freq_hz >= 20.0) & (res.frf.freq_hz <= 400.0)
    f_band = res.frf.freq_hz[band]
    linear = modal_frf(
        system, excitation=setup.impact, response=setup.accelerometer, freq_hz=f_band, damping_ratio=zeta
    ).h
    assert np.max(np.abs(res.frf.h[band] - linear)) < 0.05 * np.max(np.abs(linear))


@pytest.mark.slow
@pytest.mark.parametrize("pose_mm", [(0.0, 0.0, 0.0), (100.0, -100.0, 0.0), (-50.0, 50.0, 0.0), (50.0, 0.0, 0.2)])
def test_first_peak_matches_modal_f1_at_study_poses(symmetric_manip, pose_mm):
    """Four study poses, 4 segments, the default 0.5 s records (20-100 s each on the shared 2-core machine)."""
    built = build_manipulator(symmetric_manip, Pose.from_mm(*pose_mm), ModelOptions(segments=4, axial=False))
    res = virtual_impact_test(built, ImpactSetup())
    assert abs(res.relative_error) < FIRST_PEAK_TOL


def test_discrete_step_is_removed_by_the_ema(symmetric_manip, tmp_path):
    """The default discrete integrator against the explicit reference, end to end through the UFF record: the
    EMA of the discrete FRF, with the step written into the record and inverted, reads what the EMA of the
    explicit FRF reads; uncorrected it reads the step's damping ``~ pi f h`` on top."""
    from fpm_sim.sim.impact import write_uff58
    from fpm_sim.study.identify.ema import estimate_modes, read_frfs

    built = build_manipulator(symmetric_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, axial=False))
    system = modal_system(built)
    h = 2e-5
    runs = [
        virtual_impact_test(built, ImpactSetup(record_s=0.2, n_impacts=1, integrator=i, timestep_s=step), system=system)
        for i, step in (("explicit", None), ("discrete", h))
    ]
    assert runs[0].parameters["rollout_integrator"] == "mjINT_IMPLICITFAST"
    assert runs[0].parameters["rollout_timestep_s"] == built.timestep_s < h / 2  # the model's own step: 9.4 us
    assert runs[0].discrete_step_s is None
    assert runs[1].parameters["rollout_integrator"] == "mjINT_DISCRETE"
    assert runs[1].parameters["rollout_timestep_s"] == runs[1].discrete_step_s == h
    assert built.model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST  # the caller's model untouched
    frfs = []
    for k, r in enumerate(runs):
        path = write_uff58(r.frf, tmp_path / f"{k}.uff", window_tau_s=r.window_tau_s, discrete_step_s=r.discrete_step_s)
        frfs.append(read_frfs(path)[0])
    assert frfs[0].discrete_step_s is None
    assert frfs[1].discrete_step_s == h
    band = {"f_lower_hz": 20.0, "f_upper_hz": 400.0, "n_modes": 1}
    base, corrected = (estimate_modes(f, **band) for f in frfs)
    raw = estimate_modes(frfs[1], discrete_step_s=0.0, **band)
    assert corrected.discrete_step_s == h
    assert raw.discrete_step_s is None
    # uncorrected: 2 pi 71.8 Hz * 20 us / 2 = 0.45 % of damping added (measured 0.45 %)
    assert raw.damping[0] - base.damping[0] == pytest.approx(math.pi * runs[0].modal_f1_hz * h, abs=1e-3)
    # corrected: the integrator's effect is gone; what is left is the nonlinear response's difference between
    # the two integrators (measured -0.004 % in frequency, +0.007 points of damping)
    assert corrected.freq_hz[0] == pytest.approx(base.freq_hz[0], rel=2e-4)
    assert corrected.damping[0] == pytest.approx(base.damping[0], abs=2e-4)
    # and the result's own half-power reading subtracts the same numerical damping
    assert runs[1].numerical_damping == pytest.approx(math.pi * runs[1].first_peak_hz * h, rel=1e-3)
    assert runs[0].numerical_damping == 0.0


def test_an_in_plane_hammer_misses_the_out_of_plane_mode_1(symmetric_manip):
    """Hammer and accelerometer along the in-plane normal: the first peak is the first in-plane mode, and the
    result says so (mode 1, out-of-plane bending for the default sections, is not excited)."""
    built = build_manipulator(symmetric_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, axial=False))
    hit = LinkPoint("distal_0", 0.5, "normal")
    with pytest.warns(FpmSimWarning, match="mode 1 .* is not seen"):
        res = virtual_impact_test(built, ImpactSetup(impact=hit, accelerometer=hit, record_s=0.1, n_impacts=1))
    assert res.first_peak_mode > 1
    assert res.first_peak_hz > 1.5 * res.modal_f1_hz
    assert "not seen" in res.table()
    # the reason, from the linear model at this set-up: the in-plane hammer barely excites the out-of-plane
    # mode 1 (driving point: excitation and observation are the same vector, so both ratios agree)
    k = res.first_peak_mode - 1
    assert res.excitation[0] < 0.1 * res.excitation[k]
    assert res.excitation[0] == pytest.approx(res.observation[0], rel=1e-9)
    assert abs(res.modal_constants[0]) == pytest.approx(res.excitation[0] ** 2, rel=1e-9)
    assert f"mode {k + 1}'s" in res.mode1_note()
    assert res.to_dict()["first_peak_note"] == res.mode1_note()


def test_h1_recovers_a_single_mode():
    """Synthetic records: the analytic impulse response of a 1-dof oscillator to a short pulse."""
    fn, zeta, dt = 63.0, 0.01, 1e-4
    t = np.arange(5001) * dt
    wn = 2 * math.pi * fn
    wd = wn * math.sqrt(1 - zeta**2)
    recs = []
    for amp in (1.0, 0.8, 1.2):
        force = np.zeros_like(t)
        force[0] = amp / dt  # an impulse of amp N s
        # acceleration of x'' + 2 zeta wn x' + wn^2 x = F / 1 kg after a unit impulse (t > 0)
        x = np.exp(-zeta * wn * t) * np.sin(wd * t) / wd
        v = np.gradient(x, dt)
        a = np.gradient(v, dt)
        recs.append(ImpactRecord(t, force, amp * a, amp, 0.0))
    freq, h1, coh = h1_estimate(recs, pad_s=8.0, window_end=0.01)
    band = (freq > 10) & (freq < 200)
    peak = freq[band][np.argmax(np.abs(h1[band]))]
    # 0.125 Hz lines; accelerance peak at fn / sqrt(1 - 2 zeta^2) = fn (1 + 1e-4)
    assert peak == pytest.approx(fn, abs=0.2)
    assert np.allclose(coh[band], 1.0, atol=1e-6)  # noise-free, linear: perfectly coherent


def test_point_acceleration_is_rigid_body_kinematics(symmetric_manip):
    """At rest under a load the acceleration of a material point equals J qacc (velocity terms vanish)."""
    built = build_manipulator(symmetric_manip, Pose(0.02, 0.03, 0.0), ModelOptions(segments=3, axial=False))
    model = built.model
    data = mujoco.MjData(model)
    pt = LinkPoint("distal_1", 0.37, "z")
    mujoco.mj_forward(model, data)
    bid, p, _e = locate(built, data, pt)
    mujoco.mj_applyFT(model, data, np.array([0.0, 0.0, 3.0]), np.zeros(3), p, bid, data.qfrc_applied)
    mujoco.mj_forward(model, data)
    mujoco.mj_rnePostConstraint(model, data)
    acc = point_acceleration(model, data, bid, p)
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jac(model, data, jacp, None, p, bid)
    np.testing.assert_allclose(acc, jacp @ data.qacc, rtol=1e-6, atol=1e-9)
    assert abs(acc[2]) > 1.0  # a real acceleration (m/s^2), not zeros agreeing


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_impacts": 0}, "n_impacts"),
        ({"pulse_s": 0.5, "record_s": 0.2}, "pulse_s"),
        ({"f_max_hz": 6000.0}, "Nyquist"),
        ({"window_end": 0.0}, "window_end"),
        ({"timestep_s": 2e-4}, "sample_s"),
        ({"timestep_s": 5e-5, "pulse_s": 2e-4}, "pulse_s / 10"),
        ({"timestep_s": -1e-5}, "timestep_s must be positive"),
        ({"timestep_s": 1e-5, "integrator": "explicit"}, "^timestep_s: .*; drop it with the explicit integrator"),
        ({"integrator": "rk4"}, "^integrator: unknown integrator, got 'rk4'"),
        ({"band_hz": 0.0}, "^band_hz: must be a positive finite number, got 0.0"),
        ({"impact": LinkPoint("distal_9", 0.5, "z")}, "unknown link"),
    ],
)
def test_bad_setups_name_the_parameter(symmetric_manip, kwargs, message):
    built = build_manipulator(symmetric_manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, axial=False))
    with pytest.raises(FrfError, match=message):
        virtual_impact_test(built, ImpactSetup(**kwargs))


@pytest.mark.slow
def test_discrete_matches_the_explicit_reference_at_12_segments(default_manip):
    """The issue's check at the standard 12 segments: one 0.1 s impact on the default (discrete, band 5 x f1)
    and the explicit reference (0.41 us steps: ~8 min on the shared machine), out of plane (z) and in plane
    (normal); the EMA of each FRF, the discrete one with the step inverted: frequencies within 0.1 % and
    damping within 0.2 percentage points of the reference's. Measured (the same computation, one run): z -0.029 %
    and +0.034 points, normal -0.014 % and +0.006 points; explicit 637 / 873 s, discrete 9.2 / 43.9 s."""
    from fpm_sim.study.identify.ema import MeasuredFrf, estimate_modes

    built = build_manipulator(default_manip, Pose.from_mm(0.0, 0.0, 0.2), ModelOptions(segments=12, axial=False))
    system = modal_system(built)
    for axis in ("z", "normal"):
        p = LinkPoint("distal_0", 0.5, axis)
        est = []
        for integrator in ("explicit", "discrete"):
            setup = ImpactSetup(impact=p, accelerometer=p, record_s=0.1, n_impacts=1, integrator=integrator)
            r = virtual_impact_test(built, setup, system=system)
            frf = MeasuredFrf(r.frf.freq_hz, r.frf.h, axis, None, r.window_tau_s, r.discrete_step_s)
            est.append(estimate_modes(frf, f_lower_hz=20.0, f_upper_hz=400.0, n_modes=1))
        assert est[1].discrete_step_s is not None
        assert est[1].freq_hz[0] == pytest.approx(est[0].freq_hz[0], rel=1e-3)
        assert est[1].damping[0] == pytest.approx(est[0].damping[0], abs=2e-3)
