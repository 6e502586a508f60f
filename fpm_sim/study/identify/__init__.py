"""Model updating from measured modal data (``fpm-sim identify``).

- :mod:`.data`: measured frequencies and rig tests from CSV;
- :mod:`.parameters`: the named parameter groups ``--free`` picks, as data (:class:`ParameterSpec`), and the
  one function that applies them to a description; light to import (no MuJoCo, SciPy or JAX);
- :mod:`.problem`: what is fitted (:class:`Problem`), the search settings, the model's predictions;
- :mod:`.objective`: the picklable residual function every search minimises;
- :mod:`.strategies`: the searches behind one protocol (differential evolution, Latin hypercube, in-plane
  surrogate, least squares), their candidates as dataclasses, ``spawn`` worker pools;
- :mod:`.engine`: :func:`identify` (global search, local refinement, uncertainty) and k-fold cross-validation;
- :mod:`.report`: ``config.toml``, ``identify.json``, ``report.md`` and figures, written atomically.

The names below are imported on first use (PEP 562), so that importing :mod:`.parameters` imports nothing
heavy.
"""

from __future__ import annotations

from typing import Any

_NAMES = {
    "DEFAULT_SIGMA_PCT": "fpm_sim.study.identify.data",
    "DataError": "fpm_sim.study.identify.data",
    "DataSet": "fpm_sim.study.identify.data",
    "Observation": "fpm_sim.study.identify.data",
    "read_measured_csv": "fpm_sim.study.identify.data",
    "read_subsystems_csv": "fpm_sim.study.identify.data",
    "GROUPS": "fpm_sim.study.identify.parameters",
    "ParameterError": "fpm_sim.study.identify.parameters",
    "ParameterSet": "fpm_sim.study.identify.parameters",
    "ParameterSpec": "fpm_sim.study.identify.parameters",
    "parameter_set": "fpm_sim.study.identify.parameters",
    "GLOBAL_METHODS": "fpm_sim.study.identify.problem",
    "IdentificationError": "fpm_sim.study.identify.problem",
    "IdentifyOptions": "fpm_sim.study.identify.problem",
    "Problem": "fpm_sim.study.identify.problem",
    "predict_observations": "fpm_sim.study.identify.problem",
    "workspace_residuals": "fpm_sim.study.identify.problem",
    "Candidate": "fpm_sim.study.identify.strategies",
    "CrossValidation": "fpm_sim.study.identify.engine",
    "Identification": "fpm_sim.study.identify.engine",
    "cross_validate": "fpm_sim.study.identify.engine",
    "fold_assignment": "fpm_sim.study.identify.engine",
    "identify": "fpm_sim.study.identify.engine",
    "predict_with_std": "fpm_sim.study.identify.engine",
}

__all__ = sorted(_NAMES)


def __getattr__(name: str) -> Any:
    """Import the public names on first use (PEP 562)."""
    if name in _NAMES:
        import importlib

        value = getattr(importlib.import_module(_NAMES[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'fpm_sim.study.identify' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
