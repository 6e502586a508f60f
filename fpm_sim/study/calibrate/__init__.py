"""Bayesian calibration (``fpm-sim calibrate``): a posterior over the unknowns by nested sampling.

- :mod:`.priors`: one distribution per free parameter, the study's statements, from TOML;
- :mod:`.problem`: the picklable :class:`CalibrationProblem` (prior transform, likelihood with a
  model-discrepancy term);
- :mod:`.sampler`: dynesty in a ``spawn`` pool, checkpoint and resume;
- :mod:`.posterior`: ``posterior.nc`` (ArviZ) and ``config.toml`` (the posterior median);
- :mod:`.report`: ``report.md`` and figures.
"""

from fpm_sim.study.calibrate.priors import Prior, PriorError, Priors, read_priors
from fpm_sim.study.calibrate.problem import CalibrationError, CalibrationProblem
from fpm_sim.study.calibrate.sampler import Calibration, SamplerOptions, run_calibration

__all__ = [
    "Calibration",
    "CalibrationError",
    "CalibrationProblem",
    "Prior",
    "PriorError",
    "Priors",
    "SamplerOptions",
    "read_priors",
    "run_calibration",
]
