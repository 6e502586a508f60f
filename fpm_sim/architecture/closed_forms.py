"""Closed-form inverse kinematics of common planar chain patterns: the general solver's fast path.

The general inverse kinematics (:mod:`fpm_sim.architecture.kinematics`) solves every closure by Newton's method. Where a
chain is one of the patterns below *and its attachment point is known from the task coordinates* (the end effector's
pose all given, or a planar end effector's free ``phi`` turning no attachment point), its joint coordinates follow in
closed form, and the general solver takes them instead of iterating. Each pattern gives every assembly (two: the working
mode picks one); the caller keeps the one inside every working-mode interval, and then **checks** the whole assembly
with the general closure residual: where the pattern's assumptions fail for any reason (an axis off the plane, an
attachment point out of the plane, round-off at the workspace's edge), the check fails and the general Newton runs as
before. So these forms never change a result; they only skip iterations.

Patterns (a root chain, from its base frame ``(p0, R0)``; ``u = R0 x``, ``w`` the first revolute's world axis,
``v = w x u``):

* **planar dyad** ``revolute - link L1 - revolute - link L2 - end joint`` with both revolute axes equal (unit, and
  perpendicular to the frame's x axis): the 3RRR's chains, the five-bar's and the serial 2R arm's (their free ``phi``
  then read by the caller from the chain the tool is fixed on). The end joint's centre is
  ``p0 + L1 e(q1) + L2 e(q1 + q2)`` with ``e(a) = cos a u + sin a v``: circle-circle intersection,
  ``cos q2 = (r^2 - L1^2 - L2^2) / (2 L1 L2)``, ``q2 = +-acos``.
* **prismatic-revolute** ``prismatic - revolute - link L - end joint`` (revolute axis unit, perpendicular to the
  frame's x axis): the 3PRR's chains. The end joint's centre is ``p0 + q1 s + L e(q2)`` with ``s = R0 axis``:
  line-circle intersection, ``|d - q1 s| = L``, two roots of a quadratic.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from fpm_sim.architecture.description import ChainDesc, JointDesc, LinkDesc

__all__ = ["ChainSolver", "chain_solver"]

ChainSolver = Callable[[np.ndarray], list[np.ndarray]]
"""Every assembly of a chain (its moving joints' coordinates, path order) with its end joint's centre at a world
point (m); empty where there is none."""

_AXIS_TOL = 1e-12
"""Tolerance of the pattern's geometric assumptions (unit axes, parallel or perpendicular): exact in a description
written with unit axes, and the closure check catches anything these tests let through."""
_EDGE_TOL = 1e-9
"""``cos q2`` or the quadratic's discriminant beyond its range by this much (relative) is taken as the workspace's
edge (round-off); more is no assembly."""


def chain_solver(chain: ChainDesc) -> ChainSolver | None:
    """The closed form of a root ``chain`` (module docstring), or ``None`` when it matches no pattern."""
    end = chain.end_joint
    if chain.parent is not None or end is None:
        return None
    kinds = tuple(e.type if isinstance(e, JointDesc) else "link" for e in chain.path[:-1])
    p0 = np.array(chain.base_position_m, float)
    r0 = np.array(chain.base_rotation, float)
    if kinds == ("revolute", "link", "revolute", "link"):
        j1, l1, j2, l2 = chain.path[:4]
        if not (isinstance(j1, JointDesc) and isinstance(j2, JointDesc)):
            return None
        if not (isinstance(l1, LinkDesc) and isinstance(l2, LinkDesc)):
            return None
        if not _planar_axis(j1.axis) or not np.allclose(j1.axis, j2.axis, rtol=0.0, atol=_AXIS_TOL):
            return None
        return _dyad(p0, r0, np.array(j1.axis, float), l1.length_m, l2.length_m)
    if kinds == ("prismatic", "revolute", "link"):
        j1, j2, link = chain.path[:3]
        if not (isinstance(j1, JointDesc) and isinstance(j2, JointDesc) and isinstance(link, LinkDesc)):
            return None
        if not _planar_axis(j2.axis):
            return None
        return _slider_link(p0, r0, np.array(j1.axis, float), np.array(j2.axis, float), link.length_m)
    return None


def _planar_axis(axis: tuple[float, float, float]) -> bool:
    """A unit revolute axis perpendicular to the frame's x axis (the links turn in a plane)."""
    return abs(math.hypot(*axis) - 1.0) < _AXIS_TOL and abs(axis[0]) < _AXIS_TOL


def _plane(r0: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``u = R0 x`` and ``v = w x u`` (``w = R0 axis``): a link at angle ``a`` about the axis points along
    ``cos a u + sin a v``."""
    u, w = r0[:, 0], r0 @ axis
    return u, np.cross(w, u)


def _dyad(p0: np.ndarray, r0: np.ndarray, axis: np.ndarray, l1: float, l2: float) -> ChainSolver:
    """Circle-circle intersection (module docstring): both elbow signs."""
    u, v = _plane(r0, axis)

    def solve(target: np.ndarray) -> list[np.ndarray]:
        d = target - p0
        x, y = float(d @ u), float(d @ v)
        c = (x * x + y * y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        if abs(c) > 1.0 + _EDGE_TOL:
            return []
        out = []
        for sign in (1.0, -1.0):
            q2 = sign * math.acos(max(-1.0, min(1.0, c)))
            q1 = math.atan2(y, x) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
            out.append(np.array([q1, q2]))
        return out

    return solve


def _slider_link(p0: np.ndarray, r0: np.ndarray, slide: np.ndarray, axis: np.ndarray, length: float) -> ChainSolver:
    """Line-circle intersection (module docstring): both roots."""
    u, v = _plane(r0, axis)
    s = r0 @ slide
    ss = float(s @ s)

    def solve(target: np.ndarray) -> list[np.ndarray]:
        d = target - p0
        ds = float(d @ s)
        disc = ds * ds - ss * (float(d @ d) - length * length)
        if disc < -_EDGE_TOL * ss * length * length:
            return []
        out = []
        for sign in (1.0, -1.0):
            q1 = (ds + sign * math.sqrt(max(disc, 0.0))) / ss
            e = d - q1 * s
            out.append(np.array([q1, math.atan2(float(e @ v), float(e @ u))]))
        return out

    return solve
