"""What fpm-sim reproduce reports about identification: measured and COMSOL, the six withheld poses,
and no error statistics for links the study's tables do not describe."""

import numpy as np

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import default_config
from fpm_sim.study.reproduce import reproduce_study
from fpm_sim.study.tables import comsol_table, measured_table, withheld_cells


def test_the_withheld_poses_are_the_readable_ones_missing_from_the_packaged_table():
    w = withheld_cells()
    assert len(w) == 6
    known = {(m.row_mm, m.col_mm) for m in measured_table()}
    assert not set(w) & known
    readable = {(c.row_mm, c.col_mm) for c in comsol_table() if c.has_value}
    assert set(w) <= readable
    assert len(readable) == 18
    assert sum(m.readable for m in measured_table()) == 12


def test_report_states_predictions_for_withheld_poses_and_both_references():
    rep = reproduce_study(default_config(), options=fast_options(segments=2), subsystems=False, readability=False)
    md = rep.markdown()
    assert "Predictions at the six withheld poses" in md
    assert "fpm-sim vs measured (12 poses, in-sample)" in md
    assert "fpm-sim vs COMSOL (18 poses)" in md
    assert "COMSOL vs measured (the study's own" in md
    rows = rep.rows()
    assert sum(r["withheld"] for r in rows) == 6
    assert all(np.isnan(r["measured_hz"]) for r in rows if r["withheld"])  # never a value for them
    assert rep.stats_vs_measured()["n"] == 12


def test_thin_links_get_no_error_statistics_against_the_30_mm_tables():
    cfg = default_config().with_section(thickness_m=0.005)
    rep = reproduce_study(cfg, options=fast_options(segments=2), subsystems=False, readability=False)
    md = rep.markdown()
    assert "No error statistics: not comparable" in md
    assert "mean (%)" not in md
    assert rep.stats() == {"n": 0}
    assert rep.to_dict()["stats_vs_comsol"] is None
