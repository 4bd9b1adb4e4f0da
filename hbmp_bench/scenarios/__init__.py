"""Scenario registry: tasks, suites and deterministic episode lists (no SUMO at import)."""

from hbmp_bench.scenarios.spec import TASK_LABELS, TASKS, Episode, Suite, Traffic
from hbmp_bench.scenarios.scenario_types import SCENARIO_TYPES, all_tasks
from hbmp_bench.scenarios.suites import (
    SUITES,
    all_episodes,
    basis_town,
    check_salt,
    check_task,
    check_town,
    get_suite,
    held_episodes,
    register_suite,
    episode_entropy,
    road_network,
    sample_episode,
    selection_size,
    suite_episodes,
    traffic_for,
    with_agents,
)

__all__ = [
    "SCENARIO_TYPES",
    "SUITES",
    "TASKS",
    "TASK_LABELS",
    "Episode",
    "Suite",
    "Traffic",
    "all_episodes",
    "all_tasks",
    "basis_town",
    "check_salt",
    "check_task",
    "check_town",
    "get_suite",
    "held_episodes",
    "register_suite",
    "episode_entropy",
    "road_network",
    "sample_episode",
    "selection_size",
    "suite_episodes",
    "traffic_for",
    "with_agents",
]
