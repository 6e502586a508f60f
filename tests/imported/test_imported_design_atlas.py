"""``design`` and ``atlas`` on an imported model (issue 29): the five-bar exported once with rigid links and its motors
as joints, imported back flexible (tests/helpers/imported_copy.py), gives the native described five-bar's design table
and atlas for the same designs and poses.

Tolerance: the two are the same doubles up to the export (the MJCF writes every number at full precision) and the
same constrained eigen-solve; what differs is the kinematics (the architecture's own solver against Gauss-Newton on
MuJoCo's loop-closure rows, both closed to ~1e-12 m) and the assembly of the matrices. Measured: 9e-13 relative on
the design's frequencies, 3e-12 on the atlas's. 1e-9 leaves three orders for the solvers' convergence and stays six
orders below any design change the study is about (70 GPa against 200 GPa moves f1 by 40 %)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import TaskPose, load_description
from fpm_sim.architecture.imported import load_imported
from fpm_sim.designs import design_study
from fpm_sim.errors import FpmSimError
from fpm_sim.model.general import MIN_BODY_MASS_KG
from fpm_sim.model.imported_pose import joint_poses_of
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.atlas import build_atlas, load_atlas, model_at
from fpm_sim.rom.reduction import modal_system
from tests.helpers.imported_copy import imported_copy

ROOT = Path(__file__).resolve().parents[2]
FIVE_BAR = ROOT / "examples/architectures/five_bar.toml"
OPTS = ModelOptions(segments=2, axial=False)  # coarse: both sides share the discretisation, so the match holds at any
RTOL = 1e-9  # module docstring
VARY = {"materials.steel.young_pa": [200e9, 70e9], "materials.steel.poisson": [0.3, 0.4]}
pytestmark = pytest.mark.filterwarnings("ignore::fpm_sim.model.options.ResolutionWarning")


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """The command's exit code and its stdout (warnings go to stderr, shown when the code is not 0)."""
    from fpm_sim.cli.main import main

    code = main(argv)
    out = capsys.readouterr()
    return code, out.out if code == 0 else out.out + out.err


@pytest.fixture(scope="module")
def five_bar(tmp_path_factory: pytest.TempPathFactory) -> tuple[fs.Description, Path]:
    folder = tmp_path_factory.mktemp("five_bar")
    return load_description(FIVE_BAR), imported_copy(load_description(FIVE_BAR), folder)


def test_design_on_the_imported_five_bar_is_the_native_one(five_bar: tuple[fs.Description, Path]) -> None:
    """A factorial of the material (stiffness and Poisson's ratio) at three check poses: the same frequencies, link
    masses and summary; the moving mass is the model's own, which holds the native model's one pin body (the right
    tool's, :data:`~fpm_sim.model.general.MIN_BODY_MASS_KG`) that the description's bookkeeping leaves out. The
    joint-space poses the task poses solve to give the same study."""
    desc, toml = five_bar
    imp = load_imported(toml)
    poses = [TaskPose.from_coordinates(p) for p in desc.check_poses[:3]]
    native = design_study(desc, poses=poses, vary=VARY, n_modes=4, options=OPTS)
    back = design_study(imp, poses=poses, vary=VARY, n_modes=4, options=OPTS)
    np.testing.assert_allclose(back.frequencies_hz, native.frequencies_hz, rtol=RTOL)
    np.testing.assert_allclose(back.link_mass_kg, native.link_mass_kg, rtol=1e-12)
    np.testing.assert_allclose(back.moving_mass_kg, native.moving_mass_kg + MIN_BODY_MASS_KG, rtol=1e-12)
    for a, b in zip(native.summary(), back.summary(), strict=True):
        assert (a["weakest_x_mm"], a["weakest_y_mm"]) == (b["weakest_x_mm"], b["weakest_y_mm"])
        assert b["min_f1_hz"] == pytest.approx(a["min_f1_hz"], rel=RTOL)
    joints = design_study(imp, poses=joint_poses_of(imp, poses), vary=VARY, n_modes=4, options=OPTS)
    np.testing.assert_allclose(joints.frequencies_hz, back.frequencies_hz, rtol=1e-12)  # the same joint values
    assert joints.joint_space
    assert [r["weakest_pose"] for r in joints.summary()] == [3, 3, 3, 3]
    assert joints.plot_maps() is None
    assert "poses_joints" in joints.to_dict()


def test_design_command_on_the_imported_five_bar(
    five_bar: tuple[fs.Description, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``fpm-sim design`` on the imported file with a task-pose CSV and a designs CSV writes the native machine's
    design.csv (the same rows, frequencies to :data:`RTOL`); the facade's refusal of no poses names them."""
    _, toml = five_bar
    (tmp_path / "poses.csv").write_text("x_mm,y_mm\n0,250\n-60,220\n")
    (tmp_path / "designs.csv").write_text("materials.steel.young_pa\n2e11\n7e10\n")
    rows = {}
    for name, config in (("native", FIVE_BAR), ("imported", toml)):
        argv = ["design", "--config", str(config), "--poses", str(tmp_path / "poses.csv"), "--designs"]
        argv += [str(tmp_path / "designs.csv"), "--segments", "2", "--n-modes", "3", "--out", str(tmp_path / name)]
        code, text = _cli([*argv, "--json"], capsys)
        assert code == 0, text
        assert [Path(f).name for f in json.loads(text)["files"]][:3] == ["design.nc", "design.csv", "summary.csv"]
        rows[name] = np.genfromtxt(tmp_path / name / "design.csv", delimiter=",", names=True, dtype=None)
    for column in ("x_mm", "y_mm", "materials.steel.young_pa"):
        key = column.replace(".", "")  # numpy's names drop the dots
        np.testing.assert_array_equal(rows["imported"][key], rows["native"][key])
    for f in ("f1_hz", "f2_hz", "f3_hz"):
        np.testing.assert_allclose(rows["imported"][f], rows["native"][f], rtol=RTOL)
    with pytest.raises(FpmSimError, match="an imported model states no check poses") as info:
        fs.design(load_imported(toml), vary={"materials.steel.young_pa": [2e11]})
    assert info.value.parameter == "poses"


def test_a_section_heavier_than_the_body_is_refused_by_the_body(five_bar: tuple[fs.Description, Path]) -> None:
    """An imported body's mass is the model's <inertial>; a design whose beam outweighs it is refused naming the body
    and the section (docs/import.md: a section edits the beam's stiffness and its share of the body's mass)."""
    _, toml = five_bar
    imp = load_imported(toml)
    with pytest.raises(FpmSimError, match=r"body 'left_proximal_b0' states 0\.21195 kg, less than its beam's"):
        design_study(
            imp, poses=[TaskPose.from_coordinates({"y": 0.25})], vary={"sections.bar.height_m": [0.009]}, options=OPTS
        )


def test_atlas_on_the_imported_five_bar_is_the_native_one(
    five_bar: tuple[fs.Description, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 3 x 3 grid about the first check pose: the same tracked frequencies at every node and the same interpolated
    model between them (the reduced models' frequencies; their inputs and outputs are the imported model's own, six
    wrench components at its end-effector site and one accelerometer per flexible link). The command builds it from
    the grid given and queries it, the direct comparison on the imported model at the query pose."""
    desc, toml = five_bar
    imp = load_imported(toml)
    grid = {"x_m": [-0.02, 0.0, 0.02], "y_m": [0.23, 0.25, 0.27], "options": OPTS, "n_modes": 4, "n_extra": 2}
    native, back = build_atlas(desc, **grid), build_atlas(imp, **grid)  # type: ignore[arg-type]
    np.testing.assert_allclose(back.nodes["label_freq_hz"], native.nodes["label_freq_hz"], rtol=RTOL)
    pose = TaskPose(0.01, 0.24, 0.0, 0.0)
    np.testing.assert_allclose(back.query(pose).frequencies_hz, native.query(pose).frequencies_hz, rtol=RTOL)
    assert back.input_names[:3] == ["force_x", "force_y", "force_z"]
    out = tmp_path / "a.npz"
    argv = ["atlas", "build", "--config", str(toml), "--x-mm", "-20", "0", "20", "--y-mm", "230", "250", "270"]
    code, text = _cli([*argv, "--segments", "2", "--modes", "4", "--extra", "2", "--out", str(out), "--json"], capsys)
    assert code == 0, text
    np.testing.assert_allclose(load_atlas(out).nodes["label_freq_hz"], native.nodes["label_freq_hz"], rtol=RTOL)
    argv = ["atlas", "query", str(out), "--config", str(toml), "--x-mm", "10", "--y-mm", "240", "--direct", "--json"]
    code, text = _cli(argv, capsys)
    assert code == 0, text
    native_direct = modal_system(model_at(desc, pose, OPTS)).omega_rad_s[:4] / (2 * np.pi)
    np.testing.assert_allclose(json.loads(text)["lowest_direct_frequencies_hz"], native_direct, rtol=RTOL)
