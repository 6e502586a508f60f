"""fpm-sim: natural frequencies, modes and reduced models of flexible planar parallel manipulators on MuJoCo.

The public API, one screen (``import fpm_sim as fs``; everything is imported on first use, importing the
package has no side effects)::

    cfg = fs.default_config()                 # or fs.load_config("my.toml")
    pose = fs.Pose.from_mm(50, -20, 0.1)      # x, y (mm), phi (rad)
    fs.modes(cfg, pose)                       # natural frequencies and mode shapes at a pose
    fs.rig_modes(cfg, "cantilever")           # a subsystem rig
    fs.sweep(cfg, grid="paper")               # first frequencies over poses
    fs.reduce(cfg, pose, n_modes=6)           # reduced-order state-space model
    fs.frf(cfg, pose)                         # frequency response function
    fs.rollout(cfg, pose, force_x_n=1.0)      # nonlinear simulation
    fs.reproduce(cfg)                         # the study's tests and 25 poses
    fs.predict_bands("posterior.nc", pose)    # median and 5-95 % bands over a posterior's draws

Every result has ``.to_dict()``, ``.table()`` and ``.plot(ax=None)`` (a ``matplotlib`` ``Figure``).
Resolution: ``fidelity="fast" | "standard" | "fine"`` or ``segments=N`` in every entry point.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

_API = {
    "load_config": "fpm_sim.config",
    "default_config": "fpm_sim.config",
    "Pose": "fpm_sim.kinematics",
    "FpmSimError": "fpm_sim.errors",
    "FpmSimWarning": "fpm_sim.errors",
    "modes": "fpm_sim.api",
    "rig_modes": "fpm_sim.api",
    "sweep": "fpm_sim.api",
    "reduce": "fpm_sim.api",
    "frf": "fpm_sim.api",
    "rollout": "fpm_sim.api",
    "reproduce": "fpm_sim.api",
    "predict_bands": "fpm_sim.api",
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


def _public_frf_over_the_submodule() -> None:
    """``fs.frf`` is the API function although ``fpm_sim/frf.py`` is a submodule of the same name.

    Importing a submodule sets it as an attribute of its package; a property on the package's module
    class keeps the function there (the submodule stays importable by ``from fpm_sim.frf import ...``).
    """
    import sys
    import types

    class _Package(types.ModuleType):
        @property
        def frf(self) -> Any:
            from fpm_sim.api import frf

            return frf

        @frf.setter
        def frf(self, module: Any) -> None:
            self.__dict__["_frf_module"] = module

    sys.modules[__name__].__class__ = _Package


_public_frf_over_the_submodule()
