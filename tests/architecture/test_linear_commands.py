"""Reduced models, FRFs, the virtual impact test and the modal atlas on described architectures, against
independent truths: the constrained eigen-solve and transitionFD (``fs.modes``), the driving point's symmetry, the
modal f1 seen by the hammer, and the 3RRR's own path when the description is ``three_rrr.toml``."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import TaskPose, load_description
from fpm_sim.cli.main import main
from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.response import pick_peaks
from fpm_sim.rom.atlas import load_atlas

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = EXAMPLES / "five_bar.toml"
POSE = TaskPose.from_mm(x_mm=0.0, y_mm=250.0)
COARSE = fs.ModelOptions(segments=4, gravity=False)
"""4 segments per link: the reduced model, the FRF and the impact test all act on the model as built, whatever its
resolution, so a coarse model tests them as well as a fine one (and keeps each test to a second or two)."""


@pytest.fixture(scope="module")
def five_bar():
    return load_description(FIVE_BAR)


def _quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the coarse-resolution warning
        return fn(*args, **kwargs)


def test_reduce_on_the_five_bar_has_the_modes_poles(five_bar):
    """The reduced model's poles are the modes' frequencies at the same pose: to 1e-9 against the constrained
    eigen-solve (the same eigenproblem, assembled into A: round-off), and to 1e-3 against transitionFD (an
    independent linearisation of MuJoCo's step map, whose soft loop-closing welds and step shift the modes that
    stretch the loop: measured 4e-4 at the third mode, 1e-6 at the others)."""
    rom = _quiet(fs.reduce, five_bar, POSE, n_modes=5, options=COARSE)
    poles = rom.eigenvalues()
    # the five-bar's description has no damping: the poles lie on the imaginary axis
    np.testing.assert_allclose(poles.real, 0.0, atol=1e-9)
    constrained = _quiet(fs.modes, five_bar, POSE, options=COARSE, n_modes=5, method="constrained")
    np.testing.assert_allclose(poles.imag / (2 * math.pi), constrained.frequencies_hz, rtol=1e-9)
    fd = _quiet(fs.modes, five_bar, POSE, options=COARSE, n_modes=5, method="transition_fd")
    np.testing.assert_allclose(poles.imag / (2 * math.pi), fd.frequencies_hz, rtol=1e-3)
    # the default instrumentation: a planar wrench on the end effector, an accelerometer on each chain's last
    # flexible link (the rule of fpm_sim.model.general)
    assert rom.input_names == ["force_x", "force_y", "moment_z"]
    assert rom.output_names == ["disp_x", "disp_y", "rot_z", "acc_left_distal", "acc_right_distal"]
    assert isinstance(rom.pose, TaskPose)
    # the static gain of the displacement outputs is symmetric (Maxwell-Betti: C_q = B_q' for the wrench), which a
    # wrong Jacobian row or a wrong site would break
    gain = rom.static_gain()[:3, :3]
    np.testing.assert_allclose(gain, gain.T, rtol=1e-8, atol=1e-12 * np.abs(gain).max())


def test_reduce_on_a_spatial_machine_has_the_six_wrench_components():
    delta = load_description(EXAMPLES / "delta.toml")
    rom = _quiet(fs.reduce, delta, None, n_modes=2, options=fs.ModelOptions(segments=2, gravity=False))
    assert rom.input_names == ["force_x", "force_y", "force_z", "moment_x", "moment_y", "moment_z"]
    assert rom.output_names[:6] == ["disp_x", "disp_y", "disp_z", "rot_x", "rot_y", "rot_z"]
    gain = rom.static_gain()[:6, :6]
    np.testing.assert_allclose(gain, gain.T, rtol=1e-7, atol=1e-9 * np.abs(gain).max())


def test_frf_on_the_five_bar_peaks_at_the_modes_with_positive_driving_point_residues(five_bar):
    """The default excitation (mid-span of the first chain's last flexible link, out of the plane) as a driving
    point: every residue ``(phi' b)^2`` is >= 0, and each mode it excites (a residue above 1 % of the largest) is a
    peak of the accelerance within one frequency step (0.1 Hz: the peak picking's parabola on a grid that holds the
    natural frequency; a 0.1 % damping ratio keeps each peak narrow, 2 zeta f < 0.8 Hz, so that the neighbours'
    skirts do not move it; measured 0.006-0.009 Hz)."""
    frf = _quiet(fs.frf, five_bar, POSE, options=COARSE, f_max_hz=400.0, df_hz=0.1, damping_ratio=1e-3)
    assert frf.excitation == frf.response == "left_distal@0.5/z"
    assert np.all(frf.residues >= -1e-12 * np.abs(frf.residues).max())
    f_modes = frf.modal_freq_hz
    excited = f_modes[(frf.residues > 0.01 * frf.residues.max()) & (f_modes < 395.0)]
    assert len(excited) >= 4
    peaks = [p.freq_hz for p in pick_peaks(frf.freq_hz, np.abs(frf.h))]
    for f in excited:
        assert min(abs(p - f) for p in peaks) < 0.1, (f, peaks)
    # an in-plane excitation excites the modes the out-of-plane one leaves out (planar: the two decouple)
    normal = fs.LinkPoint("left_distal", 0.5, "normal")
    in_plane = _quiet(fs.frf, five_bar, POSE, options=COARSE, excitation=normal, damping_ratio=0.01)
    assert np.all(in_plane.residues >= -1e-12 * np.abs(in_plane.residues).max())
    both = (in_plane.residues > 1e-6 * in_plane.residues.max()) & (frf.residues > 1e-6 * frf.residues.max())
    assert not np.any(both)


def test_impact_on_the_five_bar_recovers_f1(five_bar):
    """The virtual hammer test at its defaults (the machine's test point, 3 impacts, 0.5 s records) finds the modal
    f1 within the method's stated 0.5 % (tests/sim/test_impact.py: FFT lines, the accelerance peak's shift, the
    integrator's period error)."""
    res = _quiet(fs.impact, five_bar, POSE, options=fs.ModelOptions(segments=4, gravity=False, axial=False))
    assert res.setup.impact == fs.LinkPoint("left_distal", 0.5, "z")
    assert res.first_peak_mode == 1
    assert abs(res.relative_error) < 0.005


def test_the_3rrr_through_the_general_path_reduces_and_responds_as_its_own_path():
    """three_rrr.toml through the general builder against the 3RRR's own builder at one pose: the reduced model's
    frequencies and damping to 1e-8 (as tests/architecture/test_modes.py: the inverse kinematics' and the
    finite-difference stiffness' round-off), its frequency response (every input to every output, the
    accelerometers' included: a basis-free comparison) and the default driving-point FRF to 1e-6 (the 1e-8 on the
    poles, amplified near a resonance by 1 / (2 zeta) ~ 50)."""
    cfg, desc = default_config(), load_description(EXAMPLES / "three_rrr.toml")
    native_pose, task_pose = Pose.from_mm(50.0, -50.0, 0.1), TaskPose.from_mm(50.0, -50.0, 0.0, 0.1)
    # accelerometers at 0.3 of the distal links: the nearest segment site is clear there (at 0.5, with an even
    # number of segments, two sites are equally near and round-off picks one: a tie, not a difference)
    a = _quiet(fs.reduce, cfg, native_pose, n_modes=6, options=COARSE, accel_fraction=0.3)
    b = _quiet(fs.reduce, desc, task_pose, n_modes=6, options=COARSE, accel_fraction=0.3)
    np.testing.assert_allclose(b.frequencies_hz, a.frequencies_hz, rtol=1e-8)
    np.testing.assert_allclose(b.damping_ratios, a.damping_ratios, rtol=1e-8)
    assert b.output_names == ["disp_x", "disp_y", "rot_z", "acc_0_distal", "acc_1_distal", "acc_2_distal"]
    freq = np.array([5.0, 0.5 * (a.frequencies_hz[0] + a.frequencies_hz[1]), 1.3 * a.frequencies_hz[5]])
    ha, hb = a.frequency_response(freq), b.frequency_response(freq)
    for k in range(len(freq)):
        scale = np.abs(ha[k]).max(axis=1, keepdims=True)  # per output: its own unit
        np.testing.assert_allclose(np.abs(hb[k] - ha[k]) / scale, 0.0, atol=1e-6)
    fa = _quiet(fs.frf, cfg, native_pose, options=COARSE, f_max_hz=300.0, df_hz=0.5)
    fb = _quiet(fs.frf, desc, task_pose, options=COARSE, f_max_hz=300.0, df_hz=0.5)
    assert (fa.excitation, fb.excitation) == ("distal_0@0.5/z", "0_distal@0.5/z")
    np.testing.assert_allclose(fb.freq_hz, fa.freq_hz, rtol=1e-8)
    np.testing.assert_allclose(np.abs(fb.h - fa.h), 0.0, atol=1e-6 * np.abs(fa.h).max())


def test_atlas_on_the_five_bar_interpolates_the_direct_modes(five_bar, tmp_path):
    """A 3 x 3 atlas in the five-bar's task coordinates (x, y), queried between its nodes, against a direct
    reduction there: within its own error estimate (a leave-one-out bound, fpm_sim.rom.atlas)."""
    opts = fs.ModelOptions(segments=3, gravity=False, axial=False)
    atlas = _quiet(fs.atlas, five_bar, x_m=[-0.02, 0.0, 0.02], y_m=[0.23, 0.25, 0.27], n_modes=3, options=opts)
    assert all(isinstance(p, TaskPose) for p in atlas.poses())
    query = TaskPose.from_mm(x_mm=10.0, y_mm=255.0)
    rom = _quiet(atlas.query, query)
    direct = _quiet(fs.reduce, five_bar, query, n_modes=3, options=opts)
    estimate = rom.parameters["atlas_query"]["error_estimate"]
    assert np.max(np.abs(rom.frequencies_hz / direct.frequencies_hz - 1.0)) < max(estimate, 1e-3)
    back = load_atlas(atlas.save(tmp_path / "a.npz"))  # the task poses survive the file
    assert back.poses() == atlas.poses()
    np.testing.assert_allclose(_quiet(back.query, query).a, rom.a)
    with pytest.raises(fs.FpmSimError, match="no task coordinate phi"):
        _quiet(fs.atlas, five_bar, x_m=[0.0], y_m=[0.25], phi_rad=[0.0, 0.1], options=opts)
    with pytest.raises(fs.FpmSimError, match=r"queried at a fs\.TaskPose"):
        atlas.query(Pose(0.0, 0.25, 0.0))


# --------------------------------------------------------------------------------------------- the command line


def _cli(capsys, argv):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


FAST = ["--segments", "3"]


@pytest.mark.parametrize(
    ("argv", "key"),
    [
        (["reduce", "--modes", "3", "--no-gravity"], "frequencies_hz"),
        (["frf", "--f-max-hz", "100", "--df-hz", "1", "--damping-ratio", "0.02"], "peaks"),
        (["impact", "--impacts", "1", "--record-s", "0.1", "--no-gravity"], "first_peak_hz"),
    ],
    ids=["reduce", "frf", "impact"],
)
def test_each_command_runs_on_the_five_bar_with_json(capsys, argv, key):
    code, out, err = _cli(capsys, [*argv, "--config", str(FIVE_BAR), "--x-mm", "10", "--y-mm", "240", *FAST, "--json"])
    assert code == 0, err
    payload = json.loads(out)
    assert key in payload


def test_atlas_build_and_query_run_on_the_five_bar_with_json(capsys, tmp_path):
    out_file = tmp_path / "five_bar_atlas.npz"
    argv = ["atlas", "build", "--config", str(FIVE_BAR), "--modes", "3", "--extra", "2", *FAST, "--json"]
    code, out, err = _cli(capsys, [*argv, "--out", str(out_file)])
    assert code == 0, err
    built = json.loads(out)
    assert built["x_mm"] == pytest.approx([-20.0, 0.0, 20.0])  # the first check pose +-20 mm
    assert built["y_mm"] == pytest.approx([230.0, 250.0, 270.0])
    code, out, err = _cli(
        capsys,
        ["atlas", "query", str(out_file), "--x-mm", "5", "--direct", "--config", str(FIVE_BAR), "--json"],
    )
    assert code == 0, err
    payload = json.loads(out)
    assert payload["pose"]["x_m"] == pytest.approx(0.005)
    assert payload["pose"]["y_m"] == pytest.approx(0.25)  # not given: the atlas's central node
    assert max(abs(r) for r in payload["relative_difference"]) < 0.01


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["reduce", "--modes", "3", "--config", str(FIVE_BAR), "--phi-rad", "0.1"], "error: --phi-rad: five-bar"),
        (["frf", "--config", str(FIVE_BAR), "--input-link", "distal_0"], "error: unknown link 'distal_0'"),
        (["impact", "--config", str(FIVE_BAR), "--accel-link", "nowhere"], "error: unknown link 'nowhere'"),
        (
            ["reduce", "--modes", "3", "--config", str(FIVE_BAR), "--motors", "servo"],
            "error: --motors servo: a described architecture",
        ),
        (
            ["atlas", "build", "--config", str(FIVE_BAR), "--phi-rad", "0", "0.1", "--out", "{tmp}/a.npz"],
            "error: --phi-rad: five-bar (example specification) has no task coordinate phi",
        ),
        (
            ["atlas", "build", "--config", str(FIVE_BAR), "--z-mm", "-300", "--out", "{tmp}/a.npz"],
            "error: --z-mm: five-bar (example specification) has no task coordinate z",
        ),
        (["atlas", "build", "--z-mm", "10", "--out", "{tmp}/a.npz"], "error: --z-mm: the 3RRR's task coordinates"),
        (
            ["impact", "--config", str(EXAMPLES / "delta.toml"), "--uff", "{tmp}/h.uff"],
            "error: --uff: the UFF record carries a pose in x, y and phi",
        ),
    ],
    ids=["phi-on-five-bar", "3rrr-link", "unknown-link", "servo", "atlas-phi", "atlas-z", "atlas-z-3rrr", "uff-z"],
)
def test_what_an_architecture_lacks_is_one_error_line(capsys, tmp_path, argv, message):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, _, err = _cli(capsys, [*argv, *FAST])
    lines = [line for line in err.strip().splitlines() if not line.startswith("warning:")]
    assert code == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith(message), lines[0]
    assert not list(tmp_path.iterdir())
