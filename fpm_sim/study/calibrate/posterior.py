"""Writing a calibration: ``posterior.nc`` (ArviZ ``InferenceData``, the format shared with the band
predictions) and ``config.toml`` (the posterior median with its provenance).

``posterior.nc`` groups (see ``docs/identification.md``, "Bayesian updating"):

- ``posterior``: one chain of equal-weight draws; one float64 variable per free parameter, named as
  :attr:`fpm_sim.study.identify.parameters.ParameterSet.names`; ``likelihood.discrepancy_rel``; when the
  elbow branches are sampled, ``geometry.elbow_branch`` (int8, dims ``chain, draw, arm``, values +-1).
  Attributes ``fpm_sim_base_config`` (TOML), ``fpm_sim_free_groups``, ``fpm_sim_segments``, ``fpm_sim_command``;
- ``sample_stats``: ``log_likelihood`` per draw; attributes ``log_evidence``, ``log_evidence_err``,
  ``n_calls``, ``ess_kish``; with enumerated classes ``classes`` (JSON: each class's ln Z, weight, runs), ``runs``,
  and with several runs ``runs_check_passed`` (0/1) and ``runs_check`` (the check's summary line);
- ``observed_data``: ``f_hz`` (dim ``obs``; coordinates ``x_mm``, ``y_mm``, ``phi_rad``, ``label``; for a described
  machine also ``mode``, the K of its ``fK_hz``, and ``z_mm`` where its task has z; its ``fpm_sim_base_config`` is
  its file and ``fpm_sim_free_groups`` its free dotted paths);
- ``posterior_predictive``: ``f_hz`` (the model's frequencies at each draw) and ``f_hz_measurement`` (plus
  one draw of the likelihood's noise), dims ``chain, draw, obs``; under the latent-mode model also
  ``f_hz_modes`` (``chain, draw, obs, mode``: the lowest modes) and ``read_probability`` (``chain, draw,
  setup, obs, mode``: each setup's probability that the first clear peak is that mode), and the posterior's
  attribute ``fpm_sim_mode_read`` (the model's settings, :func:`fpm_sim.study.readout.mode_read_text`).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.architecture import Description, TaskPose, description_toml
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.config import Manipulator, config_to_toml
from fpm_sim.outputs import atomic_file
from fpm_sim.study.calibrate.described import DescribedCalibrationProblem, median_description
from fpm_sim.study.calibrate.priors import BRANCH_PARAMETER
from fpm_sim.study.calibrate.problem import CalibrationProblem, FrequencyLikelihood
from fpm_sim.study.calibrate.sampler import Calibration
from fpm_sim.study.identify.problem import ELBOW_BRANCHES
from fpm_sim.study.readout import MODE_READ_ATTR, mode_read_text

__all__ = ["inference_data", "median_config", "thin", "write_config", "write_posterior"]


def _import_arviz() -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # arviz 0.23 announces its 1.0 refactor on import
        import arviz

    return arviz


def _obs_coords(cal: Calibration) -> dict[str, Any]:
    """The data's coordinates: each observation's pose (``z_mm`` too for a described machine that has it; an imported
    model's joint values, NaN where a pose names no value for a joint) and label."""
    p = cal.problem
    if isinstance(p, DescribedCalibrationProblem) and isinstance(p.base, ImportedDescription):
        qs = [o.pose if isinstance(o.pose, dict) else {} for o in p.observations]
        joints = list(dict.fromkeys(j for q in qs for j in q))
        return {
            "obs": np.arange(p.n_data),
            **{j: ("obs", np.array([q.get(j, math.nan) for q in qs])) for j in joints},
            "label": ("obs", np.array(p.labels, dtype=str)),
            "mode": ("obs", np.array([o.mode for o in p.observations], dtype=np.int64)),
        }
    xs = [o.pose.x_m * 1e3 for o in p.observations] + [math.nan] * len(p.rig_tests)
    ys = [o.pose.y_m * 1e3 for o in p.observations] + [math.nan] * len(p.rig_tests)
    ph = [o.pose.phi_rad for o in p.observations] + [math.nan] * len(p.rig_tests)
    out = {
        "obs": np.arange(p.n_data),
        "x_mm": ("obs", np.array(xs)),
        "y_mm": ("obs", np.array(ys)),
        "phi_rad": ("obs", np.array(ph)),
        "label": ("obs", np.array(p.labels, dtype=str)),
    }
    if isinstance(p, DescribedCalibrationProblem):
        out["mode"] = ("obs", np.array([o.mode for o in p.observations], dtype=np.int64))
        if isinstance(p.base, Description) and "z" in p.base.task:
            out["z_mm"] = ("obs", np.array([o.pose.z_m * 1e3 for o in p.observations if isinstance(o.pose, TaskPose)]))
    return out


def _base_text(p: FrequencyLikelihood) -> str:
    """The base description as TOML (the 3RRR's form, or a described machine's file)."""
    if isinstance(p, DescribedCalibrationProblem):
        return description_toml(p.base)
    assert isinstance(p, CalibrationProblem)
    return config_to_toml(p.base, default_source="start description")


def inference_data(cal: Calibration, *, command: str, idx: np.ndarray | None = None) -> Any:
    """The calibration as an ArviZ ``InferenceData`` (module docstring); ``idx``: a subset of the draws."""
    az = _import_arviz()
    import xarray as xr

    sel = np.arange(len(cal.draws)) if idx is None else np.asarray(idx)
    draws = cal.draws[sel]
    p = cal.problem
    n = len(sel)
    post: dict[str, Any] = {}
    for i, name in enumerate(p.names):
        if name == BRANCH_PARAMETER:
            br = np.array([ELBOW_BRANCHES[round(v)] for v in draws[:, i]], dtype=np.int8)
            post[name] = xr.DataArray(br[None], dims=("chain", "draw", "arm"))
        else:
            post[name] = xr.DataArray(draws[None, :, i].astype(np.float64), dims=("chain", "draw"))
    coords = {"chain": [0], "draw": np.arange(n), "arm": [0, 1, 2]}
    posterior = xr.Dataset(post, coords=coords if BRANCH_PARAMETER in p.names else {"chain": [0], "draw": np.arange(n)})
    posterior.attrs.update(
        fpm_sim_base_config=_base_text(p),
        fpm_sim_free_groups=",".join(p.groups),
        fpm_sim_segments=int(p.segments),
        fpm_sim_command=command,
    )
    oc = _obs_coords(cal)
    stats = xr.Dataset(
        {"log_likelihood": xr.DataArray(cal.log_likelihood[sel][None], dims=("chain", "draw"))},
        coords={"chain": [0], "draw": np.arange(n)},
    )
    stats.attrs.update(
        log_evidence=cal.log_evidence,
        log_evidence_err=cal.log_evidence_err,
        n_calls=cal.n_calls,
        n_iterations=cal.n_iterations,
        ess_kish=cal.ess_kish,
        converged=int(cal.converged),
    )
    if cal.classes:  # the enumerated classes' evidences and weights, the runs and their check (JSON)
        stats.attrs["classes"] = json.dumps([c.to_dict() for c in cal.classes])
        stats.attrs["runs"] = int(getattr(cal.options, "runs", 1))
    if cal.runs_check is not None:
        stats.attrs["runs_check_passed"] = int(cal.runs_check.passed)
        stats.attrs["runs_check"] = cal.runs_check.summary_line()
    observed = xr.Dataset({"f_hz": xr.DataArray(p.measured, dims=("obs",))}, coords=oc)
    observed["sigma_hz"] = xr.DataArray(p.sigma, dims=("obs",))
    ppc = xr.Dataset(
        {
            "f_hz": xr.DataArray(cal.f_pred[sel][None], dims=("chain", "draw", "obs")),
            "f_hz_measurement": xr.DataArray(cal.predictive_sample[sel][None], dims=("chain", "draw", "obs")),
        },
        coords={"chain": [0], "draw": np.arange(n), **oc},
    )
    if cal.readouts is not None:  # the latent-mode model: what predictions at new poses need (module docstring)
        read = p.priors.mode_read
        assert read is not None
        n_obs = len(p.observations)
        fm = np.full((n, p.n_data, read.modes), np.nan)
        pr = np.full((n, len(read.points), p.n_data, read.modes), np.nan)
        for row, k in enumerate(sel):
            fm[row, :n_obs], pr[row, :, :n_obs] = cal.readouts[int(k)][:2]
        ppc["f_hz_modes"] = xr.DataArray(fm[None], dims=("chain", "draw", "obs", "mode"))
        ppc["read_probability"] = xr.DataArray(pr[None], dims=("chain", "draw", "setup", "obs", "mode"))
        ppc = ppc.assign_coords(mode=np.arange(1, read.modes + 1), setup=[pt.label() for pt in read.points])
        posterior.attrs[MODE_READ_ATTR] = mode_read_text(read)
    return az.InferenceData(posterior=posterior, sample_stats=stats, observed_data=observed, posterior_predictive=ppc)


def thin(cal: Calibration, n: int, *, seed: int = 0) -> np.ndarray:
    """Indices of ``n`` draws picked at random without replacement (all when there are fewer)."""
    rng = np.random.default_rng(seed)
    k = len(cal.draws)
    return np.sort(rng.choice(k, size=min(n, k), replace=False))


def write_posterior(cal: Calibration, path: str | Path, *, command: str, idx: np.ndarray | None = None) -> None:
    """``posterior.nc`` (atomically)."""
    idata = inference_data(cal, command=command, idx=idx)
    with atomic_file(path) as tmp:
        idata.to_netcdf(str(tmp))


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def median_config(cal: Calibration, *, data_note: str) -> Manipulator:
    """The description at the posterior median of every continuous parameter (the most frequent elbow-branch
    class among the draws), each set value's provenance
    ``identified: posterior median +- sd (fpm-sim calibrate, DATA)``."""
    from fpm_sim.study.identify.report import identified_provenance

    p = cal.problem
    assert isinstance(p, CalibrationProblem), "a described machine's median is median_description's"
    theta = np.median(cal.draws, axis=0)
    if p.priors.sample_branches:
        k = p.names.index(BRANCH_PARAMETER)
        classes, counts = np.unique(np.round(cal.draws[:, k]).astype(int), return_counts=True)
        theta[k] = float(classes[np.argmax(counts)])
    cfg = p.config(theta)
    parts = [
        (name, f"{name} = {_fmt(float(np.median(cal.draws[:, i])))} +- {_fmt(float(np.std(cal.draws[:, i])))}")
        for i, name in enumerate(p.names[: len(p.priors.parameters)])
    ]
    prov = identified_provenance(cfg.provenance, parts, f"posterior median +- sd (fpm-sim calibrate, {data_note})")
    if p.priors.sample_branches:
        k = p.names.index(BRANCH_PARAMETER)
        share = float(np.mean(np.round(cal.draws[:, k]) == theta[k]))
        prov["geometry.elbow_branch"] = (
            f"identified: the most frequent elbow-branch class of the posterior ({100 * share:.0f} % of the draws; "
            f"fpm-sim calibrate, {data_note})"
        )
    return cfg.replace(provenance=prov)


def write_config(
    cal: Calibration, path: str | Path, *, data_note: str, command: str
) -> Manipulator | Description | ImportedDescription:
    """``config.toml``: :func:`median_config`, atomically; for a described machine its file at the posterior median
    (:func:`~fpm_sim.study.calibrate.described.median_description`)."""
    hdr = (
        "fpm-sim calibrate: the posterior median of every free parameter (a summary of the posterior, not a fit;\n"
        "the posterior itself is posterior.nc beside this file)\n" + f"Reproduce: {command}"
    )
    if isinstance(cal.problem, DescribedCalibrationProblem):
        desc = median_description(cal.problem, cal.draws, data_note=data_note)
        with atomic_file(path) as tmp:
            tmp.write_text(description_toml(desc, header=hdr))
        return desc
    cfg = median_config(cal, data_note=data_note)
    with atomic_file(path) as tmp:
        tmp.write_text(config_to_toml(cfg, header=hdr, default_source="start description"))
    return cfg
