import pytest

from fpm_sim.study.poses import READINGS, TableReading, parse_reading, study_poses


def test_grid_is_5x5_from_minus_100_to_100():
    poses = study_poses()
    assert len(poses) == 25
    xs = sorted({round(p.pose.x_m * 1e3, 9) for p in poses})
    ys = sorted({round(p.pose.y_m * 1e3, 9) for p in poses})
    assert xs == ys == [-100, -50, 0, 50, 100]


@pytest.mark.parametrize("reading", READINGS, ids=lambda r: r.name)
def test_rotation_only_at_poses_written_x_0(reading):
    for p in study_poses(reading):
        expected = reading.phi_sign * 0.2 if p.col_mm == 0 else 0.0
        assert p.pose.phi_rad == expected


def test_row_reading_swaps_x_and_y():
    by_x = {(p.row_mm, p.col_mm): p.pose for p in study_poses(TableReading("x", 1))}
    by_y = {(p.row_mm, p.col_mm): p.pose for p in study_poses(TableReading("y", 1))}
    pose_x, pose_y = by_x[(100, -50)], by_y[(100, -50)]
    assert (pose_x.x_m, pose_x.y_m) == (0.1, -0.05)
    assert (pose_y.x_m, pose_y.y_m) == (-0.05, 0.1)
    # COMSOL values stay attached to the table's labels whatever the reading
    assert [p.comsol_hz for p in study_poses(READINGS[0])][:3] == [p.comsol_hz for p in study_poses(READINGS[3])][:3]


def test_parse_reading():
    assert parse_reading("y-") == TableReading("y", -1)
    with pytest.raises(ValueError, match="x\\+, x-, y\\+ or y-"):
        parse_reading("z+")
