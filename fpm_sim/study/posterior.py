"""Predictions with bands: the frequencies of every draw of a posterior over the identified parameters.

Twelve measured first frequencies do not single out one description (``docs/identification.md``): several
optima fit about equally well and predict unmeasured poses far apart. ``fpm-sim calibrate`` samples the
posterior of the free parameters and writes ``posterior.nc`` (an ArviZ ``InferenceData``, format below);
here it is read (:class:`Posterior`) and pushed through the pose loop, draw by draw
(:func:`predict_bands`): the robust prediction of Beck & Au (2002) is the average over the posterior, and
its quantiles over the draws give the bands.

The file (the contract with the calibration):

- group ``posterior``: equal-weight draws, dims ``("chain", "draw")`` with one chain; one float64 variable per
  free parameter, named as :attr:`fpm_sim.study.identify.parameters.ParameterSet.names` (SI units); an
  optional int8 ``geometry.elbow_branch`` with dims ``("chain", "draw", "arm")`` (+1 / -1 per chain);
  likelihood hyperparameters prefixed ``likelihood.``;
- attributes of ``posterior``: ``fpm_sim_base_config`` (TOML of the description the parameters are applied to),
  ``fpm_sim_free_groups`` (comma-separated groups of :func:`~fpm_sim.study.identify.parameters.parameter_set`),
  ``fpm_sim_segments`` (the likelihood's resolution), ``fpm_sim_command``;
- optional groups ``sample_stats``, ``observed_data`` (``f_hz`` over ``obs`` with ``x_mm``, ``y_mm``,
  ``phi_rad``, ``label``) and ``posterior_predictive``.

A described machine's posterior (``fpm-sim calibrate --config machine.toml``,
:mod:`fpm_sim.study.calibrate.described`) has its file as ``fpm_sim_base_config`` (a TOML with ``[[chains]]``) and
its free dotted paths (:mod:`fpm_sim.architecture.edit`) as ``fpm_sim_free_groups``, one variable per path; its
draws are the file with each path set (:func:`~fpm_sim.study.identify.described.edited_description`) and its poses
are :class:`~fpm_sim.architecture.TaskPose` values in the machine's task coordinates. Each draw's frequencies are
then the K-th lowest elastic modes with the actuators locked, as its likelihood compared them
(:func:`~fpm_sim.batch.task_sweep.sweep_task_many`).

The bands are the quantiles (:data:`QUANTILES`) over the draws of each frequency at each pose. A draw that
cannot reach a pose (or meets a singularity there) has no frequency there: it is left out of that pose's
quantiles and counted (:attr:`PredictiveBands.computed_fraction`).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import Description, TaskPose, description_value, parse_description
from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import STATUS_NEAR, STATUS_OK, STATUS_UNREACHABLE, fast_options, solve_configs
from fpm_sim.config import ConfigError, Manipulator, parse_config
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions, resolution_summary
from fpm_sim.results import frequencies_dataset
from fpm_sim.study.discrepancy import LENGTH_SCALE_PARAMETER, conditional, pose_features
from fpm_sim.study.identify.described import edited_description
from fpm_sim.study.identify.parameters import ParameterSet, parameter_set
from fpm_sim.study.loo import LeaveOneOut, leave_one_out, loo_from_components, mixture_quantiles
from fpm_sim.study.poses import TableReading
from fpm_sim.study.readout import (
    MODE_READ_ATTR,
    ModeRead,
    draws_components,
    mode_read_from_text,
    read_probabilities,
    sensor_residues,
    setup_weights,
)
from fpm_sim.study.tables import measured_table, withheld_cells

__all__ = [
    "BASE_CONFIG_ATTR",
    "DEFAULT_POSTERIOR_NAME",
    "ELBOW_BRANCH_VAR",
    "QUANTILES",
    "AnyPose",
    "CalibrationData",
    "Posterior",
    "PosteriorError",
    "PredictiveBands",
    "StudyBands",
    "default_posterior_path",
    "pose_columns",
    "predict_bands",
    "study_bands",
]

BASE_CONFIG_ATTR = "fpm_sim_base_config"
GROUPS_ATTR = "fpm_sim_free_groups"
SEGMENTS_ATTR = "fpm_sim_segments"
COMMAND_ATTR = "fpm_sim_command"
REQUIRED_ATTRS = (BASE_CONFIG_ATTR, GROUPS_ATTR, SEGMENTS_ATTR, COMMAND_ATTR)
ELBOW_BRANCH_VAR = "geometry.elbow_branch"
LIKELIHOOD_PREFIX = "likelihood."
DISCREPANCY = "likelihood.discrepancy_rel"
"""The relative model discrepancy of ``fpm-sim calibrate``'s likelihood (:class:`PredictiveBands`)."""
DEFAULT_POSTERIOR_NAME = "default_posterior.nc"
"""The embedded default's posterior in ``fpm_sim/data`` (written by the calibration; may be absent)."""

QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
"""The quantiles of the bands: the 90 % band (5-95 %), the 50 % band (25-75 %) and the median."""
COMPUTED = (STATUS_OK, STATUS_NEAR)
WRITTEN_BY = "give the posterior.nc written by 'fpm-sim calibrate'"
DRAW_SOURCE = "posterior draw (fpm-sim calibrate)"
"""The provenance of a value a described machine's draw sets."""

AnyPose = Pose | TaskPose
"""A pose of the 3RRR (:class:`~fpm_sim.kinematics.Pose`) or of a described machine
(:class:`~fpm_sim.architecture.TaskPose`)."""


class PosteriorError(FpmSimError):
    """A posterior file cannot be used (missing, not an ArviZ posterior, incomplete); names the file."""


def default_posterior_path() -> Path | None:
    """The embedded default's posterior (``fpm_sim/data/default_posterior.nc``), or ``None`` if none is shipped."""
    ref = resources.files("fpm_sim.data").joinpath(DEFAULT_POSTERIOR_NAME)
    return Path(str(ref)) if ref.is_file() else None


# ----------------------------------------------------------------------------------------------- posterior


@dataclass(frozen=True)
class CalibrationData:
    """The measured poses a posterior was conditioned on, with every draw's model frequency there (the file's
    ``observed_data`` and ``posterior_predictive`` groups, rig tests left out): what the leave-one-out checks
    and a Gaussian-process discrepancy's predictions need.

    Attributes
    ----------
    measured_hz, sigma_hz, x_m, y_m, phi_rad
        ``(n,)`` the data, their sd and their poses.
    labels
        ``(n,)`` names.
    f_hz
        ``(n_draws, n)`` each draw's model frequency at each datum.
    """

    measured_hz: np.ndarray
    sigma_hz: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    phi_rad: np.ndarray
    labels: list[str]
    f_hz: np.ndarray
    f_modes_hz: np.ndarray | None = None
    """``(n_draws, n, modes)`` the lowest modes at each datum (latent-mode model; else ``None``)."""
    read_probability: np.ndarray | None = None
    """``(n_draws, setups, n, modes)`` each setup's probability that a datum's first clear peak is each mode."""

    @property
    def features(self) -> np.ndarray:
        return pose_features(self.x_m, self.y_m, self.phi_rad)

    @classmethod
    def from_idata(cls, idata: Any, n_draws: int) -> CalibrationData | None:
        """From an ``InferenceData`` with ``observed_data`` and ``posterior_predictive``; ``None`` without them
        or when their sizes do not match the draws."""
        if "observed_data" not in idata.groups() or "posterior_predictive" not in idata.groups():
            return None
        obs, ppc = idata.observed_data, idata.posterior_predictive
        if "f_hz" not in obs or "sigma_hz" not in obs or "f_hz" not in ppc:
            return None
        f = np.asarray(ppc["f_hz"].transpose("chain", "draw", "obs").values, float).reshape(-1, obs.sizes["obs"])
        if f.shape[0] != n_draws:
            return None
        x = np.asarray(obs["x_mm"].values, float)
        keep = np.isfinite(x)  # poses only (rig tests have no pose)
        modes = probs = None
        if "f_hz_modes" in ppc and "read_probability" in ppc:
            fm = ppc["f_hz_modes"].transpose("chain", "draw", "obs", "mode").values
            modes = np.asarray(fm, float).reshape(-1, *fm.shape[2:])[:, keep]
            rp = ppc["read_probability"].transpose("chain", "draw", "setup", "obs", "mode").values
            probs = np.asarray(rp, float).reshape(-1, *rp.shape[2:])[:, :, keep]
        return cls(
            measured_hz=np.asarray(obs["f_hz"].values, float)[keep],
            sigma_hz=np.asarray(obs["sigma_hz"].values, float)[keep],
            x_m=x[keep] * 1e-3,
            y_m=np.asarray(obs["y_mm"].values, float)[keep] * 1e-3,
            phi_rad=np.asarray(obs["phi_rad"].values, float)[keep],
            labels=[str(v) for v in np.asarray(obs["label"].values)[keep]],
            f_hz=f[:, keep],
            f_modes_hz=modes,
            read_probability=probs,
        )


@dataclass
class Posterior:
    """Equal-weight draws of the free parameters over a base description (:meth:`from_netcdf`).

    Attributes
    ----------
    base
        The description the parameters are applied to: the 3RRR's, or a described machine's
        (:class:`~fpm_sim.architecture.Description`).
    groups
        The free parameter groups (:func:`~fpm_sim.study.identify.parameters.parameter_set`); a described machine's
        free dotted paths.
    names
        The free parameters, in the parameter set's order (SI units in the names); a described machine's dotted
        paths.
    values
        ``(n_draws, n_parameters)``.
    elbow_branch
        ``(n_draws, 3)`` elbow branches (+1 / -1) when they were sampled, else ``None`` (the base's).
    segments
        Resolution (spring locations per link) of the likelihood.
    command
        The command that wrote the file.
    likelihood
        The likelihood hyperparameters' draws, by name (``likelihood.`` prefix kept).
    source
        The file read (``None`` when built in memory).
    data
        The measured poses and every draw's frequency there (:class:`CalibrationData`), when the file has them.
    mode_read
        The latent-mode model of the likelihood (:mod:`fpm_sim.study.readout`), or ``None``: each measured value
        was mode 1.
    """

    base: Manipulator | Description
    groups: tuple[str, ...]
    names: list[str]
    values: np.ndarray
    elbow_branch: np.ndarray | None = None
    segments: int | None = None
    command: str = ""
    likelihood: dict[str, np.ndarray] = field(default_factory=dict)
    source: Path | None = None
    data: CalibrationData | None = None
    mode_read: ModeRead | None = None
    _ps: ParameterSet | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.values = np.atleast_2d(np.asarray(self.values, dtype=float))
        if self.values.shape[1] != len(self.names):
            raise self._error(
                f"{self.values.shape[1]} values per draw for {len(self.names)} parameters", parameter="values"
            )
        if self.values.shape[0] < 1:
            raise self._error("no draws", parameter="values")
        if not np.isfinite(self.values).all():
            raise self._error("draws with non-finite values", parameter="values", hint="write finite draws only")
        if self.elbow_branch is not None:
            eb = np.asarray(self.elbow_branch)
            if eb.shape != (self.values.shape[0], 3) or not np.isin(eb, (-1, 1)).all():
                raise self._error(
                    "must hold +1 or -1 per draw and arm",
                    parameter=ELBOW_BRANCH_VAR,
                    hint="dims chain, draw, arm (3 arms)",
                )
            self.elbow_branch = eb.astype(int)
        self._ps = None if isinstance(self.base, Description) else self._parameter_set()
        if isinstance(self.base, Description):
            self._check_paths(self.base)

    def _error(self, message: str, **fields: Any) -> PosteriorError:
        """A :class:`PosteriorError` naming the file read (when built in memory: the parameter, else ``posterior``)."""
        if self.source is None:
            fields.setdefault("parameter", "posterior")
        return PosteriorError(message, file=self.source, **fields)

    @property
    def described(self) -> bool:
        """Whether the base is a described machine's (:class:`~fpm_sim.architecture.Description`)."""
        return isinstance(self.base, Description)

    @property
    def parameter_set(self) -> ParameterSet:
        """``parameter_set(base, groups)`` (its names are :attr:`names`, checked when built); the 3RRR's only."""
        if self._ps is None:
            raise self._error(
                "a described machine's parameters are dotted paths into its file, not the 3RRR's parameter set",
                parameter=GROUPS_ATTR,
            )
        return self._ps

    def _check_paths(self, base: Description) -> None:
        """A described machine's draws: one variable per free path, each a number of the file, no elbow branches."""
        if self.elbow_branch is not None:
            raise self._error(
                "elbow branches are the 3RRR's; a described machine fixes its working mode in its file",
                parameter=ELBOW_BRANCH_VAR,
            )
        if sorted(self.names) != sorted(self.groups):
            raise self._error(
                f"the draws' parameters {', '.join(self.names)} are not the free paths {', '.join(self.groups)}",
                parameter=GROUPS_ATTR,
                hint="one variable per free dotted path, as 'fpm-sim calibrate' writes them",
            )
        for path in self.names:
            try:
                description_value(base, path)
            except FpmSimError as exc:
                raise self._error(f"{path}: {exc.message}", parameter=GROUPS_ATTR, hint=exc.hint) from None

    def _parameter_set(self) -> ParameterSet:
        groups = ",".join(self.groups)
        assert isinstance(self.base, Manipulator)
        try:
            ps = parameter_set(self.base, list(self.groups))
        except FpmSimError as exc:
            raise self._error(f"free groups unusable ({exc})", parameter=GROUPS_ATTR, value=groups) from None
        unknown = [n for n in self.names if n not in ps.names]
        missing = [n for n in ps.names if n not in self.names]
        if unknown or missing:
            raise self._error(
                f"the draws' parameters do not match the free groups {groups!r}"
                + (f"; unknown: {', '.join(unknown)}" if unknown else "")
                + (f"; missing: {', '.join(missing)}" if missing else ""),
                hint=f"expected {', '.join(ps.names)}",
            )
        return ps

    @property
    def n_draws(self) -> int:
        return int(self.values.shape[0])

    # ----------------------------------------------------------------------------------------- reading

    @classmethod
    def from_netcdf(cls, path: str | Path) -> Posterior:
        """Read ``posterior.nc`` (module docstring).

        Raises
        ------
        PosteriorError
            Naming the file: missing, not an ArviZ ``InferenceData`` with a ``posterior`` group, an attribute
            missing, more than one chain, parameters unknown to the free groups, or an invalid draw.
        """
        p = Path(path)
        idata = _inference_data(p)
        post = idata.posterior
        base, groups, segments = _posterior_attributes(post, p)

        def flat(name: str) -> np.ndarray:
            var = post[name]
            extra = [d for d in var.dims if d not in ("chain", "draw")]
            return np.asarray(var.transpose("chain", "draw", *extra).values).reshape((-1, *var.shape[2:]))

        names = _parameter_names(post, base, groups, p)
        values = np.column_stack([flat(n).astype(float) for n in names])
        branch = flat(ELBOW_BRANCH_VAR) if ELBOW_BRANCH_VAR in post.data_vars else None
        likelihood = {
            str(n): flat(str(n)).astype(float) for n in post.data_vars if str(n).startswith(LIKELIHOOD_PREFIX)
        }
        return cls(
            base=base,
            groups=groups,
            names=names,
            values=values,
            elbow_branch=branch,
            segments=segments,
            command=str(post.attrs[COMMAND_ATTR]),
            likelihood=likelihood,
            source=p,
            data=CalibrationData.from_idata(idata, values.shape[0]),
            mode_read=_mode_read(post, p),
        )

    # ----------------------------------------------------------------------------------------- draws

    def draws(self, n: int | None = None, seed: int = 0) -> np.ndarray:
        """Indices of ``n`` draws (all when ``n`` is ``None`` or at least :attr:`n_draws`): a random subset
        without replacement (``seed``), in increasing order. Thinning equal-weight draws keeps them equal-weight."""
        if n is None or n >= self.n_draws:
            return np.arange(self.n_draws)
        if n < 1:
            raise PosteriorError("must be >= 1", parameter="n_draws", value=n, hint="or None for all draws")
        return np.sort(np.random.default_rng(seed).choice(self.n_draws, size=n, replace=False))

    def config(self, i: int) -> Manipulator | Description:
        """The description of draw ``i``: the base with the draw's elbow branches and parameter values (a described
        machine: its file with each free path at the draw's value)."""
        base = self.base
        if isinstance(base, Description):
            return self._apply_paths(self.values[i], base, f"draw {i}")
        if self.elbow_branch is not None:
            b0, b1, b2 = (int(b) for b in self.elbow_branch[i])
            branch = (b0, b1, b2)
            base = dataclasses.replace(base, geometry=dataclasses.replace(base.geometry, elbow_branch=branch))
        return self._apply(self.values[i], base, f"draw {i}")

    def configs(self, n: int | None = None, seed: int = 0) -> list[Manipulator | Description]:
        """The descriptions of :meth:`draws` ``(n, seed)``."""
        return [self.config(int(i)) for i in self.draws(n, seed)]

    def median_config(self) -> Manipulator | Description:
        """The base with each parameter at its posterior median (and the most frequent elbow-branch combination)."""
        base = self.base
        if isinstance(base, Description):
            return self._apply_paths(np.median(self.values, axis=0), base, "median")
        if self.elbow_branch is not None:
            combos, counts = np.unique(self.elbow_branch, axis=0, return_counts=True)
            b0, b1, b2 = (int(b) for b in combos[int(np.argmax(counts))])
            branch = (b0, b1, b2)
            base = dataclasses.replace(base, geometry=dataclasses.replace(base.geometry, elbow_branch=branch))
        return self._apply(np.median(self.values, axis=0), base, "median")

    def _apply_paths(self, x: np.ndarray, base: Description, label: str) -> Description:
        """``base`` with each free path at ``x`` (:func:`~fpm_sim.study.identify.described.edited_description`)."""
        try:
            desc = edited_description(base, dict(zip(self.names, np.asarray(x, float))), f"{DRAW_SOURCE}, {label}")
        except (ConfigError, ValueError) as exc:
            raise self._error(f"{label} is not a valid description ({exc})") from None
        assert isinstance(desc, Description)  # an imported base is refused when the file is read
        return dataclasses.replace(desc, name=f"{base.name} [posterior {label}]")

    def _apply(self, x: np.ndarray, base: Manipulator, label: str) -> Manipulator:
        ps = self.parameter_set
        order = [self.names.index(n) for n in ps.names]
        try:
            cfg = ps.apply(np.asarray(x)[order], base=base)
        except ConfigError as exc:
            raise self._error(f"{label} is not a valid description ({exc})") from None
        return dataclasses.replace(
            cfg, name=f"{self.base.name} [posterior {label}]", provenance=self._provenance(cfg, label)
        )

    def _provenance(self, cfg: Manipulator, label: str) -> dict[str, str]:
        """``cfg``'s provenance with every field a free parameter sets (and the elbow branches) marked as this
        posterior's draw, so that a draw written as a description does not keep the base's sources."""
        from fpm_sim.study.identify.report import identified_provenance

        where = f"{DRAW_SOURCE}, {label} of {self.source.name if self.source else 'the posterior'}"
        prov = identified_provenance(cfg.provenance, [(n, n) for n in self.names], where)
        if self.elbow_branch is not None:
            prov["geometry.elbow_branch"] = f"identified: {where}"
        return prov

    @property
    def length_scale_m(self) -> np.ndarray | None:
        """``(n_draws,)`` the Gaussian-process discrepancy's correlation length (m), or ``None`` (independent)."""
        v = self.likelihood.get(LENGTH_SCALE_PARAMETER)
        return None if v is None else np.asarray(v, float)

    def discrepancy_at(
        self, index: np.ndarray, poses: Sequence[AnyPose]
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The model discrepancy at ``poses`` for draws ``index``, relative (a frequency is ``f (1 + shift + sd
        z)``): ``(shift, sd)`` as :class:`PredictiveBands` holds them.

        No discrepancy: ``(None, None)``. Independent: ``(None, d)``, ``d`` per draw ``(len(index),)``. Gaussian
        process: each ``(len(index), len(poses))``, the conditional given the draw's residuals at the measured
        poses (:func:`fpm_sim.study.discrepancy.conditional`)."""
        if DISCREPANCY not in self.likelihood:
            return None, None
        d = np.asarray(self.likelihood[DISCREPANCY], float)[index]
        shape = (len(index), len(poses))
        ls = self.length_scale_m
        if ls is None:
            return None, d
        if self.data is None:
            raise self._error(
                "a Gaussian-process discrepancy needs the data it was conditioned on",
                parameter="observed_data",
                hint="the file's observed_data and posterior_predictive groups, as 'fpm-sim calibrate' writes them",
            )
        new = pose_features(
            np.array([p.x_m for p in poses]), np.array([p.y_m for p in poses]), np.array([p.phi_rad for p in poses])
        )
        dat = self.data
        shift, sd = np.zeros(shape), np.zeros(shape)
        for row, i in enumerate(index):
            shift[row], sd[row] = conditional(
                dat.f_hz[i], dat.measured_hz, dat.sigma_hz, dat.features, new, float(d[row]), float(ls[i])
            )
        return shift, sd

    def read_at(
        self, index: np.ndarray, poses: Sequence[AnyPose], options: ModelOptions
    ) -> tuple[np.ndarray, np.ndarray]:
        """What a hammer test like the data's would read at ``poses`` (latent-mode model): ``(freq_hz, weight)``,
        each ``(len(index), len(poses), modes)``: the lowest modes of each draw and the probability that the
        first clear peak is each one (the setups weighted by their posterior given the draw and the data)."""
        read, dat = self.mode_read, self.data
        if read is None or dat is None or dat.f_modes_hz is None or dat.read_probability is None or self.described:
            raise self._error(
                "no latent-mode model in this posterior", parameter=MODE_READ_ATTR, hint="calibrate with mode_read"
            )
        d = np.asarray(self.likelihood[DISCREPANCY], float)
        freq = np.full((len(index), len(poses), read.modes), np.nan)
        weight = np.full_like(freq, np.nan)
        for row, i in enumerate(index):
            cfg = self.config(int(i))
            assert isinstance(cfg, Manipulator)
            assert all(isinstance(p, Pose) for p in poses)
            f, res = sensor_residues(
                cfg,
                [p for p in poses if isinstance(p, Pose)],
                n_modes=read.reference_modes,
                points=read.points,
                options=options,
            )
            probs = read_probabilities(np.transpose(res, (1, 0, 2)), read)  # (setups, poses, modes)
            w = setup_weights(dat.measured_hz, dat.sigma_hz, dat.f_modes_hz[i], dat.read_probability[i], float(d[i]))
            freq[row] = f[:, : read.modes]
            weight[row] = np.einsum("s,spk->pk", w, probs)
        return freq, weight

    def leave_one_out(self) -> LeaveOneOut | None:
        """PSIS leave-one-out predictive of the measured poses (:mod:`fpm_sim.study.loo`); ``None`` when the file
        has no data groups or no discrepancy."""
        if self.data is None or DISCREPANCY not in self.likelihood or self.data.measured_hz.size < 2:
            return None
        dat = self.data
        if self.mode_read is not None and dat.f_modes_hz is not None and dat.read_probability is not None:
            d = np.asarray(self.likelihood[DISCREPANCY], float)
            mu, sd, w = draws_components(
                dat.measured_hz, dat.sigma_hz, dat.f_modes_hz, dat.read_probability, d, leave_out=True
            )
            return loo_from_components(mu, sd, w, dat.measured_hz, labels=dat.labels)
        return leave_one_out(
            self.data.f_hz,
            self.data.measured_hz,
            self.data.sigma_hz,
            np.asarray(self.likelihood[DISCREPANCY], float),
            features=self.data.features,
            length_scale_m=self.length_scale_m,
            labels=self.data.labels,
        )

    def summary(self) -> list[dict[str, Any]]:
        """Per parameter: median, 5 % and 95 % quantiles over the draws."""
        q = np.quantile(self.values, (0.05, 0.5, 0.95), axis=0)
        return [
            {"name": n, "median": float(q[1, j]), "q05": float(q[0, j]), "q95": float(q[2, j])}
            for j, n in enumerate(self.names)
        ]


# ----------------------------------------------------------------------------------------------- bands


def _predictive_quantiles(
    f: np.ndarray, d: np.ndarray, levels: Sequence[float], shift: np.ndarray | None = None
) -> np.ndarray:
    """Exact quantiles of the mixture over draws ``i`` of ``f_i (1 + shift_i + d_i z)``, ``z`` standard normal.

    ``f``: ``(n_draws, n_poses, n_modes)`` (or ``(n_draws, ...)``) with NaN where a draw has no value; ``d``:
    ``(n_draws,)`` or ``(n_draws, n_poses)``, >= 0; ``shift`` (default 0): as ``d``. The mixture's CDF
    ``mean_i Phi((x / f_i - 1 - shift_i) / d_i)`` over the draws with a value is inverted by bisection (80
    halvings of a bracket 12 standard deviations wide: to round-off). Returns ``(len(levels), ...)``; NaN where
    no draw has a value.
    """
    from scipy.special import ndtr

    valid = np.isfinite(f)
    n = valid.sum(axis=0)
    d_arr = np.asarray(d, float)
    dd = d_arr.reshape(d_arr.shape + (1,) * (f.ndim - d_arr.ndim))
    sh = np.zeros_like(dd) if shift is None else np.asarray(shift, float).reshape(dd.shape)
    fz = np.where(valid, f, 1.0)
    centre = fz * (1.0 + sh)
    spread = np.where(valid, np.abs(fz) * dd, 0.0).max(axis=0)
    lo = np.where(valid, centre, np.inf).min(axis=0) - 12.0 * spread - 1e-12
    hi = np.where(valid, centre, -np.inf).max(axis=0) + 12.0 * spread + 1e-12
    q = np.asarray(levels, float).reshape((-1,) + (1,) * (f.ndim - 1))
    lo = np.broadcast_to(lo, (len(q), *lo.shape)).copy()
    hi = np.broadcast_to(hi, (len(q), *hi.shape)).copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        for _ in range(80):
            x = 0.5 * (lo + hi)
            z = (x[None] / fz[:, None] - 1.0 - sh[:, None]) / dd[:, None]
            step = np.where(x[None] >= centre[:, None], 1.0, 0.0)  # a draw without discrepancy: a step
            p = np.where(valid[:, None], np.where(dd[:, None] > 0, ndtr(z), step), 0.0).sum(axis=0) / n
            below = p < q
            lo = np.where(below, x, lo)
            hi = np.where(below, hi, x)
    out: np.ndarray = np.where(n > 0, 0.5 * (lo + hi), np.nan)
    return out


def _quantiles(f: np.ndarray) -> np.ndarray:
    """:data:`QUANTILES` of ``f`` over its first axis, ignoring NaN (NaN where a column has no value)."""
    out = np.full((len(QUANTILES), *f.shape[1:]), np.nan)
    has = np.isfinite(f).any(axis=0)
    if has.any():
        out[:, has] = np.nanquantile(f[:, has], QUANTILES, axis=0)
    return out


@dataclass
class PredictiveBands:
    """Frequencies of the posterior's draws at poses, and their quantiles (:func:`predict_bands`).

    Attributes
    ----------
    name
        The base description's name.
    poses
        The poses: the 3RRR's, or a described machine's :class:`~fpm_sim.architecture.TaskPose` values.
    draw_index
        ``(n_draws,)`` index of each draw in the posterior.
    frequencies_hz
        ``(n_draws, n_poses, n_modes)``; NaN where a draw cannot reach the pose or meets a singularity.
    status
        ``(n_draws, n_poses)`` ``ok``, ``near_singular``, ``singular`` or ``unreachable``.
    options
        The pose loop's model options.
    labels
        Optional name of each pose (e.g. the study's cell ``row, col``).
    elapsed_s
        Wall time.
    discrepancy_rel
        ``(n_draws,)`` each draw's relative model discrepancy ``d`` (the posterior's
        ``likelihood.discrepancy_rel``), or ``(n_draws, n_poses)`` its sd at each pose (a Gaussian-process
        discrepancy conditioned on the data), or ``None`` when the posterior has none. With it the bands are
        *predictive*: a measured frequency is ``f (1 + shift + d z)``, ``z`` standard normal, as in the
        likelihood that made the posterior, so the band holds the model's own error besides the parameters'
        spread (Kennedy & O'Hagan). :attr:`parameter_quantiles_hz` keeps the parameters' spread alone.
    discrepancy_shift
        ``(n_draws, n_poses)`` the Gaussian-process discrepancy's conditional mean at each pose (relative: the
        correction the measured poses imply), or ``None`` (zero: an independent discrepancy).
    """

    name: str
    poses: list[AnyPose]
    draw_index: np.ndarray
    frequencies_hz: np.ndarray
    status: np.ndarray
    options: ModelOptions = field(default_factory=fast_options)
    labels: list[str] | None = None
    elapsed_s: float = 0.0
    discrepancy_rel: np.ndarray | None = None
    discrepancy_shift: np.ndarray | None = None
    read_freq_hz: np.ndarray | None = None
    """``(n_draws, n_poses, modes)`` under the latent-mode model: the modes a hammer test's first clear peak may
    be (:meth:`Posterior.read_at`); ``None`` otherwise."""
    read_weight: np.ndarray | None = None
    """``(n_draws, n_poses, modes)`` the probability that the first clear peak is each of them."""
    read_noise_rel: float = 0.0
    """The measurement's relative sd added to a read value's predictive (the data's median)."""
    task: tuple[str, ...] | None = None
    """A described machine's task coordinates (the poses' columns and labels); ``None``: the 3RRR's x, y, phi."""

    def coordinates(self, i: int) -> dict[str, float]:
        """Pose ``i``'s coordinates as the tables name them (:func:`pose_columns`)."""
        return pose_columns(self.poses[i], self.task)

    @property
    def read_quantiles_hz(self) -> np.ndarray | None:
        """``(len(QUANTILES), n_poses)`` quantiles of what a hammer test like the data's would read as "the first
        frequency" (latent-mode model; ``None`` otherwise): the mixture over draws and modes of ``f_k (1 + d z)``
        plus the measurement noise, weighted by the read probabilities."""
        if self.read_freq_hz is None or self.read_weight is None or self.discrepancy_rel is None:
            return None
        d = np.asarray(self.discrepancy_rel, float)
        d = d[:, None, None] if d.ndim == 1 else d[:, :, None]
        sd = self.read_freq_hz * np.sqrt(d**2 + self.read_noise_rel**2)
        w = np.where(self.computed[:, :, None], self.read_weight, np.nan)
        return mixture_quantiles(self.read_freq_hz, sd, w, QUANTILES)

    @property
    def n_draws(self) -> int:
        return int(self.frequencies_hz.shape[0])

    @property
    def n_modes(self) -> int:
        return int(self.frequencies_hz.shape[2])

    @property
    def computed(self) -> np.ndarray:
        """``(n_draws, n_poses)``: the draw has frequencies at the pose."""
        return np.isin(self.status, COMPUTED) & np.isfinite(self.frequencies_hz[:, :, 0])

    @property
    def computed_fraction(self) -> np.ndarray:
        """``(n_poses,)`` share of the draws with frequencies at each pose (the quantiles are over these)."""
        return self.computed.mean(axis=0)

    @property
    def unreachable_fraction(self) -> np.ndarray:
        """``(n_poses,)`` share of the draws that cannot reach each pose."""
        return (self.status == STATUS_UNREACHABLE).mean(axis=0)

    @property
    def parameter_quantiles_hz(self) -> np.ndarray:
        """``(len(QUANTILES), n_poses, n_modes)`` quantiles of the model's frequencies over the computed draws
        (the parameters' spread alone; NaN where no draw is computed)."""
        f = np.where(self.computed[:, :, None], self.frequencies_hz, np.nan)
        return _quantiles(f)

    @property
    def quantiles_hz(self) -> np.ndarray:
        """``(len(QUANTILES), n_poses, n_modes)`` quantiles of the prediction: with a model discrepancy, of the
        posterior predictive ``f (1 + d z)`` over the computed draws (exact, :func:`_predictive_quantiles`);
        without one, :attr:`parameter_quantiles_hz`."""
        if self.discrepancy_rel is None:
            return self.parameter_quantiles_hz
        f = np.where(self.computed[:, :, None], self.frequencies_hz, np.nan)
        return _predictive_quantiles(f, np.asarray(self.discrepancy_rel, float), QUANTILES, self.discrepancy_shift)

    def quantile_hz(self, q: float) -> np.ndarray:
        """``(n_poses, n_modes)`` quantile ``q`` (one of :data:`QUANTILES`)."""
        if q not in QUANTILES:
            raise FpmSimError("not a quantile of the bands", parameter="q", value=q, hint=f"one of {QUANTILES}")
        return self.quantiles_hz[QUANTILES.index(q)]

    @property
    def median_hz(self) -> np.ndarray:
        return self.quantile_hz(0.5)

    @property
    def relative_width(self) -> np.ndarray:
        """``(n_poses, n_modes)`` width of the 90 % band over the median."""
        q = self.quantiles_hz
        with np.errstate(invalid="ignore", divide="ignore"):
            return (q[-1] - q[0]) / q[2]

    def widest(self, mode: int = 1) -> int | None:
        """Index of the pose with the widest relative 90 % band of mode ``mode`` (``None`` if none computed):
        the pose where one more measurement says most ("measure here next"). Only poses that every draw
        reaches away from singularities (status ``ok``) are candidates, where any is: near a singularity f1
        dives to zero and a band's width says more about the locus than about the machine."""
        w = self.relative_width[:, mode - 1].copy()
        all_ok = np.all(self.status == STATUS_OK, axis=0) & np.isfinite(w)
        if all_ok.any():
            w[~all_ok] = np.nan
        return int(np.nanargmax(w)) if np.isfinite(w).any() else None

    def probability_above(self, f_min_hz: float, mode: int = 1) -> np.ndarray:
        """``(n_poses,)`` share of all draws with frequency ``mode`` at least ``f_min_hz`` (a draw without
        frequencies at the pose counts as below)."""
        f = np.where(self.computed, self.frequencies_hz[:, :, mode - 1], -np.inf)
        return (f >= f_min_hz).mean(axis=0)

    def meet_probability(self, level_hz: float, mode: int = 1) -> np.ndarray:
        """``(n_draws, n_poses)`` probability that each draw's machine has frequency ``mode`` at least
        ``level_hz`` at each pose, under the predictive model of :attr:`quantiles_hz`: ``Phi((1 - L / f) / d)``
        with a model discrepancy ``d``, else 1 where ``f >= L``; 0 where the draw has no frequency there."""
        f = np.where(self.computed, self.frequencies_hz[:, :, mode - 1], np.nan)
        if self.discrepancy_rel is None:
            out: np.ndarray = np.where(np.isfinite(f), (f >= level_hz).astype(float), 0.0)
            return out
        from scipy.special import ndtr

        d = np.asarray(self.discrepancy_rel, float)
        d = d[:, None] if d.ndim == 1 else d
        sh = 0.0 if self.discrepancy_shift is None else np.asarray(self.discrepancy_shift, float)
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.where(d > 0, (1.0 + sh - level_hz / f) / d, np.where(f * (1.0 + sh) >= level_hz, np.inf, -np.inf))
        out = np.where(np.isfinite(f), ndtr(z), 0.0)
        return out

    def label(self, i: int) -> str:
        if self.labels is not None:
            return self.labels[i]
        return pose_text(self.poses[i], self.task)

    def rows(self) -> list[dict[str, Any]]:
        """One row per pose: coordinates, shares of computed and unreachable draws, and per mode the median and
        the 5/25/75/95 % quantiles (Hz)."""
        q = self.quantiles_hz
        comp, unreach = self.computed_fraction, self.unreachable_fraction
        out = []
        for i in range(len(self.poses)):
            row: dict[str, Any] = self.coordinates(i)
            if self.labels is not None:
                row["label"] = self.labels[i]
            row.update({"computed_fraction": float(comp[i]), "unreachable_fraction": float(unreach[i])})
            for k in range(self.n_modes):
                for j, level in enumerate(QUANTILES):
                    row[f"f{k + 1}_q{round(100 * level):02d}_hz"] = float(q[j, i, k])
            out.append(row)
        return out

    def table(self) -> str:
        """Per pose and mode: median, 50 % band, 90 % band, and the share of draws computed."""
        q = self.quantiles_hz
        comp = self.computed_fraction
        heads = ["pose", "mode", "median Hz", "25-75 % Hz", "5-95 % Hz", "90 % width", "draws"]
        cells = []
        for i in range(len(self.poses)):
            for k in range(self.n_modes):
                m = q[2, i, k]
                cells.append(
                    [
                        self.label(i) if k == 0 else "",
                        str(k + 1),
                        f"{m:.2f}",
                        f"{q[1, i, k]:.2f} .. {q[3, i, k]:.2f}",
                        f"{q[0, i, k]:.2f} .. {q[4, i, k]:.2f}",
                        f"{100 * (q[4, i, k] - q[0, i, k]) / m:.1f} %" if m > 0 else "-",
                        f"{round(comp[i] * self.n_draws)}/{self.n_draws}" if k == 0 else "",
                    ]
                )
        width = [max(len(h), *(len(c[j]) for c in cells)) if cells else len(h) for j, h in enumerate(heads)]
        lines = ["  ".join(h.rjust(w) for h, w in zip(heads, width))]
        lines += ["  ".join(c.rjust(w) for c, w in zip(row, width)) for row in cells]
        lines.append(
            f"{self.n_draws} posterior draws; median and quantiles over the draws that reach each pose "
            "(draws: computed/all)"
        )
        lines.append(self.kind_line())
        return "\n".join(lines)

    def kind_line(self) -> str:
        """What the bands hold: the parameters' spread alone, or the prediction with the model discrepancy."""
        if self.discrepancy_rel is None:
            return "bands: the parameters' spread only (the posterior has no model-discrepancy term)"
        d = np.asarray(self.discrepancy_rel, float)
        if self.discrepancy_shift is not None:
            return (
                "bands: predictive, the parameters' spread and the model's own error as a Gaussian process over "
                "the pose conditioned on the measured poses, f (1 + shift + sd z) (discrepancy sd at these poses: "
                f"median {100 * np.median(d):.0f} %, 5-95 % {100 * np.quantile(d, 0.05):.0f}-"
                f"{100 * np.quantile(d, 0.95):.0f} %)"
            )
        return (
            "bands: predictive, the parameters' spread and the model's own error f (1 + d z) of the likelihood "
            f"(discrepancy d: median {100 * np.median(d):.0f} %, 5-95 % {100 * np.quantile(d, 0.05):.0f}-"
            f"{100 * np.quantile(d, 0.95):.0f} %)"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: quantile levels, per-pose rows (bands), and every draw's frequencies and status."""
        w = self.widest()
        return {
            "config": self.name,
            "task": list(self.task) if self.task is not None else None,
            "n_draws": self.n_draws,
            "n_modes": self.n_modes,
            "quantiles": list(QUANTILES),
            "draw_index": self.draw_index.tolist(),
            "bands": self.rows(),
            "widest_relative_band_pose": w,
            "frequencies_hz": np.where(np.isfinite(self.frequencies_hz), self.frequencies_hz, np.array(None)).tolist(),
            "status": self.status.tolist(),
            "segments": self.options.segments,
            "resolution": resolution_summary(self.options),
            "elapsed_s": self.elapsed_s,
            "bands_kind": self.kind_line(),
            "discrepancy_rel": None if self.discrepancy_rel is None else np.asarray(self.discrepancy_rel).tolist(),
            "discrepancy_shift": None
            if self.discrepancy_shift is None
            else np.asarray(self.discrepancy_shift).tolist(),
        }

    @property
    def dataset(self) -> Any:
        """An :class:`xarray.Dataset`: ``freq_hz`` over ``(draw, pose, mode)``, ``freq_quantile_hz`` over
        ``(quantile, pose, mode)`` and ``computed_fraction`` over ``pose``; coordinates ``x_mm``, ``y_mm``,
        ``phi_rad`` (and ``z_mm`` for a described machine; on ``pose``) and ``status`` (on ``draw, pose``)."""
        coords: dict[str, Any] = {"quantile": np.array(QUANTILES)}
        if self.task is not None:
            coords["z_mm"] = ("pose", [_value(p, "z") * 1e3 for p in self.poses])
        return frequencies_dataset(
            self.frequencies_hz,
            x_mm=[p.x_m * 1e3 for p in self.poses],
            y_mm=[p.y_m * 1e3 for p in self.poses],
            phi_rad=[p.phi_rad for p in self.poses],
            status=self.status.astype(str),
            leading={"draw": self.draw_index},
            data_vars={
                "freq_quantile_hz": (("quantile", "pose", "mode"), self.quantiles_hz),
                "computed_fraction": ("pose", self.computed_fraction),
            },
            coords=coords,
            attrs={"config": self.name, "segments": int(self.options.segments or 0), "task": ",".join(self.task or ())},
        )

    def write(self, out_dir: str | Path, *, stem: str = "bands", figures: bool = True) -> list[Path]:
        """Write ``<stem>.nc`` (:attr:`dataset`, netCDF-4), ``<stem>.csv`` (:meth:`rows`) and the figures
        ``<stem>.png`` (:meth:`plot`) and ``<stem>_map.png`` (:meth:`plot_map`); returns the paths."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = [out / f"{stem}.nc", out / f"{stem}.csv"]
        self.dataset.to_netcdf(paths[0], engine="h5netcdf")
        _write_rows(paths[1], self.rows())
        if figures:
            import matplotlib.pyplot as plt

            # the per-pose band figure only where its pose labels stay readable
            todo: list[tuple[str, Callable[[], Any]]] = [(f"{stem}.png", self.plot)] if len(self.poses) <= 60 else []
            for name, draw in [*todo, (f"{stem}_map.png", self.plot_map)]:
                fig = draw()
                fig.savefig(out / name, dpi=110)
                plt.close(fig)
                paths.append(out / name)
        return paths

    # ------------------------------------------------------------------------------------------ figures

    def plot(self, ax: Any = None, *, mode: int = 1, measured_hz: Sequence[float] | np.ndarray | None = None) -> Any:
        """Median and bands of frequency ``mode`` at each pose (thick: 25-75 %, thin: 5-95 %), with
        ``measured_hz`` (NaN: none) as crosses; at a single pose, every mode side by side. Returns the
        ``Figure``."""
        import matplotlib.pyplot as plt

        per_mode = len(self.poses) == 1 and measured_hz is None
        n = self.n_modes if per_mode else len(self.poses)
        if ax is None:
            fig, ax = plt.subplots(figsize=(max(5.0, 0.45 * n + 2), 3.8), constrained_layout=True)
        else:
            fig = ax.figure
        q = self.quantiles_hz[:, 0, :] if per_mode else self.quantiles_hz[:, :, mode - 1]
        x = np.arange(n)
        ax.vlines(x, q[0], q[4], color="C0", lw=1.2, label="5-95 %")
        ax.vlines(x, q[1], q[3], color="C0", lw=5, alpha=0.6, label="25-75 %")
        ax.plot(x, q[2], "o", color="C0", ms=4, label="median")
        if measured_hz is not None:
            ax.plot(x, np.asarray(measured_hz, float), "x", color="C3", ms=7, mew=1.5, label="measured")
        if per_mode:
            ax.set_xticks(x, [f"mode {k + 1}" for k in x])
            ax.set_ylabel("frequency (Hz)")
            what = f"at {self.label(0)}"
        else:
            ax.set_xticks(x, [self.label(i) for i in range(n)], rotation=60, ha="right", fontsize=6)
            ax.set_ylabel(f"f{mode} (Hz)")
            what = f"f{mode}"
        ax.set_title(f"{_short(self.name)}: {what}, {self.n_draws} posterior draws", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))  # beside the axes: covers no band
        return fig

    def plot_map(self, mode: int = 1) -> Any:
        """Two maps over the poses: the median of frequency ``mode`` and the relative width of its 90 % band;
        the pose of the widest band is marked "measure here next". Returns the ``Figure``."""
        import matplotlib.pyplot as plt

        x = np.array([p.x_m * 1e3 for p in self.poses])
        y = np.array([p.y_m * 1e3 for p in self.poses])
        med = self.median_hz[:, mode - 1]
        width = 100 * self.relative_width[:, mode - 1]
        fig, axes = plt.subplots(1, 2, figsize=(10, 4.4), constrained_layout=True)
        size = max(6.0, 3000.0 / max(len(x), 1))
        for a, v, lab in ((axes[0], med, f"median f{mode} (Hz)"), (axes[1], width, "90 % band width / median (%)")):
            ok = np.isfinite(v)
            sc = a.scatter(x[ok], y[ok], c=v[ok], s=size, marker="s")
            a.scatter(x[~ok], y[~ok], marker="x", s=8, color="0.7")
            fig.colorbar(sc, ax=a, label=lab, shrink=0.85)
            a.set_aspect("equal")
            a.set_xlabel("x (mm)")
            a.set_ylabel("y (mm)")
        title = "relative width of the 90 % band"
        w = self.widest(mode)
        if w is not None:
            axes[1].plot(x[w], y[w], ls="", marker="*", ms=16, color="red", mec="k", label="measure here next")
            axes[1].legend(fontsize=7, loc="lower right")
            units = "mm, rad" if "phi" in (self.task or ()) else "mm"
            at = f"({x[w]:g}, {y[w]:g}) mm" if self.task is None else f"{self.label(w)} ({units})"
            title += f"\nmeasure here next: {at}, band {width[w]:.1f} % of the median"
        axes[0].set_title(f"{_short(self.name)}: median over {self.n_draws} draws", fontsize=8)
        axes[1].set_title(title, fontsize=8)
        return fig


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """``rows`` as CSV (header from the first row); NaN and ``None`` as empty cells."""
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(
            {k: "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v for k, v in r.items()}
            for r in rows
        )


def _value(pose: AnyPose, coordinate: str) -> float:
    """A task coordinate of either pose kind (SI; the 3RRR's has no z: 0)."""
    if isinstance(pose, TaskPose):
        return pose.value(coordinate)
    return float({"x": pose.x_m, "y": pose.y_m, "z": 0.0, "phi": pose.phi_rad}[coordinate])


def pose_columns(pose: AnyPose, task: tuple[str, ...] | None) -> dict[str, float]:
    """A pose's coordinates as the tables name them: ``x_mm``, ``y_mm``, ``phi_rad`` (``task`` ``None``: the
    3RRR's), or one entry per task coordinate of a described machine (``z_mm`` where it has z)."""
    return {
        ("phi_rad" if c == "phi" else f"{c}_mm"): (_value(pose, c) if c == "phi" else round(_value(pose, c) * 1e3, 6))
        for c in task or ("x", "y", "phi")
    }


def pose_text(pose: AnyPose, task: tuple[str, ...] | None) -> str:
    """A pose in words: ``(x, y) mm, phi rad`` (the 3RRR's), or ``x=.., y=..`` in a described machine's task
    coordinates (mm, rad)."""
    if task is None:
        return f"({pose.x_m * 1e3:g}, {pose.y_m * 1e3:g}) mm, {pose.phi_rad:g} rad"
    return ", ".join(f"{c}={_value(pose, c):g}" if c == "phi" else f"{c}={_value(pose, c) * 1e3:g}" for c in task)


def _short(name: str, n: int = 40) -> str:
    return name if len(name) <= n else name[: n - 3] + "..."


def _draw_frequencies(
    posterior: Posterior,
    index: np.ndarray,
    poses: list[AnyPose],
    n_modes: int,
    opts: ModelOptions,
    engine: EngineOptions | None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(frequencies_hz, status)`` of the draws ``index`` at ``poses``: the 3RRR's pose loop on the engine
    (:func:`~fpm_sim.batch.pose_loop.solve_configs`), or a described machine's
    (:func:`~fpm_sim.batch.task_sweep.sweep_task_many`, its chunks on ``engine.workers`` processes; the likelihood's
    own frequencies: the K-th lowest elastic modes, actuators locked)."""
    configs = [posterior.config(int(i)) for i in index]
    eng = engine or EngineOptions()
    if isinstance(posterior.base, Description):
        from fpm_sim.batch.task_sweep import sweep_task_many

        bad = [i for i, p in enumerate(poses) if not isinstance(p, TaskPose)]
        if bad:
            raise FpmSimError(
                f"pose {bad[0] + 1} is not a task pose",
                parameter="poses",
                hint=f"{posterior.base.name}'s poses are fs.TaskPose values in its task coordinates "
                f"({', '.join(posterior.base.task)})",
            )
        workers = 1 if eng.scheduler == "serial" or not eng.workers else int(eng.workers)
        descs = [c for c in configs if isinstance(c, Description)]
        task_poses = [p for p in poses if isinstance(p, TaskPose)]
        sweeps = sweep_task_many(descs, task_poses, options=opts, n_modes=n_modes, workers=workers)
        return np.stack([sw.freq_hz for sw in sweeps]), np.array([sw.status for sw in sweeps], dtype=object)
    bad = [i for i, p in enumerate(poses) if not isinstance(p, Pose)]
    if bad:
        raise FpmSimError(
            f"pose {bad[0] + 1} is a task pose", parameter="poses", hint="the 3RRR's poses are fs.Pose values"
        )
    eng = dataclasses.replace(eng, desc="draws x poses" if eng.desc == "poses" else eng.desc)
    manips = [c for c in configs if isinstance(c, Manipulator)]
    parts = solve_configs(manips, [p for p in poses if isinstance(p, Pose)], n_modes=n_modes, options=opts, engine=eng)
    return np.stack([m.frequencies_hz for m in parts]), np.array([m.status for m in parts], dtype=object)


def predict_bands(
    posterior: Posterior,
    poses: Sequence[AnyPose],
    *,
    n_draws: int | None = 100,
    seed: int = 0,
    n_modes: int = 3,
    options: ModelOptions | None = None,
    engine: EngineOptions | None = None,
    labels: Sequence[str] | None = None,
    read: bool = False,
) -> PredictiveBands:
    """Lowest ``n_modes`` frequencies of ``n_draws`` posterior draws (:meth:`Posterior.draws`) at ``poses``,
    with their quantiles.

    The loop over draws x poses runs on the engine exactly as a design study's designs x poses
    (:func:`fpm_sim.batch.pose_loop.solve_configs`); a described machine's through its own pose loop
    (:func:`fpm_sim.batch.task_sweep.sweep_task_many`), at :class:`~fpm_sim.architecture.TaskPose` values.

    Parameters
    ----------
    posterior
        The posterior (:meth:`Posterior.from_netcdf`).
    poses
        The poses.
    n_draws, seed
        How many draws (``None``: all) and which (:meth:`Posterior.draws`).
    n_modes
        Modes per pose.
    options
        Discretisation (default: the pose loop's options at the likelihood's resolution,
        ``fast_options(segments=posterior.segments)``).
    engine
        Where the chunks run (:class:`fpm_sim.batch.engine.EngineOptions`).
    labels
        Optional names of the poses (tables and figures).
    read
        Also predict what a hammer test like the data's would read (:attr:`PredictiveBands.read_quantiles_hz`),
        when the posterior has the latent-mode model (:meth:`Posterior.read_at`; about 0.1 s per draw).
    """
    if n_modes < 1:
        raise FpmSimError("must be >= 1", parameter="n_modes", value=n_modes)
    poses = list(poses)
    if not poses:
        raise FpmSimError("no poses to predict at", parameter="poses", hint="give at least one pose")
    if labels is not None and len(labels) != len(poses):
        raise FpmSimError(
            f"{len(labels)} labels for {len(poses)} poses", parameter="labels", hint="give one label per pose"
        )
    index = posterior.draws(n_draws, seed)
    opts = options or (fast_options(segments=posterior.segments) if posterior.segments else fast_options())
    if isinstance(posterior.base, Description):  # its pose loop's policy (the likelihood's): inextensible, no gravity
        opts = dataclasses.replace(opts, gravity=False, axial=False)
    t0 = time.perf_counter()
    freq, status = _draw_frequencies(posterior, index, poses, n_modes, opts, engine)
    shift, sd = posterior.discrepancy_at(index, poses)
    read_f = read_w = None
    noise = 0.0
    if read and posterior.mode_read is not None and posterior.data is not None:
        read_f, read_w = posterior.read_at(index, poses, opts)
        noise = float(np.median(posterior.data.sigma_hz / posterior.data.measured_hz))
    return PredictiveBands(
        name=posterior.base.name,
        poses=poses,
        draw_index=index,
        frequencies_hz=freq,
        status=status,
        options=opts,
        labels=list(labels) if labels is not None else None,
        elapsed_s=time.perf_counter() - t0,
        discrepancy_rel=sd,
        discrepancy_shift=shift,
        read_freq_hz=read_f,
        read_weight=read_w,
        read_noise_rel=noise,
        task=posterior.base.task if isinstance(posterior.base, Description) else None,
    )


# ----------------------------------------------------------------------------------------------- the study


@dataclass
class StudyBands:
    """Bands at the study's poses (:func:`study_bands`): the measured ones, with the measured first frequency
    (in-sample coverage: the posterior was conditioned on them), then the withheld ones (predictions only:
    their measurements are not in the project)."""

    bands: PredictiveBands
    measured_hz: np.ndarray
    """``(n_poses,)`` measured f1 (NaN at the withheld poses)."""
    withheld: np.ndarray
    """``(n_poses,)`` True at the withheld poses."""
    reading: str
    loo: LeaveOneOut | None = None
    """The posterior's leave-one-out predictive of the measured poses it was conditioned on
    (:meth:`Posterior.leave_one_out`; ``None`` when the file lacks the data groups): out-of-sample, unlike the
    in-sample coverage."""

    def f1_quantiles_hz(self) -> np.ndarray:
        """``(len(QUANTILES), n_poses)`` the bands compared with the measured values: what the study's test would
        read (:attr:`PredictiveBands.read_quantiles_hz`) under the latent-mode model, else f1's."""
        read = self.bands.read_quantiles_hz
        return read if read is not None else self.bands.quantiles_hz[:, :, 0]

    def coverage(self) -> dict[str, float]:
        """At the measured poses: the share of measured f1 inside the 90 % and the 50 % bands, and the mean
        absolute error of the median (%)."""
        m = ~self.withheld & np.isfinite(self.measured_hz)
        q = self.f1_quantiles_hz()[:, m]
        f = self.measured_hz[m]
        n = int(m.sum())
        if n == 0:
            return {"measured_poses": 0, "in_90_band": math.nan, "in_50_band": math.nan, "median_error_pct": math.nan}
        with np.errstate(invalid="ignore"):
            return {
                "measured_poses": n,
                "in_90_band": float(np.mean((f >= q[0]) & (f <= q[4]))),
                "in_50_band": float(np.mean((f >= q[1]) & (f <= q[3]))),
                "median_error_pct": float(np.nanmean(np.abs(q[2] / f - 1.0)) * 100),
            }

    def table(self) -> str:
        """Measured poses (median, bands, measured, inside which band) and withheld poses (median, bands)."""
        q = self.f1_quantiles_hz()
        comp = self.bands.computed_fraction
        n = self.bands.n_draws
        what = (
            "the first clear peak a hammer test reads (latent-mode model: mode 1, 2 or 3 by its peak at the sensor)"
            if self.bands.read_quantiles_hz is not None
            else "f1"
        )
        lines = [
            f"{what} over {n} posterior draws, reading {self.reading}",
            f"{'cell':>10}  {'median Hz':>9}  {'25-75 % Hz':>15}  {'5-95 % Hz':>15}  {'measured Hz':>11}  "
            f"{'in':>4}  draws",
        ]
        for group, title in ((False, "measured poses (in-sample)"), (True, "withheld poses (predictions only)")):
            lines.append(f"  {title}")
            for i in np.flatnonzero(self.withheld == group):
                f = self.measured_hz[i]
                inside = (
                    "-"
                    if not math.isfinite(f)
                    else "50"
                    if q[1, i] <= f <= q[3, i]
                    else "90"
                    if q[0, i] <= f <= q[4, i]
                    else "out"
                )
                lines.append(
                    f"{self.bands.label(int(i)):>10}  {q[2, i]:>9.2f}  {q[1, i]:>6.2f} .. {q[3, i]:>6.2f}  "
                    f"{q[0, i]:>6.2f} .. {q[4, i]:>6.2f}  {'' if not math.isfinite(f) else f'{f:.2f}':>11}  "
                    f"{inside:>4}  {round(comp[i] * n)}/{n}"
                )
        c = self.coverage()
        lines.append(
            f"coverage at the {c['measured_poses']} measured poses: {100 * c['in_90_band']:.0f} % inside the 90 % "
            "band, "
            f"{100 * c['in_50_band']:.0f} % inside the 50 % band; median off by {c['median_error_pct']:.1f} % (mean)"
        )
        if self.loo is not None:
            lines.append(self.loo.summary_line())
        lines.append(self.bands.kind_line())
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: coverage, and per pose the bands, the measured value (``None``: withheld) and the flag."""
        rows = self.bands.rows()
        read = self.bands.read_quantiles_hz
        for i, (r, f, w) in enumerate(zip(rows, self.measured_hz, self.withheld)):
            r["measured_hz"] = float(f) if math.isfinite(f) else None
            r["withheld"] = bool(w)
            if read is not None:  # what a hammer test would read (the latent-mode model)
                r.update({f"read_q{round(100 * q):02d}_hz": float(read[k, i]) for k, q in enumerate(QUANTILES)})
        return {
            "reading": self.reading,
            "n_draws": self.bands.n_draws,
            "coverage": self.coverage(),
            "leave_one_out": None if self.loo is None else self.loo.to_dict(),
            "poses": rows,
            "resolution": resolution_summary(self.bands.options),
        }

    def write(self, out_dir: str | Path, *, stem: str = "bands") -> list[Path]:
        """Write ``<stem>.nc`` and ``<stem>.csv`` (the bands, with the measured value and the withheld flag per
        pose) and ``<stem>.png`` (:meth:`plot`); returns the paths."""
        import matplotlib.pyplot as plt

        out = Path(out_dir)
        paths = self.bands.write(out, stem=stem, figures=False)
        _write_rows(paths[1], self.to_dict()["poses"])
        fig = self.plot()
        fig.savefig(out / f"{stem}.png", dpi=110)
        plt.close(fig)
        return [*paths, out / f"{stem}.png"]

    def plot(self, ax: Any = None) -> Any:
        """The bands of f1 at the measured poses (with the measured values) and the withheld ones (shaded); under
        the latent-mode model the bands of what a hammer test reads, with the machine's f1 median beside them."""
        fig = self.bands.plot(ax, measured_hz=self.measured_hz)
        a = fig.axes[0] if ax is None else ax
        read = self.bands.read_quantiles_hz
        if read is not None:
            x = np.arange(read.shape[1]) + 0.25
            a.vlines(x, read[0], read[4], color="tab:green", alpha=0.35, lw=4, label="read: 90 % band")
            a.vlines(x, read[1], read[3], color="tab:green", alpha=0.9, lw=4, label="read: 50 % band")
            a.plot(x, read[2], "_", color="darkgreen", ms=9, label="read: median (first clear peak)")
        w = np.flatnonzero(self.withheld)
        if w.size:
            a.axvspan(w.min() - 0.5, w.max() + 0.5, color="0.9", zorder=0, label="withheld: predictions only")
            a.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        a.set_xlabel("study cell (row, col) mm")
        return fig


def study_bands(
    posterior: Posterior,
    *,
    reading: TableReading | None = None,
    n_draws: int | None = 100,
    seed: int = 0,
    options: ModelOptions | None = None,
    engine: EngineOptions | None = None,
) -> StudyBands:
    """Bands of f1 at the study's measured poses (:func:`fpm_sim.study.tables.measured_table`) and at its
    withheld poses (:func:`fpm_sim.study.tables.withheld_cells`: coordinates only) under ``reading``."""
    if isinstance(posterior.base, Description):
        raise PosteriorError(
            f"the study's measured and withheld poses are the 3RRR's; {posterior.base.name!r} has its own",
            parameter="posterior",
            hint="predict at its own task poses (predict_bands)",
        )
    rd = reading or TableReading()
    measured = [(m.row_mm, m.col_mm, m.measured_hz) for m in measured_table() if m.readable]
    cells = [(r, c, f) for r, c, f in measured] + [(r, c, math.nan) for r, c in withheld_cells()]
    bands = predict_bands(
        posterior,
        [rd.pose(r, c) for r, c, _ in cells],
        n_draws=n_draws,
        seed=seed,
        n_modes=1,
        options=options,
        engine=engine,
        labels=[f"{r:g},{c:g}" for r, c, _ in cells],
        read=True,
    )
    return StudyBands(
        bands=bands,
        measured_hz=np.array([f for _, _, f in cells]),
        withheld=np.array([i >= len(measured) for i in range(len(cells))]),
        reading=rd.name,
        loo=posterior.leave_one_out(),
    )


def _mode_read(post: Any, p: Path) -> ModeRead | None:
    """The latent-mode model the file's posterior was computed with, or ``None``."""
    if MODE_READ_ATTR not in post.attrs:
        return None
    try:
        return mode_read_from_text(str(post.attrs[MODE_READ_ATTR]))
    except (ValueError, KeyError, TypeError) as exc:
        raise PosteriorError(f"not the latent-mode settings ({exc})", parameter=MODE_READ_ATTR, file=p) from None


def _inference_data(p: Path) -> Any:
    """The ArviZ file ``p`` (an ``InferenceData``; Any: ArviZ is untyped here), refused with
    :class:`PosteriorError` when missing, unreadable, without a ``posterior`` group or with more than one chain."""
    if p.is_dir():
        raise PosteriorError("is a folder", parameter="posterior", value=str(p), hint=WRITTEN_BY)
    if not p.is_file():
        raise PosteriorError("file not found", parameter="posterior", value=str(p), hint=WRITTEN_BY)
    import arviz as az

    try:
        idata = az.from_netcdf(p)
    except Exception as exc:  # any reader failure (not HDF5/netCDF, damaged): the file given is not one; name it
        raise PosteriorError(
            f"{p}: not an ArviZ InferenceData netCDF file ({type(exc).__name__}: {exc})",
            parameter="posterior",
            hint=WRITTEN_BY,
        ) from None
    if "posterior" not in idata.groups():
        raise PosteriorError("no 'posterior' group", file=p, hint=WRITTEN_BY)
    post = idata.posterior
    missing = [a for a in REQUIRED_ATTRS if a not in post.attrs]
    if missing:
        raise PosteriorError(
            f"the posterior group lacks the attribute(s) {', '.join(missing)}",
            file=p,
            hint="it needs the base description, free groups, resolution and command; see docs/identification.md",
        )
    if post.sizes.get("chain", 1) != 1:
        raise PosteriorError(
            "more than one chain",
            parameter="chain",
            value=int(post.sizes["chain"]),
            file=p,
            hint="the format holds one chain of equal-weight draws",
        )
    return idata


def _posterior_attributes(post: Any, p: Path) -> tuple[Manipulator | Description, tuple[str, ...], int]:
    """The base description, free groups and model resolution the posterior ``post`` (of file ``p``) states: the
    3RRR's form, or a described machine's file (it has ``[[chains]]``)."""
    base: Manipulator | Description
    try:
        data = tomllib.loads(str(post.attrs[BASE_CONFIG_ATTR]))
        if data.get("kind") == "imported":
            raise PosteriorError(
                "an imported model's posterior: predictions with bands and test planning run on the 3RRR's and the "
                "described architectures' posteriors so far",
                parameter=BASE_CONFIG_ATTR,
                file=p,
                hint="predict with the posterior median (OUT/description.toml of the calibration) in 'modes' or "
                "'sweep'",
            )
        if isinstance(data.get("chains"), list):
            base = parse_description(data, source=f"posterior: {p.name}")
        else:
            base = parse_config(data, source=f"posterior: {p.name}")
    except (tomllib.TOMLDecodeError, ConfigError) as exc:
        raise PosteriorError(f"not a valid description ({exc})", parameter=BASE_CONFIG_ATTR, file=p) from None
    groups = tuple(g.strip() for g in str(post.attrs[GROUPS_ATTR]).split(",") if g.strip())
    try:
        segments = int(post.attrs[SEGMENTS_ATTR])
    except (TypeError, ValueError):
        raise PosteriorError(
            "must be an integer", parameter=SEGMENTS_ATTR, value=post.attrs[SEGMENTS_ATTR], file=p
        ) from None
    return base, groups, segments


def _parameter_names(post: Any, base: Manipulator | Description, groups: tuple[str, ...], p: Path) -> list[str]:
    """The posterior's parameter variables, in the order of the free groups' parameter set first (a described
    machine's: of its free paths)."""
    names = [str(n) for n in post.data_vars if str(n) != ELBOW_BRANCH_VAR and not str(n).startswith(LIKELIHOOD_PREFIX)]
    try:
        ps_names = list(groups) if isinstance(base, Description) else parameter_set(base, list(groups)).names
    except FpmSimError as exc:
        raise PosteriorError(
            f"free groups unusable ({exc})", parameter=GROUPS_ATTR, value=",".join(groups), file=p
        ) from None
    names = [n for n in ps_names if n in names] + [n for n in names if n not in ps_names]  # set order first
    if not names:
        raise PosteriorError(
            "the posterior group holds no parameter variables", file=p, hint=f"expected {', '.join(ps_names)}"
        )
    return names
