"""A headless ``dm_control`` environment: end-effector regulation of the flexible manipulator.

:func:`regulation_env` returns a :class:`dm_control.rl.control.Environment` (a ``dm_env.Environment``)
so that dm_env agents and controllers can drive the full flexible manipulator.

Model
    The manipulator of the given configuration, built at ``pose`` with servo motors
    (``motors.mode = "servo"``; the study's locked motors have no joint to actuate). The servo is a
    spring-damper about the assembled motor angle (:data:`DEFAULT_SERVO_STIFFNESS_NM_PER_RAD`,
    :data:`DEFAULT_SERVO_DAMPING_NMS_PER_RAD` unless the configuration is already in servo mode); one
    MuJoCo ``motor`` actuator per motor hinge adds the agent's torque on top (gear 1, ``ctrlrange``
    +-``max_torque_nm``). The MJCF is the generated model plus those actuators and the sensors below. The
    physics runs on MuJoCo's ``discrete`` integrator at the step of :mod:`fpm_sim.sim.stepping` (band 5 x f1
    unless ``band_hz`` is given) rounded down to divide the control step (``env.parameters["stepping"]`` has
    the step and its numerical damping and period error in the band); ``integrator="explicit"``: the automatic
    explicit-spring step rounded down the same way.

Actions
    ``(3,)`` motor torques (N m), bounded by ``max_torque_nm``.

Observations (MuJoCo sensors, SI units)
    ``ee_disp`` (3,): end-effector ``x, y`` (m) and rotation (rad) relative to the target (the static
    equilibrium under gravity at ``pose``); ``ee_vel`` (3,): its linear x, y (m/s) and angular z
    (rad/s) velocity; ``motor_angle`` (3,) (rad, from the assembled angle) and ``motor_velocity``
    (3,) (rad/s); ``link_accel`` (3,): accelerometer reading (m/s^2) at the middle of each distal
    link along its in-plane normal (the site frame's y axis; gravity, along z, enters only through the
    small static twist of the link).

Episodes (the task: regulation under link vibration)
    Each episode starts at rest in the statically deflected shape under a random end-effector force
    of magnitude up to ``disturbance_force_n`` (linear static response ``q_eq + G B_q F`` from
    :mod:`fpm_sim.rom.reduction`), released at ``t = 0``: the links vibrate and the agent must bring the
    end effector back to the target. Reward per step in [0, 1]: ``exp(-(|e| / scale)^2)`` with ``e``
    the planar end-effector position error and ``scale = reward_scale_m``. No early termination; an
    episode ends at ``time_limit_s`` with discount 1.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from fpm_sim.config import Manipulator, default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.rom.reduction import END_EFFECTOR_SITE, accel_site_names, modal_system
from fpm_sim.sim.rollout import aligned_options
from fpm_sim.sim.stepping import DEFAULT_INTEGRATOR, choose_stepping
from fpm_sim.sim.trajectory import (
    DEFAULT_SERVO_DAMPING_NMS_PER_RAD,
    DEFAULT_SERVO_STIFFNESS_NM_PER_RAD,
    with_servo_motors,
)

if TYPE_CHECKING:
    from dm_control import mujoco as dm_mujoco
    from dm_control.rl import control
    from dm_env import specs

__all__ = [
    "DEFAULT_SERVO_DAMPING_NMS_PER_RAD",
    "DEFAULT_SERVO_STIFFNESS_NM_PER_RAD",
    "OBSERVATION_KEYS",
    "FlexibleRegulation",  # noqa: F822  (defined on first use, module __getattr__)
    "regulation_env",
]

HOME_POSE = Pose(0.0, 0.0, 0.0)
OBSERVATION_KEYS = ("ee_disp", "ee_vel", "motor_angle", "motor_velocity", "link_accel")


def _env_xml(xml: str, accel_sites: list[str], max_torque_nm: float) -> str:
    spec = mujoco.MjSpec.from_string(xml)
    for i in range(3):
        act = spec.add_actuator(name=f"motor_{i}_torque", target=f"motor_{i}")
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.gainprm[0] = 1.0
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-max_torque_nm, max_torque_nm]
    obj = mujoco.mjtObj.mjOBJ_SITE
    spec.add_sensor(name="ee_pos", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=obj, objname=END_EFFECTOR_SITE)
    spec.add_sensor(name="ee_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=obj, objname=END_EFFECTOR_SITE)
    spec.add_sensor(name="ee_linvel", type=mujoco.mjtSensor.mjSENS_FRAMELINVEL, objtype=obj, objname=END_EFFECTOR_SITE)
    spec.add_sensor(name="ee_angvel", type=mujoco.mjtSensor.mjSENS_FRAMEANGVEL, objtype=obj, objname=END_EFFECTOR_SITE)
    for i in range(3):
        spec.add_sensor(
            name=f"motor_{i}_pos",
            type=mujoco.mjtSensor.mjSENS_JOINTPOS,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            objname=f"motor_{i}",
        )
        spec.add_sensor(
            name=f"motor_{i}_vel",
            type=mujoco.mjtSensor.mjSENS_JOINTVEL,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            objname=f"motor_{i}",
        )
    for i, s in enumerate(accel_sites):
        spec.add_sensor(name=f"accel_{i}", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objtype=obj, objname=s)
    return spec.to_xml()


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _headless_dm_control() -> tuple[Any, Any, Any]:
    """Import dm_control headless: ``MUJOCO_GL=disable`` unless the user chose a backend (egl, osmesa, glfw).

    Done when an environment is created, not on import; only effective if dm_control was not imported before.
    """
    if not os.environ.get("MUJOCO_GL"):
        os.environ["MUJOCO_GL"] = "disable"
    from dm_control import mujoco as dm_mujoco
    from dm_control.rl import control
    from dm_env import specs

    return dm_mujoco, control, specs


@functools.cache
def _task_class() -> type:
    """:class:`FlexibleRegulation`, defined on first use (it derives from dm_control's ``Task``).

    Long because: it holds the class body of ``FlexibleRegulation`` (its short methods), defined inside a function
    so that dm_control is imported only when the environment is first made.
    """
    _, rl_control, dm_specs = _headless_dm_control()
    task_base: Any = rl_control.Task  # dm_control ships no types: the base class is Any to mypy

    class FlexibleRegulation(task_base):
        """End-effector regulation under link vibration (see module docstring).

        Parameters
        ----------
        q_eq
            Static equilibrium (target state), generalised coordinates.
        flex_b
            ``G B_q`` restricted to the end-effector forces ``(nv, 2)``: static shape per unit force.
        max_torque_nm
            Action bound (N m).
        disturbance_force_n
            Largest initial static force (N).
        reward_scale_m
            Error at which the reward falls to ``1/e`` (m).
        random
            Seed or ``np.random.RandomState``.
        """

        def __init__(
            self,
            *,
            q_eq: np.ndarray,
            flex_b: np.ndarray,
            max_torque_nm: float,
            disturbance_force_n: float,
            reward_scale_m: float,
            random: int | np.random.RandomState | None = None,
        ) -> None:
            self._q_eq = np.asarray(q_eq, float)
            self._flex_b = np.asarray(flex_b, float)
            self._max_torque = float(max_torque_nm)
            self._dist_force = float(disturbance_force_n)
            self._scale = float(reward_scale_m)
            self._random = random if isinstance(random, np.random.RandomState) else np.random.RandomState(random)
            self._target: np.ndarray | None = None
            self.initial_force_n = np.zeros(2)

        @property
        def random(self) -> np.random.RandomState:
            return self._random

        def initialize_episode(self, physics: dm_mujoco.Physics) -> None:
            if self._target is None:
                self.set_target(physics)
            mag = self._dist_force * math.sqrt(self._random.uniform())
            ang = self._random.uniform(0.0, 2.0 * math.pi)
            self.initial_force_n = mag * np.array([math.cos(ang), math.sin(ang)])
            physics.data.qpos[:] = self._q_eq + self._flex_b @ self.initial_force_n
            physics.data.qvel[:] = 0.0
            physics.data.ctrl[:] = 0.0

        def set_target(self, physics: dm_mujoco.Physics) -> None:
            """Put ``physics`` at rest at the equilibrium and take its end-effector pose as the target."""
            with physics.reset_context():
                physics.data.qpos[:] = self._q_eq
                physics.data.qvel[:] = 0.0
            self._target = self._ee(physics)

        def _ee(self, physics: dm_mujoco.Physics) -> np.ndarray:
            sd = physics.named.data.sensordata
            pos = np.asarray(sd["ee_pos"])
            return np.array([pos[0], pos[1], _yaw(np.asarray(sd["ee_quat"]))])

        def action_spec(self, physics: dm_mujoco.Physics) -> specs.BoundedArray:
            return dm_specs.BoundedArray(
                shape=(3,),
                dtype=np.float64,
                minimum=-self._max_torque,
                maximum=self._max_torque,
                name="motor_torque_nm",
            )

        def before_step(self, action: np.ndarray, physics: dm_mujoco.Physics) -> None:
            physics.set_control(np.clip(np.asarray(action, float), -self._max_torque, self._max_torque))

        def get_observation(self, physics: dm_mujoco.Physics) -> dict[str, np.ndarray]:
            sd = physics.named.data.sensordata
            assert self._target is not None
            err = self._ee(physics) - self._target
            err[2] = (err[2] + math.pi) % (2 * math.pi) - math.pi
            lin, ang = np.asarray(sd["ee_linvel"]), np.asarray(sd["ee_angvel"])
            return {
                "ee_disp": err,
                "ee_vel": np.array([lin[0], lin[1], ang[2]]),
                "motor_angle": np.array([float(sd[f"motor_{i}_pos"][0]) for i in range(3)]),
                "motor_velocity": np.array([float(sd[f"motor_{i}_vel"][0]) for i in range(3)]),
                "link_accel": np.array([float(sd[f"accel_{i}"][1]) for i in range(3)]),
            }

        def get_reward(self, physics: dm_mujoco.Physics) -> float:
            assert self._target is not None
            e = self._ee(physics)[:2] - self._target[:2]
            return float(math.exp(-float(e @ e) / self._scale**2))

    return FlexibleRegulation


def __getattr__(name: str) -> Any:
    if name == "FlexibleRegulation":
        return _task_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def regulation_env(
    manip: Manipulator | None = None,
    *,
    pose: Pose = HOME_POSE,
    thickness_m: float | None = 0.005,
    segments: int | None = None,
    axial: bool = False,
    control_timestep_s: float = 1e-3,
    time_limit_s: float = 0.5,
    max_torque_nm: float = 5.0,
    disturbance_force_n: float = 10.0,
    reward_scale_m: float = 1e-3,
    seed: int | None = None,
    integrator: str = DEFAULT_INTEGRATOR,
    band_hz: float | None = None,
) -> control.Environment:
    """The regulation environment (see module docstring).

    Parameters
    ----------
    manip
        Manipulator (default: the embedded one); switched to servo motors if locked.
    pose
        Target pose (m, m, rad).
    thickness_m
        Link thickness override (default 5 mm: the study's flexible manipulator); ``None`` keeps the
        configuration's.
    segments, axial
        Link discretisation; ``None``: the standard fidelity every command uses (12 segments). Every control
        step costs ``control_timestep_s / h`` physics steps. Measured real-time factor (simulated over CPU
        seconds, 5 mm links, no action, 0.1 ms discrete steps, shared 2-core reference machine, 2 Dec 2026):
        0.15 at 12 segments, 1.3 at 4 (200 control steps timed; ``docs/time_domain.md``).
    control_timestep_s
        Agent period (s); the physics timestep is rounded down to divide it.
    time_limit_s
        Episode length (s).
    max_torque_nm, disturbance_force_n, reward_scale_m
        Action bound (N m), largest initial static force (N), reward length scale (m).
    seed
        Seed of the task's random initial disturbances.
    integrator, band_hz
        ``"discrete"`` (default) at the step of the band ``band_hz`` (Hz; default 5 x f1), or ``"explicit"``
        (:func:`fpm_sim.sim.stepping.choose_stepping`).

    Long because: the signature and the documentation of its options are half of it; the body (model, physics,
    task, environment) is about 50 lines.
    """
    manip = with_servo_motors(manip or default_config())
    if thickness_m is not None:
        manip = manip.with_section(thickness_m=thickness_m)
    for name, v in (
        ("control_timestep_s", control_timestep_s),
        ("time_limit_s", time_limit_s),
        ("max_torque_nm", max_torque_nm),
        ("reward_scale_m", reward_scale_m),
    ):
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"{name} must be positive and finite, got {v!r}")
    if not disturbance_force_n >= 0:
        raise ValueError(f"disturbance_force_n must be >= 0, got {disturbance_force_n!r}")
    dm_mujoco, control, _ = _headless_dm_control()
    opts = aligned_options(manip, pose, ModelOptions(segments=segments, axial=axial), control_timestep_s)
    built = build_manipulator(manip, pose, opts)
    system = modal_system(built)
    stepping = choose_stepping(
        built,
        integrator=integrator,
        band_hz=band_hz,
        divides_s=control_timestep_s,
        f1_hz=float(system.frequencies_hz[0]),
    )
    accel_sites = accel_site_names(built, 0.5)
    physics = dm_mujoco.Physics.from_xml_string(_env_xml(built.to_xml(), accel_sites, max_torque_nm))
    # the MJCF prints the timestep with 6 significant digits; set it exactly (control step multiple)
    physics.model.opt.timestep = stepping.step_s
    if stepping.integrator == "discrete":
        physics.model.opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    if physics.model.nv != built.model.nv:  # pragma: no cover - a guard on the MJCF round trip
        raise RuntimeError("the environment's MJCF does not reproduce the generated model")
    task = _task_class()(
        q_eq=system.qpos,
        flex_b=system.flexibility @ system.b_q[:, :2],
        max_torque_nm=max_torque_nm,
        disturbance_force_n=disturbance_force_n,
        reward_scale_m=reward_scale_m,
        random=seed,
    )
    task.set_target(physics)
    env = control.Environment(physics, task, time_limit=time_limit_s, control_timestep=control_timestep_s)
    env.parameters = {
        **built.parameters,
        "motors": dataclasses.asdict(manip.motors),
        "control_timestep_s": control_timestep_s,
        "time_limit_s": time_limit_s,
        "accel_sites": accel_sites,
        "stepping": stepping.to_dict(),
    }
    return env
