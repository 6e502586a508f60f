"""``fpm-sim check`` on an imported model: requirements over joint-space pose sets (issue 29)."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.errors import FpmSimError
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.requirements import check_requirements, parse_requirements
from tests.imported.test_import import _acrobot_toml, _cli

pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")
POSES = [{"shoulder": 0.0, "elbow": 0.0}, {"shoulder": 0.3, "elbow": -1.1}]
# Bounds fixed from the clamped 2 m tube (docs/import.md: f1 24.0 Hz straight, 26.4 Hz bent; f3 150 Hz straight,
# 98 Hz bent), not from the values under test: f1 >= 20 Hz holds, f3 >= 120 Hz fails at the bent pose, and
# 60..90 Hz holds no mode 1..4 at either pose.
REQUIREMENTS = """
[settings]
segments = 2

[[requirement]]
name = "f1 above 20 Hz"
kind = "min_frequency"
at_least_hz = 20.0
poses = { joints = [{ shoulder = 0.0, elbow = 0.0 }, { shoulder = 0.3, elbow = -1.1 }] }

[[requirement]]
name = "f3 above 120 Hz"
kind = "min_frequency"
mode = 3
at_least_hz = 120.0
poses = { joints_file = "q.csv" }

[[requirement]]
name = "clear of 60..90 Hz"
kind = "band_exclusion"
band_hz = [60.0, 90.0]
n_modes = 4
poses = { joints_file = "q.csv" }
"""


def _files(tmp_path: Path, body: str = REQUIREMENTS) -> tuple[Path, Path]:
    toml = _acrobot_toml(tmp_path)
    (tmp_path / "q.csv").write_text("shoulder,elbow\n0,0\n0.3,-1.1\n")
    req = tmp_path / "fpm-requirements.toml"
    req.write_text(body)
    return toml, req


def test_check_on_joint_poses_is_modes_there(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The worst value of each requirement is ``fs.modes``' frequency at those joint values under the sweep's policy
    (gravity off, inextensible links, 2 segments) by the exact constrained eigen-solve: the check's one compiled
    model posed at each pose against a model built at each (the same eigenproblem assembled two ways: rtol 1e-9); the
    margins are those values' distances to the bounds; exit 1 because one requirement fails; the two pose sets (a
    list and a file of the same values) share one sweep."""
    toml, req = _files(tmp_path)
    code, text = _cli(["check", str(req), "--config", str(toml), "--json"], capsys)
    assert code == 1, text
    out = {r["name"]: r for r in json.loads(text)["requirements"]}
    assert json.loads(text)["sweeps"] == 1
    opts = ModelOptions(segments=2, gravity=False, axial=False)
    each = fs.modes(fs.load_imported(toml), q=POSES, options=opts, n_modes=4, method="constrained")
    f = np.array([m.frequencies_hz[:4] for m in each])
    one, three, band = out["f1 above 20 Hz"], out["f3 above 120 Hz"], out["clear of 60..90 Hz"]
    assert one["passed"]
    assert not three["passed"]
    assert band["passed"]
    np.testing.assert_allclose(one["worst_value_hz"], f[:, 0].min(), rtol=1e-9)
    np.testing.assert_allclose(one["margin_hz"], f[:, 0].min() - 20.0, rtol=1e-9)
    np.testing.assert_allclose(three["worst_value_hz"], f[:, 2].min(), rtol=1e-9)
    assert three["worst_pose"] == POSES[int(np.argmin(f[:, 2]))] == POSES[1]
    assert three["n_failing"] == 1
    gaps = np.maximum(60.0 - f, f - 90.0)  # how far each mode is outside the band (the band's margin)
    np.testing.assert_allclose(band["margin_hz"], gaps.min(), rtol=1e-9)


@pytest.mark.parametrize(
    ("poses", "words"),
    [
        ('{ grid = "dense", step_mm = 20 }', "requirement 'r'.poses: reachable workspace, 20 mm grid"),
        ("{ list = [[0, 0, 0.0]] }", "1 listed poses is a task-space pose set and 'acrobot' is an imported model"),
        ("{ joints = [{ knee = 0.1 }] }", "no hinge or slide joint 'knee' in acrobot.xml"),
        ('{ joints_file = "missing.csv" }', "missing.csv: no such file"),
        ("{ joints = [{ elbow = 0.1 }], list = [[0, 0, 0]] }", "needs exactly one of grid, file, list, cylinder"),
    ],
)
def test_pose_sets_on_an_imported_model_are_joint_space(tmp_path: Path, poses: str, words: str) -> None:
    body = f'[[requirement]]\nname = "r"\nkind = "min_frequency"\nat_least_hz = 1.0\nposes = {poses}\n'
    toml, req = _files(tmp_path, body)
    with pytest.raises(FpmSimError, match=re.escape(words)):
        check_requirements(parse_requirements(tomllib.loads(req.read_text()), req), fs.load_imported(toml))


def test_joint_space_poses_on_a_described_machine_and_payload_are_refused(tmp_path: Path) -> None:
    """A joint-space pose set names an imported model's joints: on a described architecture it is refused naming the
    requirement; so is a payload range on an imported model (its payload is a body of its file)."""
    five_bar = fs.load_description(Path(__file__).parents[2] / "examples" / "architectures" / "five_bar.toml")
    body = '[[requirement]]\nname = "r"\nkind = "min_frequency"\nat_least_hz = 1.0\n'
    body += "poses = { joints = [{ a = 0.1 }] }\n"
    reqs = parse_requirements(tomllib.loads(body), tmp_path / "r.toml")
    with pytest.raises(
        FpmSimError, match=r"requirement 'r'\.poses: 1 listed joint-space poses are an imported model's"
    ):
        check_requirements(reqs, five_bar)
    toml, _ = _files(tmp_path)
    body = body.replace("{ a = 0.1 }", "{ elbow = 0.1 }") + "payload_kg = 0.5\n"
    reqs = parse_requirements(tomllib.loads(body), tmp_path / "r.toml")
    with pytest.raises(FpmSimError, match="an imported model carries its payload as bodies of its MuJoCo file"):
        check_requirements(reqs, fs.load_imported(toml))
