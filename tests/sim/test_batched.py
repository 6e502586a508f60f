"""Batched rollouts (``mujoco.rollout`` threads): each row equals the single rollout of its load case, threads
change nothing, the Dataset round-trips through netCDF, bad input is named."""

import json

import numpy as np
import pytest

from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.reduction import modal_system
from fpm_sim.sim.batched import BatchedRolloutError, batched_rollouts
from fpm_sim.sim.rollout import constant, rollout

WRENCHES = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.1], [1.0, 1.0, 0.0]])


@pytest.fixture(scope="module")
def model(symmetric_manip):
    manip = symmetric_manip.with_section(thickness_m=0.005)
    built = build_manipulator(manip, Pose(0.0, 0.0, 0.0), ModelOptions(segments=3, axial=False))
    return manip, built, float(modal_system(built).frequencies_hz[0])


def test_batched_rows_are_the_single_rollouts(model, tmp_path):
    manip, built, f1 = model
    ds = [batched_rollouts(built, manip, WRENCHES, duration_s=0.01, threads=t, f1_hz=f1) for t in (1, 2)]
    # the threads step the same arithmetic: identical to the bit
    assert np.array_equal(ds[0].ee_disp.values, ds[1].ee_disp.values)
    for i, w in enumerate(WRENCHES):
        single = rollout(built, manip, duration_s=0.01, ee_wrench=constant(*w), f1_hz=f1)
        # same model, same steps, same zero-order hold: round-off only (measured 1.6e-15 m)
        assert np.abs(single.ee_disp - ds[0].ee_disp.values[i]).max() < 1e-12
        assert np.abs(single.ee_disp).max() > 1e-5
    st = json.loads(ds[0].attrs["stepping"])
    assert st["integrator"] == "discrete"
    path = tmp_path / "b.nc"
    ds[0].to_netcdf(path, engine="scipy")
    import xarray as xr

    back = xr.load_dataset(path, engine="scipy")
    assert np.array_equal(back.ee_disp.values, ds[0].ee_disp.values)
    assert list(back.axis.values) == ["x", "y", "phi"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"wrenches": [[1.0, 2.0]]}, "wrenches"),
        ({"wrenches": [[np.nan, 0.0, 0.0]]}, "wrenches"),
        ({"threads": 0}, "^threads: must be an integer >= 1, got 0"),
        ({"band_hz": -1.0}, "^band_hz: must be a positive finite number"),
        ({"duration_s": -1.0}, "duration_s"),
    ],
)
def test_bad_input(model, kwargs, match):
    manip, built, f1 = model
    args = {"wrenches": WRENCHES, "duration_s": 0.01, **kwargs}
    with pytest.raises(BatchedRolloutError, match=match):
        batched_rollouts(built, manip, args.pop("wrenches"), f1_hz=f1, **args)
