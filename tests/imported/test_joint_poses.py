"""Imported models posed in joint space: CSV poses, ``modes --poses``, ``sweep``, ``frf``, ``export-mjcf``, and every
other command, or option, that has no meaning on one refused in one line (issue 29); what ``design`` and ``atlas`` need
of an imported model refused in one line too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.batch.joint_sweep import JointSweep, read_joint_poses_csv
from fpm_sim.errors import FpmSimError
from fpm_sim.model.options import ModelOptions
from tests.imported.test_import import _acrobot_toml, _cli

pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")
SEG = 2  # two segments per link: the poses' equalities below hold at any resolution


def _json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    import json

    from fpm_sim.cli.main import main

    code = main(argv)
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    result: dict = json.loads(out.out)
    return result


def _csv(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "joints.csv"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("shoulder,knee\n0,0\n", "column(s) knee name no hinge or slide joint of acrobot.xml"),
        ("shoulder,elbow\n0,0\n0.1,\n", "row 3: joint column elbow is missing"),
        ("shoulder,elbow\n0,abc\n", "row 2: joint column elbow is missing or not a finite number"),
        ("shoulder,elbow\n", "no rows after the header"),
    ],
)
def test_joint_poses_csv_names_the_column_and_row(tmp_path: Path, text: str, words: str) -> None:
    desc = fs.load_imported(_acrobot_toml(tmp_path))
    with pytest.raises(FpmSimError, match=re_escape(words)) as info:
        read_joint_poses_csv(_csv(tmp_path, text), desc)
    assert info.value.parameter == "poses"


def re_escape(words: str) -> str:
    import re

    return re.escape(words)


def test_joint_poses_csv_reads_radians(tmp_path: Path) -> None:
    desc = fs.load_imported(_acrobot_toml(tmp_path))
    poses = read_joint_poses_csv(_csv(tmp_path, "elbow, shoulder\n-1.1,0.3\n0,0\n"), desc)
    assert poses == [{"elbow": -1.1, "shoulder": 0.3}, {"elbow": 0.0, "shoulder": 0.0}]


def test_sweep_over_joint_poses_is_each_poses_modes(tmp_path: Path) -> None:
    """``fs.sweep`` over joint poses gives, at each, the frequencies ``fs.modes`` gives there under the sweep's
    policy (gravity off, inextensible links) by the exact constrained eigen-solve: the sweep's one compiled model
    posed at each pose (its locked joints locked by constraint rows) against a model built at each pose (the joints
    deleted), the same eigenproblem assembled two ways, so equal to the solve's rounding (rtol 1e-9). Both
    joints locked without gravity, turning the shoulder turns the clamped structure rigidly: the first pose's and
    the second's frequencies agree to the eigen-solve's repeatability (rtol 1e-7, as test_import's symmetry test);
    bending the elbow changes them (the L-shape is stiffer in its plane's first mode than the straight beam)."""
    desc = fs.load_imported(_acrobot_toml(tmp_path))
    poses = [{"shoulder": 0.0, "elbow": 0.0}, {"shoulder": 0.7, "elbow": 0.0}, {"shoulder": 0.3, "elbow": -1.1}]
    opts = ModelOptions(segments=SEG)
    sw = fs.sweep(desc, poses=poses, options=opts)
    assert isinstance(sw, JointSweep)
    assert sw.freq_hz.shape == (3, 3)
    policy = ModelOptions(segments=SEG, gravity=False, axial=False)
    each = fs.modes(desc, q=poses, options=policy, n_modes=3, method="constrained")
    assert isinstance(each, list)
    assert len(each) == 3
    for k, result in enumerate(each):
        np.testing.assert_allclose(sw.freq_hz[k], result.frequencies_hz, rtol=1e-9)
    np.testing.assert_allclose(sw.freq_hz[1], sw.freq_hz[0], rtol=1e-7)
    assert abs(sw.freq_hz[2, 0] / sw.freq_hz[0, 0] - 1.0) > 0.02
    assert [r["pose"] for r in sw.to_dict()["rows"]] == [1, 2, 3]
    assert "shoulder" in sw.table()
    with pytest.raises(FpmSimError, match=r"pose 2: no hinge or slide joint 'knee'"):
        fs.sweep(desc, poses=[{"shoulder": 0.0}, {"knee": 0.1}], options=opts)
    with pytest.raises(TypeError, match="joint-space poses"):
        fs.sweep(desc, options=opts)


def test_modes_and_sweep_commands_take_joint_poses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``modes --poses`` gives, at each row, the numbers of ``modes --q`` at that row's values (same model, same
    solve: rtol 1e-12); ``sweep --poses`` writes its table and figure."""
    toml = str(_acrobot_toml(tmp_path))
    poses = _csv(tmp_path, "shoulder,elbow\n0,0\n0.3,-1.1\n")
    common = ["--segments", "2", "--n-modes", "3", "--json"]
    rows = _json(["modes", "--config", toml, "--poses", str(poses), *common], capsys)["poses"]
    one = [
        m["frequency_hz"]
        for m in _json(["modes", "--config", toml, "--q", "shoulder=0.3", "--q", "elbow=-1.1", *common], capsys)[
            "modes"
        ]
    ]
    np.testing.assert_allclose([m["frequency_hz"] for m in rows[1]["modes"]], one, rtol=1e-12)
    assert rows[1]["q"] == {"shoulder": 0.3, "elbow": -1.1}
    out = tmp_path / "sw"
    code, text = _cli(["sweep", "--config", toml, "--poses", str(poses), "--segments", "2", "--out", str(out)], capsys)
    assert code == 0, text
    assert sorted(p.name for p in out.iterdir()) == ["sweep_poses.csv", "sweep_poses.png"]
    assert (out / "sweep_poses.csv").read_text().splitlines()[0].startswith("pose,shoulder,elbow,f1_hz")


def _one_line(code: int, text: str, words: str) -> None:
    assert code == 2, text
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    assert lines[0].startswith("error: "), text
    assert words in lines[0], text


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["sweep", "--out", "{tmp}/o"], "--poses: an imported model has no task grid"),
        (["sweep", "--poses", "{tmp}/joints.csv", "--grid", "paper", "--out", "{tmp}/o"], "--grid: not an option"),
        (["modes", "--x-mm", "10"], "--x-mm: acrobot names no end effector"),
        (["modes", "--poses", "{tmp}/joints.csv", "--q", "elbow=0"], "--q: one pose's option"),
        (["frf", "--q", "elbow=0.2"], "--damping-ratio: the model has no damping"),
        (["check", "{tmp}/req.toml"], "requirement 'f1'.poses: reachable workspace, 10 mm grid, phi 0 rad is a task-"),
        (["design", "--vary", "sections.tube.outer_diameter_m=0.1", "--out", "{tmp}/o"], "--poses: an imported model"),
        (
            ["design", "--vary", "sections.tube.outer_diameter_m=0.1", "--grid", "dense", "--out", "{tmp}/o"],
            "--grid: an imported model states no reach",
        ),
        (
            ["design", "--vary", "sections.tube.wall_m=0.1", "--poses", "{tmp}/joints.csv", "--out", "{tmp}/o"],
            "field 'sections.tube.wall_m'",
        ),
        (["atlas", "build", "--out", "{tmp}/a.npz"], "--x-mm and --y-mm: an imported model states no reach"),
        (
            ["atlas", "build", "--x-mm", "0", "--y-mm", "0", "--out", "{tmp}/a.npz"],
            "end_effector: acrobot names no end effector with task coordinates x and y",
        ),
        (["move", "--out", "{tmp}/m.csv"], "end_effector: acrobot names no end effector: a move commands"),
        (["rollout", "--out", "{tmp}/r.csv"], "end_effector: acrobot names no end effector: a move commands"),
        (["reduce", "--modes", "3", "--motors", "servo"], "--motors servo: a described architecture's actuated"),
        (["impact", "--uff", "{tmp}/i.uff"], "--uff: the UFF record carries a task pose in x, y and phi, and an"),
        (["reproduce", "--out", "{tmp}/o"], "'reproduce' does not run on it"),
    ],
)
def test_commands_on_an_imported_model_run_or_refuse_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    toml = _acrobot_toml(tmp_path)
    _csv(tmp_path, "shoulder,elbow\n0,0\n")
    (tmp_path / "req.toml").write_text('[[requirement]]\nname = "f1"\nkind = "min_frequency"\nat_least_hz = 10.0\n')
    before = sorted(p.name for p in tmp_path.iterdir())
    code, text = _cli([*(a.replace("{tmp}", str(tmp_path)) for a in argv), "--config", str(toml)], capsys)
    _one_line(code, text, words)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written


def test_frf_and_export_mjcf_at_joint_values(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``frf --q`` peaks at ``modes --q``'s frequencies (the peak picker's grid step, 0.05 Hz, bounds the match);
    ``export-mjcf --q`` writes the posed flexible model, which MuJoCo reads back to the same degrees of freedom."""
    import mujoco

    from fpm_sim.model.imported import build_imported

    toml = str(_acrobot_toml(tmp_path))
    q = ["--q", "shoulder=0.3", "--q", "elbow=-1.1", "--segments", "2"]
    f = [m["frequency_hz"] for m in _json(["modes", "--config", toml, *q, "--n-modes", "2", "--json"], capsys)["modes"]]
    argv = ["frf", "--config", toml, *q, "--damping-ratio", "0.01", "--input-link", "lower_arm_beam"]
    argv += ["--input-axis", "y", "--f-min-hz", "5", "--f-max-hz", "60", "--df-hz", "0.05", "--json"]
    peaks = [p["freq_hz"] for p in _json(argv, capsys)["peaks"]]
    assert min(abs(p - f[0]) for p in peaks) < 0.05 or min(abs(p - f[1]) for p in peaks) < 0.05, (peaks, f)
    out = tmp_path / "posed.xml"
    code, text = _cli(["export-mjcf", "manipulator", "--config", toml, *q, "--out", str(out)], capsys)
    assert code == 0, text
    built = build_imported(fs.load_imported(toml), {"shoulder": 0.3, "elbow": -1.1}, ModelOptions(segments=2))
    back = mujoco.MjModel.from_xml_path(str(out))
    assert back.nv == built.model.nv
    np.testing.assert_allclose(back.body_mass, built.model.body_mass, rtol=1e-12)
