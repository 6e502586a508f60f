"""Did the fit find the machine? (issue 31, item 5): the cost against the noise floor, what the data determine,
and the measured poses the identified machine cannot reach.

1. **Noise floor.** With the data's stated sigmas, ``chi2 = sum((f_model,i - f_measured,i) / sigma_i)^2`` over the
   data (the workspace prior's residuals are not data and are left out) has, at the optimum of a model that
   contains the machine, the chi-squared distribution with ``n - p`` degrees of freedom. Its upper-tail
   probability (the p-value) says how likely a cost this large is from the noise alone. The fit is "at the noise
   floor" when the p-value is at least :data:`P_VALUE_FLOOR`; otherwise it is ``chi2 / dof`` times above it (the
   model or the search is missing something, or the sigmas are too small).
2. **What the data determine.** The Gauss-Newton posterior of the parameters is ``N(x*, (J'J)^-1)`` with ``J`` the
   Jacobian of the residuals in sigmas. In parameters normalised to their bounds (``z``, so that directions mixing
   kilograms and metres are comparable), the singular value decomposition ``J_z = U S V'`` gives the posterior sd
   ``1 / s_k`` along each direction ``v_k``. A direction whose sd exceeds :data:`UNDETERMINED_SD` (a quarter of the
   bounds' width) is held by the bounds, not by the data: undetermined. Its parameters (weight ``|v_ik|`` at least
   :data:`DIRECTION_WEIGHT`) trade off against each other along it (signs: which move together). A parameter is
   undetermined when it weighs in an undetermined direction. The decision is a ratio of singular values far from
   its threshold for an exact null direction (sd ~1e12 of the width) and for a determined one, so round-off
   does not flip it. Parameters that the data determine only together are named too: every pair whose posterior
   correlation (from the same ``(J_z'J_z)^+``) is at least :data:`CORRELATED` in magnitude (e.g. the platform's
   mass against its joints' masses: the data see mostly their sum), so that a report shows where a value trades
   off against another instead of hiding it in two standard deviations.
3. **Poses.** Each distinct measured pose under the identified description: unreachable, or with a singularity
   measure (:mod:`fpm_sim.kinematics`) below the problem's ``min_singularity``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import chi2 as chi2_dist

from fpm_sim.config import Manipulator
from fpm_sim.kinematics import assemble_many
from fpm_sim.study.identify.problem import Problem, unique_poses

__all__ = [
    "CORRELATED",
    "DIRECTION_WEIGHT",
    "P_VALUE_FLOOR",
    "UNDETERMINED_SD",
    "Determination",
    "Diagnosis",
    "NoiseFloor",
    "determination",
    "diagnose",
    "noise_floor",
    "pose_problems",
]

P_VALUE_FLOOR = 1e-3
"""The smallest chi-squared p-value still called "at the noise floor" (a 1-in-1000 cost from noise alone)."""
UNDETERMINED_SD = 0.25
"""Posterior sd (fraction of the bounds' width) above which a direction is not determined by the data."""
DIRECTION_WEIGHT = 0.2
"""Smallest weight ``|v_ik|`` (unit vector) of a parameter named in an undetermined direction."""
CORRELATED = 0.9
"""Smallest posterior correlation (magnitude) of a pair of parameters reported as trading off."""


@dataclass(frozen=True)
class NoiseFloor:
    """The chi-squared test of the cost against the noise (module docstring, 1)."""

    chi2: float
    n_data: int
    n_parameters: int
    dof: int
    p_value: float

    @property
    def ratio(self) -> float:
        """``chi2 / dof`` (NaN without a degree of freedom): the cost in units of the noise's."""
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def at_floor(self) -> bool:
        return self.dof > 0 and self.p_value >= P_VALUE_FLOOR

    def summary(self) -> str:
        """The one-line verdict."""
        if self.dof <= 0:
            return "no residual degree of freedom: the noise floor cannot be tested"
        if self.at_floor:
            return f"fit at the noise floor (chi2 = {self.chi2:.4g} for {self.dof} dof, p = {self.p_value:.3g})"
        return (
            f"fit {self.ratio:.3g} times above the noise floor: the model or the search is missing something "
            f"(chi2 = {self.chi2:.4g} for {self.dof} dof, p = {self.p_value:.3g})"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "chi2": self.chi2,
            "n_data": self.n_data,
            "n_parameters": self.n_parameters,
            "dof": self.dof,
            "p_value": self.p_value,
            "ratio": self.ratio,
            "at_floor": self.at_floor,
            "summary": self.summary(),
        }


def noise_floor(residuals_sigma: np.ndarray, n_parameters: int) -> NoiseFloor:
    """The test on the data's residuals in sigmas (the workspace prior's left out by the caller)."""
    r = np.asarray(residuals_sigma, float)
    c2, dof = float(np.sum(r**2)), len(r) - n_parameters
    p = float(chi2_dist.sf(c2, dof)) if dof > 0 else math.nan
    return NoiseFloor(chi2=c2, n_data=len(r), n_parameters=n_parameters, dof=dof, p_value=p)


@dataclass(frozen=True)
class Determination:
    """Which parameters the data determine (module docstring, 2)."""

    names: list[str]
    posterior_sd: np.ndarray
    """Each parameter's Gauss-Newton posterior sd in its own unit, with the stated sigmas (inf along an exact null
    direction)."""
    determined: list[bool]
    undetermined_directions: list[dict[str, Any]] = field(default_factory=list)
    """Each: ``sd_fraction`` (posterior sd along it, fraction of the bounds' width) and ``weights`` (parameter ->
    signed weight)."""
    correlated: list[dict[str, Any]] = field(default_factory=list)
    """The pairs of parameters whose posterior correlation is at least :data:`CORRELATED` in magnitude, strongest
    first: each ``{"a": name, "b": name, "correlation": rho}`` (positive: an error in one comes with an error of
    the same sign in the other; negative: of opposite signs, the data seeing mostly a sum)."""

    def lines(self) -> list[str]:
        """The directions and the strongly correlated pairs, in words."""
        out = []
        for d in self.undetermined_directions:
            terms = " ".join(f"{w:+.2f} {n}" for n, w in d["weights"].items())
            out.append(f"undetermined (sd {d['sd_fraction']:.3g} of the bounds' width): {terms}")
        if self.correlated:
            pairs = ", ".join(f"{c['a']} ~ {c['b']} ({c['correlation']:+.3f})" for c in self.correlated)
            out.append(f"trade off (posterior correlation >= {CORRELATED:g} in magnitude): {pairs}")
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": {
                n: {"posterior_sd": float(s), "determined": bool(d)}
                for n, s, d in zip(self.names, self.posterior_sd, self.determined)
            },
            "undetermined_directions": self.undetermined_directions,
            "correlated": self.correlated,
        }


def determination(jacobian: np.ndarray, width: np.ndarray, names: Sequence[str]) -> Determination:
    """From the Jacobian of the residuals in sigmas with respect to the parameters in their units (rows: data
    only) and the bounds' widths (module docstring, 2)."""
    jz = np.asarray(jacobian, float) * np.asarray(width, float)[None, :]
    k = jz.shape[1]
    _, s, vt = np.linalg.svd(jz, full_matrices=True)
    s_full = np.zeros(k)
    s_full[: len(s)] = s
    with np.errstate(divide="ignore"):
        sd_dir = np.where(s_full > 0, 1.0 / s_full, np.inf)
    var_z = np.sum((vt.T**2) * np.where(np.isfinite(sd_dir), sd_dir**2, np.inf)[None, :], axis=1)
    sd_x = np.sqrt(var_z) * np.asarray(width, float)
    determined = [True] * k
    directions = []
    for j in np.argsort(-sd_dir):
        if not sd_dir[j] > UNDETERMINED_SD:
            break
        v = vt[j] * (1.0 if vt[j][np.argmax(np.abs(vt[j]))] > 0 else -1.0)  # sign: largest weight positive
        heavy = [i for i in np.argsort(-np.abs(v)) if abs(v[i]) >= DIRECTION_WEIGHT]
        for i in heavy:
            determined[i] = False
        directions.append(
            {"sd_fraction": float(sd_dir[j]), "weights": {names[i]: round(float(v[i]), 3) for i in heavy}}
        )
    return Determination(list(names), sd_x, determined, directions, correlated_pairs(s_full, vt, names))


def correlated_pairs(s: np.ndarray, vt: np.ndarray, names: Sequence[str]) -> list[dict[str, Any]]:
    """The pairs with posterior correlation at least :data:`CORRELATED` in magnitude, from the singular values ``s``
    and right singular vectors ``vt`` of ``J_z`` (the covariance ``V S^-2 V'`` restricted to the determined
    directions: a pair trading off along an exact null direction is named by the undetermined directions)."""
    keep = s > s.max() * 1e-10 if s.size and s.max() > 0 else np.zeros(len(s), bool)
    v = vt[keep].T
    cov = (v / s[keep][None, :] ** 2) @ v.T
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if sd[i] > 0 and sd[j] > 0:
                rho = float(cov[i, j] / (sd[i] * sd[j]))
                if abs(rho) >= CORRELATED:
                    out.append({"a": names[i], "b": names[j], "correlation": round(rho, 4)})
    return sorted(out, key=lambda c: -abs(c["correlation"]))


def pose_problems(problem: Problem, config: Manipulator) -> dict[str, list[str]]:
    """The distinct measured poses that ``config`` cannot reach, and those with a singularity measure below
    ``problem.min_singularity`` (labels with the measure)."""
    poses, _ = unique_poses(problem.observations)
    if not poses:
        return {"unreachable": [], "near_singular": []}
    asm = assemble_many(config.geometry, [p.x_m for p in poses], [p.y_m for p in poses], [p.phi_rad for p in poses])
    m = asm.singularity
    unreachable = [p.label() for p, ok in zip(poses, asm.reachable) if not ok]
    near = [
        f"{p.label()} (measure {v:.3g})"
        for p, ok, v in zip(poses, asm.reachable, m)
        if ok and np.isfinite(v) and v < problem.min_singularity
    ]
    return {"unreachable": unreachable, "near_singular": near}


@dataclass(frozen=True)
class Diagnosis:
    """Whether the fit found the machine: the three answers of the module docstring."""

    floor: NoiseFloor
    determination: Determination
    poses: dict[str, list[str]]
    min_singularity: float

    def summary(self) -> str:
        return self.floor.summary()

    def lines(self) -> list[str]:
        """The verdict, the undetermined parameters and the troubled poses, in words."""
        out = [self.summary()]
        und = [n for n, d in zip(self.determination.names, self.determination.determined) if not d]
        out.append("every parameter determined by the data" if not und else f"not determined: {', '.join(und)}")
        out += self.determination.lines()
        if self.poses["unreachable"]:
            out.append(f"measured poses the identified machine cannot reach: {', '.join(self.poses['unreachable'])}")
        if self.poses["near_singular"]:
            out.append(
                f"measured poses near a singularity (measure < {self.min_singularity:g}): "
                + ", ".join(self.poses["near_singular"])
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "summary": self.summary(),
            "noise_floor": self.floor.to_dict(),
            "determination": self.determination.to_dict(),
            "poses": dict(self.poses, min_singularity=self.min_singularity),
        }


def diagnose(
    problem: Problem, config: Manipulator, residuals: np.ndarray, jacobian: np.ndarray, width: np.ndarray
) -> Diagnosis:
    """The diagnosis at an optimum: ``residuals`` in sigmas and ``jacobian`` (parameters in their units) of the
    data rows only (the workspace prior's rows dropped by the caller)."""
    return Diagnosis(
        floor=noise_floor(residuals, len(width)),
        determination=determination(jacobian, width, problem.parameters.names),
        poses=pose_problems(problem, config),
        min_singularity=problem.min_singularity,
    )
