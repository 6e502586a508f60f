"""A twelve-degree-of-freedom out-of-plane model of the locked 3RRR: cheap, analytic, beside the in-plane one.

Every joint of the 3RRR turns about the base plane's normal ``z``, so out of the plane (``w`` along ``z``, tilts
``theta_x``, ``theta_y``) the locked mechanism is a grillage: beams joined rigidly at every joint, clamped at the
motors. At zero gravity its motion is decoupled from the in-plane one (the segment model's modes are one kind or the
other), and the lowest out-of-plane mode is, where the links' section is thinner out of the plane than in it, often
the manipulator's first mode (``docs/identification.md``, "Two mode families").

The model: one beam element per link (Euler-Bernoulli bending out of the plane, ``E I_out``, and Saint-Venant
torsion, ``G J``, with Hermite-cubic stiffness and consistent mass matrices: Rayleigh-Ritz with the static shapes),
each elbow ``B_i`` free in ``(w, theta_x, theta_y)``, each platform joint ``C_i`` rigidly tied to the platform's
centre (``w_C = w + theta_x y_r - theta_y x_r``, the tilts the platform's), the lumped hardware as point masses with
their rotary inertias, the platform (plus payload) as a rigid body with the mean of its two in-plane inertias (the
platform's frame is turned by the pose's ``phi``; the shipped descriptions' platforms are axisymmetric). Twelve
degrees of freedom, the smallest eigenvalue of ``(K, M)`` by a batched Cholesky reduction.

Left out: the links' higher bending shapes (one element a link overestimates a link's own bending mode by a few %),
joint compliances (the joints are rigid out of the plane; a finite ``passive_joint_tilt`` or ``motor_mount_tilt``
is not modelled) and gravity's prestress. Its agreement with the segment model is measured in
``tests/test_outofplane_surrogate.py``; like the in-plane surrogate it serves the calibration's emulator as a
physical baseline, never as a reported result.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fpm_sim.config import LumpedMass, Manipulator, rectangle_torsion_constant_m4
from fpm_sim.kinematics import BatchAssemblies, GeometryArrays, Pose, assemble_batch
from fpm_sim.linalg3 import smallest_generalized_eigenvalue3

__all__ = ["OutofplaneArrays", "outofplane_batch", "outofplane_first_frequencies"]


@dataclass(frozen=True)
class OutofplaneArrays:
    """What the out-of-plane model needs of ``G`` descriptions besides their kinematics (SI units; ``(G,)`` arrays
    unless said)."""

    geometry: GeometryArrays
    bending_n_m2: np.ndarray
    """``E I_out``: the links' bending stiffness out of the plane."""
    torsion_n_m2: np.ndarray
    """``G J``: their torsional stiffness."""
    line_kg_per_m: np.ndarray
    """``rho A``."""
    polar_kg_m: np.ndarray
    """``rho (I_in + I_out)``: the links' rotary inertia about their axis per length."""
    elbow_kg: np.ndarray
    elbow_kg_m2: np.ndarray
    """The elbow hardware's mass and its inertia about an in-plane axis."""
    platform_joint_kg: np.ndarray
    platform_joint_kg_m2: np.ndarray
    platform_kg: np.ndarray
    """Platform plus payload."""
    platform_kg_m2: np.ndarray
    """Platform plus payload: the mean of the inertias about its two in-plane axes."""

    def rows(self, keep: np.ndarray) -> OutofplaneArrays:
        """The descriptions ``keep`` selects (a boolean mask or indices over ``G``)."""
        fields = {k: v[keep] for k, v in vars(self).items() if k != "geometry"}
        return OutofplaneArrays(geometry=self.geometry.rows(keep), **fields)

    @classmethod
    def build(
        cls, geometry: GeometryArrays, *, young_pa: np.ndarray, shear_pa: np.ndarray, density_kg_m3: np.ndarray,
        thickness_m: np.ndarray, height_m: np.ndarray, elbow_kg: np.ndarray, elbow_kg_m2: np.ndarray,
        platform_joint_kg: np.ndarray, platform_joint_kg_m2: np.ndarray, platform_kg: np.ndarray,
        platform_kg_m2: np.ndarray,
    ) -> OutofplaneArrays:  # fmt: skip
        """From ``(G,)`` material, section (in-plane ``thickness_m``, out-of-plane ``height_m``) and hardware values;
        the torsion constant :attr:`~fpm_sim.config.Section.torsion_constant_m4`'s."""
        t, h = thickness_m, height_m
        torsion = rectangle_torsion_constant_m4(np.maximum(t, h), np.minimum(t, h))
        return cls(
            geometry=geometry, bending_n_m2=young_pa * t * h**3 / 12.0, torsion_n_m2=shear_pa * torsion,
            line_kg_per_m=density_kg_m3 * t * h, polar_kg_m=density_kg_m3 * t * h * (t**2 + h**2) / 12.0,
            elbow_kg=elbow_kg, elbow_kg_m2=elbow_kg_m2, platform_joint_kg=platform_joint_kg,
            platform_joint_kg_m2=platform_joint_kg_m2, platform_kg=platform_kg, platform_kg_m2=platform_kg_m2,
        )  # fmt: skip

    @classmethod
    def of(cls, config: Manipulator) -> OutofplaneArrays:
        """One description (``G = 1``)."""
        sec, mat, hw = config.section, config.material, config.hardware

        def one(v: float) -> np.ndarray:
            return np.array([v], float)

        def tilt(*lumps: LumpedMass) -> np.ndarray:
            return one(sum(0.5 * (m.inertia_kg_m2[0] + m.inertia_kg_m2[1]) for m in lumps))

        return cls.build(
            GeometryArrays.of(config.geometry), young_pa=one(mat.young_pa), shear_pa=one(mat.shear_pa),
            density_kg_m3=one(mat.density_kg_m3), thickness_m=one(sec.thickness_m), height_m=one(sec.height_m),
            elbow_kg=one(hw.elbow_joint.mass_kg), elbow_kg_m2=tilt(hw.elbow_joint),
            platform_joint_kg=one(hw.platform_joint.mass_kg), platform_joint_kg_m2=tilt(hw.platform_joint),
            platform_kg=one(hw.platform.mass_kg + hw.payload.mass_kg), platform_kg_m2=tilt(hw.platform, hw.payload),
        )  # fmt: skip


def outofplane_first_frequencies(config: Manipulator, poses: Sequence[Pose]) -> np.ndarray:
    """The lowest out-of-plane natural frequency (Hz) at each pose; NaN where unreachable."""
    if len(poses) == 0:
        return np.zeros(0)
    xyphi = np.array([[p.x_m, p.y_m, p.phi_rad] for p in poses])
    out: np.ndarray = outofplane_batch(OutofplaneArrays.of(config), xyphi)[0]
    return out


_BLOCKS = {
    # (a, b, c, d, e) of a beam element's 3x3 block between its ends in local (w, psi, t), as multiples of
    # (EI / L^3, EI / L^2, EI / L^2, EI / L, GJ / L) for the stiffness and of (rho A L / 420, rho A L^2 / 420,
    # rho A L^2 / 420, rho A L^3 / 420, rho I_p L / 6) for the consistent mass (Hermite cubics; Przemieniecki 1968)
    "near_near": ((12.0, 6.0, 6.0, 4.0, 1.0), (156.0, 22.0, 22.0, 4.0, 2.0)),
    "near_far": ((-12.0, 6.0, -6.0, 2.0, -1.0), (54.0, -13.0, 13.0, -3.0, 1.0)),
    "far_far": ((12.0, -6.0, -6.0, 4.0, 1.0), (156.0, -22.0, -22.0, 4.0, 2.0)),
}


Mat3 = list[list[np.ndarray]]
"""A stack of 3x3 matrices as its nine entries, each an array over the stack: elementwise arithmetic on contiguous
arrays (a quarter of the cost of NumPy's batched ``matmul`` and strided writes into ``(n, 3, 3)`` stacks)."""


def _mul(a: Mat3, b: Mat3, *, transpose_a: bool = False) -> Mat3:
    """``a b`` (``a^T b`` with ``transpose_a``)."""
    if transpose_a:
        return [[a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j] for j in range(3)] for i in range(3)]
    return [[a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)] for i in range(3)]


def _add(*terms: Mat3) -> Mat3:
    return [[sum(t[i][j] for t in terms) for j in range(3)] for i in range(3)]  # type: ignore[misc]


def _transpose(a: Mat3) -> Mat3:
    return [[a[j][i] for j in range(3)] for i in range(3)]


def _inverse(a: Mat3) -> Mat3:
    """The adjugate over the determinant (the elbows' static stiffness is well conditioned: positive definite)."""

    def cofactor(i: int, j: int) -> np.ndarray:
        i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
        out: np.ndarray = a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]
        return out

    cof = [[cofactor(i, j) for j in range(3)] for i in range(3)]
    det = a[0][0] * cof[0][0] + a[0][1] * cof[0][1] + a[0][2] * cof[0][2]
    return [[cof[j][i] / det for j in range(3)] for i in range(3)]


def _block(which: str, length: np.ndarray, e: np.ndarray, beam: tuple[np.ndarray, ...]) -> tuple[Mat3, Mat3]:
    """Stiffness and mass blocks :data:`_BLOCKS` ``which`` of elements of ``length`` ``(...)`` along the unit vectors
    ``e`` ``(..., 2)``, between their ends' global ``(w, theta_x, theta_y)``. Locally ``psi = r1 . theta`` with
    ``r1 = (e_y, -e_x)`` and ``t = r2 . theta`` with ``r2 = e``, so the block ``[[a, b, 0], [c, d, 0], [0, 0, e]]``
    is ``[[a, b r1^T], [c r1, e I + (d - e) r1 r1^T]]`` globally."""
    ei, gj, rho_a, rho_ip = beam
    ell = length
    r1 = (e[..., 1], -e[..., 0])
    scales = (
        (ei / ell**3, ei / ell**2, ei / ell**2, ei / ell, gj / ell),
        (*(rho_a * ell**p / 420.0 for p in (1, 2, 2, 3)), rho_ip * ell / 6.0),
    )
    out = []
    for coef, scale in zip(_BLOCKS[which], scales):
        a, b, c, d, t = (k * v for k, v in zip(coef, scale))
        dt = d - t
        cross = dt * r1[0] * r1[1]
        out.append([[a, b * r1[0], b * r1[1]], [c * r1[0], t + dt * r1[0] ** 2, cross],
                    [c * r1[1], cross, t + dt * r1[1] ** 2]])  # fmt: skip
    return out[0], out[1]


def _to_platform(g: Mat3, s: tuple[np.ndarray, np.ndarray], *, both: bool) -> Mat3:
    """A block over a platform joint's ``(w_C, theta)`` in the platform's ``q``: ``w_C = w + s . theta`` (``s =
    (y_r, -x_r)``). ``both``: ``S^T g S`` (a block between two platform joints' coordinates), else ``g S``."""
    out = [[g[i][0], g[i][1] + g[i][0] * s[0], g[i][2] + g[i][0] * s[1]] for i in range(3)]
    if both:
        out = [out[0], *([out[k][j] + s[k - 1] * out[0][j] for j in range(3)] for k in (1, 2))]
    return out


def _lump(per: dict[str, np.ndarray], name: str) -> Mat3:
    """A point mass with its rotary inertia at a node, ``diag(m, I, I)``."""
    z = np.zeros_like(per[f"{name}_kg"])
    m, i = per[f"{name}_kg"], per[f"{name}_kg_m2"]
    return [[m, z, z], [z, i, z], [z, z, i]]


def _chains(arrays: OutofplaneArrays, many: BatchAssemblies, n_p: int) -> tuple[Mat3, ...]:
    """Per (description, pose) and chain (arrays ``(n, 3)``), the blocks of the grillage's stiffness and mass over
    the elbow's ``B`` and the platform's ``q`` coordinates: ``K_BB, K_Bq, K_qq, M_BB, M_Bq, M_qq`` (the platform's
    own mass not included)."""
    ga = arrays.geometry
    n = len(ga.proximal_m) * n_p
    reach = many.reachable.reshape(n)
    a = np.repeat(ga.base_points, n_p, axis=0)
    b = np.where(reach[:, None, None], many.b.reshape(n, 3, 2), a + np.array([1.0, 0.0]))
    c = np.where(reach[:, None, None], many.c.reshape(n, 3, 2), b + np.array([1.0, 0.0]))
    r = np.where(reach[:, None, None], many.r.reshape(n, 3, 2), 0.0)
    s = (r[..., 1], -r[..., 0])
    per = {k: np.repeat(v, n_p, axis=0)[:, None] * np.ones(3) for k, v in vars(arrays).items() if k != "geometry"}
    beam = (per["bending_n_m2"], per["torsion_n_m2"], per["line_kg_per_m"], per["polar_kg_m"])
    l1, l2 = np.linalg.norm(b - a, axis=2), np.linalg.norm(c - b, axis=2)
    e1, e2 = (b - a) / l1[..., None], (c - b) / l2[..., None]
    kp, mp = _block("far_far", l1, e1, beam)
    knn, mnn = _block("near_near", l2, e2, beam)
    knf, mnf = _block("near_far", l2, e2, beam)
    kff, mff = _block("far_far", l2, e2, beam)
    return (
        _add(kp, knn), _to_platform(knf, s, both=False), _to_platform(kff, s, both=True),
        _add(mp, mnn, _lump(per, "elbow")), _to_platform(mnf, s, both=False),
        _to_platform(_add(mff, _lump(per, "platform_joint")), s, both=True),
    )  # fmt: skip


def outofplane_batch(
    arrays: OutofplaneArrays, xyphi: np.ndarray, *, assembled: BatchAssemblies | None = None
) -> np.ndarray:
    """``(G, P)`` the lowest out-of-plane frequency (Hz) of ``G`` descriptions at ``P`` poses (``xyphi``: ``(P,
    3)``, m and rad); NaN where unreachable. ``assembled``: their kinematics there, where the caller has it."""
    ga = arrays.geometry
    n_g, n_p = len(ga.proximal_m), len(xyphi)
    many = assembled if assembled is not None else assemble_batch(ga, xyphi[:, 0], xyphi[:, 1], xyphi[:, 2])
    kbb, kbq, kqq, mbb, mbq, mqq = _chains(arrays, many, n_p)
    # Guyan: each elbow follows the platform statically, B_i = T_i q with T_i = -K_BB^-1 K_Bq
    t = _mul(_inverse(kbb), kbq)
    t = [[-v for v in row] for row in t]
    mqb_t = _mul(mbq, t, transpose_a=True)
    k_red = _add(kqq, _mul(kbq, t, transpose_a=True))
    m_red = _add(mqq, _mul(t, _mul(mbb, t), transpose_a=True), mqb_t, _transpose(mqb_t))
    plat = np.repeat(np.stack([arrays.platform_kg, arrays.platform_kg_m2, arrays.platform_kg_m2], axis=1), n_p, 0)
    k = np.stack([np.stack([v.sum(axis=1) for v in row], axis=-1) for row in k_red], axis=-2)
    m = np.stack([np.stack([v.sum(axis=1) for v in row], axis=-1) for row in m_red], axis=-2)
    m = m + plat[:, :, None] * np.eye(3)
    reach = many.reachable.reshape(n_g * n_p)
    out = np.full(n_g * n_p, np.nan)
    if reach.any():
        lam = smallest_generalized_eigenvalue3(k[reach], m[reach])
        out[reach] = np.sqrt(np.maximum(lam, 0.0)) / (2.0 * math.pi)
    return out.reshape(n_g, n_p)
