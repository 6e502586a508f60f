"""A described machine's posterior (``fpm-sim calibrate --config five_bar.toml``): read back, its bands, and the
commands that use it (``modes``/``sweep --posterior``, ``fs.predict_bands``, ``plan-tests``).

Truth: each draw's frequencies are those of the pose loop (:func:`fpm_sim.batch.task_sweep.sweep_task`) run on that
draw's file alone, built here from the base with :func:`~fpm_sim.architecture.with_description_value` (not through
the posterior); and physics: a heavier end effector lowers every draw's f1 (the draws' f1 order is the reverse of
their masses'). Bad input is one error line naming the option (or the file's row) and nothing written."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

import fpm_sim as fs
from fpm_sim.architecture import Description, TaskPose, description_value, load_description, with_description_value
from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.task_sweep import sweep_task
from fpm_sim.cli.main import main
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.planning import PlanError, pose_file_candidates, reachable, requirement_target, study_candidates
from fpm_sim.study.posterior import Posterior, PredictiveBands, predict_bands
from tests.helpers.posterior import FIVE_BAR, MASS_PATH, MASSES_KG, write_described_posterior, write_posterior

POSES = [TaskPose.from_mm(0.0, 250.0), TaskPose.from_mm(60.0, 300.0), TaskPose.from_mm(-60.0, 220.0)]
UNREACHABLE = TaskPose.from_mm(0.0, 900.0)
"""900 mm from the base: beyond the five-bar's 400 mm chains."""
SEGMENTS = 2


@pytest.fixture(scope="module")
def posterior_file(tmp_path_factory):
    return write_described_posterior(tmp_path_factory.mktemp("dpost") / "posterior.nc", segments=SEGMENTS)


@pytest.fixture(scope="module")
def posterior(posterior_file):
    return Posterior.from_netcdf(posterior_file)


@pytest.fixture(scope="module")
def bands(posterior):
    return predict_bands(posterior, [*POSES, UNREACHABLE], n_draws=None, engine=EngineOptions(scheduler="serial"))


def test_reads_a_described_posterior(posterior):
    assert posterior.described
    assert isinstance(posterior.base, Description)
    assert posterior.names == [MASS_PATH]
    assert posterior.segments == SEGMENTS
    for i, m in enumerate(MASSES_KG):
        assert description_value(posterior.config(i), MASS_PATH) == m
    median = posterior.median_config()
    assert description_value(median, MASS_PATH) == float(np.median(MASSES_KG))
    assert median.provenance[MASS_PATH].startswith("posterior draw")
    with pytest.raises(fs.FpmSimError, match="dotted paths"):
        _ = posterior.parameter_set


def test_each_draws_bands_are_its_own_files_pose_loop(bands):
    """Each draw's frequencies equal sweep_task on the base with the draw's mass set here (the same pose loop on the
    same file: equal to round-off, 1e-9), the unreachable pose has none, and f1 falls as the mass grows."""
    base = load_description(FIVE_BAR)
    opts = ModelOptions(segments=SEGMENTS, gravity=False, axial=False)
    for row, i in enumerate(bands.draw_index):
        alone = sweep_task(with_description_value(base, MASS_PATH, float(MASSES_KG[i])), [*POSES, UNREACHABLE],
                           options=opts, n_modes=3)  # fmt: skip
        np.testing.assert_allclose(bands.frequencies_hz[row, :3], alone.freq_hz[:3], rtol=1e-9)
        assert list(bands.status[row]) == alone.status
    assert bands.status[0, 3] == "unreachable"
    assert bands.computed_fraction.tolist() == [1.0, 1.0, 1.0, 0.0]
    f1 = bands.frequencies_hz[:, 0, 0]
    order = np.argsort(MASSES_KG[bands.draw_index])
    assert np.all(np.diff(f1[order]) < 0), f1[order]
    assert bands.options.axial is False
    assert bands.options.gravity is False


def test_task_poses_in_the_outputs(bands, tmp_path):
    rows = bands.rows()
    assert list(rows[1])[:2] == ["x_mm", "y_mm"]
    assert "phi_rad" not in rows[1]
    assert (rows[1]["x_mm"], rows[1]["y_mm"]) == (60.0, 300.0)
    assert bands.label(1) == "x=60, y=300"
    assert bands.to_dict()["task"] == ["x", "y"]
    assert bands.dataset["z_mm"].values.tolist() == [0.0] * 4
    names = sorted(p.name for p in bands.write(tmp_path))
    assert names == ["bands.csv", "bands.nc", "bands.png", "bands_map.png"]
    # a spatial machine's poses carry z in the tables
    spatial = PredictiveBands("delta", [TaskPose.from_mm(1.0, 2.0, -300.0)], np.arange(1), np.ones((1, 1, 1)),
                              np.array([["ok"]], dtype=object), task=("x", "y", "z"))  # fmt: skip
    assert spatial.rows()[0]["z_mm"] == -300.0
    assert spatial.label(0) == "x=1, y=2, z=-300"


def test_the_facade_takes_task_poses_and_refuses_the_3rrr_s(posterior_file, bands):
    one = fs.predict_bands(posterior_file, POSES[1], draws=None, n_modes=3, workers=1)
    np.testing.assert_allclose(one.frequencies_hz[:, 0], bands.frequencies_hz[:, 1], rtol=1e-9)
    home = fs.predict_bands(posterior_file, draws=2, n_modes=1, workers=1)  # its first check pose, (0, 250) mm
    assert (home.poses[0].x_m, home.poses[0].y_m) == (0.0, 0.25)
    with pytest.raises(fs.FpmSimError, match="not a task pose"):
        fs.predict_bands(posterior_file, fs.Pose(0.0, 0.25, 0.0), draws=2)


def test_modes_and_sweep_with_a_described_posterior(posterior_file, bands, tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the coarse resolution's warning
        argv = ["modes", "--posterior", str(posterior_file), "--x-mm", "60", "--y-mm", "300", "--n-modes", "3"]
        assert main([*argv, "--draws", "5", "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        got = [doc["bands"][0][f"f{k}_q50_hz"] for k in (1, 2, 3)]
        np.testing.assert_allclose(got, bands.median_hz[1], rtol=1e-9)
        (tmp_path / "poses.csv").write_text("x_mm,y_mm\n0,250\n60,300\n")
        out = tmp_path / "sweep"
        sweep = ["sweep", "--posterior", str(posterior_file), "--poses", str(tmp_path / "poses.csv"), "--out", str(out)]
        assert main([*sweep, "--draws", "5", "--workers", "1", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["task"] == ["x", "y"]
    assert len(doc["bands"]) == 2
    assert (out / "bands.csv").read_text().startswith("x_mm,y_mm,computed_fraction")
    assert main(["modes", "--posterior", str(posterior_file), "--z-mm", "5"]) == 2
    assert "no task coordinate z" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("command", "needle"),
    [
        (["design", "--vary", "section.height_m=0.01:0.02:2", "--f-min-hz", "5"], "robust design"),
        (["reproduce"], "reproduction of the study"),
    ],
)
def test_the_3rrr_s_uses_of_a_posterior_refuse_a_described_one(posterior_file, tmp_path, capsys, command, needle):
    out = tmp_path / "out"
    assert main([*command, "--posterior", str(posterior_file), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error:")
    assert needle in err[0], err
    assert not out.exists()


# ------------------------------------------------------------------------------------------------ plan-tests
SMALL = ["--draws", "10", "--outcomes", "4", "--target-step-mm", "150", "--candidate-step-mm", "150", "--workers", "1"]


def test_plan_tests_on_a_described_posterior(posterior_file, tmp_path, capsys):
    """The default candidates of a described machine are its task grid and the default target f1 over the median's
    task grid; the plan's files are written, in its task coordinates."""
    out = tmp_path / "plan"
    argv = ["plan-tests", "--posterior", str(posterior_file), *SMALL, "--quantities", "f1,f1..f3", "--k", "2"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main([*argv, "--sigma-pct", "2", "--out", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["task"] == ["x", "y"]
    assert len(doc["plan"]) == 2
    assert "task grid" in doc["target"]["description"]
    assert doc["target"]["n_poses"] > 5
    assert sorted(p.name for p in out.iterdir()) == ["candidates.csv", "gain_map.png", "plan.csv", "plan.json"]
    assert (out / "plan.csv").read_text().startswith("rank,x_mm,y_mm,label,quantity,spread_after")
    assert doc["spread_now"] > doc["spread_after"]  # the mass moves f1: measuring it narrows the band


def test_plan_tests_facade_on_a_described_posterior(posterior):
    plan = fs.plan_tests(posterior, candidates=POSES, quantities=["f1"], target=[TaskPose.from_mm(30.0, 280.0)], k=1,
                         sigma_rel=0.02, draws=None, outcomes=4, workers=1)  # fmt: skip
    assert plan.to_dict()["task"] == ["x", "y"]
    assert plan.rows()[0]["label"] == ""
    assert "phi_rad" not in plan.rows()[0]
    assert "x=" in plan.table()


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--candidates", "study"], "--candidates study: the study's 25 cells are the 3RRR's"),
        (["--candidates", "{tmp}/far.csv"], "row 3: --candidates: pose x=0, y=900 is unreachable"),
        (["--target", "{tmp}/bad.csv"], "--target"),
    ],
)
def test_plan_tests_bad_input_on_a_described_posterior(posterior_file, tmp_path, capsys, extra, needle):
    (tmp_path / "far.csv").write_text("x_mm,y_mm\n0,250\n0,900\n")
    (tmp_path / "bad.csv").write_text("x_mm,phi_rad\n0,0\n")  # the five-bar's task is x, y
    out = tmp_path / "plan"
    argv = ["plan-tests", "--posterior", str(posterior_file), *SMALL, "--out", str(out)]
    assert main([*argv, *(a.replace("{tmp}", str(tmp_path)) for a in extra)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error:")
    assert needle in err[0], err
    assert not out.exists()


def test_a_read_is_refused_on_a_described_posterior_by_name(posterior, posterior_file, tmp_path, capsys):
    """The readout model (sensor_residues) is the 3RRR's: a read quantity is refused, named, before any solve."""
    read = "read:distal_0@0.5:z"
    with pytest.raises(PlanError, match=re.escape(f"'{read}': the readout model")) as exc:
        fs.plan_tests(posterior, candidates=POSES, quantities=["f1", read], sigma_rel=0.02, k=1)
    assert exc.value.parameter == "quantities"
    out = tmp_path / "plan"
    argv = ["plan-tests", "--posterior", str(posterior_file), *SMALL, "--quantities", f"f1,{read}", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"error: --quantities: '{read}': the readout model"), err
    assert not out.exists()


def test_the_library_refuses_the_study_cells_and_names_the_unreachable_row(posterior, tmp_path):
    with pytest.raises(PlanError, match="the study's 25 cells are the 3RRR's"):
        study_candidates(["f1"], posterior)
    (tmp_path / "far.csv").write_text("x_mm,y_mm\n\n0,250\n0,900\n")  # a blank line: the row is the file's line
    with pytest.raises(PlanError, match="row 4") as exc:
        pose_file_candidates(posterior, tmp_path / "far.csv", ["f1"])
    assert exc.value.parameter == "candidates"


def test_plan_tests_on_the_3rrr_names_an_unreachable_candidate_row(tmp_path, capsys):
    """The 3RRR's candidates CSV: a pose 5 m away is refused naming its row, nothing written."""
    post = write_posterior(tmp_path / "posterior.nc")
    (tmp_path / "c.csv").write_text("x_mm,y_mm,phi_rad\n0,0,0\n5000,0,0\n")
    out = tmp_path / "plan"
    argv = ["plan-tests", "--posterior", str(post), "--candidates", str(tmp_path / "c.csv"), "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "row 3: --candidates: pose (5000, 0) mm, 0 rad is unreachable" in err[0], err
    assert not out.exists()


def test_a_requirement_target_on_a_described_posterior(posterior, posterior_file, tmp_path, capsys):
    """A requirements file's task grid (resolved on the posterior median's five-bar, its unreachable points dropped)
    is the target: the plan is on the pass/fail entropy of f1 >= 30 Hz there."""
    (tmp_path / "req.toml").write_text(
        '[[requirement]]\nname = "f1 above 30 Hz"\nkind = "min_frequency"\nat_least_hz = 30.0\nmode = 1\n'
        'poses = { grid = "dense", step_mm = 100 }\n'
    )
    target = requirement_target(posterior, tmp_path / "req.toml")
    assert target.kind == "requirement"
    assert target.f_min_hz == 30.0
    assert all(isinstance(p, TaskPose) for p in target.poses)
    assert reachable(posterior.median_config(), target.poses).all()
    out = tmp_path / "plan"
    argv = ["plan-tests", "--posterior", str(posterior_file), *SMALL, "--quantities", "f1", "--k", "1"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main([*argv, "--target", str(tmp_path / "req.toml"), "--sigma-pct", "2", "--out", str(out)]) == 0
    assert "pass/fail uncertainty of f1 >= 30 Hz" in capsys.readouterr().out


def test_a_spatial_machines_posterior_carries_z(tmp_path, capsys):
    """The delta (task x, y, z): ``sweep --posterior --poses`` in its task coordinates writes z_mm beside x and y,
    and each draw's frequencies are its own file's at those poses (as above, 1e-9)."""
    import arviz as az

    from fpm_sim.architecture import description_toml

    delta = load_description(FIVE_BAR.parent / "delta.toml")
    masses = np.array([0.05, 0.2])
    idata = az.from_dict(posterior={"lumps.elbow.mass_kg": masses[None, :]})
    idata.posterior.attrs.update(fpm_sim_base_config=description_toml(delta), fpm_sim_free_groups="lumps.elbow.mass_kg",
                                 fpm_sim_segments=1, fpm_sim_command="test")  # fmt: skip
    idata.to_netcdf(str(tmp_path / "post.nc"))
    (tmp_path / "p.csv").write_text("x_mm,y_mm,z_mm\n0,0,-300\n50,0,-320\n")
    out = tmp_path / "sweep"
    argv = ["sweep", "--posterior", str(tmp_path / "post.nc"), "--poses", str(tmp_path / "p.csv"), "--out", str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main([*argv, "--workers", "1", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [(r["x_mm"], r["y_mm"], r["z_mm"]) for r in doc["bands"]] == [(0.0, 0.0, -300.0), (50.0, 0.0, -320.0)]
    assert (out / "bands.csv").read_text().startswith("x_mm,y_mm,z_mm,computed_fraction")
    poses = [TaskPose.from_mm(0.0, 0.0, -300.0), TaskPose.from_mm(50.0, 0.0, -320.0)]
    opts = ModelOptions(segments=1, gravity=False, axial=False)
    for row, m in enumerate(masses):
        alone = sweep_task(with_description_value(delta, "lumps.elbow.mass_kg", float(m)), poses, options=opts)
        np.testing.assert_allclose(doc["frequencies_hz"][row], alone.freq_hz, rtol=1e-9)
