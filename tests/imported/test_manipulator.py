"""dm_control's planar manipulator (suite/manipulator.xml) imported with its three arm links flexible and the hand
rigid: its first bending modes against Euler-Bernoulli (issue 29)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from fpm_sim.architecture.imported import load_imported
from fpm_sim.linear.analysis import analyse
from fpm_sim.model.imported import build_imported
from fpm_sim.model.options import ModelOptions
from tests.imported.test_import import _cli

pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")
LOCK = "thumb,thumbtip,finger,fingertip,ball_x,ball_z,ball_y,peg_x,peg_z,peg_y"  # the hand and the props
OUTER, INNER, LENGTH = 0.030, 0.026, 0.18 + 0.15 + 0.12  # tube:30x2mm; the three links end to end at q = 0


def _model() -> Path:
    dm_control = pytest.importorskip("dm_control")
    return Path(os.path.dirname(dm_control.__file__)) / "suite" / "manipulator.xml"


def cantilever_with_tip_body(ei: float, rho_a: float, length: float, m: float, s: float, j: float) -> list[float]:
    """The first three frequencies (Hz) of a clamped Euler-Bernoulli beam carrying a rigid body at its free end: mass
    ``m``, static moment ``s`` and rotary inertia ``j`` about the end (the natural conditions of the energy:
    EI w''' = -w^2 (m w + s w'), EI w'' = w^2 (s w + j w')). With ``s = j = 0`` and ``m`` the beam's mass it gives
    Blevins' beta L = 1.24792 (checked below)."""

    def det(beta: float) -> float:
        w2, x = ei * beta**4 / rho_a, beta * length
        ch, c, sh, sn = math.cosh(x), math.cos(x), math.sinh(x), math.sin(x)
        w = np.array([ch - c, sh - sn])
        w1 = beta * np.array([sh + sn, ch - c])
        w2d = beta**2 * np.array([ch + c, sh + sn])
        w3 = beta**3 * np.array([sh - sn, ch + c])
        r1, r2 = ei * w3 + w2 * (m * w + s * w1), ei * w2d - w2 * (s * w + j * w1)
        return float(r1[0] * r2[1] - r1[1] * r2[0]) / math.cosh(x) ** 2

    grid = np.linspace(0.05, 30.0, 6000) / length
    vals = [det(b) for b in grid]
    roots = [brentq(det, a, b, xtol=1e-14) for a, b, fa, fb in zip(grid, grid[1:], vals, vals[1:]) if fa * fb < 0]
    return [b**2 * math.sqrt(ei / rho_a) / (2 * math.pi) for b in roots[:3]]


def _hand(model_path: Path) -> tuple[float, float, float, float]:
    """The hand's subtree (hand, fingers, pinch site) as MuJoCo gives it: mass, static moment along the arm about the
    wrist, and rotary inertia about the wrist around y (in-plane bending) and x (out of plane)."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(model_path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    hand = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "hand")
    wrist = d.xanchor[m.body_jntadr[hand]].copy()
    mass, moment, inertia = 0.0, np.zeros(3), np.zeros((3, 3))
    for b in range(1, m.nbody):
        a = b
        while a > 0 and a != hand:
            a = int(m.body_parentid[a])
        if a != hand:
            continue
        r, rot = d.xipos[b] - wrist, d.ximat[b].reshape(3, 3)
        inertia += rot @ np.diag(m.body_inertia[b]) @ rot.T + m.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
        mass, moment = mass + m.body_mass[b], moment + m.body_mass[b] * r
    return mass, float(moment[2]), float(inertia[1, 1]), float(inertia[0, 0])


def test_tip_body_frequency_equation_meets_blevins() -> None:
    f = cantilever_with_tip_body(1.0, 1.0, 1.0, 1.0, 0.0, 0.0)[0]
    assert math.sqrt(2 * math.pi * f) == pytest.approx(1.24792, abs=1e-5)


def test_manipulator_arm_is_a_cantilever_carrying_its_hand(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """At q = 0 the arm stands straight up, every joint locked (the four actuated ones, and the hand's and props'
    by --lock): a 450 mm aluminium tube clamped at its root carrying the rigid hand. Without gravity (its axial load
    is 2e-4 of the tube's buckling load) the first two bending pairs are the Euler-Bernoulli cantilever's with the
    hand as a tip body, in plane (about y) and out of it (about x; the hand's inertias differ, so do the pair's).
    Tolerance: 6 segments per link (18 springs over the cantilever) put a chain above the beam by a few 1e-4 on the
    first pair and 1e-3 on the second (the resolution policy's 12-segment link: +0.16 / +0.56 %, scaled by the
    square of the spring spacing); bounds 0.1 % and 0.4 %, from above (measured +0.06 % and +0.25 %); 12 segments
    per link are closer on every mode (convergence from above)."""
    out = tmp_path / "manipulator.toml"
    argv = ["import", str(_model()), "--flexible", "upper_arm,middle_arm,lower_arm", "--section", "tube:30x2mm"]
    code, text = _cli([*argv, "--material", "aluminium", "--lock", LOCK, "--out", str(out)], capsys)
    assert code == 0, text
    assert "dropped with the locked joints: tendon grasp, tendon coupling, actuator grasp, equality coupling" in text
    desc = load_imported(out)
    ei = 70e9 * math.pi / 64 * (OUTER**4 - INNER**4)
    rho_a = 2700.0 * math.pi / 4 * (OUTER**2 - INNER**2)
    mass, moment, j_y, j_x = _hand(_model())
    in_plane = cantilever_with_tip_body(ei, rho_a, LENGTH, mass, moment, j_y)
    out_of_plane = cantilever_with_tip_body(ei, rho_a, LENGTH, mass, moment, j_x)
    errors = []
    for segments in (6, 12):
        result = analyse(build_imported(desc, {}, ModelOptions(segments=segments, gravity=False)), "transition_fd", 4)
        hz = np.asarray(result.frequencies_hz)
        assert [m.dominant for m in result.modes] == ["bend_in", "bend_out", "bend_in", "bend_out"]
        errors.append(hz / np.array([in_plane[0], out_of_plane[0], in_plane[1], out_of_plane[1]]) - 1.0)
    assert np.all(errors[0] > 0.0), errors[0]
    assert np.all(errors[0] < [1e-3, 1e-3, 4e-3, 4e-3]), errors[0]
    assert np.all((errors[1] > 0.0) & (errors[1] < errors[0])), errors


def test_a_pose_outside_a_joints_stated_range_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The model's joint ranges are kept (issue 29, item 2): the shoulder's is -160..160 deg, so 3.5 rad (200.5
    deg) is not a pose of this arm. ``modes --q`` and ``sweep --poses`` refuse it in one line naming the joint, its
    value and range; 2.7 rad (154.7 deg), inside, runs."""
    out = tmp_path / "manipulator.toml"
    argv = ["import", str(_model()), "--flexible", "upper_arm,middle_arm,lower_arm", "--section", "tube:30x2mm"]
    assert _cli([*argv, "--material", "aluminium", "--lock", LOCK, "--out", str(out)], capsys)[0] == 0
    cfg = ["--config", str(out)]
    code, text = _cli(["modes", *cfg, "--q", "arm_shoulder=3.5", "--n-modes", "2"], capsys)
    assert code == 2, text
    assert text.count("\n") == 1, text
    assert "joint 'arm_shoulder' = 3.5 rad is outside its range [-2.79253, 2.79253] rad (-160 to 160 deg)" in text
    assert _cli(["modes", *cfg, "--q", "arm_shoulder=2.7", "--n-modes", "2"], capsys)[0] == 0
    poses = tmp_path / "q.csv"
    poses.write_text("arm_shoulder\n0.5\n3.5\n")
    code, text = _cli(["sweep", *cfg, "--poses", str(poses), "--out", str(tmp_path / "sw")], capsys)
    assert code == 2, text
    assert "pose 2: joint 'arm_shoulder' = 3.5 rad is outside its range" in text, text
    assert not (tmp_path / "sw").exists()
