"""Task-space poses of an imported model: the joint values that put its end-effector site at a task pose.

An imported description may name an end-effector site and the task coordinates it is posed by
(:class:`~fpm_sim.architecture.imported.EndEffector`: ``x``, ``y``, ``z``, the site's position in the world frame, m;
``phi``, the heading of the site's x axis about the world z axis, ``atan2(R[1, 0], R[0, 0])``, rad). A task pose is
solved on the rigid model as MuJoCo compiles it, by Gauss-Newton steps on

    r(q) = [ the loop closures' residuals (the model's active <equality connect|weld>, MuJoCo's own rows);
             the task coordinates' errors ]

over every hinge and slide joint the pose does not fix (ball joints stay at the model's reference), each step the
minimum-norm least-squares step with MuJoCo's own Jacobians (the equality rows' ``efc_J``; ``mj_jacSite`` for the
site), halved until ``|r|`` falls. Rotation rows are scaled by the model's extent so that metres and radians weigh
alike. The solve starts from the model's reference (``qpos0``) or from a given start (a sweep continues from the
previous pose), so it stays on the assembly branch of its start.

A pose is refused (:class:`ImportedPoseError`, by the pose) when the residual does not vanish (not reachable from
that branch), and when the Jacobian at the solution leaves a joint motion free (a singular pose, or task coordinates
too few for the joints: name more coordinates or lock joints). The result is every hinge and slide joint's value,
which :func:`fpm_sim.model.imported.build_imported` poses the flexible model at.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import mujoco
import numpy as np

from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.architecture.kinematics import TaskPose
from fpm_sim.errors import FpmSimError
from fpm_sim.model.imported import LOOP_TOL, constrained_model, load_spec

__all__ = ["ImportedKinematics", "ImportedPoseError", "joint_poses_of", "solve_imported_pose"]

_TOL = 1e-12
"""Converged when the largest residual (m, or rad times the model's extent) is below this times the extent."""
_RANK_TOL = 1e-9
"""A singular value of the scaled Jacobian below this times its largest is a free joint motion: round-off in the
Jacobian is ~1e-15 relative, a pose one micro-radian from a singularity is ~1e-6; between the two by three decades."""
_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


class ImportedPoseError(FpmSimError):
    """A task pose an imported model cannot take (unreachable, singular) or cannot be posed by (no end effector)."""


class ImportedKinematics:
    """The rigid model of an imported description, compiled once, and its task-pose solver (module docstring).

    Parameters
    ----------
    desc
        The imported description; it must name an ``[end_effector]`` site for :meth:`solve`.
    """

    def __init__(self, desc: ImportedDescription) -> None:
        if desc.end_effector is None:
            raise ImportedPoseError(
                f"{desc.name} has no task coordinates",
                parameter="end_effector",
                hint='name a site and its coordinates in the description: [end_effector] site = "tool", '
                'coordinates = ["x", "y", "phi"]; or pose the model by its joint values',
            )
        self.desc = desc
        model, self.data = constrained_model(load_spec(desc))
        self.model = model
        self.site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, desc.end_effector.site)
        if self.site < 0:
            names = ", ".join(
                n for s in range(model.nsite) if (n := mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s))
            )
            raise ImportedPoseError(
                f"no site {desc.end_effector.site!r} in {desc.model_path.name}",
                parameter="end_effector.site",
                hint=f"sites: {names or 'none; add a <site> to the end-effector body'}",
            )
        self.coordinates = desc.end_effector.coordinates
        self.joints = {
            name: int(model.jnt_qposadr[j])
            for j in range(model.njnt)
            if int(model.jnt_type[j]) in _HINGE_SLIDE
            and (name := mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j))
        }
        self._dof = {name: int(model.jnt_dofadr[model.joint(name).id]) for name in self.joints}
        self.extent_m = float(model.stat.extent) or 1.0

    def reference_pose(self) -> TaskPose:
        """The end-effector site's task coordinates at the model's reference (``qpos0``; m, rad)."""
        return self.pose_at({})[0]

    def pose_at(self, q: Mapping[str, float]) -> tuple[TaskPose, dict[str, float]]:
        """The end-effector site's task coordinates (m, rad) with the joints at ``q`` (those not given at the model's
        reference), and every hinge and slide joint's value: forward kinematics, no loop solved (``q`` closes the
        loops, as :func:`~fpm_sim.model.imported.build_imported` checks).

        Raises
        ------
        ImportedPoseError
            A joint ``q`` names that the model has no hinge or slide of.
        """
        self._check_names(q)
        self.data.qpos[:] = self.model.qpos0
        for name, v in q.items():
            self.data.qpos[self.joints[name]] = v
        mujoco.mj_kinematics(self.model, self.data)
        p, x = self.data.site_xpos[self.site], self.data.site_xmat[self.site].reshape(3, 3)[:, 0]
        values = {n: float(self.data.qpos[a]) for n, a in self.joints.items()}
        return TaskPose(float(p[0]), float(p[1]), float(p[2]), math.atan2(x[1], x[0])), values

    def _check_names(self, q: Mapping[str, float]) -> None:
        for name in q:
            if name not in self.joints:
                raise ImportedPoseError(
                    f"no hinge or slide joint {name!r} in the model",
                    parameter="q",
                    hint=f"joints: {', '.join(self.joints)}",
                )

    def _residual(self, pose: TaskPose) -> tuple[np.ndarray, np.ndarray]:
        """``r`` and ``dr/dv`` (rows: the equality rows, then the task coordinates; columns: the model's dofs) at
        ``data.qpos``; rotation rows scaled by the extent."""
        m, d, ell = self.model, self.data, self.extent_m
        mujoco.mj_fwdPosition(m, d)
        eq = np.flatnonzero(d.efc_type[: d.nefc] == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY))
        jac_eq = d.efc_J[: d.nefc * m.nv].reshape(d.nefc, m.nv)[eq] if d.nefc else np.zeros((0, m.nv))
        rows, jac = [np.asarray(d.efc_pos[eq], float)], [jac_eq]
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jacp, jacr, self.site)
        p, rot = d.site_xpos[self.site], d.site_xmat[self.site].reshape(3, 3)
        for c in self.coordinates:
            if c == "phi":
                x = rot[:, 0]
                den = x[0] ** 2 + x[1] ** 2
                if den < 1e-12:
                    raise ImportedPoseError(
                        "phi is undefined: the end-effector site's x axis points along the world z axis",
                        parameter="end_effector.site",
                        hint="turn the site so that its x axis lies in the task plane",
                    )
                err = math.remainder(math.atan2(x[1], x[0]) - pose.phi_rad, math.tau)
                rows.append(np.array([err * ell]))
                jac.append(
                    (ell * (x[0] * (x[0] * jacr[2] - x[2] * jacr[0]) - x[1] * (x[2] * jacr[1] - x[1] * jacr[2])) / den)[
                        None
                    ]
                )
            else:
                k = "xyz".index(c)
                rows.append(np.array([p[k] - pose.value(c)]))
                jac.append(jacp[k][None])
        return np.concatenate(rows), np.vstack(jac)

    def solve(
        self, pose: TaskPose, *, fixed: Mapping[str, float] | None = None, start: Mapping[str, float] | None = None
    ) -> dict[str, float]:
        """Every hinge and slide joint's value (rad or m) with the end-effector site at ``pose`` and the loops closed.

        Parameters
        ----------
        pose
            The task pose; only the description's task coordinates are used (m, rad).
        fixed
            Joint values the solve keeps (e.g. a joint the task coordinates do not reach).
        start
            Joint values to start from (the model's reference for those not given): a sweep's previous pose.

        Raises
        ------
        ImportedPoseError
            An unknown joint, a pose not reachable from the start's assembly branch, or a singular pose.
        """
        fixed = dict(fixed or {})
        self._check_names({**fixed, **(start or {})})
        d = self.data
        d.qpos[:] = self.model.qpos0
        for name, v in {**(start or {}), **fixed}.items():
            d.qpos[self.joints[name]] = v
        free = [n for n in self.joints if n not in fixed]
        cols = np.array([self._dof[n] for n in free], int)
        adr = np.array([self.joints[n] for n in free], int)
        r, jac = self._converge(pose, cols, adr)
        label = pose.label(self.coordinates)
        if np.max(np.abs(r), initial=0.0) > LOOP_TOL * self.extent_m:
            raise ImportedPoseError(
                f"task pose {label} is not reachable from the model's assembly branch: residual "
                f"{np.max(np.abs(r)):.3g} m",
                parameter="pose",
                hint="pose it within the machine's workspace, or start from a nearby pose",
            )
        self._check_mobility(jac[:, cols], free, label)
        return {n: float(d.qpos[a]) for n, a in self.joints.items()}

    def _converge(self, pose: TaskPose, cols: np.ndarray, adr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton with halving (module docstring); returns the last residual and Jacobian."""
        d = self.data
        r, jac = self._residual(pose)
        for _ in range(60):
            norm = float(np.linalg.norm(r))
            if np.max(np.abs(r), initial=0.0) < _TOL * self.extent_m or cols.size == 0:
                break
            step = np.linalg.lstsq(jac[:, cols], -r, rcond=1e-12)[0]
            q0 = d.qpos[adr].copy()
            for _ in range(30):
                d.qpos[adr] = q0 + step
                r_new, jac_new = self._residual(pose)
                if np.linalg.norm(r_new) < norm:
                    break
                step = step / 2
            else:
                d.qpos[adr] = q0
                r, jac = self._residual(pose)
                break
            r, jac = r_new, jac_new
        return r, jac

    def _check_mobility(self, jac: np.ndarray, free: list[str], label: str) -> None:
        if not free:
            return
        s = np.linalg.svd(jac, compute_uv=False) if jac.size else np.zeros(0)
        rank = int(np.sum(s > _RANK_TOL * (s[0] if s.size else 1.0)))
        if rank < len(free):
            raise ImportedPoseError(
                f"at task pose {label} the loops and the task coordinates leave {len(free) - rank} joint motion(s) "
                f"free "
                f"(joints solved: {', '.join(free)})",
                parameter="pose",
                hint="a singular pose: move away from it; or the end effector's coordinates are too few for the "
                "joints: name more of them, or lock joints in the description",
            )


def joint_poses_of(
    desc: ImportedDescription, poses: Sequence[TaskPose], *, labels: Sequence[str] | None = None
) -> list[dict[str, float]]:
    """Every pose of ``poses`` as joint values (:meth:`ImportedKinematics.solve`), each solve started from the one
    before (continuation: the sweep stays on one assembly branch; the first starts from the model's reference).
    An :class:`ImportedPoseError` names the pose by its label in ``labels`` (e.g. its file and row), else by its
    row (``pose 3``, 1-based)."""
    kin = ImportedKinematics(desc)
    out: list[dict[str, float]] = []
    for k, pose in enumerate(poses):
        try:
            out.append(kin.solve(pose, start=out[-1] if out else None))
        except ImportedPoseError as e:
            where = f"pose {k + 1}" if labels is None else labels[k]
            raise ImportedPoseError(f"{where}: {e.message}", parameter=e.parameter, hint=e.hint) from e
    return out


def solve_imported_pose(
    desc: ImportedDescription, pose: TaskPose, *, fixed: Mapping[str, float] | None = None
) -> dict[str, float]:
    """The joint values of ``desc`` at the task pose ``pose`` (:meth:`ImportedKinematics.solve`)."""
    return ImportedKinematics(desc).solve(pose, fixed=fixed)
