"""Headless nonlinear rollouts: rest at the equilibrium, agreement with the reduced model in the
linear range (displacements, accelerations, motor torques), outputs and bad input."""

import re

import mujoco
import numpy as np
import pytest

from fpm_sim.config import Motors
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.reduction import modal_system, reduce_model
from fpm_sim.sim.rollout import RolloutError, aligned_options, constant, rollout, sine

POSE = Pose(0.05, -0.05, 0.1)


def _nrms(full, reduced):
    return float(np.sqrt(np.mean((full - reduced) ** 2)) / np.sqrt(np.mean(full**2)))


@pytest.fixture(scope="module")
def flexible(symmetric_manip):
    manip = symmetric_manip.with_section(thickness_m=0.005)
    opts = aligned_options(manip, POSE, ModelOptions(segments=3, axial=False), 1e-4)
    built = build_manipulator(manip, POSE, opts)
    return manip, built, modal_system(built)


def test_timestep_is_aligned_to_the_output_step(flexible):
    _, built, _ = flexible
    n = 1e-4 / built.timestep_s
    assert abs(n - round(n)) < 1e-9
    assert built.timestep_s <= build_manipulator(
        flexible[0], POSE, ModelOptions(segments=3, axial=False)
    ).timestep_s * (1 + 1e-12)


@pytest.mark.parametrize("integrator", ["explicit", "discrete"])
def test_unloaded_rollout_stays_at_the_equilibrium(flexible, integrator):
    manip, built, system = flexible
    res = rollout(built, manip, duration_s=0.01, qpos=system.qpos, integrator=integrator)
    # the static equilibrium solves qacc = 0 of the explicit model: only round-off drift remains (measured 6e-14 m);
    # the discrete integrator's constraint solve in the metric M + hD + h^2 K settles 1.5e-10 rad away (measured,
    # phi); 1e-10 m / 1e-9 rad are four to five orders below the ~1e-4 m responses tested below
    assert np.abs(res.ee_disp[:, :2]).max() < 1e-10
    assert np.abs(res.ee_disp[:, 2]).max() < (1e-10 if integrator == "explicit" else 1e-9)
    assert res.n_steps == round(0.01 / res.stepping.step_s)
    assert res.stepping.integrator == integrator
    # motors locked: the deflection is the end-effector pose minus the assembled (rigid) pose
    assert np.allclose(res.deflection, res.ee_pose - POSE.as_array(), atol=1e-12)


def test_small_force_rollout_matches_the_reduced_model(flexible):
    """Independent truths meet: the nonlinear time integration of the full model and the continuous
    modal model from the constrained eigen-solve. A 1 N force keeps geometric nonlinearity ~1e-3."""
    manip, built, system = flexible
    rom = reduce_model(system, band_hz=2000.0)
    res = rollout(
        built,
        manip,
        duration_s=0.05,
        ee_wrench=constant(1.0, 0.0, 0.0),
        accel_sites=system.accel_sites,
        qpos=system.qpos,
        integrator="explicit",
    )
    u = np.zeros((len(res.t_s), len(rom.input_names)))
    u[:, 0] = 1.0
    y = rom.simulate(res.t_s, u)
    # 0.5 %: geometric nonlinearity at 1 N (~0.1 %) and the integrator's phase error; measured 0.08 %
    assert _nrms(res.ee_disp[:, 0], y[:, rom.output_index("disp_x")]) < 5e-3
    assert np.allclose(res.wrench[:, 0], 1.0)
    # accelerometers: the world-frame site acceleration projected on the in-plane link normal at the
    # equilibrium, against the reduced model's acceleration outputs (modes to 2 kHz kept: the
    # truncated modes' share of the acceleration is what remains; measured 0.3 %)
    model = built.model
    data = mujoco.MjData(model)
    data.qpos[:] = system.qpos
    mujoco.mj_forward(model, data)
    for i, site in enumerate(system.accel_sites):
        normal = data.site(site).xmat.reshape(3, 3)[:, 1].copy()
        normal[2] = 0.0
        normal /= np.linalg.norm(normal)
        assert _nrms(res.accel[site] @ normal, y[:, rom.output_index(f"acc_distal_{i}")]) < 1e-2


@pytest.mark.parametrize(("band_hz", "bound"), [(None, 5e-3), (500.0, 1e-3)])
def test_discrete_rollout_matches_the_reduced_model(flexible, band_hz, bound):
    """The default (discrete) path against the same modal truth, in displacement: at the default band (5 x f1,
    here h = 0.1 ms) the numerical damping of the modes above f1 costs a little (measured 0.35 %); at 500 Hz
    (h = 12.5 us) measured 0.03 %, below the explicit reference's 0.08 % (its symplectic phase error). The
    accelerations carry the modes up to kHz, which a band of 5 x f1 damps on purpose (30 % NRMS at 0.1 ms,
    measured): accelerations need --band-hz above their content or --integrator explicit."""
    manip, built, system = flexible
    rom = reduce_model(system, band_hz=2000.0)
    res = rollout(built, manip, duration_s=0.05, ee_wrench=constant(1.0, 0.0, 0.0), qpos=system.qpos, band_hz=band_hz)
    u = np.zeros((len(res.t_s), len(rom.input_names)))
    u[:, 0] = 1.0
    y = rom.simulate(res.t_s, u)
    assert _nrms(res.ee_disp[:, 0], y[:, rom.output_index("disp_x")]) < bound
    assert res.stepping.damping_at(res.stepping.band_hz) <= 0.02


def test_motor_torque_rollout_matches_the_reduced_model(symmetric_manip):
    manip = symmetric_manip.with_section(thickness_m=0.005).replace(
        motors=Motors(mode="servo", servo_stiffness_nm_per_rad=500.0, servo_damping_nms_per_rad=1.0)
    )
    pose = Pose(0.0, 0.0, 0.0)
    built = build_manipulator(manip, pose, aligned_options(manip, pose, ModelOptions(segments=3, axial=False), 1e-4))
    rom = reduce_model(built, band_hz=2000.0)
    res = rollout(built, manip, duration_s=0.03, motor_torque=sine(40.0, 0.05, 0.0, 0.0), qpos=rom.qpos)
    u = np.zeros((len(res.t_s), len(rom.input_names)))
    u[:, rom.input_index("motor_torque_0")] = res.motor_torque[:, 0]
    y = rom.simulate(res.t_s, u)
    for k, name in enumerate(("disp_x", "disp_y")):
        # as above: small load, linear range; measured 0.04 %
        assert _nrms(res.ee_disp[:, k], y[:, rom.output_index(name)]) < 1e-2
    # the motor turns and the deflection separates link bending from it
    assert np.abs(res.motor_angles_rad[:, 0] - res.motor_angles_rad[0, 0]).max() > 1e-5
    assert not np.allclose(res.deflection, res.ee_pose - pose.as_array(), atol=1e-7)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_save(flexible, tmp_path, suffix):
    manip, built, _system = flexible
    res = rollout(built, manip, duration_s=0.002, ee_wrench=constant(0.0, 1.0, 0.0), accel_sites=["distal_0_p1"])
    path = res.save(tmp_path / f"r{suffix}")
    cols = res.columns()
    if suffix == ".csv":
        table = np.genfromtxt(path, delimiter=",", names=True)
        assert list(table.dtype.names) == list(cols)
        assert np.allclose(table["disp_y_m"], res.ee_disp[:, 1], rtol=1e-9, atol=1e-15)
    else:
        back = np.load(path)
        assert set(back.files) == set(cols)
        assert np.array_equal(back["acc_distal_0_p1_x_m_s2"], res.accel["distal_0_p1"][:, 0])


def test_bad_input(flexible):
    manip, built, _ = flexible
    with pytest.raises(RolloutError, match=re.escape("motors.mode = 'servo'")):
        rollout(built, manip, duration_s=0.001, motor_torque=constant(1.0, 0.0, 0.0))
    with pytest.raises(RolloutError, match="accel_sites"):
        rollout(built, manip, duration_s=0.001, accel_sites=["nowhere"])
    with pytest.raises(RolloutError, match="duration_s"):
        rollout(built, manip, duration_s=-1.0)
    for integrator in ("explicit", "discrete"):
        with pytest.raises(RolloutError, match="output_step_s"):
            rollout(built, manip, duration_s=0.001, output_step_s=1e-9, integrator=integrator)


@pytest.mark.parametrize("force_n", [1e9, float("inf"), float("nan")], ids=["1e9", "inf", "nan"])
def test_diverging_or_non_finite_load_is_an_error_not_zeros(flexible, force_n, tmp_path, monkeypatch):
    """1e9 N made MuJoCo reset the state to qpos0 (a CSV of zero displacement, exit 0); inf and nan too."""
    monkeypatch.chdir(tmp_path)
    manip, built, system = flexible
    with pytest.raises(RolloutError, match=r"diverged|finite"):
        rollout(built, manip, duration_s=0.002, ee_wrench=constant(force_n, 0.0, 0.0), qpos=system.qpos)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()  # MuJoCo's warning went to the error, not a file


def test_mujoco_warnings_never_write_a_log_file(tmp_path, monkeypatch):
    from fpm_sim.model.mujoco_log import MujocoWarning, mujoco_messages, route_mujoco_warnings

    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint/><geom size=".1"/></body></worldbody></mujoco>'
    )
    data = mujoco.MjData(model)
    data.qfrc_applied[:] = np.nan
    with mujoco_messages() as messages:
        mujoco.mj_step(model, data)
    assert messages
    assert "QACC" in messages[0]
    previous = mujoco.get_mju_user_warning()
    try:
        mujoco.set_mju_user_warning(None)
        route_mujoco_warnings()
        data = mujoco.MjData(model)  # MuJoCo reports each warning kind once per MjData
        data.qfrc_applied[:] = np.nan
        with pytest.warns(MujocoWarning, match="unstable"):
            mujoco.mj_step(model, data)
    finally:
        mujoco.set_mju_user_warning(previous)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duration_s": -1.0}, "duration_s"),
        ({"duration_s": float("inf")}, "duration_s"),
        ({"duration_s": 0.001, "output_step_s": float("nan")}, "output_step_s"),
        ({"duration_s": 0.001, "ee_wrench": lambda t: (1.0, 2.0)}, "ee_wrench"),
    ],
)
def test_bad_rollout_arguments_name_the_parameter(flexible, kwargs, match):
    manip, built, system = flexible
    with pytest.raises(RolloutError, match=match):
        rollout(built, manip, qpos=system.qpos, **kwargs)


def test_load_profiles_are_validated():
    from fpm_sim.sim.rollout import step_at

    with pytest.raises(RolloutError, match=r"^t0_s: must be finite"):
        step_at(float("nan"), 1.0, 0.0, 0.0)
    with pytest.raises(RolloutError, match=r"^freq_hz: must be >= 0 Hz"):
        sine(-1.0, 1.0, 0.0, 0.0)
    with pytest.raises(RolloutError, match=r"^freq_hz: must be finite"):
        sine(float("inf"), 1.0, 0.0, 0.0)
    with pytest.raises(RolloutError, match="amplitudes"):
        sine(10.0, float("nan"), 0.0, 0.0)
    assert np.allclose(step_at(0.5, 1.0, 2.0, 3.0)(0.6), [1.0, 2.0, 3.0])
    assert np.allclose(step_at(0.5, 1.0, 2.0, 3.0)(0.4), 0.0)
