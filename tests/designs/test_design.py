import csv
import pickle
import re

import numpy as np
import pytest

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.cli.main import main
from fpm_sim.designs import DesignError, design_study, factorial, moving_mass_kg, parse_spec, parse_vary
from fpm_sim.kinematics import Pose
from fpm_sim.study.poses import study_poses


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def _f(v):
    return float(v) if v != "" else np.nan


def test_design_at_30_mm_equals_the_sweep_of_the_paper_grid(tmp_path, capsys):
    # The done-when: the 30 mm design of a thickness study gives the sweep's frequencies (the same
    # pose loop, the same model at the same thickness: identical numbers, printed at full precision).
    d, s = tmp_path / "D", tmp_path / "S"
    assert main(["design", "--vary", "section.thickness_m=0.01,0.03", "--grid", "paper", "--out", str(d)]) == 0
    assert main(["sweep", "--grid", "paper", "--thickness-mm", "30", "--out", str(s)]) == 0
    out = capsys.readouterr().out
    assert "section.thickness_m" in out
    assert "min f1 Hz" in out
    design = [r for r in _rows(d / "design.csv") if float(r["section.thickness_m"]) == 0.03]
    sweep = _rows(s / "sweep_paper.csv")
    assert len(design) == len(sweep) == 25
    assert list(_rows(d / "design.csv")[0])[:7] == [
        "section.thickness_m", "x_mm", "y_mm", "phi_rad", "status", "singularity", "f1_hz",
    ]  # fmt: skip
    for a, b in zip(design, sweep):
        assert (float(a["x_mm"]), float(a["y_mm"]), float(a["phi_rad"])) == (
            float(b["x_mm"]), float(b["y_mm"]), float(b["phi_rad"]),
        )  # fmt: skip
        assert a["status"] == b["status"]
        for k in ("f1_hz", "f2_hz", "f3_hz"):
            assert _f(a[k]) == pytest.approx(_f(b[k]), rel=1e-12, nan_ok=True)
    thin = [r for r in _rows(d / "design.csv") if float(r["section.thickness_m"]) == 0.01]
    for a, b in zip(thin, design):  # thinner links: softer, pose by pose
        if a["status"] == b["status"] == "ok":
            assert _f(a["f1_hz"]) < _f(b["f1_hz"])
    summary = _rows(d / "summary.csv")
    assert [float(r["section.thickness_m"]) for r in summary] == [0.01, 0.03]
    assert float(summary[1]["min_f1_hz"]) == pytest.approx(min(_f(r["f1_hz"]) for r in design), rel=1e-12)
    for name in ("design.nc", "design_min_f1.png", "design_maps.png", "design_tradeoff.png"):
        assert (d / name).exists()


def test_design_on_the_loopback_cluster_gives_the_local_numbers(default_manip, loopback_cluster, tmp_path):
    poses = [*[p.pose for p in study_poses()][:10], Pose(0.9, 0.0, 0.0)]
    vary = {"section.thickness_m": [0.01, 0.03], "hardware.payload.mass_kg": [0.0, 1.0]}
    opts = fast_options(segments=3)
    local = design_study(default_manip, poses=poses, vary=vary, options=opts, engine=EngineOptions(scheduler="serial"))
    remote = design_study(
        default_manip,
        poses=poses,
        vary=vary,
        options=opts,
        engine=EngineOptions(scheduler=loopback_cluster, chunk=4, store=tmp_path / "chunks"),
    )
    np.testing.assert_array_equal(remote.frequencies_hz, local.frequencies_hz)
    np.testing.assert_array_equal(remote.status, local.status)
    assert remote.summary() == local.summary()
    assert len(list((tmp_path / "chunks").glob("*.pkl"))) == 4 * 3  # 4 designs x 3 chunks, streamed to disk


def test_factorial_dataset_and_summary(default_manip):
    poses = [p.pose for p in study_poses()][:6]
    vary = {"section.thickness_m": [0.01, 0.02, 0.03], "hardware.payload.mass_kg": [0.0, 1.0]}
    res = design_study(
        default_manip, poses=poses, vary=vary, f_min_hz=30.0, options=fast_options(segments=2),
        engine=EngineOptions(scheduler="serial"),
    )  # fmt: skip
    ds = res.dataset
    assert ds["freq_hz"].dims == ("section.thickness_m", "hardware.payload.mass_kg", "pose", "mode")
    assert ds["freq_hz"].shape == (3, 2, 6, 3)
    # the dataset's cells are the designs' results, in factorial order
    f = ds["freq_hz"].sel({"section.thickness_m": 0.02, "hardware.payload.mass_kg": 1.0}).values
    np.testing.assert_array_equal(f, res.frequencies_hz[3])
    st = ds["status"].sel({"section.thickness_m": 0.02, "hardware.payload.mass_kg": 1.0}).values
    assert list(st) == list(res.status[3])  # status per design and pose, a coordinate as in every frequency dataset
    assert ds["x_mm"].dims == ("pose",)
    rows = res.summary()
    assert [(r["section.thickness_m"], r["hardware.payload.mass_kg"]) for r in rows] == [
        (t, m) for t in (0.01, 0.02, 0.03) for m in (0.0, 1.0)
    ]
    for d, r in enumerate(rows):
        f1 = res.frequencies_hz[d, :, 0]
        assert r["min_f1_hz"] == np.nanmin(f1)
        assert r["mean_f1_hz"] == pytest.approx(np.nanmean(f1))
        assert r["share_above_f_min"] == pytest.approx(np.sum(f1 >= 30.0) / 6)
    # adding mass never raises an eigenvalue (Rayleigh): the 1 kg payload lowers every f1
    for t in range(3):
        assert np.all(res.frequencies_hz[2 * t + 1, :, 0] < res.frequencies_hz[2 * t, :, 0])
        assert rows[2 * t + 1]["moving_mass_kg"] == pytest.approx(rows[2 * t]["moving_mass_kg"] + 1.0)
    assert res.to_dict()["summary"] == rows
    assert "min f1 Hz" in res.table()
    fig = res.plot()
    assert len(fig.axes) == 2


def test_designs_csv_and_poses_csv(tmp_path, capsys):
    designs = tmp_path / "designs.csv"
    designs.write_text("section.thickness_m,hardware.payload.mass_kg\n0.03,0\n0.03,0.5\n")
    poses = tmp_path / "poses.csv"
    poses.write_text("x_mm,y_mm,phi_rad\n0,0,0\n50,-50,0.1\n900,0,0\n")
    out = tmp_path / "D"
    code = main(
        ["design", "--designs", str(designs), "--poses", str(poses), "--segments", "2", "--n-modes", "4",
         "--f-min-hz", "20", "--scheduler", "serial", "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    rows = _rows(out / "design.csv")
    assert len(rows) == 6
    assert rows[2]["status"] == "unreachable"
    assert rows[2]["f1_hz"] == ""
    assert list(rows[0])[-5:] == ["f1_hz", "f2_hz", "f3_hz", "f4_hz", "in_plane_mode1"]
    # sweep --poses: the same poses, sweep_poses.csv
    s = tmp_path / "S"
    sweep_argv = ["sweep", "--poses", str(poses), "--thickness-mm", "30", "--segments", "2", "--workers", "1"]
    assert main([*sweep_argv, "--out", str(s)]) == 0  # the designs are 30 mm thick
    swept = _rows(s / "sweep_poses.csv")
    assert list(swept[0])[:6] == ["x_mm", "y_mm", "phi_rad", "f1_hz", "f2_hz", "f3_hz"]
    assert list(swept[0])[-1] == "status"
    assert [r["status"] for r in swept] == [r["status"] for r in rows[:3]]
    assert _f(swept[1]["f1_hz"]) == pytest.approx(_f(rows[1]["f1_hz"]), rel=1e-12)


def test_bad_inputs_name_the_option(default_manip, tmp_path, capsys):
    assert parse_spec("0.005:0.03:6") == pytest.approx([0.005, 0.01, 0.015, 0.02, 0.025, 0.03])
    assert parse_spec("1,2,3") == [1.0, 2.0, 3.0]
    assert factorial({"a": [1, 2], "b": [3]}) == [{"a": 1, "b": 3}, {"a": 2, "b": 3}]
    with pytest.raises(DesignError, match="start:stop:count"):
        parse_spec("1:2")
    with pytest.raises(DesignError, match="dotted"):
        parse_vary(["section.thicknes_m=0.01"], default_manip)
    with pytest.raises(DesignError, match="FIELD=SPEC"):
        parse_vary(["section.thickness_m"], default_manip)
    with pytest.raises(DesignError, match=re.escape("section.thickness_m = -0.01")):
        design_study(default_manip, poses=[Pose(0, 0, 0)], vary={"section.thickness_m": [-0.01]})
    code = main(["design", "--vary", "nope.field=1", "--out", str(tmp_path / "x")])
    assert code == 2
    assert "error: --vary: field 'nope.field'" in capsys.readouterr().err
    assert moving_mass_kg(default_manip) > 0


def test_resume_continues_a_killed_run_from_its_chunks(default_manip, tmp_path, capsys):
    # A killed run leaves OUT.partial/ with the chunks it finished; --resume reuses them (the same numbers as
    # a fresh run) and removes the folder at the end.
    from fpm_sim.batch.engine import chunk_store

    args = ["design", "--vary", "section.thickness_m=0.02,0.03", "--grid", "paper", "--segments", "2",
            "--scheduler", "serial", "--chunk-poses", "5"]  # fmt: skip
    fresh = tmp_path / "fresh"
    assert main([*args, "--out", str(fresh)]) == 0
    out = tmp_path / "killed"
    poses = [p.pose for p in study_poses()]
    engine = EngineOptions(scheduler="serial", chunk=5, store=chunk_store(out))
    design_study(
        default_manip, poses=poses, vary={"section.thickness_m": [0.02, 0.03]}, options=fast_options(segments=2),
        engine=engine,
    )  # fmt: skip
    chunks = sorted(chunk_store(out).glob("*.pkl"))
    assert len(chunks) == 10
    for path in chunks[::2]:  # the run "died" before these were written
        path.unlink()
    # mark one finished chunk (f1 doubled) to see that it is reused, not recomputed
    with open(chunks[1], "rb") as fh:
        marked = pickle.load(fh)
    marked.frequencies_hz[:, 0] *= 2.0
    with open(chunks[1], "wb") as fh:
        pickle.dump(marked, fh)
    assert main([*args, "--resume", "--out", str(out)]) == 0
    assert not chunk_store(out).exists()
    resumed, ref = _rows(out / "design.csv"), _rows(fresh / "design.csv")
    changed = [(a, b) for a, b in zip(resumed, ref) if a != b]
    assert len(changed) == sum(s in ("ok", "near_singular") for s in marked.status) > 0
    for a, b in changed:
        assert _f(a["f1_hz"]) == 2.0 * _f(b["f1_hz"])
        assert a["f2_hz"] == b["f2_hz"]
