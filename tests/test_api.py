"""The public API (``import fpm_sim as fs``): every entry point on a tiny model, and no import side effects."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import matplotlib
import pytest

matplotlib.use("Agg")  # the tests' choice; the library never selects a backend

import fpm_sim as fs
from fpm_sim.frf import LinkPoint

SEG = 3  # a tiny model: 3 spring locations per link


def check_result(result, *, expect_resolution: bool = True) -> dict:
    """The contract every result keeps: JSON-ready ``to_dict``, text ``table``, ``plot`` -> Figure."""
    from matplotlib.figure import Figure

    d = result.to_dict()
    json.dumps(d)  # JSON-ready
    text = result.table()
    assert isinstance(text, str)
    assert text.strip()
    fig = result.plot()
    assert isinstance(fig, Figure)
    import matplotlib.pyplot as plt

    plt.close(fig)
    if expect_resolution:
        assert d["resolution"]["segments"] == SEG
        assert d["resolution"]["f1_error_estimate"] == pytest.approx(0.41 / SEG**2)
    return d


def test_public_names_are_lazy_and_listed():
    assert {"modes", "rig_modes", "sweep", "reduce", "frf", "rollout", "reproduce", "load_config",
            "default_config", "Pose"} <= set(dir(fs))
    with pytest.raises(AttributeError):
        fs.no_such_thing  # noqa: B018


def test_modes_and_rig_modes():
    cfg = fs.default_config()
    pose = fs.Pose.from_mm(20, -10, 0.05)
    r = fs.modes(cfg, pose, segments=SEG, n_modes=3)
    d = check_result(r)
    assert len(d["modes"]) == 3
    assert r.frequencies_hz[0] > 0
    # the same model through the library's own builder gives the same frequencies
    from fpm_sim.linear.analysis import analyse
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.options import ModelOptions

    direct = analyse(build_manipulator(cfg, pose, ModelOptions(segments=SEG)), "transition_fd", 3)
    assert list(r.frequencies_hz) == list(direct.frequencies_hz)
    rig = fs.rig_modes(cfg, "cantilever", segments=SEG, n_modes=2)
    check_result(rig)
    assert rig.frequencies_hz[0] > 0


def test_fidelity_names_a_resolution():
    r = fs.modes(fidelity="fast", n_modes=1, axial=False)
    assert r.to_dict()["resolution"] == {
        "link_model": "segments",
        "segments": 8,
        "fidelity": "fast",
        "f1_error_estimate": pytest.approx(0.41 / 64),
        "axial": False,
        "gravity": True,
    }


def test_sweep_reduce_frf():
    sw = fs.sweep(grid="dense", step_mm=100, segments=SEG)
    d = check_result(sw)
    assert d["counts"].get("ok", 0) >= 1
    rom = fs.reduce(None, fs.Pose(0.0, 0.0, 0.0), n_modes=2, segments=SEG)
    check_result(rom)
    assert rom.n_modes == 2
    h = fs.frf(None, None, excitation=LinkPoint("distal_0", 0.5, "z"), f_max_hz=200, df_hz=1.0, segments=SEG)
    check_result(h, expect_resolution=False)  # an FRF carries no model parameters; the CLI adds them
    # the FRF's modes are the reduced model's (same model built from the same config and pose)
    assert h.modal_freq_hz[0] == pytest.approx(rom.frequencies_hz[0], rel=1e-12)


def test_rollout_builds_its_own_model():
    cfg = fs.default_config()
    res = fs.rollout(cfg, None, duration_s=0.002, output_step_s=1e-3, force_x_n=1.0, segments=SEG, axial=False)
    d = check_result(res)
    assert d["n_samples"] == len(res.t_s) == 3
    assert d["parameters"]["pose"] == {"x_m": 0.0, "y_m": 0.0, "phi_rad": 0.0}


@pytest.mark.slow
def test_reproduce():
    rep = fs.reproduce(segments=SEG, readability=False)
    d = check_result(rep)
    assert len(d["poses"]) == 25


def test_import_has_no_heavy_imports_or_side_effects():
    code = (
        "import os, sys; before = dict(os.environ); import fpm_sim; "
        "heavy = [m for m in ('jax', 'matplotlib', 'dm_control', 'control', 'mujoco') if m in sys.modules]; "
        "print(heavy, os.environ == before)"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL",)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip() == "[] True"


def test_public_entry_points_load_no_jax_matplotlib_dm_control():
    code = (
        "import sys, fpm_sim as fs; fs.modes; fs.rollout; fs.reproduce; fs.Pose; "
        "print([m for m in ('jax', 'matplotlib', 'dm_control', 'control') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_coarse_resolution_warns():
    from fpm_sim.model.options import ResolutionWarning

    with pytest.warns(ResolutionWarning, match="41 %"):  # 0.41 / 1^2; measured +54 % on f1
        fs.modes(segments=1, n_modes=1)
