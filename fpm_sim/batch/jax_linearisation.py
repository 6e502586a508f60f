"""Batched, differentiable constrained linearisation of the per-pose MuJoCo models in JAX (the ``jax`` backend).

What it computes, for a model of bodies joined by hinge and slide joints (springs in
``jnt_stiffness``), closed by body ``weld`` equalities, at ``q = qpos0`` with zero velocity:

* ``M(q)``: the joint-space mass matrix (``sum_b m_b Jp_b' Jp_b + Jr_b' I_b Jr_b + diag(armature)``,
  equal to ``mj_fullM``);
* ``K = -d f / d q`` by ``jax.jacfwd`` of the generalised force ``f = qfrc_passive - qfrc_bias`` at
  ``v = 0`` (springs and, if the model has gravity, gravity), plus with ``geometric=True`` the
  constraint-force term ``-d(J' lam)/dq`` with ``lam`` solving ``J' lam = -f``;
* ``J``: the weld rows of ``efc_J`` (MuJoCo's formula, including the quaternion correction of the
  rotational rows and ``torquescale``);

then ``Z = null(J)``, ``Z'KZ x = w^2 Z'MZ x`` for the lowest modes, batched over poses
(:func:`reduced_modes`, also the eigen-solve of the ``mjx`` backend, :mod:`fpm_sim.batch.mjx_backend`).

Why its own formulas and not MJX's pipeline (``mjx.kinematics``/``crb``/``rne``, the ``mjx`` backend):
MJX's tree scans unroll one stage per tree depth level, and a segment chain has one level per body, so
its XLA compile grows with the segment count (the batched solve of the 25 study poses at 6 segments per
link compiled in 186 s through MJX against 10.6 s here, one run of what is now ``benchmarks/backends.py`` on
the shared 2-core reference CPU). Here the same formulas are written over the model's arrays with one ``lax.scan`` over
bodies, so compile time barely grows with the segment count. The per-pose models share one structure
(topology), which is static; their array fields (:data:`PARAM_FIELDS`) are stacked along a leading pose
axis and ``vmap``-ped.

Importing this module imports JAX but changes none of its settings. The functions need float64 to
agree with MuJoCo: call them inside ``jax.enable_x64(True)`` (or :func:`fpm_sim.batch.jax_backend.x64`),
as the backends do.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from fpm_sim.errors import FpmSimError

__all__ = [
    "PARAM_FIELDS",
    "Structure",
    "batched_modes",
    "linearise",
    "modal_sensitivity",
    "params_of",
    "reduced_modes",
    "smooth_terms",
    "stack_params",
    "structure_of",
]

PARAM_FIELDS = (
    "body_pos",
    "body_quat",
    "body_ipos",
    "body_inertia_b",
    "body_mass",
    "jnt_pos",
    "jnt_axis",
    "jnt_stiffness",
    "qpos0",
    "qpos_spring",
    "dof_armature",
    "eq_data",
)
"""Per-pose array fields. ``body_inertia_b`` is the full 3x3 inertia about the body's centre of mass in
the body frame (``R(body_iquat) diag(body_inertia) R'``): smooth in the model parameters, unlike the
principal axes MuJoCo stores."""

_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)


@dataclass(frozen=True, eq=False)
class Structure:
    """Topology shared by all poses of a batch (numpy; static under ``jit``).

    Attributes
    ----------
    nbody, nv
        Body count (world included) and degrees of freedom.
    parent
        ``(nbody,)`` parent body.
    body_jnt
        ``(nbody, maxj)`` joint ids of each body in MuJoCo's order, ``-1`` padded.
    jnt_slide
        ``(njnt,)`` True for slide joints (else hinge).
    ancestor
        ``(nbody, nv)`` 1 where the dof moves the body.
    weld_b1, weld_b2
        Bodies of each weld.
    gravity
        ``(3,)`` m/s^2.
    """

    nbody: int
    nv: int
    parent: np.ndarray
    body_jnt: np.ndarray
    jnt_slide: np.ndarray
    ancestor: np.ndarray
    weld_b1: np.ndarray
    weld_b2: np.ndarray
    gravity: np.ndarray

    def key(self) -> bytes:
        """Bytes identifying the structure (for caching compiled functions)."""
        parts = [self.parent, self.body_jnt, self.jnt_slide, self.ancestor, self.weld_b1, self.weld_b2, self.gravity]
        return b"|".join(np.ascontiguousarray(p).tobytes() + str(p.shape).encode() for p in parts)

    def same_as(self, other: Structure) -> bool:
        return self.key() == other.key()


def structure_of(model: mujoco.MjModel) -> Structure:
    """The static topology of ``model``.

    Raises
    ------
    FpmSimError
        If the model has joints other than hinges and slides, equalities other than body welds,
        tendons, actuators with dofs, or a non-trivial qpos/qvel mapping.
    """
    jt = np.asarray(model.jnt_type)
    if np.any((jt != _HINGE) & (jt != _SLIDE)):
        raise FpmSimError("the jax backend handles hinge and slide joints only (no free or ball joints)")
    if model.nq != model.nv or not np.array_equal(model.jnt_dofadr, np.arange(model.njnt)):
        raise FpmSimError("the jax backend needs one dof per joint in joint order")
    if np.any(model.eq_type != int(mujoco.mjtEq.mjEQ_WELD)) or np.any(
        model.eq_objtype != int(mujoco.mjtObj.mjOBJ_BODY)
    ):
        raise FpmSimError("the jax backend handles body weld equalities only")
    if model.ntendon:
        raise FpmSimError("the jax backend does not handle tendons")
    maxj = max(1, int(model.body_jntnum.max()))
    body_jnt = -np.ones((model.nbody, maxj), dtype=int)
    for b in range(model.nbody):
        for k in range(int(model.body_jntnum[b])):
            body_jnt[b, k] = int(model.body_jntadr[b]) + k
    anc = np.zeros((model.nbody, model.nv))
    for b in range(1, model.nbody):
        c = b
        while c > 0:
            for k in range(int(model.body_dofnum[c])):
                anc[b, int(model.body_dofadr[c]) + k] = 1.0
            c = int(model.body_parentid[c])
    return Structure(
        nbody=int(model.nbody),
        nv=int(model.nv),
        parent=np.asarray(model.body_parentid, dtype=int).copy(),
        body_jnt=body_jnt,
        jnt_slide=(jt == _SLIDE).copy(),
        ancestor=anc,
        weld_b1=np.asarray(model.eq_obj1id, dtype=int).copy(),
        weld_b2=np.asarray(model.eq_obj2id, dtype=int).copy(),
        gravity=np.asarray(model.opt.gravity, dtype=float).copy(),
    )


def _quat_to_mat_np(q: np.ndarray) -> np.ndarray:
    out = np.zeros((len(q), 9))
    for i, qi in enumerate(q):
        mujoco.mju_quat2Mat(out[i], qi)
    return out.reshape(-1, 3, 3)


def params_of(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """The per-pose array fields (:data:`PARAM_FIELDS`) of ``model`` as float64 numpy arrays."""
    rot = _quat_to_mat_np(np.asarray(model.body_iquat))
    inertia_b = np.einsum("bij,bj,bkj->bik", rot, np.asarray(model.body_inertia), rot)
    out = {
        "body_pos": model.body_pos,
        "body_quat": model.body_quat,
        "body_ipos": model.body_ipos,
        "body_inertia_b": inertia_b,
        "body_mass": model.body_mass,
        "jnt_pos": model.jnt_pos,
        "jnt_axis": model.jnt_axis,
        "jnt_stiffness": model.jnt_stiffness,
        "qpos0": model.qpos0,
        "qpos_spring": model.qpos_spring,
        "dof_armature": model.dof_armature,
        "eq_data": model.eq_data[:, :11],
    }
    return {k: np.array(v, dtype=float) for k, v in out.items()}


def stack_params(params: Sequence[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Stack per-pose parameter dicts along a new leading axis."""
    return {k: np.stack([p[k] for p in params]) for k in PARAM_FIELDS}


# --------------------------------------------------------------------------------------------- quaternions
# MuJoCo's conventions (w, x, y, z), as in mju_* and mujoco.mjx._src.math.


def _quat_mul(u: jax.Array, v: jax.Array) -> jax.Array:
    return jnp.array(
        [
            u[0] * v[0] - u[1] * v[1] - u[2] * v[2] - u[3] * v[3],
            u[0] * v[1] + u[1] * v[0] + u[2] * v[3] - u[3] * v[2],
            u[0] * v[2] - u[1] * v[3] + u[2] * v[0] + u[3] * v[1],
            u[0] * v[3] + u[1] * v[2] - u[2] * v[1] + u[3] * v[0],
        ]
    )


def _quat_to_mat(q: jax.Array) -> jax.Array:
    w, x, y, z = q
    return jnp.array(
        [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
    )


def _rotate(v: jax.Array, q: jax.Array) -> jax.Array:
    return _quat_to_mat(q) @ v


def _axis_angle(axis: jax.Array, angle: jax.Array) -> jax.Array:
    s = jnp.sin(angle / 2)
    return jnp.concatenate([jnp.cos(angle / 2)[None], axis * s])


def _quat_inv(q: jax.Array) -> jax.Array:
    return q * jnp.array([1.0, -1.0, -1.0, -1.0])


def _quat_mul_axis(q: jax.Array, axis: jax.Array) -> jax.Array:
    """``q * (0, axis)`` (mju_mulQuatAxis)."""
    return _quat_mul(q, jnp.concatenate([jnp.zeros(1, axis.dtype), axis]))


# --------------------------------------------------------------------------------------------- smooth terms


def _kinematics(s: Structure, p: dict[str, jax.Array], q: jax.Array) -> tuple[jax.Array, ...]:
    """Body positions/orientations and joint anchors/axes (world), MuJoCo's ``mj_kinematics``."""
    nb, maxj = s.body_jnt.shape
    bj = jnp.asarray(np.maximum(s.body_jnt, 0))
    has = jnp.asarray(s.body_jnt >= 0)
    slide = jnp.asarray(s.jnt_slide)
    parent = jnp.asarray(s.parent)
    ang = q - p["qpos0"]

    def step(carry: tuple[jax.Array, jax.Array], b: jax.Array) -> tuple[tuple[jax.Array, jax.Array], Any]:
        xpos, xquat = carry
        par = parent[b]
        pos = xpos[par] + _rotate(p["body_pos"][b], xquat[par])
        quat = _quat_mul(xquat[par], p["body_quat"][b])
        anchors, axes = [], []
        for k in range(maxj):
            j = bj[b, k]
            jpos, jaxis = p["jnt_pos"][j], p["jnt_axis"][j]
            anchor = _rotate(jpos, quat) + pos
            axis = _rotate(jaxis, quat)
            a = jnp.where(has[b, k], ang[j], 0.0)
            is_slide = slide[j]
            # hinge: rotate about the anchor; slide: translate along the axis
            quat_h = _quat_mul(quat, _axis_angle(jaxis, jnp.where(is_slide, 0.0, a)))
            quat_h = quat_h / jnp.linalg.norm(quat_h)
            pos_h = anchor - _rotate(jpos, quat_h)
            pos_s = pos + axis * a
            new_pos = jnp.where(is_slide, pos_s, pos_h)
            pos = jnp.where(has[b, k], new_pos, pos)
            quat = jnp.where(has[b, k], quat_h, quat)
            anchors.append(anchor)
            axes.append(axis)
        return (xpos.at[b].set(pos), xquat.at[b].set(quat)), (jnp.stack(anchors), jnp.stack(axes))

    xpos0 = jnp.zeros((nb, 3), q.dtype)
    xquat0 = jnp.zeros((nb, 4), q.dtype).at[:, 0].set(1.0)
    (xpos, xquat), (anc_b, ax_b) = jax.lax.scan(step, (xpos0, xquat0), jnp.arange(1, nb))
    flat = s.body_jnt[1:].reshape(-1)
    sel = np.nonzero(flat >= 0)[0]
    order = sel[np.argsort(flat[sel])]
    return xpos, xquat, anc_b.reshape(-1, 3)[order], ax_b.reshape(-1, 3)[order]


def _point_jacobian(
    s: Structure, point: jax.Array, body: int, xanchor: jax.Array, xaxis: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Translational and rotational Jacobians ``(3, nv)`` of a world point fixed to ``body`` (mj_jac)."""
    a = jnp.asarray(s.ancestor[body])[:, None]
    slide = jnp.asarray(s.jnt_slide)[:, None]
    jp = jnp.where(slide, xaxis, jnp.cross(xaxis, point[None] - xanchor)) * a
    jr = jnp.where(slide, 0.0, xaxis) * a
    return jp.T, jr.T


def smooth_terms(
    s: Structure, p: dict[str, jax.Array], q: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """``(M, f, J, r)`` at ``q`` with zero velocity for one pose.

    ``M`` (nv, nv) mass matrix; ``f`` (nv) ``qfrc_passive - qfrc_bias`` (springs, gravity); ``J``
    (6 n_weld, nv) weld Jacobian rows; ``r`` (6 n_weld) weld residual (``efc_pos``).
    """
    xpos, xquat, xanchor, xaxis = _kinematics(s, p, q)
    xmat = jax.vmap(_quat_to_mat)(xquat)
    xipos = xpos + jnp.einsum("bij,bj->bi", xmat, p["body_ipos"])
    anc = jnp.asarray(s.ancestor)[..., None]
    slide = jnp.asarray(s.jnt_slide)[None, :, None]
    arm = xipos[:, None] - xanchor[None]
    jp = jnp.where(slide, xaxis[None], jnp.cross(xaxis[None], arm)) * anc  # (nb, nv, 3)
    jr = jnp.where(slide, 0.0, xaxis[None]) * anc
    inertia_w = jnp.einsum("bij,bjk,blk->bil", xmat, p["body_inertia_b"], xmat)
    mass = (
        jnp.einsum("b,bvi,bwi->vw", p["body_mass"], jp, jp)
        + jnp.einsum("bvi,bij,bwj->vw", jr, inertia_w, jr)
        + jnp.diag(p["dof_armature"])
    )
    force = -p["jnt_stiffness"] * (q - p["qpos_spring"])
    if np.any(s.gravity != 0):
        force = force + jnp.einsum("b,bvi,i->v", p["body_mass"], jp, jnp.asarray(s.gravity))
    rows, res = [], []
    for e in range(len(s.weld_b1)):
        b1, b2 = int(s.weld_b1[e]), int(s.weld_b2[e])
        data = p["eq_data"][e]
        anchor1, anchor2, relpose, torquescale = data[0:3], data[3:6], data[6:10], data[10]
        # MuJoCo: eq_data[3:6] is the anchor on body1, eq_data[0:3] the anchor on body2
        pos1 = xmat[b1] @ anchor2 + xpos[b1]
        pos2 = xmat[b2] @ anchor1 + xpos[b2]
        jp1, jr1 = _point_jacobian(s, pos1, b1, xanchor, xaxis)
        jp2, jr2 = _point_jacobian(s, pos2, b2, xanchor, xaxis)
        quat = _quat_mul(xquat[b1], relpose)
        quat1 = _quat_inv(xquat[b2])
        jdr = (jr1 - jr2) * torquescale
        jrot = 0.5 * jax.vmap(lambda col, a=quat1, b=quat: _quat_mul(_quat_mul_axis(a, col), b)[1:])(jdr.T)
        rows.append(jnp.concatenate([jp1 - jp2, jrot.T]))
        res.append(jnp.concatenate([pos1 - pos2, _quat_mul(quat1, quat)[1:] * torquescale]))
    jac = jnp.concatenate(rows) if rows else jnp.zeros((0, s.nv), q.dtype)
    resid = jnp.concatenate(res) if res else jnp.zeros((0,), q.dtype)
    return mass, force, jac, resid


def linearise(
    s: Structure, p: dict[str, jax.Array], q: jax.Array, *, geometric: bool
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """``(M, K, J)`` at ``q`` for one pose; ``K = -df/dq`` by ``jax.jacfwd`` (exact).

    With ``geometric`` the constraint-force term ``-d(J' lam)/dq`` (``lam`` fixed, least-squares solution
    of ``J' lam = -f``) is added; it vanishes at an unstressed pose (gravity off, springs at rest), which
    is the ``jax`` backend's case, and costs ``nv`` tangents through the kinematics otherwise.
    """

    def force(qq: jax.Array) -> jax.Array:
        return smooth_terms(s, p, qq)[1]

    mass, f, jac, _ = smooth_terms(s, p, q)
    stiff = -jax.jacfwd(force)(q)
    if geometric and jac.shape[0]:
        lam = jnp.linalg.solve(jac @ jac.T, -(jac @ f))
        djac = jax.jacfwd(lambda qq: smooth_terms(s, p, qq)[2])(q)
        stiff = stiff - jnp.einsum("e,eij->ij", lam, djac)
    return mass, stiff, jac


# --------------------------------------------------------------------------------------------- eigen-solve


def reduced_modes(
    mass: jax.Array, stiff: jax.Array, jac: jax.Array, n_modes: int
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Lowest ``n_modes`` of ``Z'KZ x = w^2 Z'MZ x`` with ``Z = null(J)`` for one pose.

    Returns ``(w2, X, sv_ratio)``: eigenvalues (rad^2/s^2), full-space M-normalised shapes ``X = Z x``
    ``(nv, n_modes)`` and the smallest-to-largest singular value ratio of ``J`` (rank check: the rank is
    taken as the row count).
    """
    nc = jac.shape[0]
    if nc:
        _, sv, vt = jnp.linalg.svd(jac, full_matrices=True)
        z = vt[nc:].T
        ratio = sv[-1] / sv[0]
    else:
        z = jnp.eye(mass.shape[0], dtype=mass.dtype)
        ratio = jnp.ones((), mass.dtype)
    kr = z.T @ stiff @ z
    mr = z.T @ mass @ z
    chol = jnp.linalg.cholesky(0.5 * (mr + mr.T))
    inv = jax.scipy.linalg.solve_triangular(chol, jnp.eye(chol.shape[0], dtype=chol.dtype), lower=True)
    a = inv @ (0.5 * (kr + kr.T)) @ inv.T
    w2, y = jnp.linalg.eigh(0.5 * (a + a.T))
    x = z @ (inv.T @ y[:, :n_modes])
    return w2[:n_modes], x, ratio


def batched_modes(
    s: Structure, params: dict[str, jax.Array], *, n_modes: int, geometric: bool
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """Linearise and solve all poses (leading axis of ``params``) at ``qpos0``; jit this.

    Returns ``(w2, X, k_diag, sv_ratio)`` with shapes ``(B, n)``, ``(B, nv, n)``, ``(B, nv)``, ``(B,)``;
    ``k_diag`` is the diagonal of ``K`` (spring energy of the mode character).
    """

    def one(p: dict[str, jax.Array]) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        mass, stiff, jac = linearise(s, p, p["qpos0"], geometric=geometric)
        w2, x, ratio = reduced_modes(mass, stiff, jac, n_modes)
        return w2, x, jnp.diag(stiff), ratio

    return jax.vmap(one)(params)


def modal_sensitivity(
    s: Structure,
    params: dict[str, jax.Array],
    tangents: dict[str, jax.Array],
    *,
    n_modes: int,
    geometric: bool,
) -> tuple[jax.Array, jax.Array]:
    """Frequencies (Hz) and their derivatives along parameter tangents for one pose; jit this.

    ``tangents`` holds ``d(params)/d(p_k)`` stacked over parameters ``k`` (leading axis). Uses
    ``d(w^2) = x'(dK - w^2 dM)x`` with M-normalised ``x``: exact for distinct eigenvalues when ``J`` does
    not depend on the parameter (the caller checks that geometry is unchanged). ``dM``, ``dK`` are
    ``jax.jvp`` tangents of :func:`linearise`. Returns ``(f_hz (n,), df_hz (n_params, n))``.
    """

    def lin(p: dict[str, jax.Array]) -> tuple[jax.Array, jax.Array, jax.Array]:
        return linearise(s, p, params["qpos0"], geometric=geometric)

    mass, stiff, jac = lin(params)
    w2, x, _ = reduced_modes(mass, stiff, jac, n_modes)

    def along(t: dict[str, jax.Array]) -> jax.Array:
        _, (dm, dk, _) = jax.jvp(lin, (params,), (t,))
        return jnp.einsum("ik,ij,jk->k", x, dk, x) - w2 * jnp.einsum("ik,ij,jk->k", x, dm, x)

    dw2 = jax.vmap(along)(tangents)
    w = jnp.sqrt(w2)
    return w / (2 * jnp.pi), dw2 / (2 * w) / (2 * jnp.pi)
