"""A three-degree-of-freedom in-plane model of the locked 3RRR: cheap, analytic, for global searches.

With the motors locked, the passive joints ideal and the links axially rigid, the platform's small
in-plane motion ``dX = (dx, dy, dphi)`` is resisted only by the bending of the proximal links:

- each proximal link is a cantilever (clamped at its motor) whose tip, the elbow ``B_i``, can move
  only across the link (``n_i``, normal to ``w_i``), with stiffness ``k_c = 3 E I_in / L1^3``;
- each distal link is a rigid two-force member: ``u_i . dB_i = u_i . dC_i = (Jx dX)_i``, so the elbow
  moves ``s_i = (Jx dX)_i / cross(w_i, u_i)`` along ``n_i``.

Hence ``K = Jx' diag(k_c / cross(w_i, u_i)^2) Jx`` (zero at a parallel singularity, infinite at a
serial one). Kinetic energy: platform (+ payload) as a rigid body, platform-joint hardware at ``C_i``,
the elbow hardware plus the cantilever's effective tip mass ``(33/140) m_link`` at ``B_i``, and each
distal link as a uniform rigid bar with end velocities ``v_B``, ``v_C``
(``T = m/6 (v_B^2 + v_B . v_C + v_C^2)``). The lowest eigenvalue of ``(K, M)`` gives the first
in-plane frequency.

Left out: the links' own bending dynamics beyond the first cantilever shape, and out-of-plane modes.
Its agreement with the segment model is measured in ``tests/test_inplane_surrogate.py``; it serves
to screen geometries quickly, never as a reported result.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fpm_sim.config import Manipulator
from fpm_sim.kinematics import BatchAssemblies, GeometryArrays, Pose, assemble_batch
from fpm_sim.linalg3 import smallest_generalized_eigenvalue3

__all__ = ["CANTILEVER_TIP_MASS_FRACTION", "InplaneArrays", "inplane_batch", "inplane_first_frequencies"]

CANTILEVER_TIP_MASS_FRACTION = 33.0 / 140.0
"""Rayleigh's effective tip mass of a cantilever with the static deflection shape."""


@dataclass(frozen=True)
class InplaneArrays:
    """What the surrogate needs of ``G`` descriptions besides their kinematics, as ``(G, 3)`` per-chain and
    ``(G,)`` arrays (SI units): a sampler's particles at once (:func:`inplane_batch`), or one (:meth:`of`)."""

    geometry: GeometryArrays
    cantilever_n_per_m: np.ndarray
    """``(G, 3)`` each proximal link's tip stiffness across it, ``3 E I_in / L1^3``."""
    elbow_kg: np.ndarray
    """``(G, 3)`` elbow hardware plus the cantilever's effective tip mass."""
    distal_kg: np.ndarray
    """``(G, 3)`` each distal link's mass."""
    platform_joint_kg: np.ndarray
    platform_kg: np.ndarray
    """``(G,)`` platform plus payload."""
    platform_izz_kg_m2: np.ndarray

    @classmethod
    def build(
        cls, geometry: GeometryArrays, *, young_pa: np.ndarray, density_kg_m3: np.ndarray, area_m2: np.ndarray,
        i_inplane_m4: np.ndarray, elbow_joint_kg: np.ndarray, platform_joint_kg: np.ndarray,
        platform_kg: np.ndarray, platform_izz_kg_m2: np.ndarray,
    ) -> InplaneArrays:  # fmt: skip
        """From ``(G,)`` material, section and hardware values (module docstring's formulas)."""
        l1, l2 = geometry.proximal_m, geometry.distal_m
        lin_mass = (density_kg_m3 * area_m2)[:, None]
        return cls(
            geometry=geometry,
            cantilever_n_per_m=3.0 * young_pa[:, None] * i_inplane_m4[:, None] / l1**3,
            elbow_kg=CANTILEVER_TIP_MASS_FRACTION * lin_mass * l1 + elbow_joint_kg[:, None],
            distal_kg=lin_mass * l2,
            platform_joint_kg=platform_joint_kg,
            platform_kg=platform_kg,
            platform_izz_kg_m2=platform_izz_kg_m2,
        )

    def rows(self, keep: np.ndarray) -> InplaneArrays:
        """The descriptions ``keep`` selects (a boolean mask or indices over ``G``)."""
        fields = {f.name: getattr(self, f.name)[keep] for f in dataclasses.fields(self) if f.name != "geometry"}
        return InplaneArrays(geometry=self.geometry.rows(keep), **fields)

    @classmethod
    def of(cls, config: Manipulator) -> InplaneArrays:
        """One description (``G = 1``)."""
        sec, mat, hw = config.section, config.material, config.hardware

        def one(v: float) -> np.ndarray:
            return np.array([v], float)

        return cls.build(
            GeometryArrays.of(config.geometry), young_pa=one(mat.young_pa), density_kg_m3=one(mat.density_kg_m3),
            area_m2=one(sec.area_m2), i_inplane_m4=one(sec.i_inplane_m4), elbow_joint_kg=one(hw.elbow_joint.mass_kg),
            platform_joint_kg=one(hw.platform_joint.mass_kg), platform_kg=one(hw.platform.mass_kg + hw.payload.mass_kg),
            platform_izz_kg_m2=one(hw.platform.inertia_kg_m2[2] + hw.payload.inertia_kg_m2[2]),
        )  # fmt: skip


def inplane_first_frequencies(config: Manipulator, poses: Sequence[Pose]) -> np.ndarray:
    """First in-plane natural frequency (Hz) at each pose; NaN where unreachable or (serially) singular.

    Vectorised over the poses (about a microsecond per pose), so that geometry searches can afford
    thousands of evaluations.
    """
    if len(poses) == 0:
        return np.zeros(0)
    xyphi = np.array([[p.x_m, p.y_m, p.phi_rad] for p in poses])
    out: np.ndarray = inplane_batch(InplaneArrays.of(config), xyphi)[0]
    return out


def _gram(t: np.ndarray, weight: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` ``sum_i weight_i t_i^T s_i`` over the chains ``i`` of ``(n, 3, 2, 3)`` maps ``t``, ``s``: one
    batched matrix product of the chains' stacked ``(6, 3)`` rows (five times as fast as the three-operand
    ``einsum``; the same sums, in another order)."""
    n = len(t)
    w6 = np.repeat(weight, 2, axis=1)[..., None]
    out: np.ndarray = np.matmul(np.swapaxes(t.reshape(n, 6, 3) * w6, 1, 2), s.reshape(n, 6, 3))
    return out


def inplane_batch(arrays: InplaneArrays, xyphi: np.ndarray, *, assembled: BatchAssemblies | None = None) -> np.ndarray:
    """``(G, P)`` first in-plane frequencies (Hz) of ``G`` descriptions at ``P`` poses (``xyphi``: ``(P, 3)``, m
    and rad); NaN where unreachable or (serially) singular. :func:`inplane_first_frequencies` is ``G = 1``.

    ``assembled``: the descriptions' kinematics at those poses (:func:`~fpm_sim.kinematics.assemble_batch` of
    ``arrays.geometry`` at ``xyphi``) where the caller has them already; assembled here otherwise."""
    ga = arrays.geometry
    n_g, n_p = len(ga.proximal_m), len(xyphi)
    many = assembled if assembled is not None else assemble_batch(ga, xyphi[:, 0], xyphi[:, 1], xyphi[:, 2])

    def rows(v: np.ndarray) -> np.ndarray:  # (G, ...) per description -> (G * P, ...) per (description, pose)
        out: np.ndarray = np.repeat(v, n_p, axis=0)
        return out

    def flat(v: np.ndarray) -> np.ndarray:  # (G, P, ...) -> (G * P, ...)
        return v.reshape((n_g * n_p, *v.shape[2:]))

    reach = flat(many.reachable)
    l1, l2 = rows(ga.proximal_m), rows(ga.distal_m)
    k_c, m_elbow, m_dist = rows(arrays.cantilever_n_per_m), rows(arrays.elbow_kg), rows(arrays.distal_kg)
    m_pin, m_plat = rows(arrays.platform_joint_kg), rows(arrays.platform_kg)
    i_plat = rows(arrays.platform_izz_kg_m2)
    n = n_g * n_p
    c = np.where(reach[:, None, None], flat(many.c), 0.0)  # unreachable poses: finite placeholders, masked below
    b = np.where(reach[:, None, None], flat(many.b), 1.0)
    a = rows(ga.base_points)
    r = c - np.tile(xyphi[:, :2], (n_g, 1))[:, None, :]
    w = (b - a) / l1[..., None]  # (n, 3, 2)
    u = (c - b) / l2[..., None]
    cross = w[..., 0] * u[..., 1] - w[..., 1] * u[..., 0]
    ok = reach & np.all(np.abs(cross) > 1e-9, axis=1)
    cross = np.where(np.abs(cross) > 1e-9, cross, 1.0)
    jx = np.concatenate([u, (r[..., 0] * u[..., 1] - r[..., 1] * u[..., 0])[..., None]], axis=2)  # (n, 3, 3)
    stiff = np.einsum("nik,ni,nil->nkl", jx, k_c / cross**2, jx)
    # dC_i = tc_i dX with tc_i = [I | perp(r_i)]; dB_i = n_i (jx_i . dX) / cross_i, n_i = perp(w_i)
    tc = np.zeros((n, 3, 2, 3))
    tc[..., 0, 0] = 1.0
    tc[..., 1, 1] = 1.0
    tc[..., 0, 2] = -r[..., 1]
    tc[..., 1, 2] = r[..., 0]
    nrm = np.stack([-w[..., 1], w[..., 0]], axis=2)
    tb = nrm[..., :, None] * (jx / cross[..., None])[..., None, :]  # (n, 3, 2, 3)
    cc = _gram(tc, np.ones_like(m_dist), tc)
    cc_d = _gram(tc, m_dist / 6.0, tc)
    bb_e = _gram(tb, m_elbow, tb)
    bb_d = _gram(tb, m_dist / 6.0, tb)
    bc_d = _gram(tb, m_dist / 6.0, tc)
    mass = np.zeros((n, 3, 3))
    mass[:, 0, 0] = mass[:, 1, 1] = m_plat
    mass[:, 2, 2] = i_plat
    mass += m_pin[:, None, None] * cc + bb_e + bb_d + 0.5 * (bc_d + np.swapaxes(bc_d, 1, 2)) + cc_d
    out = np.full(n, np.nan)
    if np.any(ok):
        w2 = smallest_generalized_eigenvalue3(stiff[ok], mass[ok])
        out[ok] = np.sqrt(np.maximum(w2, 0.0)) / (2.0 * math.pi)
    return out.reshape(n_g, n_p)
