"""Bad models and descriptions: one ``error:`` line naming the body, joint, equality or file, exit 2, nothing written
(issue 29). A missing mesh is dropped with a warning when its body states its inertia (the import needs only the
inertias: fpm-sim has no contacts and draws no meshes), refused when the body takes its mass from it."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.imported.test_import import MATERIALS, _cli

ARM = (
    '<mujoco><worldbody><body name="upper"><joint name="shoulder" axis="0 1 0"/>'
    '<geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.01"/>'
    '<body name="fore" pos="0.4 0 0"><joint name="elbow" axis="0 1 0"/>'
    '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.01"/>{site}</body></body>{loop}</worldbody>{eq}</mujoco>'
)
LOOP_EQ = '<equality><connect name="tip_pin" body1="fore" anchor="0.3 0 0"/></equality>'
URDF = """<robot name="arm">
  <link name="base"/>
  <link name="arm">{inertial}
    <collision><geometry><mesh filename="meshes/arm.stl"/></geometry></collision>
  </link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""
INERTIAL = (
    '<inertial><origin xyz="0.25 0 0"/><mass value="2"/>'
    '<inertia ixx="0.001" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial>'
)


def _toml(tmp_path: Path, model: str, flexible: str, top: str = "") -> Path:
    p = tmp_path / "machine.toml"
    p.write_text(
        f'kind = "imported"\nmodel = "{model}"\n{top}{MATERIALS}\n[sections.bar]\nshape = "rect"\nthickness_m = 0.006\n'
        f"height_m = 0.025\n{flexible}"
    )
    return p


def _flex(body: str, extra: str = "") -> str:
    return f'[[flexible]]\nbody = "{body}"\nsection = "bar"\nmaterial = "aluminium"\n{extra}'


CASES = [
    ("arm", _flex("forearm"), [], "flexible[0].body: no body 'forearm' in arm.xml"),
    ("arm", _flex("fore"), [], "body 'fore' has no child body with a joint"),
    ("arm", _flex("upper", "end_m = [0, 0, 0]\n"), [], "body 'upper': the beam from"),
    ("urdf", _flex("arm", "end_m = [0.5, 0, 0]\n"), [], "mesh 'arm' of body 'arm': file not found"),
    ("loop", _flex("upper"), ["--q", "shoulder=0.3"], "the loop closure tip_pin does not close at shoulder = 0.3"),
]


@pytest.mark.parametrize(("model", "flexible", "extra", "words"), CASES, ids=[c[3][:30] for c in CASES])
def test_bad_model_one_line_exit_2_nothing_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], model: str, flexible: str, extra: list[str], words: str
) -> None:
    if model == "urdf":
        (tmp_path / "arm.urdf").write_text(URDF.format(inertial=""))
        name = "arm.urdf"
    else:
        site = "" if model == "arm" and "fore" in flexible else '<site name="tip" pos="0.3 0 0"/>'
        eq = LOOP_EQ if model == "loop" else ""
        (tmp_path / "arm.xml").write_text(ARM.format(site="" if model == "arm" else site, loop="", eq=eq))
        name = "arm.xml"
    toml = _toml(tmp_path, name, flexible)
    before = sorted(p.name for p in tmp_path.iterdir())
    argv = ["modes", "--config", str(toml), "--n-modes", "2", "--segments", "2", *extra]
    code, text = _cli([*argv, "--plot", str(tmp_path / "modes.png")], capsys)
    assert code == 2, text
    lines = [line for line in text.strip().splitlines() if not line.startswith("warning:")]
    assert len(lines) == 1, text
    assert lines[0].startswith("error: "), text
    assert words in lines[0], text
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written


def test_closed_loop_at_its_own_pose_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The loop model at its reference pose, and at values that keep the loop closed (the whole closed chain turned
    rigidly is not a pose of it: turning the shoulder alone opens it), runs."""
    (tmp_path / "arm.xml").write_text(ARM.format(site="", loop="", eq=LOOP_EQ))
    toml = _toml(tmp_path, "arm.xml", _flex("upper"))
    code, text = _cli(["modes", "--config", str(toml), "--n-modes", "2", "--segments", "2"], capsys)
    assert code == 0, text


def test_missing_mesh_on_a_body_with_its_inertial_is_dropped_with_a_warning(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The body states its mass and inertia: the mesh carries nothing the modes need; the warning names it."""
    (tmp_path / "arm.urdf").write_text(URDF.format(inertial=INERTIAL))
    toml = _toml(tmp_path, "arm.urdf", _flex("arm", "end_m = [0.5, 0, 0]\n"), 'locked_joints = ["j"]\n')
    code, text = _cli(["modes", "--config", str(toml), "--n-modes", "2", "--segments", "2"], capsys)
    assert code == 0, text
    assert "warning: mesh 'arm'" in text, text
    assert "meshes/arm.stl) not found" in text, text
