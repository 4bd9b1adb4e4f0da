"""Gymnasium ids: ``hbmp_bench/<Town>-<Task>-v0`` for the five towns and the four tasks and scenario types, plus
``hbmp_bench/Training-v0`` (random start and goal every reset; Town03 by default, as in the paper)."""

from __future__ import annotations

import gymnasium as gym

from hbmp_bench.maps import TOWNS
from hbmp_bench.scenarios import SCENARIO_TYPES, TASKS

ENTRY_POINT = "hbmp_bench.envs.behavior_env:BehaviorEnv"
RECORD_KEY = "hbmp_record"
"""The ``info`` key of the episode record at the end of an episode (the ego's, in every env of the
package). Not ``"episode"``: that key belongs to the ecosystem's episode statistics (Gymnasium's
``RecordEpisodeStatistics``, SB3's ``Monitor``), which would replace or trip over the record."""
TRAINING_ID = "hbmp_bench/Training-v0"


SCENARIO_SUITE = "scenarios"
"""The suite of the scenario types' env ids (``hbmp_bench/Town03-HardBrake-v0``)."""
SCENARIO_TOWNS: dict[str, tuple[str, ...]] = {
    "HardBrake": TOWNS,
    "CutIn": ("Town03", "Town04"),
    "PedestrianStepsOut": ("Town01", "Town02", "Town03", "Town04"),
    "UnprotectedLeft": TOWNS,
    "GiveWay": ("Town01", "Town02", "Town03", "Town05"),
    "RedLightRunner": ("Town01", "Town03", "Town04", "Town05"),
    "Merge": TOWNS,
    "LongRoute": TOWNS,
}
"""The built-in towns whose ``scenarios`` episode list holds each scenario type (a cut-in needs two lanes one
way, a pedestrian a sidewalk, a red-light runner a signalised crossing): those get an id. Known without
loading a network, so that ``import hbmp_bench`` stays light; a test checks it against the episode lists."""


def _tasks(town: str) -> tuple[str, ...]:
    return (*TASKS, *(t for t in SCENARIO_TYPES if town in SCENARIO_TOWNS.get(t, ())))


def env_ids() -> tuple[str, ...]:
    """Every registered id of the package: town × task, town × each scenario type it hosts, the training id."""
    return tuple(f"hbmp_bench/{town}-{task}-v0" for town in TOWNS for task in _tasks(town)) + (TRAINING_ID,)


def register_envs() -> None:
    """Register every id (idempotent)."""
    for town in TOWNS:
        for task in _tasks(town):
            env_id = f"hbmp_bench/{town}-{task}-v0"
            kwargs = {"town": town, "task": task, **({"suite": SCENARIO_SUITE} if task in SCENARIO_TYPES else {})}
            if env_id not in gym.registry:
                gym.register(env_id, entry_point=ENTRY_POINT, kwargs=kwargs, disable_env_checker=True)
    if TRAINING_ID not in gym.registry:
        gym.register(
            TRAINING_ID,
            entry_point=ENTRY_POINT,
            kwargs={"town": "Town03", "task": "Navigation", "random_goals": True, "suite": "hbmp"},
            disable_env_checker=True,
        )


def make(env_id: str, **kwargs) -> gym.Env:
    """``gymnasium.make`` that answers an unknown id with the list of valid ones."""
    from hbmp_bench.errors import UnknownNameError

    if env_id not in env_ids():
        raise UnknownNameError("env id", env_id, env_ids())
    return gym.make(env_id, **kwargs)
