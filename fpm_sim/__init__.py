"""fpm-sim: natural frequencies, modes and reduced models of flexible planar parallel manipulators on MuJoCo.

The public API, one screen (``import fpm_sim as fs``; everything is imported on first use, importing the
package has no side effects). One function per command; the description first, the pose second, everything
else keyword-only; the model options are one ``options=fs.ModelOptions(...)``::

    cfg = fs.default_config()                 # or fs.load_config("my.toml")
    pose = fs.Pose.from_mm(50, -20, 0.1)      # x, y (mm), phi (rad)
    fast = fs.ModelOptions(fidelity="fast")   # or segments=N, link_model=, axial=, gravity=, ...
    fs.modes(cfg, pose, options=fast)         # natural frequencies and mode shapes at a pose
    fs.rig_modes(cfg, "cantilever")           # a subsystem rig
    fs.sweep(cfg, grid="paper")               # first frequencies over poses
    fs.design(cfg, poses=[pose], vary={"section.thickness_m": [0.02, 0.03]})
    fs.reduce(cfg, pose, n_modes=6)           # reduced-order state-space model
    fs.frf(cfg, pose, excitation=fs.LinkPoint("distal_0", 0.5, "z"))
    fs.rollout(cfg, pose, force_x_n=1.0)      # nonlinear simulation
    fs.move(cfg, pose, end=fs.Pose.from_mm(80, -20, 0.1))  # point-to-point move: residual vibration
    fs.batched_rollouts(cfg, pose, wrenches=[[1, 0, 0], [0, 1, 0]])  # many loads in mujoco.rollout's threads
    fs.impact(cfg, pose)                      # virtual hammer test
    fs.transient(cfg)                         # the study's transient: full model vs reduced model
    fs.readability(cfg)                       # mode-1 readability at the study's poses
    fs.atlas(cfg, x_m=[-0.05, 0, 0.05], y_m=[0.0])  # modal atlas (.query(pose))
    fs.ema("frfs.uff", f_lower_hz=5, f_upper_hz=200)  # modes from measured FRFs
    fs.identify(cfg, measured=["f.csv"])      # model updating
    fs.calibrate(cfg, priors="p.toml", measured=["f.csv"])  # Bayesian updating: a posterior
    fs.reproduce(cfg)                         # the study's tests and 25 poses
    fs.export_mjcf(cfg, pose)                 # the generated MJCF
    delta = fs.load_description("examples/architectures/delta.toml")  # any architecture (docs/architectures.md)
    fs.modes(delta, fs.TaskPose.from_mm(x_mm=50, z_mm=-320))          # in its own task coordinates
    arm = fs.load_imported("acrobot.toml")    # a MuJoCo model with links made flexible (fpm-sim import)
    fs.modes(arm, q={"shoulder": 0.3})        # posed in joint space (rad, m)
    fs.check_requirements(fs.load_requirements("fpm-requirements.toml"), cfg)  # docs/testing.md
    fs.predict_bands("posterior.nc", pose)    # median and 5-95 % bands over a posterior's draws
    fs.plan_tests("posterior.nc", k=3)        # which measurements would narrow those bands most

Every result keeps :class:`fpm_sim.results.Result`: ``.to_dict()`` (JSON-ready), ``.table()`` (text) and
``.plot(ax=None)`` (a ``matplotlib`` ``Figure``); frequencies over poses are ``.to_xarray()``.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

_API = {
    "load_config": "fpm_sim.config",
    "default_config": "fpm_sim.config",
    "Pose": "fpm_sim.kinematics",
    "load_description": "fpm_sim.architecture",
    "TaskPose": "fpm_sim.architecture",
    "load_imported": "fpm_sim.architecture.imported",
    "ModelOptions": "fpm_sim.model.options",
    "LinkPoint": "fpm_sim.response",
    "FpmSimError": "fpm_sim.errors",
    "FpmSimWarning": "fpm_sim.errors",
    "Result": "fpm_sim.results",
    "modes": "fpm_sim.api",
    "rig_modes": "fpm_sim.api",
    "sweep": "fpm_sim.api",
    "design": "fpm_sim.api",
    "reduce": "fpm_sim.api",
    "frf": "fpm_sim.api",
    "rollout": "fpm_sim.api",
    "move": "fpm_sim.api",
    "batched_rollouts": "fpm_sim.api",
    "impact": "fpm_sim.api",
    "transient": "fpm_sim.api",
    "readability": "fpm_sim.api",
    "atlas": "fpm_sim.api",
    "ema": "fpm_sim.api",
    "identify": "fpm_sim.api",
    "calibrate": "fpm_sim.api",
    "reproduce": "fpm_sim.api",
    "export_mjcf": "fpm_sim.api",
    "load_requirements": "fpm_sim.study.requirements",
    "check_requirements": "fpm_sim.study.requirements",
    "predict_bands": "fpm_sim.api",
    "plan_tests": "fpm_sim.api",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    """Import the public names on first use (PEP 562)."""
    if name in _API:
        import importlib

        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'fpm_sim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
