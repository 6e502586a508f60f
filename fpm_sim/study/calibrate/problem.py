"""The calibration problem: a picklable description of what is sampled and its likelihood.

Coordinates ``theta`` (in the order of :attr:`CalibrationProblem.names`): the free parameters of
``parameter_set(base, groups)`` (SI, as named), then ``likelihood.discrepancy_rel`` when it has a prior and
``likelihood.length_scale_m`` when the discrepancy is a Gaussian process, then the elbow-branch class index
(0..7 into :data:`ELBOW_BRANCHES`) when the branches are sampled.

Likelihood (independent Gaussian errors)::

    log L = sum_i [ -0.5 (f_i - y_i)^2 / s_i^2 - 0.5 log(2 pi s_i^2) ] + statements
    s_i^2 = sigma_i^2 + (d f_i)^2      at the measured poses (sigma_i: the data file's sd, d: discrepancy)
    s_i^2 = sigma_i^2                  for a rig test (sigma_i = rig_sigma_pct of the value)

The discrepancy is the manipulator model's (joint hardware, unmodelled compliance): it multiplies the
prediction, so it scales with the frequency as the model's relative errors do. The rig tests are beams and a
hinge with their own parameters, and get none. With a correlation length ``l`` (a Gaussian-process
discrepancy, :mod:`fpm_sim.study.discrepancy`) the measured poses' errors are jointly Gaussian,
``log L = log N(y - f | 0, diag(sigma^2) + d^2 diag(f) K_l diag(f))`` over the poses, the rig tests as above.

A description that is invalid, or under which a measured pose is unreachable or a frequency cannot be given,
has ``log L = -inf``: the machine was measured there, so such a description is impossible (dynesty treats
``-inf`` as outside the prior's support).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.config import ConfigError, Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import GeometryArrays, assemble_batch, assemble_many
from fpm_sim.study.calibrate.priors import Priors
from fpm_sim.study.calibrate.terms import independent_log_likelihood, log_sigmoid_soft, statements_batch
from fpm_sim.study.discrepancy import covariance, gaussian_log_likelihood, pose_features
from fpm_sim.study.identify.data import Observation
from fpm_sim.study.identify.parameters import ParameterSet, parameter_set
from fpm_sim.study.identify.problem import ELBOW_BRANCHES, family_frequencies, predict_observations
from fpm_sim.study.inplane_surrogate import inplane_first_frequencies
from fpm_sim.study.readout import mixture_log_likelihood, read_probabilities, sensor_residues
from fpm_sim.study.rigs import subsystem_frequencies
from fpm_sim.study.tables import SubsystemTest

__all__ = [
    "MODELS",
    "STUDY_GROUPS",
    "CalibrationError",
    "CalibrationProblem",
    "FrequencyLikelihood",
    "log_sigmoid_soft",
    "study_problem",
]

MODELS = ("segments", "inplane")
STUDY_GROUPS = ("geometry", "hardware", "section-height")
"""The free groups of the study's calibration (docs/identification.md, "Bayesian updating")."""


class CalibrationError(FpmSimError):
    """The calibration cannot run as asked (no data, a checkpoint that does not match, ...)."""


def _independent_log_likelihood(residual: np.ndarray, sd: np.ndarray) -> float:
    """``sum_i log N(residual_i | 0, sd_i^2)``."""
    return float(independent_log_likelihood(residual, sd))


class FrequencyLikelihood:
    """What the sampler, the posterior and the report need of a calibration problem: the data (observations, then
    rig tests), the prior transform and the Gaussian likelihood's parts shared by the 3RRR's problem
    (:class:`CalibrationProblem`) and a described architecture's
    (:class:`~fpm_sim.study.calibrate.described.DescribedCalibrationProblem`). A subclass gives the data fields,
    :meth:`possible`, :meth:`predict`, :meth:`log_likelihood`, :meth:`start_values` and :meth:`start_class`."""

    priors: Priors
    observations: tuple[Any, ...]
    """Each with ``pose`` (``x_m``, ``y_m``, ``phi_rad``), ``mode``, ``freq_hz``, ``sigma_hz`` and ``describe()``."""
    rig_tests: tuple[SubsystemTest, ...]
    groups: tuple[str, ...]
    """What is free, as the report names it (the 3RRR's groups, a described machine's dotted paths)."""
    segments: int
    closed_form_kinematics: ClassVar[bool] = False
    """Whether the problem is the 3RRR's, whose cheap likelihoods :mod:`~fpm_sim.study.calibrate.vectorised` gives
    for many particles at once."""

    @functools.cached_property
    def _measured(self) -> np.ndarray:
        return np.array([o.freq_hz for o in self.observations] + [t.experimental_hz for t in self.rig_tests])

    @functools.cached_property
    def _sigma(self) -> np.ndarray:
        return np.array(
            [o.sigma_hz for o in self.observations]
            + [t.experimental_hz * self.priors.rig_sigma_pct / 100.0 for t in self.rig_tests]
        )

    @functools.cached_property
    def features(self) -> np.ndarray:
        """``(n_observations, 3)`` pose features of the observations (:func:`pose_features`)."""
        o = self.observations
        return pose_features(
            np.array([x.pose.x_m for x in o]), np.array([x.pose.y_m for x in o]), np.array([x.pose.phi_rad for x in o])
        )

    @property
    def names(self) -> list[str]:
        """The sampled coordinates (module docstring)."""
        return self.priors.names

    @property
    def ndim(self) -> int:
        return len(self.names)

    @property
    def n_data(self) -> int:
        return len(self.observations) + len(self.rig_tests)

    @property
    def measured(self) -> np.ndarray:
        return self._measured.copy()

    @property
    def sigma(self) -> np.ndarray:
        return self._sigma.copy()

    @property
    def labels(self) -> list[str]:
        return [o.describe() for o in self.observations] + [f"rig {t.label}" for t in self.rig_tests]

    @property
    def branch_classes(self) -> tuple[int | None, ...]:
        """The classes sampled each on its own; ``(None,)``: one."""
        return (None,)

    def class_label(self, klass: int | None) -> str:
        """The name of a class (an index into :data:`ELBOW_BRANCHES`; ``None``: the one class)."""
        return "the base's branches" if klass is None else str(ELBOW_BRANCHES[klass])

    def notes(self) -> dict[str, str]:
        """Statements the result carries about what was compared (none for the 3RRR's study form)."""
        return {}

    def prepare(self) -> None:
        """Build what every likelihood call shares (once per worker process)."""

    def possible(self, theta: np.ndarray) -> bool:
        raise NotImplementedError

    def predict(self, theta: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def log_likelihood(self, theta: np.ndarray) -> float:
        raise NotImplementedError

    def cheap_log_likelihood(self, theta: np.ndarray) -> float:
        """The part of :meth:`log_likelihood` that needs no frequency (``-inf`` where it is impossible, and the
        study's statements where enabled): what a two-stage sampler tempers in first
        (:mod:`fpm_sim.study.calibrate.smc`). Here: the support only."""
        return 0.0 if self.possible(theta) else -math.inf

    def start_values(self) -> np.ndarray:
        """The free parameters' values in the base description."""
        raise NotImplementedError

    def start_class(self) -> list[float]:
        """The base description's class coordinate (empty: the classes are not sampled)."""
        return []

    # -- the unit cube -> parameters
    def prior_transform(self, u: np.ndarray) -> np.ndarray:
        """Unit-cube point -> ``theta`` (each prior's inverse CDF; the branch class ``floor(8 u)``); rows ``(n, ndim)``
        -> ``(n, ndim)``, vectorised (a sampler's particles)."""
        u = np.asarray(u, float)
        rows = np.atleast_2d(u)
        theta = np.empty((len(rows), self.ndim))
        k = 0
        for p in (*self.priors.parameters, *self.priors.hyperpriors):
            theta[:, k] = p.transform(rows[:, k])
            k += 1
        if self.priors.sample_branches:
            theta[:, k] = np.minimum((rows[:, k] * len(ELBOW_BRANCHES)).astype(int), len(ELBOW_BRANCHES) - 1)
        return theta if u.ndim == 2 else theta[0]

    def discrepancy(self, theta: np.ndarray) -> float:
        """The relative model discrepancy at ``theta`` (sampled, or the priors' fixed value)."""
        if self.priors.discrepancy is None:
            return self.priors.discrepancy_fixed
        return float(theta[len(self.priors.parameters)])

    def length_scale_m(self, theta: np.ndarray) -> float | None:
        """The Gaussian-process discrepancy's correlation length (m) at ``theta``; ``None``: independent."""
        if self.priors.length_scale is None:
            return None
        return float(theta[len(self.priors.parameters) + (self.priors.discrepancy is not None)])

    def noise_sd(self, f_pred: np.ndarray, discrepancy: float) -> np.ndarray:
        """``s_i`` of the module docstring at predictions ``f_pred``."""
        s2 = self._sigma**2
        n = len(self.observations)
        s2[:n] += (discrepancy * f_pred[:n]) ** 2
        sd: np.ndarray = np.sqrt(s2)
        return sd

    def simulate_measurement(self, f: np.ndarray, theta: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """One draw of the likelihood's measurement at model frequencies ``f`` (the posterior predictive)."""
        d = self.discrepancy(theta)
        length = self.length_scale_m(theta)
        sd = self.noise_sd(f, d)
        out: np.ndarray = f + sd * rng.standard_normal(f.shape)
        n = len(self.observations)
        if length is not None and n and np.all(np.isfinite(f[:n])):
            cov = covariance(f[:n], self._sigma[:n], self.features, d, length)
            out[:n] = f[:n] + np.linalg.cholesky(cov) @ rng.standard_normal(n)
        return out

    def start_log_likelihood(self) -> float:
        """``log L`` at the base description (its own elbow branches, :meth:`start_class`), the discrepancy at its
        best on a grid over its prior (when sampled): a check of the sampler. A posterior whose draws all fit worse
        than the start missed the start's region (nested sampling with too few live points misses narrow modes)."""
        theta = list(self.start_values())
        ds = [self.priors.discrepancy_fixed]
        if self.priors.discrepancy is not None:
            ds = [float(self.priors.discrepancy.transform(u)) for u in np.linspace(0.01, 0.99, 25)]
        ls = [] if self.priors.length_scale is None else [float(self.priors.length_scale.transform(0.01))]
        best = -math.inf
        for d in ds:  # (the shortest correlation length: nearest to the independent model)
            t = theta + ([d] if self.priors.discrepancy is not None else []) + ls
            t += self.start_class()
            best = max(best, self.log_likelihood(np.asarray(t)))
        return best

    def data_log_likelihood(self, f: np.ndarray, d: float, length_scale_m: float | None) -> float:
        """The data's ``log L`` at model frequencies ``f`` (module docstring), without the statements."""
        s = self.noise_sd(f, d)
        residual = f - self._measured
        n = len(self.observations)
        if length_scale_m is None or n == 0:
            return _independent_log_likelihood(residual, s)
        cov = covariance(f[:n], self._sigma[:n], self.features, d, length_scale_m)
        return gaussian_log_likelihood(residual[:n], cov) + _independent_log_likelihood(residual[n:], s[n:])


@dataclass(frozen=True)
class CalibrationProblem(FrequencyLikelihood):
    """Base description, free groups, priors, data and likelihood settings (see module docstring).

    Picklable (plain data, its parameter set too: :class:`~fpm_sim.study.identify.parameters.ParameterSpec`),
    so a ``spawn`` pool can be given one in its initializer.
    """

    base: Manipulator
    groups: tuple[str, ...]
    priors: Priors
    observations: tuple[Observation, ...]
    rig_tests: tuple[SubsystemTest, ...] = ()
    segments: int = 4
    subsystem_segments: int = 8
    closed_form_kinematics: ClassVar[bool] = True
    model: str = "segments"
    """``"segments"``: the segment model (:func:`predict_observations`); ``"inplane"``: the analytic in-plane
    surrogate (:mod:`fpm_sim.study.inplane_surrogate`; first frequencies only, no rig tests): thousands of times
    cheaper, for checks of the sampler itself (simulation-based calibration), never for a reported result."""

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise CalibrationError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        if self.model == "inplane" and (
            self.rig_tests or any(o.mode != 1 or o.label == "out_of_plane" for o in self.observations)
        ):
            raise CalibrationError(
                "the in-plane surrogate gives first in-plane frequencies only: no rig tests, f1 only"
            )
        if self.priors.mode_read is not None and (
            self.model != "segments" or any(o.mode != 1 or o.label is not None for o in self.observations)
        ):
            raise CalibrationError(
                "the latent-mode model ([likelihood.mode_read]) reads unlabelled first frequencies on the segment "
                "model only",
                parameter="mode_read",
                hint="give f1 only, without a mode label, or switch mode_read off",
            )
        if not self.observations and not self.rig_tests:
            raise CalibrationError(
                "no data",
                parameter="measured",
                hint="give measured frequencies (a CSV file) and/or rig tests (subsystems, a CSV file)",
            )
        if self.segments < 1:
            raise CalibrationError("must be >= 1", parameter="segments", value=self.segments)
        free = self.parameters.names
        if [p.name for p in self.priors.parameters] != free:
            raise CalibrationError(
                f"the priors ({', '.join(p.name for p in self.priors.parameters)}) do not match the free parameters "
                f"({', '.join(free)}); read them with read_priors(path, parameter_set(base, groups).names)"
            )
        if any(p.subsystem for p in self.parameters.parameters) and not self.rig_tests:
            raise CalibrationError(
                "the free group rig needs rig tests",
                parameter="subsystems",
                hint="give rig tests (a CSV file; the rig parameters are seen only by rig tests) "
                "or remove rig from the free groups",
            )

    @functools.cached_property
    def parameters(self) -> ParameterSet:
        return parameter_set(self.base, list(self.groups))

    def prepare(self) -> None:
        _ = self.parameters

    def start_values(self) -> np.ndarray:
        return self.parameters.x0

    def start_class(self) -> list[float]:
        if not self.priors.sample_branches:
            return []
        return [float(ELBOW_BRANCHES.index(self.base.geometry.elbow_branch))]

    @functools.cached_property
    def measured_pose_array(self) -> np.ndarray:
        """``(n, 3)`` the distinct measured poses (x_m, y_m, phi_rad)."""
        return np.array(sorted({(o.pose.x_m, o.pose.y_m, o.pose.phi_rad) for o in self.observations}))

    @functools.cached_property
    def observation_pose_index(self) -> np.ndarray:
        """``(n_obs,)`` each observation's row of :attr:`measured_pose_array`."""
        rows = {tuple(p): i for i, p in enumerate(self.measured_pose_array.tolist())}
        return np.array([rows[(o.pose.x_m, o.pose.y_m, o.pose.phi_rad)] for o in self.observations], dtype=int)

    @property
    def branch_classes(self) -> tuple[int | None, ...]:
        """The elbow-branch classes enumerated (indices into :data:`ELBOW_BRANCHES`), each sampled on its own;
        ``(None,)`` when the branches are fixed (one class: the base's)."""
        return tuple(range(len(ELBOW_BRANCHES))) if self.priors.sample_branches else (None,)

    def possible(self, theta: np.ndarray) -> bool:
        """The description at ``theta`` is valid and reaches every measured pose (else ``log L = -inf``)."""
        try:
            cfg = self.config(theta)
        except (ConfigError, ValueError):
            return False
        if not self.observations:
            return True
        xyz = self.measured_pose_array
        return bool(assemble_many(cfg.geometry, xyz[:, 0], xyz[:, 1], xyz[:, 2]).reachable.all())

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, float, tuple[int, int, int]]:
        """``theta`` -> (free-parameter values, discrepancy, elbow branches)."""
        n = len(self.priors.parameters)
        x = np.asarray(theta[:n], float)
        d = self.discrepancy(theta)
        k = n + (self.priors.discrepancy is not None) + (self.priors.length_scale is not None)
        branch = self.base.geometry.elbow_branch
        if self.priors.sample_branches:
            branch = ELBOW_BRANCHES[round(float(theta[k]))]
        return x, d, branch

    def config(self, theta: np.ndarray) -> Manipulator:
        """The description at ``theta``. Raises :class:`ConfigError` for an impossible one."""
        x, _, branch = self.split(theta)
        base = self.base
        if branch != base.geometry.elbow_branch:
            base = base.replace(geometry=dataclasses.replace(base.geometry, elbow_branch=branch))
        return self.parameters.apply(x, base=base)

    def predict(self, theta: np.ndarray, cfg: Manipulator | None = None) -> np.ndarray:
        """The model's frequency (Hz) at every observation, then every rig test (NaN where it has none)."""
        if cfg is None:
            try:
                cfg = self.config(theta)
            except (ConfigError, ValueError):
                return np.full(self.n_data, np.nan)
        if self.model == "inplane":
            return inplane_first_frequencies(cfg, [o.pose for o in self.observations])
        f = predict_observations(cfg, list(self.observations), options=fast_options(segments=self.segments))
        if self.rig_tests:
            f = np.concatenate([f, self._rig_predictions(cfg)])
        return f

    def predict_families(self, theta: np.ndarray) -> np.ndarray:
        """``(2, n_obs)`` the lowest in-plane and out-of-plane frequency (Hz) at every observation
        (:func:`~fpm_sim.study.identify.problem.family_frequencies`; NaN where the description is impossible):
        the emulator's training runs (:mod:`.emulator`)."""
        try:
            cfg = self.config(theta)
        except (ConfigError, ValueError):
            return np.full((2, len(self.observations)), np.nan)
        return family_frequencies(cfg, list(self.observations), options=fast_options(segments=self.segments))

    def _rig_predictions(self, cfg: Manipulator) -> np.ndarray:
        """The rig tests' frequencies (Hz) under ``cfg``."""
        rigs = [
            r.ours_hz for r in subsystem_frequencies(cfg, segments=self.subsystem_segments, tests=list(self.rig_tests))
        ]
        return np.asarray(rigs, float)

    def statements_log_likelihood(self, cfg: Manipulator) -> float:
        """The enabled study statements' soft terms (:mod:`.priors`) under ``cfg``."""
        ga = GeometryArrays.of(cfg.geometry)
        measure = None
        if self.observations:
            p = self.measured_pose_array
            measure = assemble_batch(ga, p[:, 0], p[:, 1], p[:, 2]).singularity
        return float(statements_batch(self.priors, ga, measure)[0])

    def cheap_log_likelihood(self, theta: np.ndarray) -> float:
        """``-inf`` for an impossible description (invalid, or a measured pose unreachable), else the enabled
        statements' terms (closed-form kinematics, about a millisecond)."""
        try:
            cfg = self.config(theta)
        except (ConfigError, ValueError):
            return -math.inf
        if self.observations:
            xyz = self.measured_pose_array
            if not assemble_many(cfg.geometry, xyz[:, 0], xyz[:, 1], xyz[:, 2]).reachable.all():
                return -math.inf
        return self.statements_log_likelihood(cfg)

    def log_likelihood(self, theta: np.ndarray) -> float:
        """``log L(theta)`` (module docstring); ``-inf`` for an impossible description."""
        try:
            cfg = self.config(theta)
        except (ConfigError, ValueError):
            return -math.inf
        if self.observations:  # an unreachable measured pose: -inf before any model is built (cheap)
            xyz = self.measured_pose_array
            if not assemble_many(cfg.geometry, xyz[:, 0], xyz[:, 1], xyz[:, 2]).reachable.all():
                return -math.inf
        _, d, _ = self.split(theta)
        if self.priors.mode_read is not None:
            return self._mixture_log_likelihood(cfg, d)
        f = self.predict(theta, cfg)
        if not np.all(np.isfinite(f)):
            return -math.inf
        return self.data_log_likelihood(f, d, self.length_scale_m(theta)) + self.statements_log_likelihood(cfg)

    def read_modes(self, cfg: Manipulator) -> tuple[np.ndarray, np.ndarray]:
        """Under the latent-mode model: ``(freq_hz, probs)``, the lowest ``modes`` frequencies at every
        observation ``(n, modes)`` and the probability that each is the first clear peak ``(n_setups, n, modes)``
        (:mod:`fpm_sim.study.readout`)."""
        read = self.priors.mode_read
        assert read is not None
        freq, res = sensor_residues(
            cfg,
            [o.pose for o in self.observations],
            n_modes=read.reference_modes,
            points=read.points,
            options=fast_options(segments=self.segments),
        )
        return freq[:, : read.modes], read_probabilities(np.transpose(res, (1, 0, 2)), read)

    def _mixture_log_likelihood(self, cfg: Manipulator, d: float) -> float:
        n = len(self.observations)
        freq, probs = self.read_modes(cfg)
        if not np.all(np.isfinite(freq)) or not np.all(np.isfinite(probs)):
            return -math.inf
        ll = mixture_log_likelihood(self._measured[:n], self._sigma[:n], freq, probs, d)
        if self.rig_tests:
            f_rig = self._rig_predictions(cfg)
            if not np.all(np.isfinite(f_rig)):
                return -math.inf
            ll += _independent_log_likelihood(f_rig - self._measured[n:], self._sigma[n:])
        return ll + self.statements_log_likelihood(cfg)


def study_problem(
    *, model: str = "segments", branch: tuple[int, int, int] | None = None,
    as_built: tuple[float, float] | None = None,
) -> CalibrationProblem:  # fmt: skip
    """The study's calibration as docs/identification.md runs it: the embedded default, the study's measured first
    frequencies (``measured_table4_train.csv``, reading x+), the free groups :data:`STUDY_GROUPS` and the shipped
    priors and statements (``study_priors.toml``). ``branch``: the elbow branches fixed to one class (their prior
    left out) instead of sampled; ``model``: :attr:`CalibrationProblem.model`; ``as_built``: ``(angle sd in deg,
    relative length sd)``, the ``as-built`` group freed too, with normal priors of those sds
    (:func:`as_built_priors`)."""
    import re
    from importlib.resources import files

    from fpm_sim.config import default_config
    from fpm_sim.study.calibrate.priors import read_priors
    from fpm_sim.study.identify.data import read_measured_csv
    from fpm_sim.study.poses import parse_reading

    data = files("fpm_sim.data")
    start = default_config()
    text = data.joinpath("study_priors.toml").read_text()
    if branch is not None:
        start = start.replace(geometry=dataclasses.replace(start.geometry, elbow_branch=branch))
        text = re.sub(r'\[parameters\."geometry\.elbow_branch"\][^\[]*', "", text)
    measured = read_measured_csv(str(data.joinpath("measured_table4_train.csv")), reading=parse_reading("x+"))
    groups = STUDY_GROUPS + (("as-built",) if as_built is not None else ())
    names = parameter_set(start, list(groups)).names
    if as_built is not None:
        text = text.replace("[likelihood]", as_built_priors(*as_built) + "\n[likelihood]", 1)
    priors = read_priors("study_priors.toml", names, text=text)
    return CalibrationProblem(start, groups, priors, tuple(measured.observations), (), model=model)


def as_built_priors(angle_sd_deg: float, length_sd_rel: float) -> str:
    """Priors TOML of the ``as-built`` group's 12 parameters: each chain's joint angles normal with sd
    ``angle_sd_deg``, its link lengths' relative deviations normal with sd ``length_sd_rel``, all of mean 0."""
    out = []
    for i in range(3):
        for name, sd in (
            ("base_angle_dev_deg", angle_sd_deg),
            ("platform_angle_dev_deg", angle_sd_deg),
            ("proximal_length_dev_rel", length_sd_rel),
            ("distal_length_dev_rel", length_sd_rel),
        ):
            out.append(
                f'[parameters."geometry.{name}[{i}]"]\ndist = "normal"\nmean = 0.0\nsd = {sd!r}\nreason = "assumed: '
                'a bench-top machine built with its joint circles and links known to about this much"\n'
            )  # fmt: skip
    return "\n".join(out)
