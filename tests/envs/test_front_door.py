"""One front door: every env takes the same frozen configs (or their one keyword form, with one set of
defaults), an action is validated once by one rule, and the control driver takes its vector
through the same door as a behavior."""

import dataclasses

import numpy as np
import pytest
from gymnasium import spaces

from hbmp_bench.envs import BehaviorEnv, ScenarioConfig, WorldConfig, traffic_v0
from hbmp_bench.envs.actions import CONTROL_SPACE, check_action
from hbmp_bench.envs.config import env_configs
from hbmp_bench.envs.control_env import ControlEnv


def test_every_door_has_the_configs_defaults():
    scenario, world = env_configs()
    assert (scenario, world) == (ScenarioConfig(), WorldConfig())
    for env in (BehaviorEnv(), traffic_v0.parallel_env(), traffic_v0.ego_env()):
        view = getattr(env, "parallel", env)
        assert (view.scenario, view.config) == (scenario, world)
    assert ControlEnv().config == dataclasses.replace(world, ego_driver="control")


def test_configs_or_keywords_never_both_and_no_typo_is_swallowed():
    scenario, world = env_configs(town="Town02", task="Straight", fidelity="event")
    env = BehaviorEnv(scenario=scenario, world=world)
    assert env.town == "Town02" and env.config.fidelity == "event"
    with pytest.raises(TypeError, match="not both"):
        BehaviorEnv(scenario=scenario, town="Town01")
    with pytest.raises(TypeError, match="fidelty"):
        BehaviorEnv(fidelty="event")
    with pytest.raises(ValueError, match="ControlEnv"):
        BehaviorEnv(ego_driver="control")
    with pytest.raises(ValueError, match="contradict"):
        BehaviorEnv(observation="vehicle_centric", observation_config=world.observation)


def test_the_control_ego_acts_with_a_vector_at_the_door():
    env = traffic_v0.parallel_env(town="Town01", task="Straight", controlled="none", ego_driver="control")
    assert env.action_space("ego") == CONTROL_SPACE
    assert env.observation_space("ego")["road"].shape == (12,)
    assert ControlEnv(town="Town01", task="Straight").action_space == env.action_space("ego")


def test_one_rule_for_an_action():
    behaviors = spaces.Discrete(5)
    assert check_action(behaviors, np.int64(3)) == 3 and type(check_action(behaviors, np.array(2))) is int
    for bad in (5, -1, 2.5, "left", True, np.True_, np.array(True), np.array([1])):
        with pytest.raises(ValueError, match=r"must be an int in \[0, 5\) \(speed_up"):
            check_action(behaviors, bad)
    got = check_action(CONTROL_SPACE, [[0.5, 2.0]])
    assert got.dtype == np.float32 and got.shape == (2,) and got[1] == 2.0  # the driver clips
    for bad in ([0.1, 0.2, 0.3], [np.nan, 0.0], "fast"):
        with pytest.raises(ValueError, match=r"2 finite numbers \[accel, steer\] in \[-1, 1\]"):
            check_action(CONTROL_SPACE, bad)
    with pytest.raises(ValueError, match="accel, steer"):
        check_action(CONTROL_SPACE, [0.5, 2.0], strict=True)  # the evaluator: an element of the space
