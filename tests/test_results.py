"""The result contract (fpm_sim.results.Result) for every public result type, JSON-ready conversion, and the one
xarray shape of frequencies over poses."""

import functools
import json
import math
import warnings
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")  # the tests' choice; the library never selects a backend

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

import fpm_sim as fs
from fpm_sim.results import Result, frequencies_dataset, to_jsonable

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "architectures"
SEG = 3  # a tiny model: every instance here is built in well under a second or a few
TINY = fs.ModelOptions(segments=SEG)
LOOP = fs.ModelOptions(segments=SEG, axial=False, gravity=False)  # the pose loop's options at the tiny resolution
POSES = [fs.Pose.from_mm(0, 0, 0), fs.Pose.from_mm(50, -50, 0)]
REPR_MARKS = ("array(", "<", "Pose(", "dtype", "np.float", "object at 0x")
"""What a Python repr leaves in a string (``array([...])``, ``<Figure ...>``, ``Pose(x_m=...)``)."""


def _quiet(build):
    @functools.wraps(build)
    def wrapper(*args, **kwargs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the tiny resolution's ResolutionWarning
            return build(*args, **kwargs)

    return functools.cache(wrapper)


@_quiet
def _sweep(grid="dense"):
    if grid == "paper":
        return fs.sweep(grid="paper", options=LOOP)
    return fs.sweep(grid="poses", poses=POSES, options=LOOP)


@_quiet
def _frf():
    return fs.frf(options=TINY, f_max_hz=150.0, df_hz=0.5)


@_quiet
def _identification():
    import tempfile
    from pathlib import Path

    from fpm_sim.study.identify import IdentifyOptions

    poses = [*POSES, fs.Pose.from_mm(-50, 50, 0), fs.Pose.from_mm(50, 50, 0)]
    f1 = 1.03 * fs.sweep(grid="poses", poses=poses, options=LOOP).frequencies.f1_hz  # a heavier-looking machine
    folder = Path(tempfile.mkdtemp())
    csv = folder / "measured.csv"
    csv.write_text(
        "x_mm,y_mm,phi_rad,f1_hz\n"
        + "".join(f"{p.x_m * 1e3:g},{p.y_m * 1e3:g},{p.phi_rad:g},{f:.6f}\n" for p, f in zip(poses, f1))
    )
    settings = IdentifyOptions(segments=SEG, global_method="none", max_nfev=3)
    return fs.identify(measured=[csv], free=["hardware"], settings=settings)


def _cross_validation():
    from fpm_sim.study.identify import cross_validate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cross_validate(_identification(), folds=2, max_nfev=2)


def _ema():
    import tempfile
    from pathlib import Path

    path = _frf().save_csv(Path(tempfile.mkdtemp()) / "frf.csv")
    return fs.ema(path, f_lower_hz=5.0, f_upper_hz=150.0, n_modes=1, pol_order=20)[0]


def _impact():
    from fpm_sim.sim.impact import ImpactSetup

    setup = ImpactSetup(n_impacts=1, record_s=0.05, pad_s=0.1, f_max_hz=200.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fs.impact(options=fs.ModelOptions(segments=SEG, axial=False), setup=setup)


def _quiet_call(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)


def _joint_sweep():
    """A one-link pendulum arm (inline MJCF) made flexible, swept over two joint-space poses."""
    import tempfile

    folder = Path(tempfile.mkdtemp())
    (folder / "arm.xml").write_text(
        '<mujoco><worldbody><body name="arm"><joint name="j" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.01"/><site name="tip" pos="0.5 0 0"/>'
        "</body></worldbody></mujoco>"
    )
    (folder / "arm.toml").write_text(
        'kind = "imported"\nmodel = "arm.xml"\nlocked_joints = ["j"]\n[materials.steel]\nyoung_pa = 200e9\n'
        'poisson = 0.3\ndensity_kg_m3 = 7850.0\n[sections.bar]\nshape = "rect"\nthickness_m = 0.006\n'
        'height_m = 0.025\n[[flexible]]\nbody = "arm"\nsection = "bar"\nmaterial = "steel"\nend_site = "tip"\n'
    )
    desc = fs.load_imported(folder / "arm.toml")
    return _quiet_call(fs.sweep, desc, poses=[{"j": 0.0}, {"j": 0.5}], options=fs.ModelOptions(segments=SEG))


def _described_identification():
    from fpm_sim.study.identify.described import TaskMeasurements, identify_description

    data = TaskMeasurements("twin", [fs.TaskPose(0.0, 0.25)], np.array([[30.0]]), np.array([[0.6]]))
    desc = fs.load_description(EXAMPLES / "five_bar.toml")
    free = {"sections.bar.height_m": (0.003, 0.012)}
    return _quiet_call(identify_description, desc, data, free, options=LOOP, max_nfev=3)


def _readability():
    from fpm_sim.study.poses import study_poses

    return _quiet_call(fs.readability, options=LOOP, poses=study_poses()[:2], f_max_hz=150.0)


def _reproduction():
    from fpm_sim.study.reproduce import StudyReproduction

    return StudyReproduction.from_sweep(_sweep("paper"), None)


@functools.cache
def _posterior():
    import tempfile
    from pathlib import Path

    from fpm_sim.study.posterior import Posterior
    from tests.helpers.posterior import write_posterior

    return Posterior.from_netcdf(write_posterior(Path(tempfile.mkdtemp()) / "posterior.nc"))


@_quiet
def _bands():
    return fs.predict_bands(_posterior(), POSES, draws=3, n_modes=2, options=LOOP, workers=1)


def _study_bands():
    from fpm_sim.study.posterior import StudyBands

    f1 = float(_bands().median_hz[0, 0])  # a measured pose (at the median) and a withheld one
    measured_hz, withheld = np.array([f1, np.nan]), np.array([False, True])
    return StudyBands(bands=_bands(), measured_hz=measured_hz, withheld=withheld, reading="x+")


@_quiet
def _design_bands():
    from fpm_sim.batch.engine import EngineOptions
    from fpm_sim.designs.robust import design_over_draws

    draws = _posterior().configs(2)
    vary = {"section.thickness_m": [0.02, 0.03]}
    return design_over_draws(
        draws, poses=POSES, f_min_hz=5.0, vary=vary, options=LOOP, engine=EngineOptions(scheduler="serial")
    )


BUILDERS = {
    "ModalResult": lambda: _quiet_call(fs.modes, options=TINY, n_modes=3),
    "ModalComparison": lambda: _quiet_call(fs.modes, options=TINY, n_modes=3, method="both"),
    "ReducedModel": lambda: _quiet_call(fs.reduce, options=TINY, n_modes=3),
    "StepResponse": lambda: _quiet_call(fs.reduce, options=TINY, n_modes=3).step_response("force_x", duration_s=0.01),
    "FrequencyResponse": _frf,
    "RolloutResult": lambda: _quiet_call(
        fs.rollout, duration_s=0.002, output_step_s=1e-3, force_x_n=1.0, options=fs.ModelOptions(segments=SEG)
    ),
    "ImpactTestResult": _impact,
    "BatchedRollouts": lambda: _quiet_call(
        fs.batched_rollouts,
        wrenches=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        duration_s=0.002,
        output_step_s=1e-3,
        options=fs.ModelOptions(segments=SEG),
    ),
    "MoveResult": lambda: _move(),
    "Stepping": lambda: _move().stepping,
    "WorkspaceSweep": _sweep,
    "TaskSweep": lambda: _quiet_call(
        fs.sweep,
        fs.load_description(EXAMPLES / "five_bar.toml"),
        grid="poses",
        poses=[fs.TaskPose(0.0, 0.25), fs.TaskPose(0.04, 0.18), fs.TaskPose(0.0, 0.6)],
        options=fs.ModelOptions(segments=SEG),
    ),
    "JointSweep": _joint_sweep,
    "PoseFrequencies": lambda: _sweep().frequencies,
    "StudyReproduction": _reproduction,
    "DescribedIdentification": _described_identification,
    "DesignResult": lambda: _quiet_call(
        fs.design, poses=POSES, vary={"hardware.payload.mass_kg": [0.0, 0.5]}, options=LOOP
    ),
    "PredictiveBands": _bands,
    "StudyBands": _study_bands,
    "DesignBands": _design_bands,
    "ModalAtlas": lambda: _quiet_call(fs.atlas, x_m=[0.0, 0.02], y_m=[0.0], n_modes=2, n_extra=1, options=LOOP),
    "ReadabilityTable": _readability,
    "TransientResult": lambda: _quiet_call(
        fs.transient, duration_s=0.003, output_step_s=1e-3, options=fs.ModelOptions(segments=2), n_modes=3
    ),
    "Identification": _identification,
    "CrossValidation": _cross_validation,
    "ModalEstimate": _ema,
    "CheckReport": lambda: _check_report(),
    "Calibration": lambda: _calibration(),
    "LeaveOneOut": lambda: _leave_one_out(),
    "PlanResult": lambda: _plan(),
}


def _plan():
    """A small plan on the shipped posterior: 12 draws, two candidate poses, two target poses."""
    return _quiet_call(
        fs.plan_tests,
        candidates=[fs.Pose.from_mm(0, 0, 0.2), fs.Pose.from_mm(50, 50, 0.2)],
        quantities=["f1"],
        target=[fs.Pose.from_mm(0, 50, 0.0), fs.Pose.from_mm(-50, 0, 0.0)],
        k=1,
        draws=12,
        outcomes=8,
        workers=1,
    )


def _leave_one_out():
    """PSIS leave-one-out of the shipped posterior (its data groups hold what it needs: no model is built)."""
    from fpm_sim.study.posterior import Posterior, default_posterior_path

    path = default_posterior_path()
    assert path is not None
    loo = Posterior.from_netcdf(path).leave_one_out()
    assert loo is not None
    return loo


@_quiet
def _calibration():
    """A few live points on the in-plane surrogate (no MuJoCo model): well under a second of sampling."""
    import dataclasses

    from fpm_sim.study.calibrate import CalibrationProblem, SamplerOptions, read_priors, run_calibration
    from fpm_sim.study.identify import Observation

    names = ["hardware.platform.mass_kg", "hardware.elbow_joint.mass_kg", "hardware.platform_joint.mass_kg"]
    priors = read_priors(
        "p.toml",
        names,
        text="".join(
            f'[parameters."{n}"]\ndist = "uniform"\nlower = {lo}\nupper = {hi}\nreason = "assumed: test"\n'
            for n, lo, hi in zip(names, (0.5, 0.3, 0.3), (5.0, 0.31, 0.31))
        ),
    )
    obs = tuple(Observation(p, 1, 1.0, 1.0, None, "t") for p in POSES)
    prob = CalibrationProblem(fs.default_config(), ("hardware",), priors, obs, model="inplane")
    f_hz = prob.predict(np.array([1.5, 0.305, 0.305]))  # a synthetic truth's frequencies as the data
    obs = tuple(dataclasses.replace(o, freq_hz=float(f)) for o, f in zip(obs, f_hz))
    prob = dataclasses.replace(prob, observations=obs)
    return run_calibration(prob, SamplerOptions(live_points=8, dlogz=10.0, sample="unif", draws=20), progress=False)


@_quiet
def _move():
    opts = fs.ModelOptions(segments=SEG, axial=False)
    return fs.move(end=fs.Pose.from_mm(5, 0, 0), move_s=0.01, settle_s=0.003, options=opts)


@_quiet
def _check_report():
    from pathlib import Path

    from fpm_sim.study.requirements import check_requirements, parse_requirements

    reqs = parse_requirements(
        {
            "settings": {"segments": SEG},
            "requirement": [
                {"name": "f1 floor", "kind": "min_frequency", "at_least_hz": 1.0, "mode": 1,
                 "poses": {"list": [[0, 0, 0.0], [50, -50, 0.0]]}},
            ],
        },
        Path("fpm-requirements.toml"),
    )
    return check_requirements(reqs, fs.default_config())


def test_every_public_result_class_is_built_here():
    """The list above names every result class of the package (a new one must join the contract test)."""
    import importlib
    import inspect
    import pkgutil

    import fpm_sim

    found = set()
    for mod in pkgutil.walk_packages(fpm_sim.__path__, "fpm_sim."):
        if ".cli" in mod.name or mod.name.endswith(("jax_backend", "mjx_backend", "dm_env")):
            continue
        module = importlib.import_module(mod.name)
        for name, obj in vars(module).items():
            if inspect.isclass(obj) and obj.__module__ == mod.name and not name.startswith("_"):
                if all(callable(getattr(obj, m, None)) for m in ("to_dict", "table")) or name.endswith(
                    ("Result", "Comparison", "Reproduction", "Sweep", "Frequencies", "Response", "Atlas")
                ):
                    found.add(name)
    rows = {
        "Result": "the protocol itself",
        "SubsystemResult": "one row of StudyReproduction (its subsystems)",
        "FpmSweep": "the pytest plugin's session cache of sweeps (a fixture, not an answer)",
        "ModeFrequencies": "the pytest plugin's comparison operand (one column of a PoseFrequencies)",
        "ClassResult": "one elbow-branch class's samples inside a Calibration (its classes)",
        "RunsCheck": "the between-run check inside a Calibration (its runs_check, in its table and to_dict)",
    }
    assert found - set(rows) <= set(BUILDERS), found - set(rows) - set(BUILDERS)


@pytest.mark.parametrize("name", list(BUILDERS))
def test_result_contract(name):
    r = BUILDERS[name]()
    assert type(r).__name__ == name
    assert isinstance(r, Result)
    d = r.to_dict()
    assert isinstance(d, dict)
    raw = json.dumps(d)  # JSON-ready as it is (NaN allowed here: to_jsonable makes it standard)
    for mark in REPR_MARKS:
        assert mark not in raw, (name, mark, raw[max(0, raw.find(mark) - 80) : raw.find(mark) + 80])
    json.dumps(to_jsonable(d), allow_nan=False)
    text = r.table()
    assert isinstance(text, str)
    assert text.strip()
    fig = r.plot()
    assert isinstance(fig, Figure)
    plt.close(fig)
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d") if name == "ModalResult" else fig.add_subplot()  # mode shapes are 3D
    assert r.plot(ax=ax) is fig
    assert ax.has_data()  # drawn into the given axes
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# the one xarray shape of frequencies over poses


def check_frequency_dataset(ds, f_hz, poses, status):
    assert ds["freq_hz"].dims[-2:] == ("pose", "mode")
    np.testing.assert_array_equal(ds["freq_hz"].values, f_hz)
    assert list(ds["mode"].values) == list(range(1, f_hz.shape[-1] + 1))
    for c in ("x_mm", "y_mm", "phi_rad"):
        assert ds[c].dims == ("pose",)
    np.testing.assert_allclose(ds["x_mm"].values, [p.x_m * 1e3 for p in poses], rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds["y_mm"].values, [p.y_m * 1e3 for p in poses], rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds["phi_rad"].values, [p.phi_rad for p in poses], rtol=0, atol=1e-12)
    assert [str(s) for s in np.ravel(ds["status"].values)] == list(np.ravel(status))


def test_sweep_pose_frequencies_and_reproduction_share_the_dataset_shape():
    sw = _sweep()
    fr = sw.frequencies
    for ds in (sw.to_xarray(), fr.to_xarray()):
        check_frequency_dataset(ds, fr.frequencies_hz, fr.poses, fr.status)
    rep = _reproduction()
    ds = rep.to_xarray()
    check_frequency_dataset(ds, rep.frequencies.frequencies_hz, rep.frequencies.poses, rep.frequencies.status)
    np.testing.assert_array_equal(ds["comsol_hz"].values, rep.comsol_hz)
    assert ds.attrs["reading"] == rep.reading.name


def test_design_and_atlas_share_the_dataset_shape():
    res = BUILDERS["DesignResult"]()
    ds = res.to_xarray()
    assert ds["freq_hz"].dims == ("hardware.payload.mass_kg", "pose", "mode")
    for d in range(2):
        sel = ds.isel({"hardware.payload.mass_kg": d})
        check_frequency_dataset(sel, res.frequencies_hz[d], res.poses, res.status[d])
    atlas = BUILDERS["ModalAtlas"]()
    ds = atlas.to_xarray()
    poses = atlas.poses()
    f = np.array([[atlas.nodes["label_freq_hz"][i, 0, 0, k] for k in range(2)] for i in range(2)])
    check_frequency_dataset(ds, f, poses, ["ok"] * len(poses))


def test_posterior_bands_share_the_dataset_shape():
    b = _bands()
    ds = b.dataset
    assert ds["freq_hz"].dims == ("draw", "pose", "mode")
    for d in range(b.n_draws):
        check_frequency_dataset(ds.isel(draw=d), b.frequencies_hz[d], b.poses, b.status[d])
    np.testing.assert_array_equal(ds["freq_quantile_hz"].values, b.quantiles_hz)
    assert list(ds["draw"].values) == b.draw_index.tolist()


def test_frequencies_dataset_with_a_draw_dimension_and_its_checks():
    f = np.arange(2 * 3 * 4, dtype=float).reshape(2, 3, 4)
    ds = frequencies_dataset(
        f, x_mm=[0, 1, 2], y_mm=[3, 4, 5], phi_rad=[0, 0, 0.1], status=["ok", "ok", "singular"],
        leading={"draw": [0, 1]},
    )  # fmt: skip
    assert ds["freq_hz"].dims == ("draw", "pose", "mode")
    assert ds["freq_hz"].sel(draw=1, pose=2, mode=4).item() == f[1, 2, 3]
    assert ds["status"].sel(pose=2).item() == "singular"
    with pytest.raises(ValueError, match="expected 3"):
        frequencies_dataset(f[0, 0], x_mm=[0], y_mm=[0], phi_rad=[0], status=["ok"], leading={"draw": [0]})


def test_xarray_stays_lazy():
    import subprocess
    import sys

    code = "import sys, fpm_sim, fpm_sim.results; print('xarray' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == (
        "False"
    )


# ---------------------------------------------------------------------------------------------
# JSON-ready conversion


def test_numpy_values_tuples_and_non_finite_floats_become_standard_json():
    value = {
        1: (np.float64(1.5), np.int64(3)),
        "a": np.array([[1.0, math.inf], [math.nan, -2.0]]),
        "b": [np.float32(0.25), "text", None],
    }
    out = to_jsonable(value)
    assert out == {"1": [1.5, 3], "a": [[1.0, "inf"], ["nan", -2.0]], "b": [0.25, "text", None]}
    assert json.loads(json.dumps(out, allow_nan=False)) == out  # standard JSON: no NaN/Infinity tokens


def test_a_task_sweep_shares_the_dataset_shape():
    sw = BUILDERS["TaskSweep"]()
    assert sw.status == ["ok", "ok", "unreachable"]
    check_frequency_dataset(sw.to_xarray(), sw.freq_hz, sw.poses, sw.status)
