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

from .config import Manipulator
from .kinematics import Pose, SingularPoseError, UnreachablePoseError, inverse_kinematics, jacobians

__all__ = ["inplane_first_frequencies", "CANTILEVER_TIP_MASS_FRACTION"]

CANTILEVER_TIP_MASS_FRACTION = 33.0 / 140.0
"""Rayleigh's effective tip mass of a cantilever with the static deflection shape."""


def _perp(v: np.ndarray) -> np.ndarray:
    return np.array([-v[1], v[0]])


def inplane_first_frequencies(config: Manipulator, poses: Sequence[Pose]) -> np.ndarray:
    """First in-plane natural frequency (Hz) at each pose; NaN where unreachable or singular."""
    g = config.geometry
    sec, mat, hw = config.section, config.material, config.hardware
    l1, l2 = g.proximal_length_m, g.distal_length_m
    k_c = 3.0 * mat.young_pa * sec.i_inplane_m4 / l1**3
    lin_mass = mat.density_kg_m3 * sec.area_m2
    m_prox, m_dist = lin_mass * l1, lin_mass * l2
    m_elbow = CANTILEVER_TIP_MASS_FRACTION * m_prox + hw.elbow_joint.mass_kg / 2.0
    m_dist_start = hw.elbow_joint.mass_kg / 2.0
    m_pin = hw.platform_joint.mass_kg
    m_plat = hw.platform.mass_kg + hw.payload.mass_kg
    i_plat = hw.platform.inertia_kg_m2[2] + hw.payload.inertia_kg_m2[2]
    out = np.full(len(poses), np.nan)
    for j, pose in enumerate(poses):
        try:
            asm = inverse_kinematics(g, pose, check_singularity=False)
        except (UnreachablePoseError, SingularPoseError):
            continue
        jx, _ = jacobians(g, asm)
        w, u = asm.proximal_dirs, asm.distal_dirs
        cross = w[:, 0] * u[:, 1] - w[:, 1] * u[:, 0]
        if np.min(np.abs(cross)) < 1e-9:
            continue
        stiff = jx.T @ np.diag(k_c / cross**2) @ jx
        mass = np.diag([m_plat, m_plat, i_plat])
        p = np.array([pose.x_m, pose.y_m])
        for i in range(3):
            r = asm.c[i] - p
            tc = np.column_stack([np.eye(2), _perp(r)])  # dC_i = tc @ dX
            n = _perp(w[i])
            tb = np.outer(n, jx[i] / cross[i])  # dB_i = tb @ dX
            mass += m_pin * tc.T @ tc + (m_elbow + m_dist_start) * tb.T @ tb
            mass += m_dist / 6.0 * (tb.T @ tb + 0.5 * (tb.T @ tc + tc.T @ tb) + tc.T @ tc)
        w2 = np.linalg.eigvals(np.linalg.solve(mass, stiff)).real
        out[j] = math.sqrt(max(float(np.min(w2)), 0.0)) / (2.0 * math.pi)
    return out
