"""Rollouts and moves of any described architecture (:mod:`fpm_sim.architecture`), in its task coordinates.

The same time stepping as the 3RRR's (:func:`fpm_sim.sim.rollout.rollout`, :func:`fpm_sim.sim.trajectory`), read
through a :class:`fpm_sim.sim.rollout.RolloutMachine` (:func:`machine_of`):

- the end effector's recorded coordinates are the architecture's task coordinates (``x, y[, z][, phi]``), its
  load a force along each translational one (N) and a moment about z (N m) for ``phi``;
- the motors are the actuated joints, in the description's order, named ``<chain>_<joint>``; they have joints
  only in a model built with ``motors="servo"`` (:func:`fpm_sim.model.general.build_general`): position servos of
  the description's gains (:class:`fpm_sim.architecture.description.ServoGains`);
- the deflection is the pose minus the rigid-link pose of the motor coordinates, to first order about the
  assembly: ``pose + J (theta - theta_0)`` with ``J`` the rigid kinematics' task-per-motor Jacobian, by central
  differences of the inverse kinematics (:func:`rigid_jacobian`). With locked motors it is exact (``theta =
  theta_0``); with servos its error is of order ``|J'| |theta - theta_0|^2``, second order in the small motions a
  rollout makes.

A move (:func:`simulate_task_move`) commands a path in task coordinates (:class:`TaskPath`); the joint targets are
the general inverse kinematics (:func:`fpm_sim.architecture.solve_task_pose`) on a grid of :data:`IK_POINTS` times
along it, each warm-started from the previous one so the path stays in the working mode it starts in, and a cubic
spline between them (the path is smooth; a sampled path is interpolated linearly between its own rows, as the
command). The servos track them as the 3RRR's do (:mod:`fpm_sim.sim.trajectory`); the residual vibration of the
end effector's position after the move is compared with the modal f1 at the end pose (servos on) and its dominant
mode (the largest share of the end effector's translational static compliance), which input shapers are designed
for. The move's deflection uses ``J`` at the end pose about the joint targets: ``cmd + J (theta - theta_ref)``.

The move reads the machine through a :class:`MoveMachine` (its pose solver, motors, model with servos and their
gains), so that one implementation moves both a described architecture (:class:`DescribedMover`: the inverse
kinematics above, :func:`fpm_sim.model.general.build_general` with ``motors="servo"``) and an imported model
(:class:`fpm_sim.sim.imported_move.ImportedMover`: Gauss-Newton on the model's loop rows and end-effector site,
:func:`fpm_sim.model.imported.build_imported` with ``motors="servo"``); ``J`` is the same central differences of
either solver (:func:`motor_jacobian`). A rollout reads the same adapter (:func:`rollout_machine`: the model at a
state with its motors locked or as servos, and its :class:`~fpm_sim.sim.rollout.RolloutMachine`), so it runs on both
too.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import mujoco
import numpy as np

from fpm_sim.architecture.description import Description
from fpm_sim.architecture.kinematics import (
    TaskAssembly,
    TaskPose,
    actuated_coordinates,
    solve_task_pose,
    task_unknowns,
)
from fpm_sim.errors import FpmSimError
from fpm_sim.model.general import actuated_joint_names, build_general
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel
from fpm_sim.sim.rollout import RolloutMachine, aligned_step
from fpm_sim.sim.stepping import DEFAULT_INTEGRATOR

if TYPE_CHECKING:
    from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.sim.trajectory import (
    DEFAULT_SETTLE_TOL_M,
    MoveError,
    MoveResult,
    check_move,
    check_profile,
    path_duration_s,
    path_poses,
    read_path_csv,
    residual_vibration,
    shaper,
    track_servos,
)

__all__ = [
    "IK_POINTS",
    "DescribedMover",
    "MoveMachine",
    "TaskPath",
    "machine_of",
    "motor_jacobian",
    "mover_of",
    "pose_vector",
    "rigid_jacobian",
    "rollout_machine",
    "simulate_task_move",
    "task_pose",
]

IK_POINTS = 201
"""Inverse-kinematics solves along a profile move (a cubic spline between them). A minimum-jerk 30 mm move's joint
targets are smooth on 1/200 of the move: the spline's error is below 1e-9 rad (its fourth derivative times h^4)."""
FD_STEP = 1e-6
"""Central-difference step (m, rad) of :func:`rigid_jacobian`: the inverse kinematics converges to 1e-11 m, so the
derivative's round-off is ~1e-5 relative and its truncation ~1e-12."""


def pose_vector(pose: TaskPose, task: tuple[str, ...]) -> np.ndarray:
    """The task coordinates ``task`` of ``pose`` (m, rad)."""
    return np.array([pose.value(c) for c in task])


def task_pose(values: np.ndarray, task: tuple[str, ...]) -> TaskPose:
    """The :class:`TaskPose` of task-coordinate values (the others 0)."""
    v = dict(zip(task, map(float, values)))
    return TaskPose(v.get("x", 0.0), v.get("y", 0.0), v.get("z", 0.0), v.get("phi", 0.0))


class MoveMachine(Protocol):
    """What a move and a rollout read of a machine besides its MuJoCo model, whatever describes it: the pose solver,
    the motors, the model with servos and their gains. A *state* is the solver's assembly at a pose (the described
    architectures' :class:`~fpm_sim.architecture.kinematics.TaskAssembly`, an imported model's joint values), opaque
    to the move. :class:`DescribedMover` and :class:`fpm_sim.sim.imported_move.ImportedMover`."""

    @property
    def task(self) -> tuple[str, ...]:
        """The task coordinates."""

    @property
    def motor_names(self) -> tuple[str, ...]:
        """The motors, in their order (their servo joints' names in the model)."""

    @property
    def ee_site(self) -> str | None:
        """The end-effector site's name where it is none of :data:`fpm_sim.sim.rollout.EE_SITES`."""

    @property
    def no_motor_hint(self) -> str:
        """How to give the motors joints (:attr:`fpm_sim.sim.rollout.RolloutMachine.no_motor_hint`)."""

    def solve(self, pose: TaskPose, near: Any = None) -> Any:
        """The state at ``pose``, solved from ``near`` (a state; ``None``: the machine's own start)."""

    def pose_of(self, state: Any) -> TaskPose:
        """The task pose of ``state``."""

    def motors(self, state: Any) -> np.ndarray:
        """The motors' coordinates at ``state`` (rad or m, as the model's servo joints count them)."""

    def build(self, pose: TaskPose, state: Any, options: ModelOptions, motors: str = "servo") -> BuiltModel:
        """The flexible model at ``pose`` (``state`` its state; ``None``: solved), its motors ``motors``: servos (a
        move's), or ``"locked"`` (a rollout's default)."""

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """Each motor's servo stiffness and damping (N m/rad and N m s/rad, or N/m and N s/m)."""


@dataclass(frozen=True)
class DescribedMover:
    """A described architecture as a :class:`MoveMachine`: its inverse kinematics
    (:func:`~fpm_sim.architecture.solve_task_pose`), its actuated joints, :func:`build_general` with servos."""

    desc: Description
    ee_site: str | None = None
    no_motor_hint: str = (
        "give the actuated joints servos (motors='servo': fs.rollout(..., motors='servo'), "
        "build_general(..., motors='servo')); locked ones have no joint"
    )

    @property
    def task(self) -> tuple[str, ...]:
        return self.desc.task

    @property
    def motor_names(self) -> tuple[str, ...]:
        return tuple(f"{c}_{j}" for c, j in actuated_joint_names(self.desc))

    def solve(self, pose: TaskPose, near: TaskAssembly | None = None) -> TaskAssembly:
        return solve_task_pose(self.desc, pose, start=None if near is None else task_unknowns(self.desc, near))

    def pose_of(self, state: TaskAssembly) -> TaskPose:
        return state.pose

    def motors(self, state: TaskAssembly) -> np.ndarray:
        return actuated_coordinates(self.desc, state)

    def build(
        self, pose: TaskPose, state: TaskAssembly | None, options: ModelOptions, motors: str = "servo"
    ) -> BuiltModel:
        return build_general(self.desc, pose, options, assembly=state, motors=motors)

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        types = [j.type for c in self.desc.chains for j in c.joints if j.actuated]
        k, c = zip(*(self.desc.servos.gains(t) for t in types)) if types else ((), ())
        return np.array(k, float), np.array(c, float)


def mover_of(desc: Description | ImportedDescription | MoveMachine, *, need_motors: bool = True) -> MoveMachine:
    """The :class:`MoveMachine` of a described architecture or of an imported model
    (:class:`fpm_sim.sim.imported_move.ImportedMover`: it needs an ``[end_effector]``, and motors with
    ``need_motors``); a :class:`MoveMachine` as it is."""
    from fpm_sim.architecture.imported import ImportedDescription

    if isinstance(desc, Description):
        return DescribedMover(desc)
    if isinstance(desc, ImportedDescription):
        from fpm_sim.sim.imported_move import ImportedMover

        return ImportedMover(desc, need_motors=need_motors)
    return desc


def rollout_machine(
    mover: MoveMachine, state: Any, options: ModelOptions, output_step_s: float, motors: str = "locked"
) -> tuple[RolloutMachine, BuiltModel]:
    """The model of ``mover`` at ``state`` for a rollout (:func:`fpm_sim.sim.rollout.rollout`), its motors
    ``motors`` (``"locked"`` or ``"servo"``), the timestep (automatic unless ``options`` sets it) rounded down to
    divide ``output_step_s``; and its :class:`RolloutMachine` (:func:`machine_of`)."""
    pose = mover.pose_of(state)
    h = options.timestep_s or mover.build(pose, state, options, motors).timestep_s
    built = mover.build(pose, state, aligned_step(options, h, output_step_s), motors)
    return machine_of(built, mover, state), built


def motor_jacobian(mover: MoveMachine, state: Any) -> np.ndarray:
    """``d pose / d theta`` (task coordinates per motor coordinate) of the rigid kinematics at ``state``: the
    inverse of the pose solver's central differences (a pseudo-inverse when the counts differ), each solve started
    from ``state``."""
    x0 = pose_vector(mover.pose_of(state), mover.task)
    cols = []
    for k in range(len(mover.task)):
        dx = np.zeros_like(x0)
        dx[k] = FD_STEP
        hi = mover.motors(mover.solve(task_pose(x0 + dx, mover.task), near=state))
        lo = mover.motors(mover.solve(task_pose(x0 - dx, mover.task), near=state))
        cols.append((hi - lo) / (2 * FD_STEP))
    out: np.ndarray = np.linalg.pinv(np.column_stack(cols))
    return out


def rigid_jacobian(desc: Description, asm: TaskAssembly) -> np.ndarray:
    """``d pose / d theta`` of a described architecture at ``asm`` (:func:`motor_jacobian`)."""
    return motor_jacobian(DescribedMover(desc), asm)


def machine_of(built: BuiltModel, desc: Description | MoveMachine, asm: Any) -> RolloutMachine:
    """The :class:`RolloutMachine` of ``desc`` (a described architecture, or any :class:`MoveMachine`) built as
    ``built`` at the state ``asm``: its motors are servos where ``built`` has their joints with
    ``motors="servo"``."""
    mover = mover_of(desc)
    model = built.model
    names = mover.motor_names
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
    dofs = [int(model.jnt_dofadr[i]) for i in ids] if all(i >= 0 for i in ids) else []
    motor0 = mover.motors(asm)
    x0 = pose_vector(mover.pose_of(asm), mover.task)
    jac: list[np.ndarray] = []

    def rigid(ma: np.ndarray) -> np.ndarray:
        if not dofs:
            return x0
        if not jac:
            jac.append(motor_jacobian(mover, asm))
        out: np.ndarray = x0 + jac[0] @ (ma - motor0)
        return out

    servo = dofs and built.parameters.get("motors") == "servo"
    return RolloutMachine(
        coordinates=mover.task,
        motor_names=names,
        motor_dofs=dofs,
        motor0=motor0,
        servo_stiffness=mover.gains()[0] if servo else None,
        rigid_pose=rigid,
        no_motor_hint=mover.no_motor_hint,
        parameters={"motors": "servo" if servo else "locked", "actuated_joints": list(names)},
        ee_site=mover.ee_site,
    )


@dataclass(frozen=True)
class TaskPath:
    """A commanded end-effector path in task coordinates ``task``: a profile move from ``start`` to ``end``
    (arrays of the task coordinates, m and rad) in ``move_s`` with the profile ``kind``, or ``samples`` (rows
    ``t_s`` and the task coordinates; linear between rows, the last held). ``impulses`` shape the profile."""

    task: tuple[str, ...]
    start: np.ndarray
    end: np.ndarray
    move_s: float
    kind: str = "minimum-jerk"
    samples: np.ndarray | None = None
    impulses: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.array([1.0]), np.array([0.0])))

    @classmethod
    def from_csv(cls, path: str | Path, task: tuple[str, ...]) -> TaskPath:
        """The sampled path of a CSV ``t_s`` and the task columns (``x_mm, y_mm[, z_mm][, phi_rad]``)."""
        s = read_path_csv(path, task)
        return cls(task, s[0, 1:], s[-1, 1:], float(s[-1, 0]), samples=s)

    def check(self) -> None:
        check_profile(self.kind, self.move_s, self.samples)

    @property
    def duration_s(self) -> float:
        """When the command stops changing (s)."""
        return path_duration_s(self.move_s, self.samples, self.impulses)

    def poses(self, t_s: np.ndarray) -> np.ndarray:
        """``(n, len(task))`` commanded task coordinates at ``t_s``."""
        return path_poses(t_s, np.asarray(self.start, float), np.asarray(self.end, float), self)


def _joint_targets(mover: MoveMachine, path: TaskPath, start: Any, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The motor coordinates along the commanded path at ``t_s`` and their rates (module docstring)."""
    from scipy.interpolate import CubicSpline

    if path.samples is not None:
        grid = path.samples[:, 0]
    else:
        grid = np.linspace(0.0, path.duration_s, IK_POINTS)
    cmd = path.poses(grid)
    guess, theta = start, []
    for k, x in enumerate(cmd):
        try:
            guess = mover.solve(task_pose(x, mover.task), near=guess)
        except FpmSimError as e:
            raise MoveError(
                f"the commanded path leaves the workspace at t = {grid[k]:.4g} s: {e}",
                parameter="path",
                hint="choose start and end poses whose straight path stays inside the workspace",
            ) from None
        theta.append(mover.motors(guess))
    th = np.array(theta)
    th = th[0] + np.unwrap(th - th[0], axis=0)
    if path.samples is not None:
        ref = np.column_stack([np.interp(t_s, grid, th[:, i]) for i in range(th.shape[1])])
    else:
        ref = CubicSpline(grid, th, axis=0)(np.minimum(t_s, grid[-1]))
    step = float(t_s[1] - t_s[0]) if len(t_s) > 1 else 1.0
    return ref, np.gradient(ref, step, axis=0)


def _end_modes(mover: MoveMachine, end: TaskPose, opts: ModelOptions) -> tuple[float, float, float]:
    """Modal f1 at the end pose (servos on), the frequency and damping ratio of its dominant mode (the largest share
    of the end effector's translational static compliance: ``|C phi_r|^2 / omega_r^2``)."""
    from fpm_sim.rom.reduction import modal_system
    from fpm_sim.sim.rollout import end_effector_site_id

    system = modal_system(mover.build(end, None, opts))
    model = system.built.model
    data = mujoco.MjData(model)
    data.qpos[:] = system.qpos
    mujoco.mj_forward(model, data)
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacp, None, end_effector_site_id(model, mover.ee_site))
    rows = jacp[[k for k, c in enumerate("xyz") if c in mover.task]]
    share = np.sum((rows @ system.phi) ** 2, axis=0) / system.omega_rad_s**2
    r = int(np.argmax(share))
    w = float(system.omega_rad_s[r])
    return float(system.frequencies_hz[0]), w / (2 * math.pi), float(system.xi[r, r] / (2 * w))


def simulate_task_move(
    desc: Description | ImportedDescription | MoveMachine,
    path: TaskPath,
    *,
    settle_s: float = 0.3,
    options: ModelOptions | None = None,
    output_step_s: float = 1e-4,
    shaper_kind: str = "none",
    settle_tol_m: float = DEFAULT_SETTLE_TOL_M,
    integrator: str = DEFAULT_INTEGRATOR,
    band_hz: float | None = None,
    progress: bool = False,
) -> MoveResult:
    """Simulate the move ``path`` of ``desc`` on its full flexible model with servos (module docstring); the
    options as :func:`fpm_sim.sim.trajectory.simulate_move`. ``desc``: a described architecture, an imported model
    (:class:`fpm_sim.sim.imported_move.ImportedMover`: its ``[end_effector]`` and motors), or a
    :class:`MoveMachine`.

    Long because: the move's steps in order (the end pose's modes and shaper, the joint targets, the rollout, the
    torques and the residual vibration) and the result's fields.
    """
    check_move(path, shaper_kind, settle_s=settle_s, settle_tol_m=settle_tol_m, output_step_s=output_step_s)
    opts = options or ModelOptions(axial=False)
    mover = mover_of(desc)
    task = mover.task
    start, end = task_pose(path.start, task), task_pose(path.end, task)
    f1_end, f_dom, z_dom = _end_modes(mover, end, opts)
    impulses = shaper(shaper_kind, f_dom, z_dom)
    if path.samples is None:
        path = dataclasses.replace(path, impulses=impulses)
    asm0 = mover.solve(start)
    h_auto = opts.timestep_s or mover.build(start, asm0, opts).timestep_s
    built = mover.build(start, asm0, aligned_step(opts, h_auto, output_step_s))
    machine = machine_of(built, mover, asm0)
    n = round((path.duration_s + settle_s) / output_step_s)
    t = np.arange(n + 1) * output_step_s
    cmd = path.poses(t)
    ref, dref = _joint_targets(mover, path, asm0, t)
    gains = mover.gains()
    res, torque, wall = track_servos(
        built,
        machine,
        ref,
        dref,
        machine.motor0,
        (gains[0], gains[1]),
        duration_s=float(t[-1]),
        output_step_s=output_step_s,
        integrator=integrator,
        band_hz=band_hz,
        f1_hz=f1_end,
        progress=progress,
    )
    m = len(res.t_s)
    theta = res.motor_angles_rad
    jac_end = motor_jacobian(mover, mover.solve(end))
    deflection = res.ee_pose - (cmd[:m] + (theta - ref[:m]) @ jac_end.T)
    tr = [i for i, x in enumerate(task) if x != "phi"]
    err = res.ee_pose - cmd[:m]
    residual = residual_vibration(res.t_s, err[:, tr], path.duration_s, settle_tol_m, (f1_end, f_dom, z_dom))
    return MoveResult(
        t_s=res.t_s,
        command=cmd[:m],
        ee_pose=res.ee_pose,
        deflection=deflection,
        motor_ref_rad=ref[:m],
        motor_angles_rad=theta,
        motor_torque_nm=torque,
        residual=residual,
        move_end_s=path.duration_s,
        shaper=shaper_kind,
        impulses=impulses,
        stepping=res.stepping,
        wall_s=wall,
        coordinates=task,
        motor_names=machine.motor_names,
        parameters={
            **res.parameters,
            "start": dataclasses.asdict(start),
            "end": dataclasses.asdict(end),
            "profile": path.kind if path.samples is None else "csv",
            "move_s": path.move_s,
            "settle_s": settle_s,
        },
    )
