"""Analytic Euler-Bernoulli beam frequencies: the independent truth for the single-link rigs."""

from __future__ import annotations

import math

import numpy as np

from fpm_sim.config import Material, Section

__all__ = ["BETA_L", "euler_bernoulli_hz"]

BETA_L: dict[str, tuple[float, ...]] = {
    "cantilever": (1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349, 14.1371683910),
    "free-free": (4.7300407449, 7.8532046241, 10.9956078380, 14.1371654913, 17.2787596574),
}
"""Roots ``beta_n L`` of the characteristic equations (cos cosh = -1 clamped-free, = 1 free-free)."""


def euler_bernoulli_hz(
    boundary: str,
    *,
    length_m: float,
    section: Section,
    material: Material,
    plane: str = "in",
    n_modes: int = 3,
) -> np.ndarray:
    """First ``n_modes`` bending frequencies (Hz) of a uniform slender beam.

    ``f_n = (beta_n L)^2 / (2 pi L^2) * sqrt(E I / (rho A))`` with ``I`` for bending in the base plane
    (``plane="in"``) or out of it (``"out"``). Neglects shear and rotary inertia (slenderness L/t > 20
    keeps both below ~1 % for the first three modes).
    """
    if boundary not in BETA_L:
        raise ValueError(f"boundary must be one of {sorted(BETA_L)}, got {boundary!r}")
    if n_modes > len(BETA_L[boundary]):
        raise ValueError(f"at most {len(BETA_L[boundary])} modes tabulated")
    inertia = section.i_inplane_m4 if plane == "in" else section.i_outofplane_m4
    c = math.sqrt(material.young_pa * inertia / (material.density_kg_m3 * section.area_m2))
    bl = np.array(BETA_L[boundary][:n_modes])
    return bl**2 / (2.0 * math.pi * length_m**2) * c


def mode_shape(boundary: str, n: int, xi: np.ndarray) -> np.ndarray:
    """Euler-Bernoulli mode ``n`` (1-based) at ``xi = x / L`` in [0, 1] (unnormalised)."""
    bl = BETA_L[boundary][n - 1]
    b = bl * np.asarray(xi, float)
    if boundary == "cantilever":
        sigma = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
        return np.cosh(b) - np.cos(b) - sigma * (np.sinh(b) - np.sin(b))
    sigma = (math.cosh(bl) - math.cos(bl)) / (math.sinh(bl) - math.sin(bl))
    return np.cosh(b) + np.cos(b) - sigma * (np.sinh(b) + np.sin(b))


def rotary_inertia_shift(boundary: str, n: int, *, length_m: float, radius_of_gyration_m: float) -> float:
    """First-order relative frequency change of mode ``n`` from the section's rotary inertia.

    Rayleigh's quotient with the Euler-Bernoulli shape ``w``:
    ``d f / f = -(r^2 / 2) * int(w'^2) / int(w^2)`` (Rayleigh beam, small ``r / L``).
    """
    xi = np.linspace(0.0, 1.0, 20001)
    w = mode_shape(boundary, n, xi)
    dw = np.gradient(w, xi) / length_m
    return -0.5 * radius_of_gyration_m**2 * float(np.trapezoid(dw**2, xi) / np.trapezoid(w**2, xi))
