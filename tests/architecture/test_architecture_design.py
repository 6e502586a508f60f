"""``design`` on described architectures: dotted paths into the file over its task poses; the 3RRR written as a
description gives the 3RRR's own design study; the command line runs it and refuses what is the 3RRR's by name."""

from __future__ import annotations

import csv
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import TaskPose, load_description
from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.cli.main import main
from fpm_sim.config import default_config
from fpm_sim.designs import DesignError, design_study
from fpm_sim.kinematics import Pose

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
FIVE_BAR = EXAMPLES / "five_bar.toml"
COARSE = fast_options(segments=2)  # both paths build the same model at any resolution: the coarsest is the fastest


def test_the_3rrr_as_a_description_gives_the_3rrr_s_own_design_study():
    """three_rrr.toml varying ``sections.links.thickness_m`` and the 3RRR varying ``section.thickness_m`` at the same
    values and poses: the same frequencies to the round-off of the inverse kinematics and of the finite-difference
    stiffness (as tests/architecture/test_modes.py: 1e-8; measured 5e-12), the same statuses and masses."""
    poses = [(0.0, 0.0, 0.0), (50.0, -50.0, 0.1), (-40.0, 80.0, -0.2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        general = design_study(
            load_description(EXAMPLES / "three_rrr.toml"),
            poses=[TaskPose.from_mm(x, y, 0.0, phi) for x, y, phi in poses],
            vary={"sections.links.thickness_m": [0.02, 0.04]},
            options=COARSE,
        )
        native = design_study(
            default_config(),
            poses=[Pose.from_mm(x, y, phi) for x, y, phi in poses],
            vary={"section.thickness_m": [0.02, 0.04]},
            options=COARSE,
            engine=EngineOptions(scheduler="serial"),
        )
    np.testing.assert_allclose(general.frequencies_hz, native.frequencies_hz, rtol=1e-8)
    assert general.frequencies_hz[1, 0, 0] > 1.5 * general.frequencies_hz[0, 0, 0]  # the thickness did change
    assert general.status.tolist() == native.status.tolist()
    np.testing.assert_allclose(general.link_mass_kg, native.link_mass_kg, rtol=1e-12)
    np.testing.assert_allclose(general.moving_mass_kg, native.moving_mass_kg, rtol=1e-12)
    assert general.fields == ["sections.links.thickness_m"]


def test_the_facade_s_design_at_the_check_poses_is_the_sweep_s_base_design():
    """Two entry points over the same pose loop: the unedited design's frequencies are the sweep's at the check poses
    (its other design moves them)."""
    desc = load_description(FIVE_BAR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        des = fs.design(desc, vary={"sections.bar.height_m": [0.006, 0.009]}, options=COARSE)
        home = [TaskPose(p["x"], p["y"]) for p in desc.check_poses]
        sw = fs.sweep(desc, grid="poses", poses=home, options=COARSE)
    np.testing.assert_allclose(des.frequencies_hz[0], sw.frequencies_hz, rtol=1e-12)
    assert np.all(des.frequencies_hz[1, :, 0] > des.frequencies_hz[0, :, 0])
    ds = des.to_xarray()
    assert ds["freq_hz"].dims == ("sections.bar.height_m", "pose", "mode")
    assert des.to_dict()["fields"] == ["sections.bar.height_m"]
    with pytest.raises(DesignError, match="takes poses as TaskPose"):
        fs.design(desc, poses=[Pose(0.0, 0.25, 0.0)], vary={"sections.bar.height_m": [0.006]}, options=fast_options())


def _design(tmp_path, *extra):
    return [
        "design",
        "--config",
        str(FIVE_BAR),
        "--segments",
        "2",
        "--workers",
        "1",
        "--out",
        str(tmp_path / "o"),
        *extra,
    ]


def test_the_command_runs_on_the_five_bar_with_json(tmp_path, capsys):
    argv = _design(
        tmp_path, "--vary", "sections.bar.height_m=0.004:0.008:3", "--vary", "chains.left.proximal.length_m=0.18"
    )
    assert main([*argv, "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    rows = payload["summary"]
    assert [r["sections.bar.height_m"] for r in rows] == [0.004, 0.006, 0.008]
    assert all(r["computed_poses"] == 6 for r in rows)  # the six check poses
    f1 = [r["min_f1_hz"] for r in rows]
    assert f1 == sorted(f1)  # a higher section is stiffer out of the plane
    masses = [r["link_mass_kg"] for r in rows]
    # four links of 0.18 + 0.22 m, 25 mm x h, steel
    np.testing.assert_allclose(masses, [2 * 0.4 * 0.025 * h * 7850.0 for h in (0.004, 0.006, 0.008)], rtol=1e-12)
    tidy = list(csv.DictReader(open(tmp_path / "o" / "design.csv")))
    assert len(tidy) == 18
    assert {"sections.bar.height_m", "x_mm", "y_mm", "status", "f1_hz"} <= set(tidy[0])


H4 = ["--vary", "sections.bar.height_m=0.004"]


@pytest.mark.parametrize(
    ("extra", "start"),
    [
        (["--vary", "sections.bars.height_m=0.004"], "error: --vary: field 'sections.bars.height_m': unknown"),
        (["--vary", "sections.bar.height_m=-0.004"], "error: sections.bar.height_m: must be > 0, got -0.004"),
        ([*H4, "--grid", "paper"], "error: --grid paper:"),
        ([*H4, "--scheduler", "serial"], "error: --scheduler: an option of the 3RRR"),
        ([*H4, "--posterior", "p.nc"], "error: --posterior: an option of the 3RRR"),
        ([*H4, "--z-mm", "3"], "error: --z-mm: five-bar"),
    ],
)
def test_an_unknown_path_a_bad_value_and_the_3rrr_s_options_are_one_error_line(extra, start, tmp_path, capsys):
    code = main(_design(tmp_path, *extra))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1, err
    assert err[0].startswith(start), err[0]
    assert not (tmp_path / "o").exists()


def test_the_delta_s_poses_file_is_read_in_its_task_coordinates(tmp_path, capsys):
    """A spatial machine: the poses file's z_mm reaches the poses, and the tidy table carries it."""
    poses = tmp_path / "poses.csv"
    poses.write_text("x_mm,y_mm,z_mm\n0,0,-300\n0,0,-1000\n")
    argv = [
        "design",
        "--config",
        str(EXAMPLES / "delta.toml"),
        "--vary",
        f"materials.{_first_material(EXAMPLES / 'delta.toml')}.young_pa=70e9",
        "--poses",
        str(poses),
        "--segments",
        "2",
        "--workers",
        "1",
        "--out",
        str(tmp_path / "o"),
        "--json",
    ]
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["summary"][0]["computed_poses"] == 1  # the second is out of reach
    tidy = list(csv.DictReader(open(tmp_path / "o" / "design.csv")))
    assert [float(r["z_mm"]) for r in tidy] == [-300.0, -1000.0]
    assert [r["status"] for r in tidy] == ["ok", "unreachable"]


def _first_material(path: Path) -> str:
    import tomllib

    return next(iter(tomllib.loads(path.read_text())["materials"]))
