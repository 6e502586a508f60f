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

SEG = 3  # a tiny model: 3 spring locations per link
TINY = fs.ModelOptions(segments=SEG)


def check_result(result, *, expect_resolution: bool = True) -> dict:
    """The facade's result states its resolution (the result contract itself: tests/test_results.py)."""
    from fpm_sim.results import Result

    assert isinstance(result, Result)
    d = result.to_dict()
    json.dumps(d)  # JSON-ready
    if expect_resolution:
        assert d["resolution"]["segments"] == SEG
        assert d["resolution"]["f1_error_estimate"] == pytest.approx(0.41 / SEG**2)
    return d


FACADE = {
    "modes",
    "rig_modes",
    "sweep",
    "design",
    "reduce",
    "frf",
    "rollout",
    "move",
    "batched_rollouts",
    "impact",
    "ema",
    "identify",
    "calibrate",
    "predict_bands",
    "reproduce",
    "transient",
    "readability",
    "atlas",
    "export_mjcf",
    "ModelOptions",
    "LinkPoint",
    "Pose",
    "load_config",
    "default_config",
    "FpmSimError",
    "Result",
}


def test_public_names_are_lazy_and_listed():
    assert set(dir(fs)) >= FACADE
    with pytest.raises(AttributeError):
        fs.no_such_thing  # noqa: B018


def test_every_command_has_its_facade_function():
    """One function per command that computes (config and the atlas's query are not computations of their own)."""
    from fpm_sim.cli.main import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    # import writes a description file (fs.load_imported reads it; fs.modes(desc, q=...) computes on it)
    commands = {c.replace("-", "_") for c in sub.choices} - {"config", "import"}
    renamed = {"rig": "rig_modes", "check": "check_requirements"}
    assert {renamed.get(c, c) for c in commands} <= set(dir(fs))
    for name in FACADE - {"Result", "FpmSimError", "Pose", "ModelOptions", "LinkPoint"}:
        assert callable(getattr(fs, name))


def test_facade_signatures_put_config_first_and_options_once():
    """Config first, pose second, the rest keyword-only; the model options are one ``options`` parameter."""
    import inspect

    from fpm_sim import api

    # a posterior IS a set of descriptions (its draws'): it stands in the description's place, its poses (one or
    # several, as modes' pose) in the pose's
    in_place = {"predict_bands": {"posterior": "config", "poses": "pose"}, "plan_tests": {"posterior": "config"}}
    for name in api.__all__:
        if name == "ema":  # a file of measured FRFs first: no description, no pose
            continue
        rename = in_place.get(name, {})
        params = list(inspect.signature(getattr(api, name)).parameters.values())
        assert rename.get(params[0].name, params[0].name) == "config", name
        positional = [rename.get(p.name, p.name) for p in params if p.kind is p.POSITIONAL_OR_KEYWORD]
        assert positional in (["config"], ["config", "pose"], ["config", "rig"]), (name, positional)
        names = {p.name for p in params}
        if name == "calibrate":  # the likelihood's model is the pose loop's at one resolution, the fit's setting
            assert names & {"options", "fidelity", "link_model", "axial", "gravity"} == set(), name
            continue
        assert not names & {"fidelity", "segments", "link_model", "axial", "gravity"}, name
        if name != "identify":  # identify's fitted model: its own settings (segments, Timoshenko links)
            assert "options" in names, name


def test_frf_is_the_function_and_the_module_is_response():
    import importlib

    import fpm_sim.response as response

    assert callable(fs.frf)
    assert fs.frf is importlib.import_module("fpm_sim.api").frf
    assert response.LinkPoint is fs.LinkPoint
    assert not hasattr(importlib.import_module("fpm_sim"), "_public_frf_over_the_submodule")
    assert type(fs) is type(importlib)  # a plain module: no module-class trick


def test_modes_and_rig_modes():
    cfg = fs.default_config()
    pose = fs.Pose.from_mm(20, -10, 0.05)
    r = fs.modes(cfg, pose, options=TINY, n_modes=3)
    d = check_result(r)
    assert len(d["modes"]) == 3
    assert r.frequencies_hz[0] > 0
    # the same model through the library's own builder gives the same frequencies
    from fpm_sim.linear.analysis import analyse
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.options import ModelOptions

    direct = analyse(build_manipulator(cfg, pose, ModelOptions(segments=SEG)), "transition_fd", 3)
    assert list(r.frequencies_hz) == list(direct.frequencies_hz)
    rig = fs.rig_modes(cfg, "cantilever", options=TINY, n_modes=2)
    check_result(rig)
    assert rig.frequencies_hz[0] > 0


def test_fidelity_names_a_resolution():
    r = fs.modes(options=fs.ModelOptions(fidelity="fast", axial=False), n_modes=1)
    assert r.to_dict()["resolution"] == {
        "link_model": "segments",
        "segments": 8,
        "fidelity": "fast",
        "f1_error_estimate": pytest.approx(0.41 / 64),
        "axial": False,
        "gravity": True,
    }


def test_sweep_reduce_frf():
    sw = fs.sweep(grid="dense", step_mm=100, options=fs.ModelOptions(segments=SEG, axial=False, gravity=False))
    d = check_result(sw)
    assert d["counts"].get("ok", 0) >= 1
    rom = fs.reduce(None, fs.Pose(0.0, 0.0, 0.0), n_modes=2, options=TINY)
    check_result(rom)
    assert rom.n_modes == 2
    h = fs.frf(None, None, excitation=fs.LinkPoint("distal_0", 0.5, "z"), f_max_hz=200, df_hz=1.0, options=TINY)
    check_result(h, expect_resolution=False)  # an FRF carries no model parameters; the CLI adds them
    # the FRF's modes are the reduced model's (same model built from the same config and pose)
    assert h.modal_freq_hz[0] == pytest.approx(rom.frequencies_hz[0], rel=1e-12)


def test_rollout_builds_its_own_model():
    cfg = fs.default_config()
    res = fs.rollout(
        cfg,
        None,
        duration_s=0.002,
        output_step_s=1e-3,
        force_x_n=1.0,
        options=fs.ModelOptions(segments=SEG, axial=False),
    )
    d = check_result(res)
    assert d["n_samples"] == len(res.t_s) == 3
    assert d["parameters"]["pose"] == {"x_m": 0.0, "y_m": 0.0, "phi_rad": 0.0}


def test_rollout_stepping_options():
    """The facade's stepping keywords reach the rollout: the band, a given discrete step, the explicit reference."""
    kw = {"duration_s": 0.002, "output_step_s": 1e-3, "force_x_n": 1.0, "options": fs.ModelOptions(segments=SEG)}
    band = fs.rollout(band_hz=300.0, **kw).to_dict()["stepping"]
    assert (band["integrator"], band["band_hz"], band["band_source"]) == ("discrete", 300.0, "given")
    assert fs.rollout(step_s=5e-5, **kw).stepping.step_s == 5e-5
    assert fs.rollout(integrator="explicit", **kw).stepping.integrator == "explicit"
    with pytest.raises(fs.FpmSimError, match=r"^step_s: sets the discrete integrator's step"):
        fs.rollout(integrator="explicit", step_s=5e-5, **kw)


def test_batched_rollouts_are_the_single_rollouts():
    """Each row of fs.batched_rollouts is fs.rollout under that constant load (same model, same steps)."""
    import numpy as np

    kw = {"duration_s": 0.003, "output_step_s": 1e-3, "options": fs.ModelOptions(segments=SEG, axial=False)}
    wrenches = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.1]]
    res = fs.batched_rollouts(None, fs.Pose.from_mm(10, 0, 0), wrenches=wrenches, threads=2, **kw)
    d = check_result(res)
    assert [r["wrench"] for r in d["rollouts"]] == [
        {"fx_n": 1.0, "fy_n": 0.0, "mz_nm": 0.0},
        {"fx_n": 0.0, "fy_n": 2.0, "mz_nm": 0.1},
    ]
    disp = res.to_xarray()["ee_disp"].values
    for w, row in zip(wrenches, disp):
        single = fs.rollout(
            None, fs.Pose.from_mm(10, 0, 0), force_x_n=w[0], force_y_n=w[1], moment_z_nm=w[2], accel_fraction=None, **kw
        )
        assert single.stepping.to_dict() == d["stepping"]
        # same model and steps, mujoco.rollout against mj_step: round-off only (tests/sim/test_batched.py: 1.6e-15 m)
        assert np.abs(single.ee_disp - row).max() < 1e-12
        assert np.abs(row).max() > 1e-7  # the load moved it
    with pytest.raises(fs.FpmSimError, match=r"^threads: must be an integer >= 1, got 0$"):
        fs.batched_rollouts(wrenches=wrenches, threads=0, **kw)


def test_move_is_the_library_move(tmp_path):
    """fs.move is simulate_move on the same path; a CSV of its commanded path commands the same path."""
    import numpy as np

    from fpm_sim.sim.trajectory import MovePath, simulate_move

    cfg = fs.default_config()
    opts = fs.ModelOptions(segments=SEG, axial=False)
    end = fs.Pose.from_mm(5, 0, 0)
    kw = {"settle_s": 0.003, "output_step_s": 1e-4, "options": opts}
    res = fs.move(cfg, None, end=end, move_s=0.01, **kw)
    d = check_result(res)
    assert d["move_end_s"] == 0.01
    ref = simulate_move(cfg, MovePath(fs.Pose(0.0, 0.0, 0.0), end, 0.01), **kw)
    np.testing.assert_array_equal(res.ee_pose, ref.ee_pose)
    csv = tmp_path / "path.csv"
    rows = [",".join(f"{v:.17g}" for v in (t, c[0] * 1e3, c[1] * 1e3, c[2])) for t, c in zip(res.t_s, res.command)]
    csv.write_text("t_s,x_mm,y_mm,phi_rad\n" + "\n".join(rows) + "\n")
    sampled = fs.move(cfg, path_csv=csv, **kw)
    n = len(res.t_s)
    np.testing.assert_allclose(sampled.command[:n], res.command, rtol=0, atol=1e-15)  # mm -> m rounding only
    assert sampled.to_dict()["parameters"]["profile"] == "csv"
    with pytest.raises(fs.FpmSimError, match=r"^path_csv: a sampled path sets its own start and end poses"):
        fs.move(cfg, fs.Pose(0.0, 0.0, 0.0), path_csv=csv)


@pytest.mark.slow
def test_reproduce():
    rep = fs.reproduce(options=fs.ModelOptions(segments=SEG, axial=False, gravity=False), readability=False)
    d = check_result(rep)
    assert len(d["poses"]) == 25


def test_import_has_no_heavy_imports_or_side_effects():
    code = (
        "import os, sys; before = dict(os.environ); import fpm_sim; "
        "heavy = [m for m in ('jax', 'matplotlib', 'dm_control', 'control', 'mujoco', 'scipy', 'xarray') "
        "if m in sys.modules]; "
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
        fs.modes(options=fs.ModelOptions(segments=1), n_modes=1)


def test_no_public_name_is_shadowed_by_a_submodule():
    """Importing a submodule sets it on the package: a submodule named like a public function would replace it."""
    import pkgutil

    submodules = {m.name for m in pkgutil.iter_modules(fs.__path__)}
    assert not submodules & set(fs.__all__), submodules & set(fs.__all__)
    import importlib

    importlib.import_module("fpm_sim.designs")  # the package beside fs.design
    importlib.import_module("fpm_sim.response")  # the module beside fs.frf
    assert callable(fs.design)
    assert callable(fs.frf)


def test_export_mjcf_is_the_model_the_other_entry_points_solve():
    from fpm_sim.model.manipulator import build_manipulator
    from fpm_sim.model.rigs import RigSetup, build_rig, rig_piece

    cfg, pose = fs.default_config(), fs.Pose.from_mm(20, 0, 0)
    xml = fs.export_mjcf(cfg, pose, options=TINY)
    assert xml.lstrip().startswith("<mujoco")
    assert xml == build_manipulator(cfg, pose, TINY).to_xml()
    rig = fs.export_mjcf(cfg, rig="chain", angle_deg=120.0, options=TINY)
    direct = build_rig(RigSetup("chain", angle_deg=120.0), rig_piece(cfg), TINY, compliance=cfg.compliance)
    assert rig == direct.to_xml()
    assert rig != fs.export_mjcf(cfg, rig="chain", options=TINY)  # the hinge angle reaches the model


def test_design_and_sweep_agree_at_the_same_poses():
    """Two entry points over the same pose loop: the base design's frequencies are the sweep's."""
    import numpy as np

    loop = fs.ModelOptions(segments=SEG, axial=False, gravity=False)
    poses = [fs.Pose.from_mm(0, 0, 0), fs.Pose.from_mm(40, -30, 0.05)]
    sw = fs.sweep(grid="poses", poses=poses, options=loop)
    des = fs.design(poses=poses, vary={"hardware.payload.mass_kg": [fs.default_config().hardware.payload.mass_kg, 2.0]},
                    options=loop)  # fmt: skip
    np.testing.assert_allclose(des.frequencies_hz[0], sw.frequencies.frequencies_hz, rtol=1e-12)
    assert np.all(des.frequencies_hz[1, :, 0] < des.frequencies_hz[0, :, 0])  # a heavier payload: lower f1


def test_calibrate_is_the_library_calibration():
    """fs.calibrate reads the data and priors as the CLI does and samples (a few calls: the wiring, not the
    posterior; the sampler's accuracy is tests/study/test_calibrate_*)."""
    from importlib import resources

    from fpm_sim.study.calibrate import Calibration, SamplerOptions

    data = resources.files("fpm_sim.data")
    cal = fs.calibrate(
        priors=str(data / "study_priors.toml"),
        measured=[str(data / "measured_table4_train.csv")],
        reading="x+",
        segments=2,
        sampler=SamplerOptions(live_points=14, max_calls=40, walks=2, draws=5, runs=1),
    )
    assert isinstance(cal, Calibration)
    assert cal.problem.names[:2] == ["geometry.base_radius_m", "geometry.platform_radius_m"]
    assert len(cal.problem.observations) == 12
    with pytest.raises(fs.FpmSimError, match="priors"):
        fs.calibrate(priors="no_such_priors.toml", measured=[str(data / "measured_table4_train.csv")], reading="x+")
