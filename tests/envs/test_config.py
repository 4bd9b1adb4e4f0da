"""The frozen scenario and world configs: validated in one place, at construction."""

import dataclasses

import numpy as np
import pytest

from hbmp_bench.envs.config import ScenarioConfig, WorldConfig
from hbmp_bench.errors import UnknownNameError


@pytest.mark.parametrize("field, value", [("town", "Town09"), ("task", "Drift"), ("suite", "nope"), ("density", "jam")])
def test_unknown_names_list_the_valid_ones(field, value):
    with pytest.raises(UnknownNameError, match="valid:"):
        ScenarioConfig(**{field: value})


def test_episode_selection():
    with pytest.raises(ValueError, match="episode_index"):
        ScenarioConfig(town="Town01", task="Straight", episode_index=10_000)
    with pytest.raises(ValueError, match="exclude"):
        ScenarioConfig(episode_index=0, random_goals=True)
    config = ScenarioConfig(town="Town01", task="Straight", density="regular")
    assert all(e.traffic == config.traffic for e in config.episodes)
    assert config.pick(np.random.default_rng(0), 2) == config.episodes[2]
    drawn = config.pick(np.random.default_rng(5))
    assert drawn == config.episodes[int(np.random.default_rng(5).integers(len(config.episodes)))]
    fresh = ScenarioConfig(town="Town01", task="Straight", random_goals=True).pick(np.random.default_rng(1))
    assert fresh.town == "Town01" and fresh.route_length_m > 0


def test_configs_are_frozen_and_checked():
    config = ScenarioConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.town = "Town02"
    with pytest.raises(ValueError, match="ego_driver"):
        WorldConfig(ego_driver="joystick")
    with pytest.raises(ValueError, match="bicycle model"):
        WorldConfig(fidelity="event", ego_driver="control")
    with pytest.raises(ValueError, match="background_fidelity"):
        WorldConfig(background_fidelity="control")


def test_scene_dict_leaves_out_what_a_vehicle_does_not_have():
    from hbmp_bench.envs.scene import Scene

    base = dict(speed_mps=3.0, speed_limit_mps=13.9, in_junction=False, route_lane_offset=0,
                stop_distance_m=20.0, lane_pos_m=5.0, light="r", turn_ahead="s")
    assert Scene(**base).to_dict() == base
    ego = Scene(**base, goal_distance_m=80.0, route_lane_light=(), pedestrians=())
    assert ego.to_dict() == {**base, "goal_distance_m": 80.0, "route_lane_light": (), "pedestrians": ()}
    with pytest.raises(TypeError):
        Scene(**base, speed=1.0)  # a misspelt field fails where the scene is built


def test_privileged_is_a_bool_and_off_by_default():
    assert WorldConfig().privileged is False and WorldConfig(privileged=True).privileged is True
    with pytest.raises(ValueError, match="privileged must be True or False"):
        WorldConfig(privileged=1)
