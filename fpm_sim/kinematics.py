"""Planar 3RRR kinematics: inverse and forward kinematics, Jacobians, singularity measure.

Conventions: the base plane is the world xy plane; chain ``i`` has its motor axis at
``A_i = R_b (cos a_i, sin a_i)``, its elbow at ``B_i`` and its platform joint at
``C_i = p + Rot(phi) r_p (cos g_i, sin g_i)``. Motor angle ``q_i`` is the direction of ``A_i -> B_i``.

Velocity relation (from d/dt |C_i - B_i|^2 = 0)::

    Jx @ [xdot, ydot, phidot] = Jq @ qdot
    Jx[i] = [u_i, cross(r_i, u_i)]            u_i = (C_i - B_i) / L2,  r_i = C_i - p
    Jq    = diag(L1 * cross(w_i, u_i))         w_i = (B_i - A_i) / L1

``Jq`` singular: a chain is stretched or folded (serial, type 1). ``Jx`` singular: the three distal
link lines meet in a point or are parallel (parallel, type 2; the platform gains a motion with the
motors locked: its stiffness, and so its natural frequencies, drop to zero there).

Singularity measure (dimensionless, 0 at a singularity, 1 at best):
``min(min_i |cross(w_i, u_i)|, sigma_min(Jx_n) / sigma_max(Jx_n))`` where ``Jx_n`` is ``Jx`` with
its rotation column divided by the characteristic length ``max(r_p, L2 / 4)``.
Poses whose measure is below :data:`SINGULAR_TOL` are refused (:class:`SingularPoseError`); below
:data:`NEAR_SINGULAR_WARN` a :class:`NearSingularityWarning` is issued.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fpm_sim.config import Geometry
from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.linalg3 import inverse_condition3

__all__ = [
    "NEAR_SINGULAR_WARN",
    "SINGULAR_TOL",
    "Assemblies",
    "Assembly",
    "BatchAssemblies",
    "GeometryArrays",
    "NearSingularityWarning",
    "Pose",
    "PoseValueError",
    "SingularPoseError",
    "SingularityMeasure",
    "UnreachablePoseError",
    "assemble_batch",
    "assemble_many",
    "base_points",
    "checked_pose_mm",
    "forward_kinematics",
    "inverse_kinematics",
    "jacobians",
    "platform_points",
    "singularity_measure",
]

SINGULAR_TOL = 1e-3
"""Singularity measure below which a pose is refused (stiffness ~ measure^2 -> frequencies vanish)."""
NEAR_SINGULAR_WARN = 0.05
"""Singularity measure below which a pose is accepted with a :class:`NearSingularityWarning`."""


class UnreachablePoseError(FpmSimError):
    """No assembly exists: a chain cannot span the distance from its motor to its platform joint."""


class SingularPoseError(FpmSimError):
    """The pose is (numerically) at a serial or parallel singularity."""


class PoseValueError(FpmSimError):
    """A pose value that is not a number, not finite, or a rotation outside -pi..pi."""


class NearSingularityWarning(FpmSimWarning):
    """The pose is close to a singularity: results are valid but very sensitive to the pose."""


@dataclass(frozen=True)
class Pose:
    """End-effector pose: platform centre (m) and rotation about the motor axes (rad)."""

    x_m: float
    y_m: float
    phi_rad: float = 0.0

    @classmethod
    def from_mm(cls, x_mm: float, y_mm: float, phi_rad: float = 0.0) -> Pose:
        return cls(x_mm * 1e-3, y_mm * 1e-3, phi_rad)

    def as_array(self) -> np.ndarray:
        return np.array([self.x_m, self.y_m, self.phi_rad])

    def label(self) -> str:
        return f"(x={self.x_m * 1e3:.1f} mm, y={self.y_m * 1e3:.1f} mm, phi={self.phi_rad:.3f} rad)"


def checked_pose_mm(
    x_mm: float | str, y_mm: float | str, phi_rad: float | str, *, file: object = None, row: int | None = None
) -> Pose:
    """The one pose validator (command line, poses files, measured data): a :class:`Pose` from millimetres and
    radians, each a finite number, the rotation within -pi..pi (refused, not wrapped: a file in degrees would
    otherwise be read silently). Raises :class:`PoseValueError` naming the value, and ``file``/``row`` if given."""
    values: list[float] = []
    for name, v in (("x_mm", x_mm), ("y_mm", y_mm), ("phi_rad", phi_rad)):
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise PoseValueError("must be a number", parameter=name, value=v, file=file, row=row) from None
        if not math.isfinite(f):
            raise PoseValueError("must be a finite number", parameter=name, value=v, file=file, row=row)
        values.append(f)
    if abs(values[2]) > math.pi:
        raise PoseValueError(
            f"outside -pi..pi (it would be wrapped to {math.remainder(values[2], 2 * math.pi):.4g} rad)",
            parameter="phi_rad",
            value=values[2],
            hint="give the rotation in radians within -pi..pi",
            file=file,
            row=row,
        )
    return Pose.from_mm(*values)


@dataclass(frozen=True)
class SingularityMeasure:
    """Dimensionless distances from the two singularity types (0 = singular, 1 = best)."""

    serial: float
    parallel: float
    worst_chain: int

    @property
    def value(self) -> float:
        return min(self.serial, self.parallel)

    @property
    def kind(self) -> str:
        return (
            "serial (a chain stretched or folded)"
            if self.serial <= self.parallel
            else "parallel (distal lines concurrent)"
        )


@dataclass(frozen=True)
class Assembly:
    """An assembled configuration: joint points (3 x 2 arrays, m) and motor angles (rad)."""

    pose: Pose
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    motor_angles_rad: np.ndarray
    singularity: SingularityMeasure

    @property
    def proximal_dirs(self) -> np.ndarray:
        d = self.b - self.a
        dirs: np.ndarray = d / np.linalg.norm(d, axis=1, keepdims=True)
        return dirs

    @property
    def distal_dirs(self) -> np.ndarray:
        d = self.c - self.b
        dirs: np.ndarray = d / np.linalg.norm(d, axis=1, keepdims=True)
        return dirs


def _rot(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def _cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    cross: np.ndarray = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    return cross


def base_points(g: Geometry) -> np.ndarray:
    """Motor axis points A_i (3 x 2, m)."""
    ang = np.asarray(g.base_angles_rad)
    points: np.ndarray = np.asarray(g.base_radius_per_chain)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return points


def platform_points(g: Geometry, pose: Pose) -> np.ndarray:
    """Platform joint points C_i in the world (3 x 2, m)."""
    ang = np.asarray(g.platform_angles_rad)
    local = np.asarray(g.platform_radius_per_chain)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    points: np.ndarray = np.array([pose.x_m, pose.y_m]) + local @ _rot(pose.phi_rad).T
    return points


def _char_length(g: Geometry) -> float:
    return max(max(g.platform_radius_per_chain), float(np.mean(g.distal_length_per_chain)) / 4.0)


def jacobians(g: Geometry, asm: Assembly) -> tuple[np.ndarray, np.ndarray]:
    """``(Jx, Jq)`` with ``Jx @ [xdot, ydot, phidot] = Jq @ qdot`` (see module docstring)."""
    u = asm.distal_dirs
    w = asm.proximal_dirs
    r = asm.c - np.array([asm.pose.x_m, asm.pose.y_m])
    jx = np.column_stack([u, _cross2(r, u)])
    jq = np.diag(np.asarray(g.proximal_length_per_chain) * _cross2(w, u))
    return jx, jq


def singularity_measure(g: Geometry, asm: Assembly) -> SingularityMeasure:
    """Serial and parallel singularity measures of an assembly (see module docstring)."""
    return assemble_many(g, asm.pose.x_m, asm.pose.y_m, asm.pose.phi_rad).assembly(0, asm.pose).singularity


@dataclass(frozen=True)
class BatchAssemblies:
    """:func:`assemble_batch`'s result: arrays over a leading ``(G, P)``, geometries by poses.

    Attributes
    ----------
    b, c
        ``(G, P, 3, 2)`` elbow and platform-joint points (m); ``b`` is NaN for a chain that cannot reach.
    r
        ``(G, P, 3, 2)`` the platform joints from the platform's centre, ``c - p`` (m).
    motor_angles_rad
        ``(G, P, 3)``; NaN for a chain that cannot reach.
    distance_m
        ``(G, P, 3)`` motor-to-platform-joint distance of each chain.
    reachable
        ``(G, P)`` every chain spans its distance.
    serial, parallel
        ``(G, P)`` the two singularity measures (module docstring); NaN where unreachable.
    det_jx
        ``(G, P)`` ``det(Jx)`` with the rotation column over the characteristic length (its sign flips across
        a parallel singularity); NaN where unreachable.
    """

    b: np.ndarray
    c: np.ndarray
    r: np.ndarray
    motor_angles_rad: np.ndarray
    distance_m: np.ndarray
    reachable: np.ndarray
    serial: np.ndarray
    parallel: np.ndarray
    det_jx: np.ndarray

    @property
    def singularity(self) -> np.ndarray:
        """Singularity measure ``min(serial, parallel)`` (NaN where unreachable)."""
        measure: np.ndarray = np.minimum(self.serial, self.parallel)
        return measure

    def rows(self, keep: np.ndarray) -> BatchAssemblies:
        """The geometries ``keep`` selects (a boolean mask or indices over ``G``), every pose of each."""
        return BatchAssemblies(*(getattr(self, f.name)[keep] for f in dataclasses.fields(BatchAssemblies)))


@dataclass(frozen=True)
class Assemblies(BatchAssemblies):
    """Many poses of one geometry assembled at once (see :func:`assemble_many`): the fields of
    :class:`BatchAssemblies` without the geometry axis (``b``: ``(n, 3, 2)``, ``reachable``: ``(n,)``, ...), and:

    Attributes
    ----------
    x_m, y_m, phi_rad
        ``(n,)`` the poses.
    a
        ``(3, 2)`` motor points (m).
    """

    x_m: np.ndarray
    y_m: np.ndarray
    phi_rad: np.ndarray
    a: np.ndarray

    def assembly(self, k: int, pose: Pose | None = None) -> Assembly:
        """Pose ``k`` as an :class:`Assembly` (it must be reachable); ``pose`` is recorded in it if given."""
        if pose is None:
            pose = Pose(float(self.x_m[k]), float(self.y_m[k]), float(self.phi_rad[k]))
        serial_each = np.abs(_cross2(_unit(self.b[k] - self.a), _unit(self.c[k] - self.b[k])))
        measure = SingularityMeasure(
            serial=float(self.serial[k]), parallel=float(self.parallel[k]), worst_chain=int(serial_each.argmin())
        )
        return Assembly(
            pose=pose,
            a=self.a,
            b=self.b[k],
            c=self.c[k],
            motor_angles_rad=self.motor_angles_rad[k],
            singularity=measure,
        )


def _unit(d: np.ndarray) -> np.ndarray:
    unit: np.ndarray = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return unit


@dataclass(frozen=True)
class GeometryArrays:
    """What the in-plane kinematics needs of ``G`` geometries, as arrays over a leading geometry axis: the many
    descriptions of a sampler's particles at once (:func:`assemble_batch`), or one (:meth:`of`).

    Attributes
    ----------
    base_points
        ``(G, 3, 2)`` motor points A_i (m).
    platform_local
        ``(G, 3, 2)`` platform joints in the platform frame (m).
    proximal_m, distal_m
        ``(G, 3)`` link lengths per chain (m).
    elbow_branch
        ``(G, 3)`` each chain's elbow solution (+1 or -1).
    char_length_m
        ``(G,)`` the singularity measure's characteristic length ``max(r_p, L2 / 4)`` (m).
    """

    base_points: np.ndarray
    platform_local: np.ndarray
    proximal_m: np.ndarray
    distal_m: np.ndarray
    elbow_branch: np.ndarray
    char_length_m: np.ndarray

    @classmethod
    def of(cls, g: Geometry) -> GeometryArrays:
        """One geometry (``G = 1``)."""

        def one(v: tuple[float, ...]) -> np.ndarray:
            return np.asarray(v, float)[None]

        return cls.from_polar(
            base_radius_m=one(g.base_radius_per_chain), base_angles_rad=one(g.base_angles_rad),
            platform_radius_m=one(g.platform_radius_per_chain), platform_angles_rad=one(g.platform_angles_rad),
            proximal_m=one(g.proximal_length_per_chain), distal_m=one(g.distal_length_per_chain),
            elbow_branch=one(g.elbow_branch),
        )  # fmt: skip

    @classmethod
    def from_polar(
        cls, *, base_radius_m: np.ndarray, base_angles_rad: np.ndarray, platform_radius_m: np.ndarray,
        platform_angles_rad: np.ndarray, proximal_m: np.ndarray, distal_m: np.ndarray, elbow_branch: np.ndarray,
    ) -> GeometryArrays:  # fmt: skip
        """From ``(G, 3)`` per-chain radii, angles (rad), lengths (m) and branches, as :class:`Geometry` has them."""
        def points(radius: np.ndarray, angles: np.ndarray) -> np.ndarray:
            out: np.ndarray = radius[..., None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
            return out

        char = np.maximum(np.max(platform_radius_m, axis=1), np.mean(distal_m, axis=1) / 4.0)  # as _char_length
        return cls(points(base_radius_m, base_angles_rad), points(platform_radius_m, platform_angles_rad),
                   proximal_m, distal_m, np.broadcast_to(np.asarray(elbow_branch, float), proximal_m.shape),
                   char)  # fmt: skip

    def rows(self, keep: np.ndarray) -> GeometryArrays:
        """The geometries ``keep`` selects (a boolean mask or indices over ``G``)."""
        return GeometryArrays(*(getattr(self, f.name)[keep] for f in dataclasses.fields(self)))


def assemble_batch(ga: GeometryArrays, x_m: ArrayLike, y_m: ArrayLike, phi_rad: ArrayLike) -> BatchAssemblies:
    """Inverse kinematics and singularity measures of ``G`` geometries at ``P`` poses at once (vectorised over both;
    no checks, no warnings): the formulas of :func:`assemble_many`, which calls this with ``G = 1``."""
    x, y, phi = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, float)).ravel() for v in (x_m, y_m, phi_rad)))
    a = ga.base_points[:, None]  # (G, 1, 3, 2)
    local = ga.platform_local[:, None]
    cos_p, sin_p = np.cos(phi)[:, None], np.sin(phi)[:, None]  # (P, 1)
    p = np.stack([x, y], axis=1)[:, None, :]  # (P, 1, 2)
    c = p + np.stack([local[..., 0] * cos_p - local[..., 1] * sin_p, local[..., 0] * sin_p + local[..., 1] * cos_p],
                     axis=-1)  # fmt: skip
    r = c - p
    l1 = ga.proximal_m[:, None, :]  # (G, 1, 3): per chain
    l2 = ga.distal_m[:, None, :]
    d = c - a
    dist = np.hypot(d[..., 0], d[..., 1])
    chain_ok = (abs(l1 - l2) <= dist) & (dist <= l1 + l2)
    reachable = chain_ok.all(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_alpha = np.clip((l1**2 + dist**2 - l2**2) / (2.0 * l1 * dist), -1.0, 1.0)
    q = np.arctan2(d[..., 1], d[..., 0]) + ga.elbow_branch[:, None, :] * np.arccos(cos_alpha)
    q = np.where(chain_ok, q, np.nan)
    b = a + l1[..., None] * np.stack([np.cos(q), np.sin(q)], axis=-1)
    w = (b - a) / l1[..., None]
    u = _unit(c - b)
    serial = np.min(np.abs(_cross2(w, u)), axis=-1)
    jxn = np.concatenate([u, (_cross2(r, u) / ga.char_length_m[:, None, None])[..., None]], axis=-1)
    jxn = np.where(reachable[..., None, None], jxn, 0.0)
    parallel, det_jx = inverse_condition3(jxn)  # closed form: a batched SVD was most of the cost
    nan = np.full(reachable.shape, np.nan)
    return BatchAssemblies(
        b=b, c=c, r=r, motor_angles_rad=q, distance_m=dist, reachable=reachable,
        serial=np.where(reachable, serial, nan), parallel=np.where(reachable, parallel, nan),
        det_jx=np.where(reachable, det_jx, nan),
    )  # fmt: skip


def assemble_many(g: Geometry, x_m: ArrayLike, y_m: ArrayLike, phi_rad: ArrayLike) -> Assemblies:
    """Inverse kinematics and singularity measures of many poses at once (vectorised; no checks, no warnings).

    The same formulas as :func:`inverse_kinematics` (which calls this for one pose), for arrays of positions
    (m) and rotations (rad) broadcast to one shape ``(n,)``.
    """
    ga = GeometryArrays.of(g)
    many = assemble_batch(ga, x_m, y_m, phi_rad)
    x, y, phi = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, float)).ravel() for v in (x_m, y_m, phi_rad)))
    return Assemblies(
        x_m=x,
        y_m=y,
        phi_rad=phi,
        a=ga.base_points[0],
        b=many.b[0],
        c=many.c[0],
        r=many.r[0],
        motor_angles_rad=many.motor_angles_rad[0],
        distance_m=many.distance_m[0],
        reachable=many.reachable[0],
        serial=many.serial[0],
        parallel=many.parallel[0],
        det_jx=many.det_jx[0],
    )


def inverse_kinematics(
    g: Geometry,
    pose: Pose,
    *,
    check_singularity: bool = True,
) -> Assembly:
    """Assemble the manipulator at ``pose``.

    Parameters
    ----------
    g
        Geometry; ``g.elbow_branch`` picks each chain's solution.
    pose
        Platform pose.
    check_singularity
        Refuse singular poses and warn near them (thresholds :data:`SINGULAR_TOL`,
        :data:`NEAR_SINGULAR_WARN`).

    Raises
    ------
    UnreachablePoseError
        Naming the chain whose motor-to-platform-joint distance is outside ``[|L1-L2|, L1+L2]``.
    SingularPoseError
        When the singularity measure is below :data:`SINGULAR_TOL`.
    """
    many = assemble_many(g, pose.x_m, pose.y_m, pose.phi_rad)
    if not many.reachable[0]:
        l1, l2 = np.asarray(g.proximal_length_per_chain), np.asarray(g.distal_length_per_chain)
        lo, hi = abs(l1 - l2), l1 + l2
        dist = many.distance_m[0]
        i = int(np.argmax((dist < lo) | (dist > hi)))
        raise UnreachablePoseError(
            f"pose {pose.label()} is unreachable: chain {i} needs {dist[i] * 1e3:.2f} mm from motor to "
            f"platform joint but its links span {lo[i] * 1e3:.2f}..{hi[i] * 1e3:.2f} mm; move the pose towards "
            f"the workspace centre or change geometry.proximal_length_m / distal_length_m"
        )
    asm = many.assembly(0, pose)
    measure = asm.singularity
    if check_singularity:
        if measure.value < SINGULAR_TOL:
            raise SingularPoseError(
                f"pose {pose.label()} is singular: measure {measure.value:.2e} < {SINGULAR_TOL:g} "
                f"({measure.kind}); the locked manipulator has a zero-stiffness motion there. Move the pose or "
                f"rotate the platform (phi_rad)"
            )
        if measure.value < NEAR_SINGULAR_WARN:
            warnings.warn(
                f"pose {pose.label()} is near a {measure.kind} singularity: measure {measure.value:.3f} < "
                f"{NEAR_SINGULAR_WARN:g}; low frequencies there are very sensitive to the pose",
                NearSingularityWarning,
                stacklevel=2,
            )
    return asm


def forward_kinematics(
    g: Geometry,
    motor_angles_rad: np.ndarray,
    *,
    guess: Pose,
    tol_m: float = 1e-13,
    max_iter: int = 50,
) -> Pose:
    """Platform pose from motor angles by Newton's method on ``|C_i - B_i|^2 = L2^2``.

    The 3RRR has up to six assembly modes; the one nearest ``guess`` is returned.

    Raises
    ------
    UnreachablePoseError
        If Newton's method does not converge (no assembly near ``guess``).
    """
    q = np.asarray(motor_angles_rad, dtype=float)
    a = base_points(g)
    b = a + np.asarray(g.proximal_length_per_chain)[:, None] * np.stack([np.cos(q), np.sin(q)], axis=1)
    ang = np.asarray(g.platform_angles_rad)
    local = np.asarray(g.platform_radius_per_chain)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    x = guess.as_array().astype(float)
    for _ in range(max_iter):
        rot = _rot(x[2])
        r = local @ rot.T
        c = x[:2] + r
        d = c - b
        f = np.sum(d * d, axis=1) - np.asarray(g.distal_length_per_chain) ** 2
        jac = 2.0 * np.column_stack([d, _cross2(r, d)])
        try:
            step = np.linalg.solve(jac, -f)
        except np.linalg.LinAlgError as exc:
            raise SingularPoseError("forward kinematics hit a parallel singularity") from exc
        x += step
        if np.max(np.abs(step[:2])) < tol_m and abs(step[2]) * max(max(g.platform_radius_per_chain), 1e-3) < tol_m:
            return Pose(float(x[0]), float(x[1]), float(x[2]))
    raise UnreachablePoseError(f"forward kinematics did not converge from guess {guess.label()}")
