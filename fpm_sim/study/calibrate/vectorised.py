"""The study calibration's cheap likelihoods for many particles at once: the support and the study's statements
(closed-form kinematics), and the in-plane surrogate's data likelihood, vectorised over descriptions.

A sampler's particles are thousands of descriptions; building each as a :class:`~fpm_sim.config.Manipulator` and
assembling it costs about a millisecond in Python. Here the free parameters of every particle become arrays at once
(:func:`~fpm_sim.study.identify.parameters.apply_parameters_batch`), the kinematics runs over (description, pose)
(:func:`~fpm_sim.kinematics.assemble_batch`) and the surrogate over the same
(:func:`~fpm_sim.study.inplane_surrogate.inplane_batch`): microseconds per particle. Row ``i`` of every function
equals what :class:`~fpm_sim.study.calibrate.problem.CalibrationProblem` gives for ``thetas[i]`` one at a time
(``tests/study/test_calibrate_vectorised.py``: to round-off, ``-inf`` where it is ``-inf``).

Only the 3RRR's problem (:func:`supports`): a described architecture has no closed-form kinematics here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fpm_sim.kinematics import BatchAssemblies, GeometryArrays, assemble_batch
from fpm_sim.study.calibrate.terms import independent_log_likelihood, statements_batch
from fpm_sim.study.identify.parameters import apply_parameters_batch
from fpm_sim.study.identify.problem import ELBOW_BRANCHES
from fpm_sim.study.inplane_surrogate import InplaneArrays, inplane_batch
from fpm_sim.study.outofplane_surrogate import OutofplaneArrays, outofplane_batch

if TYPE_CHECKING:
    from fpm_sim.study.calibrate.problem import CalibrationProblem, FrequencyLikelihood

__all__ = [
    "cheap_log_likelihood_batch",
    "family_frequencies_batch",
    "frequencies_log_likelihood_batch",
    "inplane_arrays",
    "inplane_frequencies_batch",
    "inplane_log_likelihood_batch",
    "inplane_split_log_likelihood_batch",
    "split_log_likelihood_batch",
    "supports",
]


def supports(problem: FrequencyLikelihood) -> bool:
    """Whether ``problem`` has the vectorised likelihoods: the 3RRR's problem with first in-plane frequencies only,
    independent errors (no correlation length), no latent mode read and no rig tests."""
    return (
        getattr(problem, "closed_form_kinematics", False)
        and not problem.rig_tests
        and bool(problem.observations)
        and problem.priors.length_scale is None
        and problem.priors.mode_read is None
        and all(o.mode == 1 and o.label != "out_of_plane" for o in problem.observations)
    )


def _branches(problem: CalibrationProblem, thetas: np.ndarray) -> np.ndarray:
    """``(n, 3)`` each row's elbow branches (the base's when they are not sampled)."""
    if not problem.priors.sample_branches:
        return np.broadcast_to(np.asarray(problem.base.geometry.elbow_branch, float), (len(thetas), 3))
    k = problem.ndim - 1
    return np.asarray(ELBOW_BRANCHES, float)[np.rint(thetas[:, k]).astype(int)]


@dataclass(frozen=True)
class _Described:
    """Descriptions as arrays over their rows (SI units; a lumped mass ``(n, 4)``: its mass, then its inertia's
    diagonal; the payload in the platform's)."""

    geometry: GeometryArrays
    thickness: np.ndarray
    height: np.ndarray
    young: np.ndarray
    density: np.ndarray
    poisson: np.ndarray
    platform: np.ndarray
    elbow: np.ndarray
    pin: np.ndarray


def _described(problem: CalibrationProblem, thetas: np.ndarray) -> tuple[_Described, np.ndarray]:
    """The descriptions at the rows of ``thetas`` as arrays, and ``(n,)`` which rows are valid descriptions
    (positive lengths and masses, the platform inside the base circle: what :func:`~fpm_sim.config.validate`
    refuses of the fields a free parameter edits)."""
    base = problem.base
    n_free = len(problem.priors.parameters)
    f = apply_parameters_batch(base, problem.parameters.parameters, thetas[:, :n_free])
    n = len(thetas)
    g, sec, mat, hw = base.geometry, base.section, base.material, base.hardware

    def get(path: str, default: object) -> np.ndarray:
        if path in f:
            return f[path]
        row = np.asarray(default, float)
        return np.repeat(row[None], n, axis=0)

    def lump(name: str) -> np.ndarray:
        m = getattr(hw, name)
        return get(f"hardware.{name}", (m.mass_kg, *m.inertia_kg_m2))

    br = get("geometry.base_radius_m", g.base_radius_per_chain)
    pr = get("geometry.platform_radius_m", g.platform_radius_per_chain)
    l1 = get("geometry.proximal_length_m", g.proximal_length_per_chain)
    l2 = get("geometry.distal_length_m", g.distal_length_per_chain)
    ga = GeometryArrays.from_polar(
        base_radius_m=br, base_angles_rad=get("geometry.base_angles_rad", g.base_angles_rad), platform_radius_m=pr,
        platform_angles_rad=get("geometry.platform_angles_rad", g.platform_angles_rad), proximal_m=l1, distal_m=l2,
        elbow_branch=_branches(problem, thetas),
    )  # fmt: skip
    out = _Described(
        geometry=ga, thickness=get("section.thickness_m", sec.thickness_m),
        height=get("section.height_m", sec.height_m),
        young=get("material.young_pa", mat.young_pa), density=get("material.density_kg_m3", mat.density_kg_m3),
        poisson=get("material.poisson", mat.poisson), platform=lump("platform") + lump("payload"),
        elbow=lump("elbow_joint"), pin=lump("platform_joint"),
    )  # fmt: skip
    masses = np.stack([lump("platform"), lump("payload"), out.elbow, out.pin])[..., 0]
    with np.errstate(invalid="ignore"):
        valid = (
            np.all((br > 0) & (l1 > 0) & (l2 > 0) & (pr >= 0) & np.isfinite(br + l1 + l2 + pr), axis=1)
            & (np.max(pr, axis=1) < np.min(br, axis=1))
            & (out.thickness > 0) & (out.height > 0)
            & np.all(masses >= 0, axis=0) & (out.platform[:, 0] > 0)
        )  # fmt: skip
    return out, valid


def _inplane(d: _Described) -> InplaneArrays:
    """The in-plane surrogate's arrays of :func:`_described`'s descriptions."""
    t, h = d.thickness, d.height
    return InplaneArrays.build(
        d.geometry, young_pa=d.young, density_kg_m3=d.density, area_m2=t * h, i_inplane_m4=h * t**3 / 12.0,
        elbow_joint_kg=d.elbow[:, 0], platform_joint_kg=d.pin[:, 0], platform_kg=d.platform[:, 0],
        platform_izz_kg_m2=d.platform[:, 3],
    )  # fmt: skip


def _outofplane(d: _Described) -> OutofplaneArrays:
    """The out-of-plane surrogate's arrays of :func:`_described`'s descriptions (a rotary inertia about an in-plane
    axis: the mean of the two)."""

    def tilt(lump: np.ndarray) -> np.ndarray:
        out: np.ndarray = 0.5 * (lump[:, 1] + lump[:, 2])
        return out

    return OutofplaneArrays.build(
        d.geometry, young_pa=d.young, shear_pa=d.young / (2.0 * (1.0 + d.poisson)), density_kg_m3=d.density,
        thickness_m=d.thickness, height_m=d.height, elbow_kg=d.elbow[:, 0], elbow_kg_m2=tilt(d.elbow),
        platform_joint_kg=d.pin[:, 0], platform_joint_kg_m2=tilt(d.pin), platform_kg=d.platform[:, 0],
        platform_kg_m2=tilt(d.platform),
    )  # fmt: skip


def inplane_arrays(problem: CalibrationProblem, thetas: np.ndarray) -> tuple[InplaneArrays, np.ndarray]:
    """The descriptions at the rows of ``thetas`` as the in-plane surrogate's arrays, and ``(n,)`` which rows are
    valid descriptions (:func:`_described`)."""
    d, valid = _described(problem, thetas)
    return _inplane(d), valid


def _support_and_statements(
    problem: CalibrationProblem, thetas: np.ndarray
) -> tuple[_Described, np.ndarray, BatchAssemblies]:
    """:func:`_described`'s arrays, ``(n,)`` the cheap log-likelihood (``-inf`` off the support), and the
    kinematics at the distinct measured poses (``problem.measured_pose_array``)."""
    d, valid = _described(problem, thetas)
    ga = d.geometry
    xyz = problem.measured_pose_array
    measured = assemble_batch(ga, xyz[:, 0], xyz[:, 1], xyz[:, 2])  # the reach and statement (b)
    out = np.full(len(thetas), -math.inf)
    ok = valid & measured.reachable.all(axis=1)
    out[ok] = statements_batch(problem.priors, ga.rows(ok), measured.singularity[ok])
    return d, out, measured


def cheap_log_likelihood_batch(problem: CalibrationProblem, thetas: np.ndarray) -> np.ndarray:
    """``(n,)`` :meth:`~fpm_sim.study.calibrate.problem.CalibrationProblem.cheap_log_likelihood` of every row."""
    return _support_and_statements(problem, np.atleast_2d(thetas))[1]


def inplane_frequencies_batch(problem: CalibrationProblem, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``((n, n_obs), (n,))``: the in-plane surrogate's first frequencies (Hz) at the observations of every row
    (NaN off the support), and the cheap log-likelihood (``-inf`` off the support)."""
    freq, cheap = _surrogates(problem, np.atleast_2d(thetas), (_INPLANE,))
    return freq[:, 0], cheap


def family_frequencies_batch(problem: CalibrationProblem, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``((n, 2, n_obs), (n,))``: the in-plane and the out-of-plane surrogate's lowest frequencies (Hz) at the
    observations of every row (NaN off the support), and the cheap log-likelihood (``-inf`` off the support): the
    two mode families the emulator corrects (:mod:`~fpm_sim.study.calibrate.emulator`)."""
    return _surrogates(problem, np.atleast_2d(thetas), (_INPLANE, _OUTOFPLANE))


_Surrogate = tuple[Callable[[_Described], InplaneArrays | OutofplaneArrays], Callable[..., np.ndarray]]
"""A surrogate: its arrays of :func:`_described`'s descriptions, and its batched frequencies of those arrays."""
_INPLANE: _Surrogate = (_inplane, inplane_batch)
_OUTOFPLANE: _Surrogate = (_outofplane, outofplane_batch)


def _surrogates(
    problem: CalibrationProblem, thetas: np.ndarray, models: tuple[_Surrogate, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """``((n, len(models), n_obs), (n,))`` each surrogate's frequencies at the observations, on the kinematics the
    support assembled at the distinct measured poses, and the cheap log-likelihood."""
    d, cheap, measured = _support_and_statements(problem, thetas)
    ok = np.isfinite(cheap)
    freq = np.full((len(thetas), len(models), len(problem.observations)), np.nan)
    if ok.any():
        xyz = problem.measured_pose_array
        for k, (arrays_of, model) in enumerate(models):
            at = model(arrays_of(d).rows(ok), xyz, assembled=measured.rows(ok))
            freq[ok, k] = at[:, problem.observation_pose_index]
    return freq, cheap


def inplane_log_likelihood_batch(problem: CalibrationProblem, thetas: np.ndarray) -> np.ndarray:
    """``(n,)`` the full log-likelihood (data and statements) with the in-plane surrogate as the model: what
    :meth:`~fpm_sim.study.calibrate.problem.CalibrationProblem.log_likelihood` gives with ``model = "inplane"``."""
    thetas = np.atleast_2d(thetas)
    freq, cheap = inplane_frequencies_batch(problem, thetas)
    return frequencies_log_likelihood_batch(problem, thetas, freq, cheap)


def inplane_split_log_likelihood_batch(
    problem: CalibrationProblem, thetas: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``((n,), (n,))``: the cheap log-likelihood and the rest of :func:`inplane_log_likelihood_batch`'s (``log L -
    log L_cheap``; both ``-inf`` off the support), the support and the statements computed once: an SMC data stage's
    evaluation (:data:`~fpm_sim.study.calibrate.smc.Evaluate`)."""
    thetas = np.atleast_2d(thetas)
    freq, cheap = inplane_frequencies_batch(problem, thetas)
    return split_log_likelihood_batch(problem, thetas, freq, cheap)


def split_log_likelihood_batch(
    problem: CalibrationProblem, thetas: np.ndarray, freq: np.ndarray, cheap: np.ndarray, *,
    model_error_rel: float | np.ndarray = 0.0,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``(cheap, log L - cheap)`` (``-inf`` where ``log L`` is) of :func:`frequencies_log_likelihood_batch`: an SMC
    data stage's evaluation (:data:`~fpm_sim.study.calibrate.smc.Evaluate`) from any model's frequencies."""
    full = frequencies_log_likelihood_batch(problem, thetas, freq, cheap, model_error_rel=model_error_rel)
    with np.errstate(invalid="ignore"):
        return cheap, np.where(np.isfinite(full), full - cheap, -math.inf)


def frequencies_log_likelihood_batch(
    problem: CalibrationProblem, thetas: np.ndarray, freq: np.ndarray, cheap: np.ndarray, *,
    model_error_rel: float | np.ndarray = 0.0,
) -> np.ndarray:  # fmt: skip
    """``(n,)`` the full log-likelihood at the rows of ``thetas`` given the model's frequencies there (``freq``,
    ``(n, n_obs)`` Hz: any model's, the segment model's included) and the cheap log-likelihood ``cheap`` (``-inf``
    off the support): what :meth:`~fpm_sim.study.calibrate.problem.CalibrationProblem.log_likelihood` gives with
    that model. ``model_error_rel``: the model's own relative error (a float, or ``(n_obs,)`` one per datum; an
    emulator's, :mod:`~fpm_sim.study.calibrate.emulator`), added to each datum's variance as ``(model_error_rel
    f)^2``."""
    ok = np.isfinite(cheap)
    out = np.full(len(thetas), -math.inf)
    if not ok.any():
        return out
    f = freq[ok]
    pr = problem.priors
    d = thetas[ok, len(pr.parameters)] if pr.discrepancy is not None else np.full(ok.sum(), pr.discrepancy_fixed)
    rel2 = d[:, None] ** 2 + np.asarray(model_error_rel, float) ** 2
    sd = np.sqrt(problem.sigma[None] ** 2 + rel2 * f**2)  # as noise_sd
    with np.errstate(invalid="ignore"):
        data = independent_log_likelihood(f - problem.measured[None], sd)
    out[ok] = np.where(np.all(np.isfinite(f), axis=1), data + cheap[ok], -math.inf)
    return out
