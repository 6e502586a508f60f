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

import math
from collections.abc import Sequence

import numpy as np

from fpm_sim.config import Manipulator
from fpm_sim.kinematics import Pose, assemble_many

__all__ = ["CANTILEVER_TIP_MASS_FRACTION", "inplane_first_frequencies"]

CANTILEVER_TIP_MASS_FRACTION = 33.0 / 140.0
"""Rayleigh's effective tip mass of a cantilever with the static deflection shape."""


def inplane_first_frequencies(config: Manipulator, poses: Sequence[Pose]) -> np.ndarray:
    """First in-plane natural frequency (Hz) at each pose; NaN where unreachable or (serially) singular.

    Vectorised over the poses (about a microsecond per pose), so that geometry searches can afford
    thousands of evaluations.
    """
    g = config.geometry
    sec, mat, hw = config.section, config.material, config.hardware
    l1 = np.asarray(g.proximal_length_per_chain)[None, :]  # (1, 3): per chain
    l2 = np.asarray(g.distal_length_per_chain)[None, :]
    k_c = 3.0 * mat.young_pa * sec.i_inplane_m4 / l1**3
    lin_mass = mat.density_kg_m3 * sec.area_m2
    m_elbow = (CANTILEVER_TIP_MASS_FRACTION * lin_mass * l1 + hw.elbow_joint.mass_kg)[0]  # (3,)
    m_dist = (lin_mass * l2)[0]  # (3,)
    m_pin = hw.platform_joint.mass_kg
    m_plat = hw.platform.mass_kg + hw.payload.mass_kg
    i_plat = hw.platform.inertia_kg_m2[2] + hw.payload.inertia_kg_m2[2]
    n = len(poses)
    if n == 0:
        return np.zeros(0)
    xyphi = np.array([[p.x_m, p.y_m, p.phi_rad] for p in poses])
    many = assemble_many(g, xyphi[:, 0], xyphi[:, 1], xyphi[:, 2])  # the one vectorised inverse kinematics
    reach = many.reachable
    c = np.where(reach[:, None, None], many.c, 0.0)  # unreachable poses: finite placeholders, masked below
    b = np.where(reach[:, None, None], many.b, 1.0)
    a = many.a
    r = c - xyphi[:, None, :2]
    w = (b - a[None]) / l1[..., None]  # (n, 3, 2)
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
    cc = np.einsum("nijk,nijl->nkl", tc, tc)
    cc_d = np.einsum("nijk,nijl,i->nkl", tc, tc, m_dist / 6.0)
    bb_e = np.einsum("nijk,nijl,i->nkl", tb, tb, m_elbow)
    bb_d = np.einsum("nijk,nijl,i->nkl", tb, tb, m_dist / 6.0)
    bc_d = np.einsum("nijk,nijl,i->nkl", tb, tc, m_dist / 6.0)
    mass = np.zeros((n, 3, 3))
    mass[:, 0, 0] = mass[:, 1, 1] = m_plat
    mass[:, 2, 2] = i_plat
    mass += m_pin * cc + bb_e + bb_d + 0.5 * (bc_d + np.swapaxes(bc_d, 1, 2)) + cc_d
    out = np.full(n, np.nan)
    if np.any(ok):
        w2 = np.linalg.eigvals(np.linalg.solve(mass[ok], stiff[ok])).real.min(axis=1)
        out[ok] = np.sqrt(np.maximum(w2, 0.0)) / (2.0 * math.pi)
    return out
