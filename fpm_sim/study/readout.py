"""Which mode a hammer test's first clear peak is: the latent mode behind a measured "first frequency".

The study read "the first natural frequency" from the peaks of driving-point FRFs: one accelerometer on a
distal link, the hammer along the same axis (which link and which axis are not stated). Where mode 1 barely
moves that point along that axis, its peak is lost and the first clear peak is mode 2 or 3
(:mod:`fpm_sim.study.readability` shows it on the default at (-50, 50)). A calibration that insists the
measured value is mode 1 then pulls the machine towards a wrong one.

The model here (used by the calibration's likelihood, ``[likelihood.mode_read]`` of the priors file):

- **Peak heights.** A driving-point accelerance peak of mode ``k`` is about ``r_k / (2 zeta_k)`` with the modal
  constant ``r_k = (c v_k)^2`` (``c``: the point's velocity row along the axis, ``v_k``: the mass-normalised
  shape); with equal damping ratios (the study's modes are all lightly damped; not measured per mode) the
  peak's height relative to the highest of the lowest ``reference_modes`` modes is ``h_k = 20 log10(r_k /
  r_max)`` dB (the peak magnitude is linear in ``r``).
- **Visible.** Mode ``k`` shows a clear peak with probability ``v_k = sigmoid((h_k - height_db) / width_db)``
  (``height_db = -20``: the readability module's a-priori threshold; ``width_db``: how soft it is).
- **First clear peak.** ``P(read k) = v_k prod_{j<k} (1 - v_j)`` for ``k = 1..modes``, renormalised over the
  ``modes`` lowest (a test whose first ``modes`` modes all hide would not have been reported as readable).
- **Setups.** The accelerometer's link and axis are one unknown for the whole test campaign: every candidate
  point (the middle of each distal link, in-plane normal or out of plane: six) is a setup, and the likelihood is
  the average over setups of the product over poses of ``sum_k P(read k) N(y | f_k, s_k)``
  (:func:`mixture_log_likelihood`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.special import logsumexp

from fpm_sim.batch.pose_loop import fast_options, pose_model
from fpm_sim.config import Manipulator
from fpm_sim.kinematics import Pose, assemble_many
from fpm_sim.linear.threads import blas_threads
from fpm_sim.model.options import ModelOptions
from fpm_sim.response import LinkPoint, MaterialPoint, material_point

__all__ = [
    "MODE_READ_ATTR",
    "SENSOR_POINTS",
    "ModeRead",
    "components",
    "draws_components",
    "mixture_log_likelihood",
    "mode_read_from_text",
    "mode_read_text",
    "read_probabilities",
    "responsibilities",
    "sensor_residues",
    "setup_weights",
]

SENSOR_POINTS = tuple(LinkPoint(f"distal_{i}", 0.5, axis) for i in range(3) for axis in ("normal", "z"))
"""Candidate accelerometer (and hammer) points: the middle of each distal link, along its in-plane normal or
out of the plane. Assumed: the study says "on the second links" and nothing of the axis or the chain."""


MODE_READ_ATTR = "fpm_sim_mode_read"
"""The ``posterior.nc`` attribute that holds the latent-mode model's settings (:func:`mode_read_text`)."""


@dataclass(frozen=True)
class ModeRead:
    """The latent-mode model's settings (module docstring)."""

    modes: int = 3
    reference_modes: int = 6
    height_db: float = -20.0
    width_db: float = 3.0
    points: tuple[LinkPoint, ...] = SENSOR_POINTS
    reason: str = ""


def mode_read_text(read: ModeRead) -> str:
    """The settings as JSON (the file attribute :data:`MODE_READ_ATTR`)."""
    import json

    return json.dumps(
        {
            "modes": read.modes,
            "reference_modes": read.reference_modes,
            "height_db": read.height_db,
            "width_db": read.width_db,
            "points": [[pt.link, pt.fraction, pt.axis] for pt in read.points],
        }
    )


def mode_read_from_text(text: str) -> ModeRead:
    """Inverse of :func:`mode_read_text` (raises ``ValueError``/``KeyError``/``TypeError`` on a bad text)."""
    import json

    d = json.loads(text)
    return ModeRead(
        modes=int(d["modes"]),
        reference_modes=int(d["reference_modes"]),
        height_db=float(d["height_db"]),
        width_db=float(d["width_db"]),
        points=tuple(LinkPoint(str(a), float(b), str(c)) for a, b, c in d["points"]),
    )


def sensor_residues(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    n_modes: int,
    points: Sequence[LinkPoint] = SENSOR_POINTS,
    options: ModelOptions | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and driving-point modal constants of the lowest ``n_modes`` modes at each pose.

    Returns ``(freq_hz, residues)``: ``(n_poses, n_modes)`` Hz and ``(n_poses, len(points), n_modes)``
    ``(c v_k)^2`` (1/kg); NaN at a pose the machine cannot reach or where it is singular.
    """
    opts = options or fast_options()
    poses = list(poses)
    freq = np.full((len(poses), n_modes), np.nan)
    res = np.full((len(poses), len(points), n_modes), np.nan)
    many = assemble_many(config.geometry, [p.x_m for p in poses], [p.y_m for p in poses], [p.phi_rad for p in poses])
    pm = None
    located: list[MaterialPoint] = []
    with blas_threads():  # one BLAS thread around the small dense solves, as in the pose loop
        for i, pose in enumerate(poses):
            if not many.reachable[i] or many.singularity[i] <= 0:
                continue
            asm = many.assembly(i, pose)
            pm = pm or pose_model(config, opts, asm)
            located = located or [material_point(pm.built, pt) for pt in points]
            f, _, deficient, v = pm.solve_shapes(asm, n_modes)
            if deficient:
                continue
            jacp = np.zeros((3, pm.model.nv))
            for j, mp in enumerate(located):
                pos, axis = mp.world(pm.data)
                mujoco.mj_jac(pm.model, pm.data, jacp, None, pos, mp.body_id)
                res[i, j, : v.shape[1]] = (axis @ jacp @ v) ** 2
            freq[i] = f
    return freq, res


def read_probabilities(residues: np.ndarray, read: ModeRead) -> np.ndarray:
    """``(..., read.modes)`` probability that the first clear peak is mode ``k`` (module docstring), from
    ``(..., n_ref)`` modal constants of the lowest ``n_ref >= read.modes`` modes."""
    r = np.asarray(residues, float)
    top = np.max(r, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = 20.0 * np.log10(np.maximum(r[..., : read.modes], 1e-300) / top)
    v = 0.5 * (1.0 + np.tanh(0.5 * (h - read.height_db) / read.width_db))  # the logistic sigmoid, overflow-free
    hidden_before = np.concatenate([np.ones_like(v[..., :1]), np.cumprod(1.0 - v, axis=-1)[..., :-1]], axis=-1)
    p = v * hidden_before
    total = p.sum(axis=-1, keepdims=True)
    out: np.ndarray = np.where(total > 0, p / np.where(total > 0, total, 1.0), 1.0 / read.modes)
    return out


def mixture_log_likelihood(
    y_hz: np.ndarray, sigma_hz: np.ndarray, freq_hz: np.ndarray, probs: np.ndarray, d: float
) -> float:
    """``log mean_setups prod_i sum_k P_sik N(y_i | f_ik, sigma_i^2 + (d f_ik)^2)``.

    ``y_hz``, ``sigma_hz``: ``(n,)``; ``freq_hz``: ``(n, modes)``; ``probs``: ``(n_setups, n, modes)``.
    """
    per_setup = _setup_log_likelihoods(_log_pose_terms(y_hz, sigma_hz, freq_hz, probs, d)[0])
    return float(logsumexp(per_setup) - math.log(per_setup.size))


def _log_pose_terms(
    y_hz: np.ndarray, sigma_hz: np.ndarray, freq_hz: np.ndarray, probs: np.ndarray, d: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(log P_sik + log N(y_i | f_ik, s_ik))`` ``(setups, n, modes)`` and ``s_ik`` ``(n, modes)``."""
    f = np.asarray(freq_hz, float)
    s = np.sqrt(np.asarray(sigma_hz, float)[:, None] ** 2 + (d * f) ** 2)
    logn = -0.5 * ((np.asarray(y_hz, float)[:, None] - f) / s) ** 2 - np.log(math.sqrt(2 * math.pi) * s)
    with np.errstate(divide="ignore"):
        return np.log(probs) + logn[None], s


def _setup_log_likelihoods(lp: np.ndarray) -> np.ndarray:
    """``(setups,)`` ``log prod_i sum_k`` of the pose terms ``lp`` (:func:`_log_pose_terms`)."""
    out: np.ndarray = logsumexp(lp, axis=-1).sum(axis=-1)
    return out


def _normalised(log_w: np.ndarray, axis: int = 0) -> np.ndarray:
    """``exp(log_w)`` normalised along ``axis``; where every weight is zero, zeros (not NaN)."""
    with np.errstate(invalid="ignore"):  # -inf - -inf where every entry is impossible: zeroed
        out: np.ndarray = np.nan_to_num(np.exp(log_w - logsumexp(log_w, axis=axis, keepdims=True)))
    return out


def setup_weights(
    y_hz: np.ndarray, sigma_hz: np.ndarray, freq_hz: np.ndarray, probs: np.ndarray, d: float
) -> np.ndarray:
    """``(setups,)`` the posterior probability of each setup given the data and one draw's machine (uniform
    when the data rule every setup out)."""
    tot = _setup_log_likelihoods(_log_pose_terms(y_hz, sigma_hz, freq_hz, probs, d)[0])
    return _normalised(tot) if np.isfinite(tot).any() else np.full(tot.shape, 1.0 / tot.size)


def responsibilities(
    y_hz: np.ndarray, sigma_hz: np.ndarray, freq_hz: np.ndarray, probs: np.ndarray, d: float
) -> np.ndarray:
    """``(n, modes)`` the probability that datum ``i`` was mode ``k``, given the data and one draw's machine."""
    lp, _ = _log_pose_terms(y_hz, sigma_hz, freq_hz, probs, d)
    tot = _setup_log_likelihoods(lp)
    w = _normalised(tot) if np.isfinite(tot).any() else np.full(tot.shape, 1.0 / tot.size)
    out: np.ndarray = np.einsum("s,snk->nk", w, _normalised(lp, axis=-1))  # per setup: P(mode | datum, setup)
    return out


def components(
    y_hz: np.ndarray, sigma_hz: np.ndarray, freq_hz: np.ndarray, probs: np.ndarray, d: float, *, leave_out: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One draw's predictive of every datum as a Gaussian mixture: ``(means, sds, weights)``, each ``(n,
    setups * modes)``: mode ``k``'s frequency and sd under setup ``s``, weighted ``P(s | data) P_sik``, or with
    ``leave_out`` ``P(s | the other data) P_sik`` (the leave-one-out predictive of datum ``i``)."""
    lp, s = _log_pose_terms(y_hz, sigma_hz, freq_hz, probs, d)
    per = logsumexp(lp, axis=-1)  # (setups, n)
    n = per.shape[1]
    if leave_out:
        rest = np.stack([np.delete(per, i, axis=1).sum(axis=1) for i in range(n)], axis=1)  # (setups, n)
    else:
        rest = np.broadcast_to(per.sum(axis=1)[:, None], per.shape)
    w = _normalised(rest)  # (setups, n): P(s | ...)
    weights = (w[:, :, None] * probs).transpose(1, 0, 2).reshape(n, -1)
    k = probs.shape[0]
    means = np.broadcast_to(np.asarray(freq_hz, float)[None], probs.shape).transpose(1, 0, 2).reshape(n, -1)
    sds = np.broadcast_to(s[None], (k, *s.shape)).transpose(1, 0, 2).reshape(n, -1)
    return means, sds, weights / weights.sum(axis=1, keepdims=True)


def draws_components(
    y_hz: np.ndarray,
    sigma_hz: np.ndarray,
    freq_hz: np.ndarray,
    probs: np.ndarray,
    d: np.ndarray,
    *,
    leave_out: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`components` of every draw, stacked: ``(n_draws, n, setups * modes)`` means, sds and weights, from
    each draw's ``freq_hz`` ``(n_draws, n, modes)``, ``probs`` ``(n_draws, setups, n, modes)`` and ``d``
    ``(n_draws,)``."""
    parts = [components(y_hz, sigma_hz, f, pr, float(dd), leave_out=leave_out) for f, pr, dd in zip(freq_hz, probs, d)]
    means, sds, weights = (np.stack([c[j] for c in parts]) for j in range(3))
    return means, sds, weights
