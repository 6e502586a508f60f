"""Rollouts and moves of described architectures (fpm_sim.sim.task), against independent truths: beam theory and the
linear static solution, the modal f1, the commanded end pose and the inverse kinematics, and the 3RRR's own path."""

from __future__ import annotations

import json
import math
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import TaskPose, load_description, parse_description, solve_task_pose
from fpm_sim.architecture.kinematics import actuated_coordinates
from fpm_sim.architecture.three_rrr import description_of_3rrr
from fpm_sim.cli.main import main
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.general import build_general
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.reduction import modal_system
from fpm_sim.sim.rollout import rollout, step_at
from fpm_sim.sim.task import machine_of
from fpm_sim.sim.trajectory import dominant_frequency_hz

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = EXAMPLES / "five_bar.toml"
COARSE = ModelOptions(segments=4, axial=False)


def _quiet(f, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return f(*a, **kw)


def _damped(name: str, beta_s: float):
    raw = tomllib.loads((EXAMPLES / f"{name}.toml").read_text())
    raw["damping"] = {"stiffness_proportional_s": beta_s}
    return parse_description(raw)


def _two_link_cantilever_m(desc, pose: TaskPose, force: np.ndarray) -> np.ndarray:
    """Tip displacement of the serial arm with its joints locked: a plane frame of two Euler-Bernoulli beams built
    in at the shoulder, by the unit-load method (delta = sum of int M M_unit / (E I) ds over both links), the
    bending moment of a tip force ``F`` at ``s`` being ``(r_tip - r(s)) x F``; the links inextensible."""
    asm = solve_task_pose(desc, pose)
    frames = asm.chains["arm"]
    tip = np.array([pose.x_m, pose.y_m])
    compliance = np.zeros((2, 2))
    for k, e in enumerate(desc.chains[0].path):
        if not hasattr(e, "length_m"):
            continue
        a, u = frames.positions_m[k][:2], frames.rotations[k][:2, 0]
        ei = e.material.young_pa * e.section.thickness_m**3 * e.section.height_m / 12.0
        s = np.linspace(0.0, e.length_m, 401)
        r = tip[None, :] - (a[None, :] + s[:, None] * u[None, :])
        m_unit = np.column_stack([-r[:, 1], r[:, 0]])  # moment of a unit force along x, along y
        compliance += np.trapezoid(m_unit[:, :, None] * m_unit[:, None, :], s, axis=0) / ei
    return compliance @ force


def test_a_tip_force_on_the_serial_arm_settles_to_beam_theory_and_to_the_linear_static_solution():
    """The serial arm (both joints locked) under a small constant tip force settles to the static deflection of
    (1) the modal model's K^-1 f (its static flexibility), and (2) a two-link cantilever by beam theory.

    Tolerances: (1) 1e-3 of |u|: the damping added here (beta = 0.03 s: zeta 33 % at f1 = 3.5 Hz) leaves e^-11 of
    the step after 1.5 s, and the geometric nonlinearity is of the order of the tip rotation, |u| / L ~ 3e-4 for
    0.06 N; the integrator's static solution is the model's own (measured 6e-5 in x, 4e-4 in y). (2) 0.5 %: the
    segments model's static compliance converges at second order (measured 0.5 %, 0.13 %, 0.03 % at 2, 4, 8
    segments).
    """
    desc = _damped("serial_arm", 0.03)
    pose = TaskPose(0.6, 0.2)
    force = np.array([0.03, -0.05])
    res = _quiet(
        fs.rollout,
        desc,
        pose,
        force_x_n=force[0],
        force_y_n=force[1],
        duration_s=1.5,
        output_step_s=1e-3,
        options=COARSE,
    )
    assert res.coordinates == ("x", "y")
    settled = res.ee_disp[-1]
    built = _quiet(build_general, desc, pose, COARSE)
    system = modal_system(built)
    linear = (system.c_q @ system.flexibility @ system.b_q[:, :2] @ force)[:2]
    assert np.linalg.norm(settled - linear) < 1e-3 * np.linalg.norm(linear)
    beam = _two_link_cantilever_m(desc, pose, force)
    assert np.linalg.norm(settled - beam) < 5e-3 * np.linalg.norm(beam)
    # the deflection of a locked machine is its displacement from the rigid pose (the equilibrium's sag included)
    np.testing.assert_allclose(res.deflection[-1] - res.deflection[0], settled, atol=1e-12)


def test_the_free_response_after_a_step_rings_at_the_modal_f1():
    """The five-bar on its servos (no structural damping) after a step force along y: the dominant frequency of the
    response is the modal f1 (its first mode carries 99 % of the end effector's static y compliance, checked),
    within the FFT's resolution 1 / T (T = 0.5 s: 2 Hz); the second mode is more than 1 / T away, so the test tells
    them apart. The servo damping (zeta ~ 0.11) lowers the ringing frequency by 1 - sqrt(1 - zeta^2) = 0.6 %, the
    discrete integrator's period error at f1 is 0.002 % (fpm_sim.sim.stepping): both far inside 1 / T.

    With the motors locked the five-bar's first three modes are out of the plane, and an in-plane force does not
    excite them (modes 4 and 5 carry its in-plane compliance): the servo model is the one whose f1 a move rings at.
    """
    desc = load_description(FIVE_BAR)
    pose = TaskPose(0.0, 0.25)
    opts = ModelOptions(segments=2, axial=False)
    asm = solve_task_pose(desc, pose)
    built = _quiet(build_general, desc, pose, opts, assembly=asm, motors="servo")
    system = modal_system(built)
    f1, f2 = system.frequencies_hz[:2]
    share = (system.c_q[1] @ system.phi) ** 2 / system.omega_rad_s**2
    assert share[0] > 0.99 * share.sum()
    duration = 0.5
    machine = machine_of(built, desc, asm)
    res = rollout(built, machine, duration_s=duration, output_step_s=2e-4, ee_wrench=step_at(0.0, 0.0, 1.0))
    f_dom = dominant_frequency_hz(res.t_s, res.ee_disp[:, 1])
    assert abs(f2 - f1) > 1.0 / duration
    assert abs(f_dom - f1) < 1.0 / duration


def test_a_short_move_of_the_five_bar_ends_on_its_end_pose_in_its_working_mode():
    """A 10 mm move in 50 ms: the end effector ends within the settling tolerance (20 um) of the commanded end pose
    and the residual vibration settles inside the record (the servo modes it excites, 18 and 25 Hz, have 11 % and
    16 % damping from the servo dampers: 1.5 mm decays to 20 um in ~0.18 s), and the joint targets, followed from
    the start by warm-started inverse kinematics, end on the cold inverse kinematics of the end pose (the working mode's
    solution: a branch switch would differ by radians) without a jump on the way."""
    desc = load_description(FIVE_BAR)
    start, end = TaskPose(0.0, 0.25), TaskPose(0.01, 0.25)
    res = _quiet(
        fs.move,
        desc,
        start,
        end=end,
        move_s=0.05,
        settle_s=0.35,
        output_step_s=2e-4,
        options=ModelOptions(segments=2, axial=False),
    )
    assert res.coordinates == ("x", "y")
    assert np.linalg.norm(res.ee_pose[-1] - [end.x_m, end.y_m]) < res.residual.tol_m
    assert np.linalg.norm(res.residual.final_offset_m) < res.residual.tol_m
    assert math.isfinite(res.residual.settling_time_s)
    np.testing.assert_allclose(res.motor_ref_rad[-1], actuated_coordinates(desc, solve_task_pose(desc, end)), atol=1e-9)
    np.testing.assert_allclose(
        res.motor_ref_rad[0], actuated_coordinates(desc, solve_task_pose(desc, start)), atol=1e-9
    )
    # a step of the targets is at most their rate times the sample (0.15 rad over 50 ms: ~1e-3 rad per sample)
    assert np.abs(np.diff(res.motor_ref_rad, axis=0)).max() < 2e-3
    assert res.to_dict()["residual"]["modal_f1_hz"] > 0


def test_the_3rrr_through_the_general_path_has_the_3rrr_rollout():
    """The study's 3RRR written as a description (examples/architectures/three_rrr.toml's form) and built by the
    general builder under the same force and moment, motors locked: the same end-effector history as the 3RRR's own
    path. Its modes agree to 1e-8 (tests/architecture/test_modes.py) and the stepping is chosen from the same f1,
    so the histories differ only by round-off in the static equilibrium and the step: measured 1e-9 of the peak, allowed
    1e-7."""
    cfg = default_config()
    desc = load_description(EXAMPLES / "three_rrr.toml")
    assert desc == description_of_3rrr(cfg)  # the file is the embedded default's description
    opts = ModelOptions(segments=2, axial=False)
    kw = dict(force_x_n=0.5, force_y_n=-0.3, duration_s=0.03, options=opts)
    native = _quiet(fs.rollout, cfg, Pose.from_mm(20.0, -10.0, 0.05), moment_z_nm=0.02, **kw)
    general = _quiet(
        fs.rollout, desc, TaskPose.from_mm(20.0, -10.0, 0.0, 0.05), moment_z_nm=0.02, accel_fraction=None, **kw
    )
    assert general.coordinates == native.coordinates == ("x", "y", "phi")
    assert general.t_s.shape == native.t_s.shape
    peak = np.abs(native.ee_disp).max(axis=0)
    assert np.all(np.abs(general.ee_disp - native.ee_disp).max(axis=0) < 1e-7 * peak)


def test_batched_rollouts_of_the_five_bar_are_its_rollouts():
    """The batched rollouts (mujoco.rollout's threads) of two loads in the five-bar's task coordinates: each the
    rollout of that load, the same model and steps, to round-off (1e-9 of the peak)."""
    desc = load_description(FIVE_BAR)
    opts = ModelOptions(segments=2, axial=False)
    kw = dict(duration_s=0.01, options=opts)
    batch = _quiet(fs.batched_rollouts, desc, None, wrenches=[[1.0, 0.0], [0.0, -2.0]], **kw)
    disp = np.asarray(batch.to_xarray()["ee_disp"].values)
    assert list(batch.to_xarray()["axis"].values) == ["x", "y"]
    for k, (fx, fy) in enumerate([(1.0, 0.0), (0.0, -2.0)]):
        one = _quiet(fs.rollout, desc, None, force_x_n=fx, force_y_n=fy, **kw).ee_disp
        assert np.abs(disp[k] - one).max() < 1e-9 * np.abs(one).max()


def test_the_time_commands_run_on_the_five_bar(capsys):
    base = ["--config", str(FIVE_BAR), "--segments", "2", "--json"]
    assert main(["rollout", *base, "--duration-s", "0.02", "--force-x-n", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["final_disp"]) == {"x_m", "y_m"}
    assert (
        main(
            [
                "move",
                *base,
                "--move-s",
                "0.02",
                "--settle-s",
                "0.02",
                "--to-x-mm",
                "5",
                "--to-y-mm",
                "250",
                "--output-step-s",
                "2e-4",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["residual"]["modal_f1_hz"] > 0


@pytest.mark.parametrize(
    ("command", "option", "says"),
    [
        (
            "rollout",
            ["--moment-z-nm", "1"],
            "--moment-z-nm: five-bar (example specification) has no task coordinate phi",
        ),
        ("rollout", ["--motors", "servo", "--motor-torque-nm", "1", "2", "3"], "--motor-torque-nm needs 2 values"),
        ("move", ["--to-phi-rad", "0.1"], "--to-phi-rad: five-bar (example specification) has no task coordinate phi"),
    ],
)
def test_an_option_the_five_bar_lacks_is_refused_in_one_line(capsys, command, option, says):
    assert main([command, "--config", str(FIVE_BAR), *option]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1
    assert err[0].startswith("error: ")
    assert says in err[0]


def test_the_servo_gains_come_from_the_file_with_their_source_or_the_stated_default():
    from fpm_sim.architecture.description import SERVO_SOURCE
    from fpm_sim.config.schema import ConfigError

    raw = tomllib.loads(FIVE_BAR.read_text())
    raw["servos"] = {"stiffness_nm_per_rad": {"value": 800.0, "source": "datasheet"}}
    desc = parse_description(raw)
    assert desc.servos.gains("revolute") == (800.0, 1.0)
    built = _quiet(build_general, desc, TaskPose(0.0, 0.25), ModelOptions(segments=2), motors="servo")
    gains = built.parameters["servos"]
    assert gains["stiffness_nm_per_rad"] == {"value": 800.0, "source": "datasheet"}
    assert gains["damping_nms_per_rad"]["source"] == SERVO_SOURCE
    assert "servos" not in _quiet(build_general, desc, TaskPose(0.0, 0.25), ModelOptions(segments=2)).parameters
    raw["servos"] = {"stiffness_nm_per_rad": 0.0}
    with pytest.raises(ConfigError, match=r"servos\.stiffness_nm_per_rad"):
        parse_description(raw)
