"""One compiled model of a described architecture, re-posed in place for every pose of a sweep.

The general builder (:func:`fpm_sim.model.general.build_general`) places every body at the assembly, so the model's
topology, masses, inertias (in the bodies' own frames) and joint springs do not depend on the pose: only the bodies'
placements in their parents, the joints' positions and axes in their bodies, and the equalities' frames at
``qpos0`` do. :class:`TaskPoseModel` compiles the model once; at every pose it takes the placements the builder gives
(:class:`fpm_sim.model.general.Reposer`: the one builder's placements, without a spec; nothing here re-derives a
frame), copies those fields into the compiled model, recomputes the equality frames as the compiler does
(:func:`fpm_sim.batch.pose_loop.reset_equality_frames`), and solves the constrained eigenproblem from the mass matrix,
the joint springs and the equality Jacobian, as the 3RRR's :class:`fpm_sim.batch.pose_loop.PoseModel` does: on the
in-plane and out-of-plane blocks of a planar machine when they are exactly decoupled
(:class:`fpm_sim.batch.pose_loop.PlaneSplit`), else whole.

Valid where the 3RRR's loop is: gravity off, straight unstressed links at ``qpos0`` (the stiffness is the joint
springs' diagonal), ``segments`` or ``rigid`` links. ``tests/architecture/test_task_pose_model.py`` keeps the
re-posed model equal to one compiled at the pose, field by field and in its frequencies.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from fpm_sim.architecture import Description, TaskAssembly
from fpm_sim.batch.pose_loop import IN_PLANE_DOF_KINDS, PlaneSplit, reset_equality_frames, structural_length_m
from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.linear.matrices import mass_matrix
from fpm_sim.linear.nullspace import unit_scales
from fpm_sim.model.general import build_reposable
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.passive import dof_stiffness

__all__ = ["TaskPoseModel"]


class TaskPoseModel:
    """A described architecture's model compiled once at ``reference`` and re-posed for every pose (module
    docstring).

    Parameters
    ----------
    desc
        The machine.
    options
        Discretisation; gravity and axial stretch are turned off (the sweep's options).
    reference
        An assembly of ``desc`` to compile at (checked for mobility there by the builder).
    """

    def __init__(self, desc: Description, options: ModelOptions, reference: TaskAssembly) -> None:
        self.desc = desc
        self.options = replace(options, gravity=False)
        self.built, self.reposer = build_reposable(desc, reference.pose, self.options, assembly=reference)
        self.model = self.built.model
        self.data = mujoco.MjData(self.model)
        stiffness = dof_stiffness(self.model)
        in_plane = [kind in IN_PLANE_DOF_KINDS for kind in self.built.dof_kinds]
        # a spatial machine has no base plane: one whole problem (PlaneSplit with no out-of-plane dofs is unusable)
        self.split = PlaneSplit(in_plane if desc.planar else [True] * self.model.nv, stiffness)
        # what the pose sets, by name (the frames pass records the bodies it places: a link's first, pins, the end
        # effector), and where it goes in the compiled model
        placed = self.reposer.frames(reference)
        m = self.model
        self._body_names, self._joint_names = list(placed.bodies), list(placed.joints)
        self._equality_names = list(placed.equalities)
        self._bodies = [m.body(n).id for n in self._body_names]
        self._joints = [m.joint(n).id for n in self._joint_names]
        self._equalities = [m.equality(n).id for n in self._equality_names]
        self.scales: tuple[np.ndarray, np.ndarray] | None = None

    def set_pose(self, asm: TaskAssembly) -> None:
        """Re-pose the model at ``asm``: the builder's body placements, joint frames and equality anchors, then the
        equality frames at ``qpos0`` (module docstring)."""
        frames, m = self.reposer.frames(asm), self.model
        for i, (pos, quat) in zip(self._bodies, (frames.bodies[n] for n in self._body_names)):
            m.body_pos[i] = pos
            m.body_quat[i] = np.asarray(quat) / np.linalg.norm(quat)
        for i, (pos, axis) in zip(self._joints, (frames.joints[n] for n in self._joint_names)):
            m.jnt_pos[i] = pos
            m.jnt_axis[i] = np.asarray(axis) / np.linalg.norm(axis)
        for i, n in zip(self._equalities, self._equality_names):
            m.eq_data[i, 0:3] = np.asarray(frames.equalities[n].data)[0:3]
        reset_equality_frames(m, self.data, self._equalities)

    def solve(self, asm: TaskAssembly, n_modes: int) -> tuple[np.ndarray, bool]:
        """``(frequencies_hz, deficient)``: the lowest ``n_modes`` frequencies at ``asm`` (NaN-padded), and whether
        the constraint rank decision found a loop direction lost (a singular pose)."""
        self.set_pose(asm)
        mujoco.mj_fwdPosition(self.model, self.data)
        if self.scales is None:  # structural: which rows are rotations, which dofs translate
            self.scales = unit_scales(self.model, self.data, structural_length_m(self.model))
        jac = equality_jacobian(self.model, self.data)
        freq, _, deficient = self.split.modes(mass_matrix(self.model, self.data), jac, n_modes, scales=self.scales)
        return freq, deficient
