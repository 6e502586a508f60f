"""One compiled flexible model of an imported description, posed by its joint values for every pose of a sweep.

:func:`fpm_sim.model.imported.build_imported` builds a model per pose (the spec read, the beams made, two compiles:
~0.5 s for the five-bar). A sweep needs only what changes with the pose, and under the pose loop's policy (gravity
off, straight unstressed links at the pose; :mod:`fpm_sim.batch.task_sweep`) that is the mass matrix and the
loop-closure Jacobian at the joint values. :class:`ImportedPoseModel` builds the flexible model once, at the model's
reference, with the joints modal analysis locks kept as joints (``keep_locked``); at each pose it sets the posed
joints' ``qpos`` (the beams' own joints stay at zero: straight), and solves the constrained eigenproblem

    K x = w^2 M x   on the null space of   [ the active <equality connect|weld> rows ; one row per locked dof ],

``K`` the joint springs' diagonal (the beams), as the described architectures' pose loop does
(:class:`fpm_sim.batch.pose_loop.PlaneSplit`: on the in-plane and out-of-plane blocks when they are exactly decoupled,
else whole). A locked joint's row removes its motion exactly as deleting the joint does. A pose whose loops do not
close (the equality rows' residual above :data:`fpm_sim.model.imported.LOOP_TOL`) is refused by the equality's name.
``tests/imported/test_imported_pose_model.py`` keeps it equal to a model built at each pose.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import mujoco
import numpy as np

from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.batch.pose_loop import IN_PLANE_DOF_KINDS, PlaneSplit, structural_length_m
from fpm_sim.linear.equilibrium import equality_jacobian
from fpm_sim.linear.matrices import mass_matrix
from fpm_sim.linear.nullspace import unit_scales
from fpm_sim.model.imported import build_imported, check_loops_closed
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.passive import dof_stiffness

__all__ = ["ImportedPoseModel"]


class ImportedPoseModel:
    """An imported model's flexible model compiled once and posed by joint values (module docstring).

    Parameters
    ----------
    desc
        The imported description.
    options
        Discretisation; gravity is turned off (the pose loop's policy).
    """

    def __init__(self, desc: ImportedDescription, options: ModelOptions) -> None:
        self.desc = desc
        self.options = replace(options, gravity=False)
        self.built = build_imported(desc, None, self.options, keep_locked=True)
        m = self.model = self.built.model
        self.data = mujoco.MjData(m)
        kinds = self.built.dof_kinds
        self.locked_dofs = np.array([k for k, kind in enumerate(kinds) if kind == "locked"], int)
        self.joints = {
            name: int(m.jnt_qposadr[j])
            for j in range(m.njnt)
            if (name := mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j))
        }
        stiffness = dof_stiffness(m)
        self.split = PlaneSplit([kind in IN_PLANE_DOF_KINDS or kind == "locked" for kind in kinds], stiffness)
        self._lock_rows = np.zeros((self.locked_dofs.size, m.nv))
        self._lock_rows[np.arange(self.locked_dofs.size), self.locked_dofs] = 1.0
        self.scales: tuple[np.ndarray, np.ndarray] | None = None

    def set_pose(self, q: Mapping[str, float]) -> None:
        """Set the joint values ``q`` (rad or m; joints not named at the model's reference) and run the position
        stage; a loop that does not close there is refused by the equality's name."""
        d = self.data
        d.qpos[:] = self.model.qpos0
        for name, value in q.items():
            d.qpos[self.joints[name]] = value
        mujoco.mj_fwdPosition(self.model, d)
        check_loops_closed(self.model, d, q)

    def solve(self, q: Mapping[str, float], n_modes: int) -> tuple[np.ndarray, bool]:
        """``(frequencies_hz, deficient)``: the lowest ``n_modes`` frequencies at ``q`` (NaN-padded), and whether
        the constraint rank decision found a loop direction lost (a singular pose)."""
        self.set_pose(q)
        if self.scales is None:  # structural: which rows are rotations, which dofs translate
            rows, cols = unit_scales(self.model, self.data, structural_length_m(self.model))
            self.scales = (np.concatenate([rows, np.ones(self.locked_dofs.size)]), cols)
        jac = np.vstack([equality_jacobian(self.model, self.data), self._lock_rows])
        freq, _, deficient = self.split.modes(mass_matrix(self.model, self.data), jac, n_modes, scales=self.scales)
        return freq, deficient
