"""Model updating from measured modal data (``fpm-sim identify``).

- :mod:`.data`: measured frequencies and rig tests from CSV;
- :mod:`.parameters`: the named parameter groups ``--free`` picks;
- :mod:`.engine`: global search, local least squares, uncertainty, k-fold cross-validation;
- :mod:`.report`: ``config.toml``, ``identify.json``, ``report.md`` and figures, written atomically.
"""

from fpm_sim.study.identify.data import (
    DEFAULT_SIGMA_PCT,
    DataError,
    DataSet,
    Observation,
    read_measured_csv,
    read_subsystems_csv,
)
from fpm_sim.study.identify.engine import (
    GLOBAL_METHODS,
    CrossValidation,
    Identification,
    IdentifyOptions,
    Problem,
    cross_validate,
    fold_assignment,
    identify,
    predict_observations,
    predict_with_std,
    workspace_residuals,
)
from fpm_sim.study.identify.parameters import GROUPS, ParameterError, ParameterSet, parameter_set

__all__ = [
    "DEFAULT_SIGMA_PCT",
    "GLOBAL_METHODS",
    "GROUPS",
    "CrossValidation",
    "DataError",
    "DataSet",
    "Identification",
    "IdentifyOptions",
    "Observation",
    "ParameterError",
    "ParameterSet",
    "Problem",
    "cross_validate",
    "fold_assignment",
    "identify",
    "parameter_set",
    "predict_observations",
    "predict_with_std",
    "read_measured_csv",
    "read_subsystems_csv",
    "workspace_residuals",
]
