"""The dm_control regulation environment: dm_env's own conformance harness, plus the task semantics."""

import dm_env
import numpy as np
import pytest
from absl.testing import absltest
from dm_env import test_utils

from fpm_sim.sim.dm_env import OBSERVATION_KEYS, regulation_env

# 10 ms episodes (10 control steps) so that the harness's 20-action sequences cross episode ends
_ENV_KW = dict(segments=3, time_limit_s=0.01, seed=1)


class RegulationEnvConformance(test_utils.EnvironmentTestMixin, absltest.TestCase):
    """dm_env.test_utils.EnvironmentTestMixin: reset/step types, specs of every observation, reward
    and discount, FIRST only after LAST."""

    def make_object_under_test(self):
        return regulation_env(**_ENV_KW)


@pytest.fixture(scope="module")
def env():
    return regulation_env(segments=3, time_limit_s=0.02, seed=3)


def test_specs(env):
    spec = env.action_spec()
    assert spec.shape == (3,)
    assert np.all(spec.minimum == -5.0)
    assert np.all(spec.maximum == 5.0)
    assert tuple(env.observation_spec()) == OBSERVATION_KEYS
    assert env.parameters["motors"]["mode"] == "servo"
    # the physics step divides the control step exactly
    n = env.control_timestep() / env.physics.timestep()
    assert abs(n - round(n)) < 1e-6
    # on the discrete integrator at the band's step (default 5 x f1; numerical damping <= 2 % at its top)
    import mujoco

    st = env.parameters["stepping"]
    assert env.physics.model.opt.integrator == mujoco.mjtIntegrator.mjINT_DISCRETE
    assert st["integrator"] == "discrete"
    assert env.physics.timestep() == pytest.approx(st["step_s"], rel=1e-12)
    assert st["numerical_damping_at_band_top"] <= 0.02


def test_episode_starts_deflected_and_vibrates(env):
    ts = env.reset()
    f = env.task.initial_force_n
    obs = ts.observation
    # released from the static shape under the random force: the end effector starts displaced
    # along that force (compliance ~1e-4 m/N at 5 mm links) and at rest
    assert np.linalg.norm(f) > 0
    assert float(obs["ee_disp"][:2] @ f) > 0
    assert np.allclose(obs["ee_vel"], 0.0, atol=1e-9)
    steps = 0
    while True:
        ts = env.step(np.zeros(3))
        steps += 1
        assert 0.0 <= ts.reward <= 1.0
        if ts.last():
            break
    assert steps == 20
    assert ts.discount == 1.0
    # links vibrate: velocities and accelerometer readings appear
    assert np.abs(ts.observation["ee_vel"]).max() > 1e-4
    assert np.abs(ts.observation["link_accel"]).max() > 1e-2
    assert env.step(np.zeros(3)).step_type == dm_env.StepType.FIRST


def test_seeded_resets_are_reproducible():
    a = regulation_env(segments=3, time_limit_s=0.005, seed=7)
    b = regulation_env(segments=3, time_limit_s=0.005, seed=7)
    oa, ob = a.reset().observation, b.reset().observation
    for k in OBSERVATION_KEYS:
        assert np.array_equal(oa[k], ob[k])


def test_actions_drive_the_motors(env):
    """A positive torque on motor 0 turns it positively relative to the unforced run from the same
    initial state (the servo spring alone cannot)."""

    def run(action):
        env.task._random = np.random.RandomState(11)  # same initial disturbance for both runs
        env.reset()
        for _ in range(5):
            ts = env.step(action)
        return ts.observation["motor_angle"][0]

    assert run(np.array([2.0, 0.0, 0.0])) - run(np.zeros(3)) > 1e-4


def test_bad_options():
    with pytest.raises(ValueError, match="time_limit_s"):
        regulation_env(segments=3, time_limit_s=0.0)
