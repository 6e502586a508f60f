"""Rollouts, reduced models and virtual impact tests of an imported model (issue 29: every command on an imported
model): the described five-bar exported once with rigid links and its motors as joints, imported back flexible
(tests/helpers/imported_copy.py), gives the native five-bar's results for the same inputs.

The two models are the same doubles up to the export round trip (full-precision XML, the bodies re-placed: round-off,
~1e-15 relative) and the two pose solvers' convergence (the native architecture's kinematics and the imported model's
Gauss-Newton, both to ~1e-12 of the model's extent). Each comparison's bound is issue 29's round-trip bound, 1e-6 of
the compared quantity's scale: far above both (the measured differences, in each test's docstring, are 1e-10 or
below), far below a modelling difference (the imported servo 1 % stiffer moves a move's trajectory by 6e-3 of its
motion: tests/imported/test_imported_move.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import TaskPose, load_description, solve_task_pose
from fpm_sim.architecture.imported import load_imported
from fpm_sim.architecture.kinematics import actuated_coordinates
from fpm_sim.cli.main import main
from fpm_sim.errors import FpmSimError
from fpm_sim.model.imported_pose import ImportedKinematics
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import LinkPoint
from fpm_sim.sim.impact import ImpactSetup
from fpm_sim.sim.trajectory import MoveError
from tests.helpers.imported_copy import imported_copy
from tests.imported.test_import import _acrobot_toml

ROOT = Path(__file__).resolve().parents[2]
FIVE_BAR = ROOT / "examples/architectures/five_bar.toml"
COARSE = ModelOptions(segments=2, axial=False)
POSE = TaskPose(0.004, 0.246)  # off the export pose (the first check pose, x 0, y 250 mm): the solvers work
ROUND_TRIP = 1e-6
pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")


def _close(back: np.ndarray, native: np.ndarray) -> None:
    scale = float(np.abs(native).max())
    assert scale > 0
    np.testing.assert_allclose(back, native, rtol=0, atol=ROUND_TRIP * scale)


def test_the_imported_five_bar_makes_the_native_five_bar_rollouts(tmp_path: Path) -> None:
    """10 ms from the static equilibrium at a pose off the export pose, coarse links: under an end-effector force
    with the motors locked, and under motor torques with the motors as servos (the description's [servos]). The end
    effector's trajectory, displacement, deflection and the motors' angles are the native ones (measured: 4.7e-16 m
    of a 94 um motion locked; with servos 5.0e-16 m of a 0.15 mm motion, the deflection 1.7e-14 m of 5.8 um, the
    motor angles 4.5e-16 rad of 0.58 mrad); the
    imported joints count from the export pose (their ref 0 there: fpm_sim.model.imported). Posed by the joint
    values instead of the task pose, the imported rollout is the same one (the same model: rtol 1e-12)."""
    desc = load_description(FIVE_BAR)
    imp = load_imported(imported_copy(desc, tmp_path, servo=True))
    export = actuated_coordinates(desc, solve_task_pose(desc, TaskPose.from_coordinates(desc.check_poses[0])))
    kw = dict(duration_s=0.01, output_step_s=2e-4, options=COARSE)
    for extra in (dict(force_x_n=30.0, force_y_n=-20.0), dict(motors="servo", motor_torque_nm=[0.5, -0.3])):
        native = fs.rollout(desc, POSE, **kw, **extra)  # type: ignore[arg-type]
        back = fs.rollout(imp, POSE, **kw, **extra)  # type: ignore[arg-type]
        assert back.coordinates == native.coordinates == ("x", "y")
        assert back.motor_names == native.motor_names == ("left_motor", "right_motor")
        assert back.parameters["motors"] == native.parameters["motors"] == extra.get("motors", "locked")
        assert back.parameters["timestep_s"] == pytest.approx(native.parameters["timestep_s"], rel=1e-12)
        np.testing.assert_array_equal(back.t_s, native.t_s)
        assert np.abs(native.ee_disp).max() > 5e-5
        _close(back.ee_pose - native.ee_pose[0], native.ee_pose - native.ee_pose[0])
        _close(back.ee_disp, native.ee_disp)
        _close(back.deflection, native.deflection)
        turn = native.motor_angles_rad - native.motor_angles_rad[0]
        if "motors" in extra:  # servos turn; locked motors stay at their posed angles
            _close(back.motor_angles_rad - back.motor_angles_rad[0], turn)
        else:
            assert not np.any(turn)
            assert not np.any(back.motor_angles_rad - back.motor_angles_rad[0])
        np.testing.assert_allclose(back.motor_angles_rad[0], native.motor_angles_rad[0] - export, rtol=0, atol=1e-9)
    q = ImportedKinematics(imp).solve(POSE)
    by_q = fs.rollout(imp, q=q, **kw, motors="servo", motor_torque_nm=[0.5, -0.3])  # type: ignore[arg-type]
    np.testing.assert_allclose(by_q.ee_disp, back.ee_disp, rtol=1e-12, atol=1e-18)


def test_an_end_effector_force_acts_at_the_site_off_its_body_centre_of_mass(tmp_path: Path) -> None:
    """dm_control's acrobot, its end-effector site the lower arm's tip, 1 m from the body's centre of mass: a 1 N, 0.5
    N force at the site for 30 ms, stepped by the explicit reference, is the reduced model's linear response to the same
    force (the reduced model's wrench input is the site Jacobian's transpose: the force at the site exactly; every mode
    to 5 kHz with the static correction, the same zero-order hold). Measured within 7.7e-4 of the peak tip
    displacement (the explicit step's error on the upper modes, and the geometric nonlinearity of a 3e-5 m deflection
    of a 2 m arm: ~1e-5); the bound, 5e-3, is far below what the force at the centre of mass alone would give
    (measured 0.66 apart: the moment of the force about it is what turns the arm)."""
    extra = '[end_effector]\nsite = "tip"\ncoordinates = ["x", "z"]\n[damping]\nstiffness_proportional_s = 1e-4\n'
    desc = fs.load_imported(_acrobot_toml(tmp_path, extra))
    opts = ModelOptions(segments=4, gravity=False, axial=False)
    q = {"elbow": 0.3}
    run = fs.rollout(desc, q=q, duration_s=0.03, options=opts, force_x_n=1.0, force_z_n=0.5, integrator="explicit")
    rom = fs.reduce(desc, q=q, band_hz=5000.0, options=opts)
    u = np.zeros((len(run.t_s), len(rom.input_names)))
    u[:, rom.input_index("force_x")], u[:, rom.input_index("force_z")] = 1.0, 0.5
    y = rom.simulate(run.t_s, u)
    for k, out in enumerate(("disp_x", "disp_z")):
        lin = y[:, rom.output_index(out)]
        np.testing.assert_allclose(run.ee_disp[:, k], lin, rtol=0, atol=5e-3 * np.abs(lin).max())


def test_the_imported_five_bar_reduces_to_the_native_reduced_model(tmp_path: Path) -> None:
    """Six modes at a pose off the export pose, 3 segments: the same frequencies and the same transfer functions
    ``C (sI - A)^-1 B + D`` (invariant to the modes' signs) at 0, 20, 100 and 300 Hz, static correction on, from the
    native model's inputs (force_x, force_y, moment_z at the end effector) to its outputs (the end effector's
    displacements, an accelerometer mid-span of each distal link). The imported model is not known to be planar, so
    it has all six wrench components and reads an accelerometer along its link frame's y axis where the native one
    projects it on the base plane: gravity is off so that the links do not sag out of the plane and the two axes are
    one (with gravity the sag tilts it: measured 6e-5 apart, the displacements still 1.2e-12). Measured: frequencies
    within 1.5e-12, transfer functions within 4.7e-13 of each output's scale."""
    desc = load_description(FIVE_BAR)
    imp = load_imported(imported_copy(desc, tmp_path))
    opts = ModelOptions(segments=3, axial=False, gravity=False)
    native = fs.reduce(desc, POSE, n_modes=6, options=opts)
    back = fs.reduce(imp, POSE, n_modes=6, options=opts)
    np.testing.assert_allclose(back.frequencies_hz, native.frequencies_hz, rtol=ROUND_TRIP)
    assert len(back.input_names) == 6
    assert back.input_names[:2] == native.input_names[:2] == ["force_x", "force_y"]
    outputs = {n: n for n in ("disp_x", "disp_y", "rot_z")}
    outputs |= {"acc_left_distal": "acc_left_distal_b0_beam", "acc_right_distal": "acc_right_distal_b0_beam"}
    inputs = ("force_x", "force_y", "moment_z")
    freq = np.array([0.0, 20.0, 100.0, 300.0])
    h_nat = native.frequency_response(freq)[:, [native.output_index(o) for o in outputs]]
    h_back = back.frequency_response(freq)[:, [back.output_index(o) for o in outputs.values()]]
    h_nat = h_nat[:, :, [native.input_index(i) for i in inputs]]
    h_back = h_back[:, :, [back.input_index(i) for i in inputs]]
    for k in range(len(outputs)):
        _close(h_back[:, k], h_nat[:, k])


def test_the_imported_five_bar_makes_the_native_impact_test(tmp_path: Path) -> None:
    """One 20 N hammer hit mid-span of the left distal link, along its z, 0.1 s recorded, coarse links: the same
    accelerometer record (measured within 1.6e-12 of its peak), H1 FRF (1.1e-10 of its peak: the H1 divides by the
    force's spectrum) and first peak (1.4e-13), on the same integrator step."""
    desc = load_description(FIVE_BAR)
    imp = load_imported(imported_copy(desc, tmp_path))

    def setup(link: str) -> ImpactSetup:
        point = LinkPoint(link, 0.5, "z")
        return ImpactSetup(impact=point, accelerometer=point, n_impacts=1, record_s=0.1, f_max_hz=400.0)

    native = fs.impact(desc, POSE, setup=setup("left_distal"), options=COARSE)
    back = fs.impact(imp, POSE, setup=setup("left_distal_b0_beam"), options=COARSE)
    assert back.stepping is not None
    assert native.stepping is not None
    assert back.stepping.step_s == native.stepping.step_s
    _close(back.records[0].accel_m_s2, native.records[0].accel_m_s2)
    _close(back.frf.h, native.frf.h)
    assert back.first_peak_hz == pytest.approx(native.first_peak_hz, rel=ROUND_TRIP)
    assert back.modal_f1_hz == pytest.approx(native.modal_f1_hz, rel=ROUND_TRIP)


@pytest.mark.filterwarnings("ignore:the first FRF peak")  # at the default point mode 1 is barely seen: noted, expected
def test_the_commands_run_on_an_imported_model_as_the_library(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``fpm-sim rollout``, ``reduce`` and ``impact`` on the imported five-bar at a task pose are the facade's at that
    pose (the same calls: rtol 1e-12); the impact's default point is mid-span of the first flexible body's beam."""
    desc = load_description(FIVE_BAR)
    toml = imported_copy(desc, tmp_path, servo=True)
    imp = load_imported(toml)
    base = ["--config", str(toml), "--segments", "2", "--no-axial", "--x-mm", "4", "--y-mm", "246", "--json"]

    def run(argv: list[str]) -> dict:
        assert main([*argv, *base]) == 0
        out: dict = json.loads(capsys.readouterr().out)
        return out

    out = run(["rollout", "--duration-s", "0.01", "--output-step-s", "2e-4", "--motors", "servo"])
    lib = fs.rollout(imp, POSE, duration_s=0.01, output_step_s=2e-4, options=COARSE, motors="servo")
    assert out["final_disp"]["x_m"] == pytest.approx(float(lib.ee_disp[-1, 0]), rel=1e-12)
    out = run(["reduce", "--modes", "4"])
    rom = fs.reduce(imp, POSE, n_modes=4, options=COARSE)
    np.testing.assert_allclose(out["frequencies_hz"], rom.frequencies_hz, rtol=1e-12)
    out = run(["impact", "--impacts", "1", "--record-s", "0.05"])
    first = LinkPoint("left_proximal_b0_beam", 0.5, "z")  # the default: mid-span of the first flexible body's beam
    hit = fs.impact(imp, POSE, setup=ImpactSetup(first, first, n_impacts=1, record_s=0.05), options=COARSE)
    assert out["first_peak_hz"] == pytest.approx(hit.first_peak_hz, rel=1e-12)


def test_what_an_imported_model_cannot_do_is_refused_by_name(tmp_path: Path) -> None:
    """A rollout records and loads the end effector: a model that names none is refused, naming the description's
    key; servos need motors (a model whose motors are all locked has none); joint values pose only an imported
    model."""
    desc = load_description(FIVE_BAR)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    no_site = load_imported(imported_copy(desc, tmp_path / "a", coordinates=()))
    with pytest.raises(MoveError, match="names no end effector") as e:
        fs.rollout(no_site, duration_s=0.01, options=COARSE)
    assert e.value.parameter == "end_effector"
    locked = load_imported(imported_copy(desc, tmp_path / "b"))
    with pytest.raises(MoveError, match="no motors to drive") as e:
        fs.rollout(locked, motors="servo", duration_s=0.01, options=COARSE)
    assert e.value.parameter == "servo_joints"
    for call in (fs.rollout, fs.reduce, fs.impact):
        with pytest.raises(FpmSimError, match="joint values are for an imported model") as e:
            call(desc, q={"left_motor": 0.0}, options=COARSE)  # type: ignore[operator]
        assert e.value.parameter == "q"


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["rollout", "--config", "{copy}", "--motors", "servo"], "error: servo_joints: five-bar (example spec"),
        (["rollout", "--config", "{copy}", "--force-z-n", "1"], "error: --force-z-n: five-bar (example specification)"),
        (["rollout", "--config", "{copy}", "--accel-fraction", "0.5"], "error: --accel-fraction is for the study's"),
        (["rollout", "--config", "{copy}", "--q", "elbow=0.1"], "no hinge or slide joint 'elbow' in the model"),
        (["rollout", "--config", str(FIVE_BAR), "--q", "left_motor=0.1"], "error: --q: joint values pose an imported"),
        (["impact", "--config", str(FIVE_BAR), "--q", "left_motor=0.1"], "error: --q: joint values pose an imported"),
        (["reduce", "--modes", "2", "--config", "{copy}", "--motors", "servo"], "error: --motors servo: a described"),
    ],
)
def test_the_commands_refuse_what_an_imported_model_lacks_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    """Each in one ``error:`` line naming the option (or the description's key), nothing written; the copy's motors
    are all locked (``locked_joints``), so it has none to servo."""
    copy = str(imported_copy(load_description(FIVE_BAR), tmp_path))
    out = {"rollout": "--out", "impact": "--csv", "reduce": "--out"}[argv[0]]
    suffix = ".npz" if argv[0] == "reduce" else ".csv"
    argv = [copy if a == "{copy}" else a for a in argv] + ["--segments", "2", out, str(tmp_path / f"r{suffix}")]
    assert main(argv) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip() and "coarse resolution" not in line]
    assert len(err) == 1, err
    assert err[0].startswith("error: "), err
    assert words in err[0], err
    assert not (tmp_path / f"r{suffix}").exists()
