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
