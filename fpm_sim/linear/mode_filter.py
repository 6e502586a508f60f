"""Which eigenpairs are physical modes, and when the linearised model is unstable.

Modes dropped, by documented physical criteria (:class:`ModeFilter`), counted in ``ModalResult.dropped``.
No absolute frequency is used: a physical mode near a parallel singularity falls towards 0 Hz (its
stiffness ~ measure^2) and must be reported, with a :class:`~fpm_sim.kinematics.NearSingularityWarning`.

- ``non_oscillatory``: real eigenvalues (``Im s <= 0``), e.g. critically damped constraint motions;
- ``rigid_body``: no strain energy to within the computation's noise: ``|w^2| <= w2_tol`` with
  ``w2_tol = max((rigid_fraction * w_ref)^2, FD_NOISE_MARGIN * |x'(K(e) - K(2e))x|)`` (:func:`noise_w2`):
  ``w_ref`` is the model's own scale, the lowest uncoupled spring frequency ``min_i sqrt(k_i / M_ii)``
  (:func:`reference_frequency_hz`; the lowest link's first frequency is of the same order: 51 Hz
  against the manipulator's 70-75 Hz first mode at 12 segments, 401 Hz against the cantilever's
  221 Hz), and the second term the measured finite-difference noise of ``x'K x`` (constrained
  method; ``transition_fd`` uses the first term). With
  ``rigid_fraction = 1e-4`` the threshold sits 25x below the lowest physical frequency the
  kinematics accept (a pose refused below singularity measure 1e-3 keeps ``f1 >= ~2.5e-3 f_normal``)
  and far above the exact zeros of a floating rig's rigid-body motions;
- ``constraint``: the shape violates the loop closure, ``|J v| / (|J|_2 |v|) > max_constraint_ratio``,
  ``J`` with its rows in consistent units (:func:`~fpm_sim.linear.nullspace.constraint_rank`): motions of the
  soft weld itself (constraint stabilisation), not of the structure. Measured: lightly damped physical modes up to
  7.3e-4 (the flex chain rig's highest modes; the manipulator's ~1e-8), the welds' own motions from
  2.9e-3 (segment chain rig) to 0.3; the default 1.5e-3 sits at their geometric mean;
- ``overdamped``: damping ratio above ``max_damping_ratio``.

An eigenvalue ``w^2 < -w2_tol`` (constrained method) or a growing mode (``transition_fd``: a damping
ratio below ``-NEGATIVE_DAMPING_TOL`` or a real eigenvalue growing faster than the rigid-body
threshold) is never clipped to zero: :class:`UnstableModelError` is raised, naming the growth.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from fpm_sim.errors import FpmSimError
from fpm_sim.linear.matrices import energy_stiffness

__all__ = [
    "FD_NOISE_MARGIN",
    "NEGATIVE_DAMPING_TOL",
    "RIGID_BODY_FRACTION",
    "ModeFilter",
    "UnstableModelError",
    "check_stable",
    "classify",
    "eigenvalue_tolerances",
    "noise_w2",
    "reference_frequency_hz",
]


RIGID_BODY_FRACTION = 1e-4
"""``ModeFilter.rigid_fraction`` default: rigid-body threshold as a fraction of the model's reference
frequency (:func:`reference_frequency_hz`)."""


FD_NOISE_MARGIN = 10.0
"""The finite-difference noise of an eigenvalue ``w_i^2`` is estimated as ``|x_i' (K(e) - K(2e)) x_i|`` (the
stiffness at two steps, the mode ``x_i`` M-normalised), times this margin (measured: 1.6e-4 rad^2/s^2 at
``w^2 = 11`` near the singular pose (83 mm, 4.5 mm, 0), where an entrywise worst-case bound gives 6e3)."""


NEGATIVE_DAMPING_TOL = 1e-6
"""A ``transition_fd`` mode with a damping ratio below ``-NEGATIVE_DAMPING_TOL`` grows: the free-free
bar's modes measure ``|zeta| ~ 3e-13`` of round-off."""


class UnstableModelError(FpmSimError):
    """The linearised model grows: a negative stiffness eigenvalue or negative damping beyond round-off."""

    worst_w2: float | None = None
    """The most negative stiffness eigenvalue (rad^2/s^2), when that is the cause (:func:`check_stable`)."""


@dataclass(frozen=True)
class ModeFilter:
    """Criteria that separate physical modes from the rest (see module docstring).

    Attributes
    ----------
    rigid_fraction
        A mode below ``rigid_fraction`` times :func:`reference_frequency_hz` (and its round-off)
        carries no strain energy: rigid-body motion or mechanism.
    max_constraint_ratio
        Largest loop-closure violation ``|J v| / (|J|_2 |v|)`` (consistent units) of a physical mode.
    max_damping_ratio
        Larger damping ratios are overdamped motions (dropped).
    """

    rigid_fraction: float = RIGID_BODY_FRACTION
    max_constraint_ratio: float = 1.5e-3
    max_damping_ratio: float = 0.5

    def __post_init__(self) -> None:
        for name in ("rigid_fraction", "max_constraint_ratio", "max_damping_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise FpmSimError(f"ModeFilter.{name} must be a finite number >= 0, got {v!r}")


def reference_frequency_hz(model: mujoco.MjModel, mass: np.ndarray) -> float:
    """The model's own frequency scale (Hz): the lowest uncoupled spring frequency ``min sqrt(k_i / M_ii) / 2 pi``
    over the degrees of freedom that carry a spring (:func:`~fpm_sim.linear.matrices.energy_stiffness`); 0 without
    springs.

    Measured: 51 Hz for the manipulator at 12 segments (first mode 70-75 Hz), 28 Hz at 3 segments,
    401 Hz for the cantilever rig (first mode 221 Hz), 281 Hz for the free-free bar (985 Hz).
    """
    k = energy_stiffness(model)
    m = np.diag(mass)
    live = (k > 0) & (m > 0)
    if not np.any(live):
        return 0.0
    return float(np.sqrt(np.min(k[live] / m[live])) / (2 * np.pi))


def noise_w2(model: mujoco.MjModel, mass: np.ndarray, filt: ModeFilter, fd_noise: float = 0.0) -> float:
    """``w2_tol`` (rad^2/s^2): eigenvalues within ``+-w2_tol`` of zero carry no strain energy to within the
    computation's noise (module docstring); ``fd_noise = |x'(K(e) - K(2e))x|`` for an ``M``-normalised shape."""
    return float(_w2_tol(2 * np.pi * reference_frequency_hz(model, mass), filt, np.asarray(fd_noise)))


def _w2_tol(w_ref: float, filt: ModeFilter, fd_noise: np.ndarray) -> np.ndarray:
    """:func:`noise_w2` for the reference ``w_ref`` (rad/s), per finite-difference noise in ``fd_noise``."""
    out: np.ndarray = np.maximum((filt.rigid_fraction * w_ref) ** 2, FD_NOISE_MARGIN * fd_noise)
    return out


def eigenvalue_tolerances(
    model: mujoco.MjModel,
    mass: np.ndarray,
    shapes: np.ndarray,
    w2: np.ndarray,
    stiff_change: Callable[[], np.ndarray] | None,
    filt: ModeFilter,
) -> np.ndarray:
    """Per-mode ``w2_tol`` (:func:`noise_w2`) of the eigenvalues ``w2`` with ``M``-normalised full-space shapes
    ``shapes`` (columns). ``stiff_change() = K(e) - K(2e)`` (``None``: an exact stiffness, no finite-difference
    noise) is evaluated only when a mode lies below a tenth of the reference frequency (one more stiffness
    evaluation): above it the noise (measured 1e-4 rad^2/s^2) is below 1e-6 of ``w^2`` and cannot change a
    classification."""
    w_ref = 2 * np.pi * reference_frequency_hz(model, mass)
    if stiff_change is None or w2.size == 0 or np.min(w2) > (0.1 * w_ref) ** 2:  # (none: a rigid structure)
        fd = np.zeros(shapes.shape[1])
    else:
        fd = np.abs(np.einsum("ik,ij,jk->k", shapes, stiff_change(), shapes))
    return _w2_tol(w_ref, filt, fd)  # the reference computed once for every mode


def check_stable(w2: np.ndarray, tol: np.ndarray, *, what: str = "the equilibrium") -> None:
    """Raise :class:`UnstableModelError` when an eigenvalue lies below ``-tol`` (never clipped to zero)."""
    bad = w2 < -tol
    if np.any(bad):
        worst = float(np.min(w2[bad]))
        error = UnstableModelError(
            f"{what} is unstable: {int(np.sum(bad))} negative stiffness eigenvalue(s), the most negative "
            f"{worst:.4g} rad^2/s^2 (growth time {1.0 / math.sqrt(-worst):.3g} s), beyond the round-off bound "
            f"{float(np.max(tol[bad])):.2g}; the structure buckles under gravity or the compliances are too soft "
            "(check section, material, hardware masses and compliance)"
        )
        error.worst_w2 = worst
        raise error


def classify(w2: float, w2_tol: float, zeta: float, ratio: float, filt: ModeFilter) -> str | None:
    if abs(w2) <= w2_tol:
        return "rigid_body"
    if ratio > filt.max_constraint_ratio:
        return "constraint"
    if zeta > filt.max_damping_ratio:
        return "overdamped"
    return None
