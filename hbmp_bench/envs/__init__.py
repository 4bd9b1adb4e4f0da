"""Environments: the gymnasium behavior env over a shared driving world."""

from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.envs.observation import ROAD_FEATURES, ObservationConfig
from hbmp_bench.envs.registration import TRAINING_ID, env_ids, make, register_envs
from hbmp_bench.envs.world import BEHAVIORS, DrivingWorld, WorldConfig

__all__ = ["BEHAVIORS", "ROAD_FEATURES", "TRAINING_ID", "BehaviorEnv", "DrivingWorld", "ObservationConfig",
           "WorldConfig", "env_ids", "make", "register_envs"]
