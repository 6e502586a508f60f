import math

from fpm_sim.study.tables import STUDY_COMSOL_VS_EXPERIMENT, comsol_table, mesh_convergence, subsystem_tests


def test_subsystem_tests_match_the_study():
    tests = subsystem_tests()
    assert [t.label for t in tests] == [
        "link free-free",
        "link cantilever",
        "chain 60 deg",
        "chain 90 deg",
        "chain 180 deg",
    ]
    assert [t.experimental_hz for t in tests] == [985, 221, 79, 88, 81]
    assert [t.angle_deg for t in tests[2:]] == [60, 90, 180]


def test_comsol_table_has_25_cells_18_values():
    cells = comsol_table()
    assert len(cells) == 25
    assert sum(c.has_value for c in cells) == 18
    centre = next(c for c in cells if c.row_mm == 0 and c.col_mm == 0)
    assert centre.comsol_hz == 61.37
    vals = [c.comsol_hz for c in cells if c.has_value]
    assert math.isclose(min(vals), 27.14)
    assert math.isclose(max(vals), 74.56)


def test_mesh_convergence_and_stats_load():
    assert len(mesh_convergence()) == 34
    assert STUDY_COMSOL_VS_EXPERIMENT["mean_abs_pct"] == 5.84
