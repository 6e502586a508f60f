"""Moves x designs on the engine: each cell is the direct simulate_move of its pair."""

import numpy as np
import pytest

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.moves import MOVE_SUMMARY_FIELDS, moves_over_designs
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions
from fpm_sim.sim.trajectory import MovePath, simulate_move


@pytest.mark.slow
def test_moves_over_designs_are_the_direct_moves(default_manip):
    """Two designs (10 and 5 mm links) x two short moves, serial engine (3 segments: ~20 s)."""
    designs = [default_manip, default_manip.with_section(thickness_m=0.005)]
    paths = [
        MovePath(Pose(0.0, 0.0, 0.0), Pose.from_mm(5.0, 0.0, 0.0), 0.1),
        MovePath(Pose(0.0, 0.0, 0.0), Pose.from_mm(0.0, 5.0, 0.0), 0.1, kind="trapezoidal"),
    ]
    opts = ModelOptions(segments=3, axial=False)
    ds = moves_over_designs(designs, paths, settle_s=0.1, options=opts, engine=EngineOptions(scheduler="serial"))
    assert set(MOVE_SUMMARY_FIELDS) <= set(ds.data_vars)
    assert ds.residual_peak_m.shape == (2, 2)
    direct = simulate_move(designs[1], paths[1], settle_s=0.1, options=opts)
    # the same computation in a task: identical
    assert ds.residual_peak_m.values[1, 1] == direct.residual.peak_m
    assert ds.modal_f1_hz.values[1, 1] == direct.residual.modal_f1_hz
    # the designs differ: thinner links ring lower
    assert not np.allclose(ds.inplane_mode_hz.values[0], ds.inplane_mode_hz.values[1])
