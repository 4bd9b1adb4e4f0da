"""Environments: the PettingZoo traffic env (the core, the one front door: the frozen configs or their
keyword form :func:`env_configs`), the gymnasium behavior and control envs as views of it (:class:`EgoView`).

The registration helpers (``env_ids``, ``make``, ``register_envs``, ``TRAINING_ID``) load with the
package; the env classes and their constants load on first access (they import SUMO and the
planner), so that ``import hbmp_bench`` registers the ids without them.
"""

from hbmp_bench._lazy import lazy_exports
from hbmp_bench.envs.registration import TRAINING_ID, env_ids, make, register_envs

__all__ = ["BEHAVIORS", "ROAD_FEATURES", "TRAINING_ID", "BehaviorEnv", "ControlledVehicle", "DrivingWorld", "EgoView",
           "ObservationConfig", "ScenarioConfig", "WorldConfig", "env_configs", "env_ids", "make", "register_envs"]

__getattr__, __dir__ = lazy_exports(__name__, {
    ".behavior_env": ("BehaviorEnv",),
    ".config": ("ScenarioConfig", "WorldConfig", "env_configs"),
    ".ego_view": ("EgoView",),
    ".observation": ("ROAD_FEATURES", "ObservationConfig"),
    ".vehicle": ("ControlledVehicle",),
    ".world": ("DrivingWorld",),
    "hbmp_bench.planning.behaviors": ("BEHAVIORS",),
})
