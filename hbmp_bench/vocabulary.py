"""The benchmark's shared names: behaviors, fidelities, reward modes and infraction kinds.

Every room takes these names from here (the env, the detectors, the records, the reports, training
and the boards), so a new kind is added in one place and a typo is an ``ImportError``, not a silent
zero column. The module imports nothing; it is the floor below every room.

A new infraction kind is added to :data:`INFRACTION_KINDS` (and :data:`COLLISION_KINDS` or
:data:`VIOLATION_KINDS`), then given its detector in :mod:`hbmp_bench.metrics.detectors`, its
count in the episode record (:class:`~hbmp_bench.metrics.records.EpisodeRecord`) and, when it is
paid, its terminal reward (:data:`~hbmp_bench.metrics.episode.TERMINAL_REWARD`).
"""

from __future__ import annotations

BEHAVIORS: tuple[str, ...] = ("speed_up", "speed_down", "change_left", "change_right", "keep")
"""The behaviors' names in the paper's order: behavior ``b`` of ``Discrete(NUM_BEHAVIORS)`` is
``BEHAVIORS[b]`` (:class:`~hbmp_bench.planning.behaviors.Behavior` has the same order)."""

NUM_BEHAVIORS: int = len(BEHAVIORS)
"""Size of the behavior action space and of ``info["action_mask"]`` (5)."""

FIDELITIES: tuple[str, ...] = ("event", "continuous")
"""How the ego executes a behavior: ``event`` through SUMO's own lane change and speed commands, one
decision per behavior (the paper's SUMO stage); ``continuous`` through the motion planner, tracking
and vehicle model at 10 Hz (the paper's CARLA stage, the envs' default)."""

DEFAULT_FIDELITY: str = "continuous"
"""The fidelity an env runs when none is asked for."""

REWARD_MODES: tuple[str, ...] = ("dense", "sparse")
"""The env's behavior reward: ``dense`` r_k + r_T (HBMP), ``sparse`` r_T only (HBMP-S)."""

ENV_REWARDS: tuple[str, ...] = (*REWARD_MODES, "carla")
"""The env's ``reward`` option: a behavior reward of :data:`REWARD_MODES`, or ``carla``, CARLA's reinforcement
learning baseline reward paid every step (:data:`~hbmp_bench.metrics.episode.CARLA_RL_REWARD`)."""

TRAINING_REWARD_MODES: tuple[str, ...] = (*REWARD_MODES, "env")
"""What a training run learns from: a behavior reward of :data:`REWARD_MODES` (taken from the env's
``info["reward_components"]``), or ``env``, the reward the env returns (the flat baseline's control
env)."""

COLLISION_KINDS: tuple[str, ...] = ("collision_vehicle", "collision_pedestrian", "collision_other")
"""Collision counts of an episode record (``collision_other``: an obstacle that is neither)."""

VIOLATION_KINDS: tuple[str, ...] = ("wrong_lane", "off_road", "red_light")
"""Traffic-rule violation counts of an episode record."""

INFRACTION_KINDS: tuple[str, ...] = (*COLLISION_KINDS, *VIOLATION_KINDS)
"""Every infraction count of an episode record, in the record's column order."""

DETECTED_KINDS: tuple[str, ...] = tuple(k for k in INFRACTION_KINDS if k != "collision_other")
"""The kinds the SUMO detectors report each simulation step (``collision_other``, an obstacle, comes
only from the highway-env transfer env)."""

__all__ = ["BEHAVIORS", "COLLISION_KINDS", "DEFAULT_FIDELITY", "DETECTED_KINDS", "ENV_REWARDS", "FIDELITIES", "INFRACTION_KINDS",
           "NUM_BEHAVIORS", "REWARD_MODES", "TRAINING_REWARD_MODES", "VIOLATION_KINDS"]
