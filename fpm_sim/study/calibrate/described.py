"""Calibration of a described architecture (``fpm-sim calibrate --config machine.toml``): a posterior over dotted paths
into its file (:mod:`fpm_sim.architecture.edit`) from natural frequencies measured at poses in its task coordinates.

Priors: the priors file's form (:mod:`fpm_sim.study.calibrate.priors`) with dotted paths as the parameters' names,
``[parameters."sections.bar.height_m"]``, and/or bounds given with the free paths (``PATH=lo:hi``: uniform between
them, :func:`described_priors`). Every path must name a number of the file, and every value a prior can draw must
give a valid file (checked at its bounds, or at the 0.01 % and 99.99 % quantiles of an unbounded one).

Data: identify's measured file of a described machine
(:func:`~fpm_sim.study.identify.described.read_task_measured_csv`: task coordinates in mm / rad, ``f1_hz, f2_hz, ...``,
optional ``sigma_hz``).

What is compared: each measured ``fK_hz`` with the K-th lowest elastic natural frequency of the described machine at
that pose, its actuators locked (:func:`~fpm_sim.study.identify.described.task_frequencies`): modes paired by order
among the elastic modes. The 3RRR's readout model (which mode a hammer test on it reads, in- and out-of-plane labels)
is the study's own.

Likelihood: the 3RRR's Gaussian with its relative model discrepancy
(:class:`~fpm_sim.study.calibrate.problem.FrequencyLikelihood`; a Gaussian-process discrepancy over ``x, y, phi`` for
machines whose task has no ``z``). A measured pose the machine at ``theta`` cannot reach, or a frequency it does not
compute there, is ``log L = -inf``.

An imported model (:mod:`fpm_sim.architecture.imported`) is calibrated the same way in joint space: priors on dotted
paths of the imported TOML, identify's joint-space measured file
(:func:`~fpm_sim.study.identify.described.read_joint_measured_csv`), its frequencies those of
:func:`~fpm_sim.batch.joint_sweep.sweep_joints`. Its discrepancy is the relative one only (a Gaussian process over task
poses has no meaning without task coordinates: ``[likelihood.length_scale_m]`` is refused); ``posterior.nc`` gives
each observation's joint values as coordinates.

One class: a described machine fixes its working mode per chain (``branch_deg`` in its file), so there are no
elbow-branch classes to enumerate. The 3RRR's study statements, rig tests and latent-mode readout are its own and are
refused here.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fpm_sim.architecture import Description, description_value, with_description_value
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.config import ConfigError
from fpm_sim.model.options import ModelOptions
from fpm_sim.study.calibrate.priors import Prior, PriorError, Priors, prior_names, read_priors, read_priors_text
from fpm_sim.study.calibrate.problem import CalibrationError, FrequencyLikelihood
from fpm_sim.study.identify.described import (
    Machine,
    MeasuredPose,
    TaskMeasurements,
    check_measured_poses,
    edited_description,
    parse_free_paths,
    task_frequencies,
)
from fpm_sim.study.tables import SubsystemTest

__all__ = [
    "CALIBRATED_SOURCE",
    "COMPARED",
    "ONE_CLASS",
    "DescribedCalibrationProblem",
    "TaskObservation",
    "check_prior_paths",
    "described_priors",
    "described_problem",
    "median_description",
]

CALIBRATED_SOURCE = "calibration draw (fpm-sim calibrate)"
"""The provenance of a value set by a draw of the sampler."""
COMPARED = (
    "each measured fK_hz against the K-th lowest elastic natural frequency of the described machine at its pose, "
    "actuators locked (modes paired by order among the elastic modes; the 3RRR's readout model is the study's own)"
)
ONE_CLASS = (
    "one class: a described machine fixes its working mode per chain (branch_deg in its file), so there are no "
    "elbow-branch classes to enumerate"
)
_TAIL = 1e-4
"""The quantile at which an unbounded prior's support is checked against the file's validity."""


@dataclass(frozen=True)
class TaskObservation:
    """One measured natural frequency of a described machine: the ``mode``-th lowest elastic mode at ``pose`` (task
    coordinates, or an imported model's ``{joint: value}``)."""

    pose: MeasuredPose
    task: tuple[str, ...]
    mode: int
    freq_hz: float
    sigma_hz: float
    source: str
    line: int | None = None
    label: str | None = None

    def describe(self) -> str:
        if isinstance(self.pose, dict):
            return f"{self.source} ({', '.join(f'{j}={v:g}' for j, v in self.pose.items())}) f{self.mode}"
        pose = self.pose
        where = ", ".join(
            f"{c}={pose.value(c):g}" if c == "phi" else f"{c}={pose.value(c) * 1e3:g}" for c in self.task
        )
        return f"{self.source} ({where}) f{self.mode}"


def _observations(desc: Machine, data: TaskMeasurements) -> tuple[TaskObservation, ...]:
    """The measured frequencies in row-major order of ``data.freq_hz`` (pose, then mode)."""
    lines = data.lines or list(range(2, len(data.poses) + 2))
    task = tuple(desc.task) if isinstance(desc, Description) else ()
    return tuple(
        TaskObservation(p, task, k + 1, float(data.freq_hz[i, k]), float(data.sigma_hz[i, k]), data.source, ln)
        for i, (p, ln) in enumerate(zip(data.poses, lines))
        for k in range(data.n_modes)
        if math.isfinite(data.freq_hz[i, k])
    )


def _support(prior: Prior) -> tuple[float, float]:
    """The ends of the values ``prior`` draws: its bounds, or its ``_TAIL`` quantiles when it has none."""
    v = dict(prior.params)
    if "lower" in v:
        return v["lower"], v["upper"]
    return float(prior.transform(_TAIL)), float(prior.transform(1.0 - _TAIL))


def check_prior_paths(desc: Machine, priors: Priors) -> None:
    """Every prior names a number of ``desc``'s file and draws only values the file accepts (module docstring)."""
    for p in priors.parameters:
        where = f'{priors.source} [parameters."{p.name}"]'
        try:
            description_value(desc, p.name)
        except ConfigError as exc:
            raise PriorError(f"{where}: {exc.message}", parameter=p.name, hint=exc.hint) from None
        for end in _support(p):
            try:
                with_description_value(desc, p.name, end)
            except ConfigError as exc:
                raise PriorError(
                    f"{where}: the prior reaches {end:g}, where the file is invalid ({exc.message})",
                    hint="bound the prior to values the file accepts (a length, section or density > 0, a mass >= 0)",
                ) from None


@dataclass(frozen=True)
class DescribedCalibrationProblem(FrequencyLikelihood):
    """A described machine, priors on dotted paths of its file, its measured frequencies (module docstring).

    Picklable (a description is plain data), so a ``spawn`` pool can be given one in its initializer. The free
    parameters (:attr:`groups`) are the priors' paths, in their order."""

    base: Machine
    priors: Priors
    data: TaskMeasurements
    segments: int = 4
    observations: tuple[TaskObservation, ...] = field(init=False)
    rig_tests: tuple[SubsystemTest, ...] = field(init=False, default=())
    groups: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "observations", _observations(self.base, self.data))
        object.__setattr__(self, "groups", tuple(p.name for p in self.priors.parameters))
        pr = self.priors
        refused = [
            ("the elbow-branch classes (geometry.elbow_branch)", pr.sample_branches, ONE_CLASS),
            ("the study's statements ([statements.*])", pr.singular_at_phi0 or pr.measured_poses_clear, "remove them"),
            ("the latent-mode readout ([likelihood.mode_read])", pr.mode_read, COMPARED),
            ("a correlation length over z ([likelihood.length_scale_m])", pr.length_scale and "z" in self._task, ""),
            ("a correlation length over task poses ([likelihood.length_scale_m])",
             pr.length_scale and isinstance(self.base, ImportedDescription), "an imported model has no task poses"),
        ]  # fmt: skip
        for what, given, why in refused:
            if given:
                raise CalibrationError(
                    f"{what} are the 3RRR's; a described machine has none", parameter="priors", hint=why or None
                )
        if not self.observations:
            raise CalibrationError("no data", parameter="measured", hint="give measured frequencies (a CSV file)")
        if not self.groups:
            raise CalibrationError("no free parameter", parameter="priors", hint="give a prior on a dotted path")
        if self.segments < 1:
            raise CalibrationError("must be >= 1", parameter="segments", value=self.segments)
        check_prior_paths(self.base, self.priors)

    @property
    def _task(self) -> tuple[str, ...]:
        return tuple(self.base.task) if isinstance(self.base, Description) else ()

    @functools.cached_property
    def features(self) -> np.ndarray:
        """The observations' pose features for the Gaussian-process discrepancy; an imported model has none (its
        correlation length is refused) and gives zeros, unused."""
        if isinstance(self.base, ImportedDescription):
            return np.zeros((len(self.observations), 3))
        features: np.ndarray = super().features
        return features

    @property
    def options(self) -> ModelOptions:
        """The likelihood's model: ``segments`` per link, gravity off, inextensible (the pose loop's fast path)."""
        return ModelOptions(segments=self.segments, gravity=False, axial=False)

    def class_label(self, klass: int | None) -> str:
        return "the file's working modes"

    def notes(self) -> dict[str, str]:
        return {"compared": COMPARED, "working_mode": ONE_CLASS}

    def config(self, theta: np.ndarray) -> Machine:
        """The description at ``theta``. Raises :class:`~fpm_sim.config.ConfigError` for an invalid file."""
        n = len(self.groups)
        return edited_description(self.base, dict(zip(self.groups, np.asarray(theta[:n], float))), CALIBRATED_SOURCE)

    def possible(self, theta: np.ndarray) -> bool:
        """The file at ``theta`` is valid (whether it reaches the measured poses is the likelihood's: ``-inf``)."""
        try:
            self.config(theta)
        except (ConfigError, ValueError):
            return False
        return True

    def predict(self, theta: np.ndarray, desc: Machine | None = None) -> np.ndarray:
        """The model's frequency (Hz) at every observation (NaN where the machine computes none)."""
        if desc is None:
            try:
                desc = self.config(theta)
            except (ConfigError, ValueError):
                return np.full(self.n_data, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # near-singular poses warn once per call; the likelihood judges them
            model = task_frequencies(desc, self.data, self.options)
        out: np.ndarray = model[np.isfinite(self.data.freq_hz)]
        return out

    def log_likelihood(self, theta: np.ndarray) -> float:
        """``log L(theta)``; ``-inf`` for an invalid file or a measured frequency the machine does not give."""
        try:
            desc = self.config(theta)
        except (ConfigError, ValueError):
            return -math.inf
        f = self.predict(theta, desc)
        if not np.all(np.isfinite(f)):
            return -math.inf
        return self.data_log_likelihood(f, self.discrepancy(theta), self.length_scale_m(theta))

    def start_values(self) -> np.ndarray:
        return np.array([description_value(self.base, p) for p in self.groups])


def described_priors(
    desc: Machine, source: str | Path | None, free: str | None = None, *, text: str | None = None
) -> Priors:
    """The priors of a described machine's calibration: the priors file ``source`` (or its ``text``), whose
    ``[parameters."PATH"]`` name dotted paths of ``desc``'s file, and the free paths ``free`` (``PATH[=lo:hi],...``;
    ``None``: every path the file gives a prior for). A path with bounds gets a uniform prior between them (it must
    then have none in the file); one without must have its prior in the file."""
    where = str(source) if source is not None else "free paths"
    body = "" if source is None and text is None else (text if text is not None else read_priors_text(source or ""))
    listed = prior_names(where, body)
    items = [s.strip() for s in (free or "").split(",") if s.strip()]
    paths, extra = [], []
    for item in items:
        path = item.partition("=")[0].strip()
        paths.append(path)
        if "=" not in item:
            if path not in listed:
                raise PriorError(
                    f"no prior for the free path {path}",
                    parameter=path,
                    hint=f'add [parameters."{path}"] to the priors file, or give its bounds as {path}=lo:hi',
                )
            continue
        if path in listed:
            raise PriorError(
                f"{path} has a prior in {where} and bounds with the free paths", parameter=path, hint="give one"
            )
        ((_, (lo, hi)),) = parse_free_paths(item, desc).items()
        extra.append(
            f'\n[parameters."{path}"]\ndist = "uniform"\nlower = {lo!r}\nupper = {hi!r}\n'
            'reason = "assumed: uniform between the bounds given with the free path"\n'
        )
    if not items and not listed:
        raise PriorError("no free parameter", parameter="priors", hint='give [parameters."PATH"] tables')
    return read_priors(where, paths or listed, text=body + "".join(extra))


def described_problem(
    desc: Machine,
    data: TaskMeasurements,
    *,
    priors: str | Path | None,
    free: str | None = None,
    segments: int = 4,
) -> DescribedCalibrationProblem:
    """The calibration problem of ``desc`` (:func:`described_priors` from ``priors`` and ``free``; ``data`` read by
    :func:`~fpm_sim.study.identify.described.read_task_measured_csv`); a measured frequency the file's own machine does
    not compute (its pose unreachable or singular) is refused naming its row, before any sampling."""
    if priors is None and not free:
        raise PriorError(
            "no priors", parameter="priors", hint='give a priors file ([parameters."PATH"] tables) or PATH=lo:hi bounds'
        )
    problem = DescribedCalibrationProblem(desc, described_priors(desc, priors, free), data, segments=segments)
    check_measured_poses(desc, data, problem.options)
    return problem


def median_description(problem: DescribedCalibrationProblem, draws: np.ndarray, *, data_note: str) -> Machine:
    """The file at the posterior median of every free path, each one's provenance
    ``identified: posterior median +- sd (fpm-sim calibrate, DATA); PATH = ... +- ...``."""
    desc = problem.base
    for i, path in enumerate(problem.groups):
        col = draws[:, i]
        med, sd = float(np.median(col)), float(np.std(col))
        source = f"identified: posterior median +- sd (fpm-sim calibrate, {data_note}); {path} = {med:.4g} +- {sd:.4g}"
        desc = with_description_value(desc, path, med, source=source)
    return desc
