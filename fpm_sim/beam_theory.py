"""Analytic beam frequencies (Euler-Bernoulli bending, free torsion, Timoshenko FE): the independent truths for the
single-link rigs and the root springs."""

from __future__ import annotations

import math

import numpy as np

from fpm_sim.config import Material, Section

__all__ = [
    "BETA_L",
    "euler_bernoulli_hz",
    "shear_coefficient_rectangle",
    "spring_held_torsion_hz",
    "spring_held_torsion_roots",
    "spring_hinged_cantilever_beta_l",
    "spring_hinged_cantilever_hz",
    "timoshenko_beam_hz",
    "timoshenko_simply_supported_hz",
]

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
    return _beta_l_to_hz(np.array(BETA_L[boundary][:n_modes]), length_m, section, material, plane)


def _beta_l_to_hz(bl: np.ndarray, length_m: float, section: Section, material: Material, plane: str) -> np.ndarray:
    """``f_n = (beta_n L)^2 / (2 pi L^2) * sqrt(E I / (rho A))`` (Hz) for bending in or out of the base plane."""
    if plane not in ("in", "out"):
        raise ValueError(f"plane must be 'in' or 'out', got {plane!r}")
    inertia = section.i_inplane_m4 if plane == "in" else section.i_outofplane_m4
    c = math.sqrt(material.young_pa * inertia / (material.density_kg_m3 * section.area_m2))
    return np.asarray(bl, float) ** 2 / (2.0 * math.pi * length_m**2) * c


def _check_spring_root(stiffness_ratio: float, n_modes: int) -> None:
    """The arguments shared by the spring-held root solvers: ``K > 0`` (``inf`` = clamped), ``n_modes >= 1``."""
    if not stiffness_ratio > 0:
        raise ValueError(f"stiffness_ratio must be > 0 (inf = clamped), got {stiffness_ratio!r}")
    if n_modes < 1:
        raise ValueError(f"n_modes must be >= 1, got {n_modes!r}")


def spring_hinged_cantilever_beta_l(stiffness_ratio: float, n_modes: int = 3) -> np.ndarray:
    """Roots ``beta_n L`` of a cantilever whose root is held by a rotational spring (elastically restrained).

    The root cannot move but turns against a spring ``k`` (N m/rad); the tip is free. With
    ``w = A (cosh - cos) + B sinh + D sin`` (so ``w(0) = 0``), the root condition ``E I w''(0) = k w'(0)``
    and a free tip (``w''(L) = 0``, ``w'''(L) = 0``) have a non-zero solution when

    ``K (1 + cos(bL) cosh(bL)) = bL (sin(bL) cosh(bL) - cos(bL) sinh(bL))``,  ``K = k L / (E I)``,

    solved here divided by ``cosh(bL)`` (no overflow) with :func:`scipy.optimize.brentq` between the
    sign changes on a 0.01 grid (the roots are more than 1.5 apart). ``K -> inf`` gives the clamped-free
    roots (:data:`BETA_L` ``"cantilever"``, 1.8751...); ``K -> 0`` the pinned-free ones: a rigid rotation
    (``bL -> (3 K)^(1/4)``, the link swinging on its spring) then ``tan(bL) = tanh(bL)`` (3.9266...).

    Parameters
    ----------
    stiffness_ratio
        ``K = k L / (E I)`` (dimensionless), > 0; ``math.inf`` for a clamped root.
    n_modes
        Number of roots, lowest first.
    """
    from scipy.optimize import brentq

    _check_spring_root(stiffness_ratio, n_modes)
    clamped = math.isinf(stiffness_ratio)
    k_ratio = 1.0 if clamped else float(stiffness_ratio)
    slope = 0.0 if clamped else 1.0

    def f(x: float) -> float:
        return k_ratio * (1.0 / math.cosh(x) + math.cos(x)) - slope * x * (math.sin(x) - math.cos(x) * math.tanh(x))

    # root n lies below the clamped-free root n, itself below (n - 1/2) pi + 0.4
    grid = np.arange(1e-9, (n_modes + 0.5) * math.pi, 0.01)
    values = np.array([f(x) for x in grid])
    roots = [
        brentq(f, grid[j], grid[j + 1], xtol=1e-14, rtol=1e-14)
        for j in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))
    ]
    return np.array(roots[:n_modes], float)


def spring_hinged_cantilever_hz(
    *,
    length_m: float,
    section: Section,
    material: Material,
    root_stiffness_nm_per_rad: float,
    plane: str = "out",
    n_modes: int = 3,
) -> np.ndarray:
    """First ``n_modes`` bending frequencies (Hz) of a uniform Euler-Bernoulli cantilever whose root turns
    against a rotational spring of ``root_stiffness_nm_per_rad`` in the bending plane (``"out"``: out of the
    base plane, the default; ``"in"``). Roots from :func:`spring_hinged_cantilever_beta_l`."""
    inertia = section.i_inplane_m4 if plane == "in" else section.i_outofplane_m4
    ratio = root_stiffness_nm_per_rad * length_m / (material.young_pa * inertia)
    return _beta_l_to_hz(spring_hinged_cantilever_beta_l(ratio, n_modes), length_m, section, material, plane)


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


def shear_coefficient_rectangle(poisson: float) -> float:
    """Cowper's shear coefficient of a solid rectangle: ``10 (1 + nu) / (12 + 11 nu)`` (0.850 for steel)."""
    return 10.0 * (1.0 + poisson) / (12.0 + 11.0 * poisson)


def _bending(section: Section, material: Material, plane: str) -> tuple[float, float, float, float]:
    """``(EI, rho A, rho I, kappa G A)`` for bending in (``"in"``) or out of (``"out"``) the base plane."""
    if plane not in ("in", "out"):
        raise ValueError(f"plane must be 'in' or 'out', got {plane!r}")
    inertia = section.i_inplane_m4 if plane == "in" else section.i_outofplane_m4
    kappa = shear_coefficient_rectangle(material.poisson)
    return (
        material.young_pa * inertia,
        material.density_kg_m3 * section.area_m2,
        material.density_kg_m3 * inertia,
        kappa * material.shear_pa * section.area_m2,
    )


def timoshenko_simply_supported_hz(
    n: int, *, length_m: float, section: Section, material: Material, plane: str = "in"
) -> float:
    """Mode ``n`` (1-based) of a simply supported Timoshenko beam (shear and rotary inertia), closed form.

    With ``k = n pi / L`` the frequency solves ``EI k^4 - w^2 (rho A + rho I k^2 (1 + E / (kappa G)))
    + w^4 rho I rho A / (kappa G A) = 0``; the lower root is the bending mode (Timoshenko 1921).
    """
    ei, rho_a, rho_i, kga = _bending(section, material, plane)
    k = n * math.pi / length_m
    a = rho_i * rho_a / kga
    b = rho_a + rho_i * k**2 + rho_a * ei * k**2 / kga
    c = ei * k**4
    w2 = (b - math.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    return math.sqrt(w2) / (2.0 * math.pi)


def _timoshenko_element(h: float, ei: float, rho_a: float, kga: float) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and consistent translational mass of a two-node beam element of length ``h`` (m), dofs
    ``(w1, theta1, w2, theta2)``: the exact static stiffness of a shear-flexible beam (``phi = 12 EI / (kappa G A
    h^2)``; ``kga = inf``: no shear, Euler-Bernoulli)."""
    phi = 12.0 * ei / (kga * h * h)
    ke = (
        ei
        / ((1.0 + phi) * h**3)
        * np.array(
            [
                [12.0, 6 * h, -12.0, 6 * h],
                [6 * h, (4 + phi) * h * h, -6 * h, (2 - phi) * h * h],
                [-12.0, -6 * h, 12.0, -6 * h],
                [6 * h, (2 - phi) * h * h, -6 * h, (4 + phi) * h * h],
            ]
        )
    )
    me = (
        rho_a
        * h
        / 420.0
        * np.array(
            [
                [156.0, 22 * h, 54.0, -13 * h],
                [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                [54.0, 13 * h, 156.0, -22 * h],
                [-13 * h, -3 * h * h, -22 * h, 4 * h * h],
            ]
        )
    )
    return ke, me


def timoshenko_beam_hz(
    boundary: str,
    *,
    length_m: float,
    section: Section,
    material: Material,
    plane: str = "in",
    n_modes: int = 3,
    elements: int = 100,
    shear: bool = True,
    rotary_inertia: bool = True,
    hub_length_m: float = 0.0,
) -> np.ndarray:
    """Bending frequencies (Hz) of a uniform Timoshenko beam by finite elements (reference solution).

    Two-node elements with the exact static stiffness of a shear-flexible beam
    (``phi = 12 EI / (kappa G A h^2)``, Przemieniecki), consistent translational mass and the section's
    rotary inertia ``rho I h / 2`` lumped at the nodes. Converges to the continuum Timoshenko beam as
    ``1/elements^2`` (checked against :func:`timoshenko_simply_supported_hz` in the tests); ``shear`` and
    ``rotary_inertia`` switch the two corrections off (both off: Euler-Bernoulli).
    ``boundary``: ``"cantilever"``, ``"free-free"`` or ``"pinned-pinned"``. ``hub_length_m``: a rigid
    piece of the same section at each end (the elastic span is ``length_m - 2 hub_length_m``), its mass
    and inertia added as a rigid body at the end node it is fixed to (a clamped hub does not move).
    """
    import scipy.linalg

    if boundary not in ("cantilever", "free-free", "pinned-pinned"):
        raise ValueError(f"boundary must be cantilever, free-free or pinned-pinned, got {boundary!r}")
    ei, rho_a, rho_i, kga = _bending(section, material, plane)
    span = length_m - 2.0 * hub_length_m
    if not span > 0:
        raise ValueError(f"hub_length_m {hub_length_m} leaves no elastic span on a {length_m} m beam")
    h = span / elements
    ke, me = _timoshenko_element(h, ei, rho_a, kga if shear else math.inf)
    if rotary_inertia:
        me = me + np.diag([0.0, rho_i * h / 2.0, 0.0, rho_i * h / 2.0])
    n = 2 * (elements + 1)
    k = np.zeros((n, n))
    m = np.zeros((n, n))
    for e in range(elements):
        s = slice(2 * e, 2 * e + 4)
        k[s, s] += ke
        m[s, s] += me
    if hub_length_m > 0:
        mh = rho_a * hub_length_m
        j_end = mh * hub_length_m**2 / 3.0 + (rho_i * hub_length_m if rotary_inertia else 0.0)
        for node, sign in ((0, -1.0), (elements, 1.0)):  # centre of mass half a hub beyond the end
            d = [2 * node, 2 * node + 1]
            m[np.ix_(d, d)] += np.array([[mh, sign * mh * hub_length_m / 2.0], [sign * mh * hub_length_m / 2.0, j_end]])
    fixed = {"cantilever": [0, 1], "free-free": [], "pinned-pinned": [0, n - 2]}[boundary]
    keep = [i for i in range(n) if i not in fixed]
    k, m = k[np.ix_(keep, keep)], m[np.ix_(keep, keep)]
    skip = 2 if boundary == "free-free" else 0  # the two rigid-body modes
    w2 = scipy.linalg.eigh(k, m, eigvals_only=True, subset_by_index=[0, skip + n_modes - 1])[skip:]
    freq_hz: np.ndarray = np.sqrt(np.maximum(w2, 0.0)) / (2.0 * math.pi)  # w2 is Any: scipy has no stubs here
    return freq_hz


def spring_held_torsion_roots(stiffness_ratio: float, n_modes: int = 3) -> np.ndarray:
    """Roots ``alpha_n L`` of a uniform bar in free torsion whose root turns against a torsional spring.

    With ``theta = A cos(alpha x) + B sin(alpha x)``, the root condition ``G J theta'(0) = k theta(0)`` and
    a free end (``theta'(L) = 0``) give ``alpha L tan(alpha L) = K``, ``K = k L / (G J)``; root ``n`` lies in
    ``((n - 1) pi, (n - 1/2) pi)``, found by :func:`scipy.optimize.brentq` on ``x sin x - K cos x`` (no poles).
    ``K -> inf``: the clamped-free roots ``(n - 1/2) pi``; ``K -> 0``: a rigid rotation
    (``alpha L -> sqrt(K)``) then ``(n - 1) pi``.

    Parameters
    ----------
    stiffness_ratio
        ``K = k L / (G J)`` (dimensionless), > 0; ``math.inf`` for a clamped root.
    n_modes
        Number of roots, lowest first.
    """
    from scipy.optimize import brentq

    _check_spring_root(stiffness_ratio, n_modes)
    n = np.arange(1, n_modes + 1)
    if math.isinf(stiffness_ratio):
        out: np.ndarray = (n - 0.5) * math.pi
        return out
    k_ratio = float(stiffness_ratio)

    def f(x: float) -> float:
        return x * math.sin(x) - k_ratio * math.cos(x)

    return np.array([brentq(f, (j - 1) * math.pi, (j - 0.5) * math.pi, xtol=1e-14, rtol=1e-14) for j in n])


def spring_held_torsion_hz(
    *,
    length_m: float,
    section: Section,
    material: Material,
    root_stiffness_nm_per_rad: float,
    n_modes: int = 3,
) -> np.ndarray:
    """First ``n_modes`` torsion frequencies (Hz) of a uniform bar whose root turns against a torsional spring
    of ``root_stiffness_nm_per_rad``, the other end free: ``f_n = alpha_n L / (2 pi L) * sqrt(G J / (rho I_p))``
    with Saint-Venant's ``J`` (:attr:`Section.torsion_constant_m4`) and the section's polar moment
    ``I_p = A (t^2 + h^2) / 12``. Roots from :func:`spring_held_torsion_roots`."""
    gj = material.shear_pa * section.torsion_constant_m4
    rho_ip = material.density_kg_m3 * section.area_m2 * (section.thickness_m**2 + section.height_m**2) / 12.0
    roots = spring_held_torsion_roots(root_stiffness_nm_per_rad * length_m / gj, n_modes)
    freq_hz: np.ndarray = roots / (2.0 * math.pi * length_m) * math.sqrt(gj / rho_ip)
    return freq_hz
