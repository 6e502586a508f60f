import csv

import numpy as np
import pytest

from fpm_sim.cli.main import main


def test_sweep_keeps_every_point_with_a_status(tmp_path, capsys):
    code = main(
        ["sweep", "--grid", "dense", "--step-mm", "100", "--segments", "2", "--workers", "1", "--out", str(tmp_path)]
    )
    assert code == 0
    with open(tmp_path / "sweep_dense.csv") as fh:
        rows = list(csv.DictReader(fh))
    statuses = {r["status"] for r in rows}
    assert "ok" in statuses
    assert "unreachable" in statuses
    for r in rows:
        assert (r["f1_hz"] == "") == (r["status"] in ("unreachable", "singular"))
    assert (tmp_path / "sweep_dense.png").exists()


def test_singularity_fields_match_the_kinematics_module(default_manip):
    from fpm_sim.kinematics import Pose, UnreachablePoseError, inverse_kinematics
    from fpm_sim.study.sweep import singularity_fields

    xs, ys = np.array([-120.0, 0.0, 90.0, 400.0]), np.array([-80.0, 0.0, 60.0])
    det, ser = singularity_fields(default_manip, xs, ys, 0.1)
    for iy, y in enumerate(ys):
        for ix, x in enumerate(xs):
            try:
                asm = inverse_kinematics(default_manip.geometry, Pose.from_mm(x, y, 0.1), check_singularity=False)
            except UnreachablePoseError:
                assert np.isnan(det[iy, ix])
                assert np.isnan(ser[iy, ix])
                continue
            assert ser[iy, ix] == pytest.approx(asm.singularity.serial, abs=1e-12)
            assert np.isfinite(det[iy, ix])


def test_paper_sweep_writes_the_reproduce_pose_table(tmp_path):
    """``sweep --grid paper`` writes poses.csv through the library (StudyReproduction.from_sweep)."""
    from fpm_sim.config import default_config
    from fpm_sim.errors import FpmSimError
    from fpm_sim.model.options import ModelOptions
    from fpm_sim.study.reproduce import StudyReproduction
    from fpm_sim.study.sweep import sweep_workspace

    code = main(["sweep", "--grid", "paper", "--segments", "2", "--workers", "1", "--out", str(tmp_path)])
    assert code == 0
    with open(tmp_path / "poses.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 25
    with open(tmp_path / "sweep_paper.csv") as fh:
        swept = {(round(float(r["x_mm"]), 3), round(float(r["y_mm"]), 3)): r["f1_hz"] for r in csv.DictReader(fh)}
    for r in rows:  # the same frequencies at the same poses, read the same way
        key = (round(float(r["x_mm"]), 3), round(float(r["y_mm"]), 3))
        assert float(r["f1_hz"]) == pytest.approx(float(swept[key]), rel=1e-5)  # both written with 6+ digits
    dense = sweep_workspace(default_config(), grid="dense", step_mm=150, options=ModelOptions(segments=2, axial=False))
    with pytest.raises(FpmSimError, match="grid 'paper'"):
        StudyReproduction.from_sweep(dense)
