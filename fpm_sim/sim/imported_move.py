"""Moves of an imported model (:mod:`fpm_sim.architecture.imported`): the :class:`~fpm_sim.sim.task.MoveMachine` that
:func:`fpm_sim.sim.task.simulate_task_move` moves.

An imported model moves as a described architecture does (:mod:`fpm_sim.sim.task`), read through
:class:`ImportedMover`:

- the pose solver is :class:`fpm_sim.model.imported_pose.ImportedKinematics` (Gauss-Newton on the model's loop rows
  and its end-effector site), each solve along the path started from the one before (continuation: the path stays
  on the assembly branch it starts on); a state is the task pose and every hinge and slide joint's value;
- the motors are :func:`fpm_sim.model.imported.motor_joints` (the joints an ``<actuator>`` drives, and
  ``servo_joints``), in the model's joint order, in MuJoCo's own coordinates (rad or m from the model's reference);
- the model with servos is :func:`fpm_sim.model.imported.build_imported` with ``motors="servo"``: each motor a
  spring-damper of the description's ``[servos]`` gains about its posed coordinate;
- the end effector's coordinates are those of the description's site (``phi``: the heading of the site's x axis).

A model that names no ``[end_effector]`` has no task path to command, and one without motors nothing to drive: both
refused (:class:`~fpm_sim.sim.trajectory.MoveError`) naming what to add to the description. A rollout
(:func:`fpm_sim.sim.task.rollout_machine`) reads the same mover: it needs the ``[end_effector]`` (its recorded
coordinates and its load), and motors only with ``motors="servo"`` (``need_motors=False``: locked motors, none
needed).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.architecture.kinematics import TaskPose
from fpm_sim.model.imported import build_imported, motor_joints
from fpm_sim.model.imported_pose import ImportedKinematics
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel
from fpm_sim.sim.trajectory import MoveError

__all__ = ["ImportedMover", "ImportedState"]


@dataclass(frozen=True)
class ImportedState:
    """An imported model posed at a task pose: the pose and every hinge and slide joint's value (rad or m)."""

    pose: TaskPose
    q: dict[str, float]


class ImportedMover:
    """An imported description as a :class:`~fpm_sim.sim.task.MoveMachine` (module docstring).

    Raises
    ------
    MoveError
        The description names no ``[end_effector]``, or its model has no motors (with ``need_motors``).
    """

    no_motor_hint = "build the model with its motors as servos (build_imported(..., motors='servo'))"

    def __init__(self, desc: ImportedDescription, *, need_motors: bool = True) -> None:
        if desc.end_effector is None:
            raise MoveError(
                f"{desc.name} names no end effector: a move commands the end effector's path in task coordinates, "
                "a rollout records and loads the end effector in them",
                parameter="end_effector",
                hint='name its site and coordinates in the description: [end_effector] site = "tool", '
                'coordinates = ["x", "y"] (docs/import.md)',
            )
        motors = tuple(motor_joints(desc))
        if not motors and need_motors:
            raise MoveError(
                f"{desc.name} has no motors to drive: no <actuator> drives a joint (but locked_joints) and "
                "servo_joints is empty",
                parameter="servo_joints",
                hint="name the joints the machine's motors turn in the description: servo_joints = [...] "
                "(docs/import.md)",
            )
        self.desc = desc
        self.kin = ImportedKinematics(desc)
        self.task = desc.task
        self.ee_site: str | None = desc.end_effector.site
        self.motor_names = motors

    def reference_pose(self) -> TaskPose:
        """The end effector's task pose at the model's reference (a move's default start)."""
        return self.kin.reference_pose()

    def state_at(self, pose: TaskPose | None = None, q: dict[str, float] | None = None) -> ImportedState:
        """The state at the task pose ``pose`` (the joints of ``q`` kept fixed), or, with no ``pose``, at the joint
        values ``q`` (the others at the model's reference; forward kinematics); neither: the model's reference."""
        if pose is not None:
            q = self.kin.solve(pose, fixed=q)
        at, values = self.kin.pose_at(q or {})
        return ImportedState(at, values)

    def solve(self, pose: TaskPose, near: ImportedState | None = None) -> ImportedState:
        """The joint values at ``pose``, solved from ``near`` (``None``: the model's reference)."""
        return ImportedState(pose, self.kin.solve(pose, start=None if near is None else near.q))

    def pose_of(self, state: ImportedState) -> TaskPose:
        return state.pose

    def motors(self, state: ImportedState) -> np.ndarray:
        return np.array([state.q[n] for n in self.motor_names])

    def build(
        self, pose: TaskPose, state: ImportedState | None, options: ModelOptions, motors: str = "servo"
    ) -> BuiltModel:
        q = (state if state is not None else self.solve(pose)).q
        return build_imported(self.desc, q, options, motors=motors)

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.motor_names:
            return np.zeros(0), np.zeros(0)
        model = self.kin.model
        hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
        types = ["revolute" if int(model.joint(n).type[0]) == hinge else "prismatic" for n in self.motor_names]
        k, c = zip(*(self.desc.servos.gains(t) for t in types))
        return np.array(k, float), np.array(c, float)
