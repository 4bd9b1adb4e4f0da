"""How far a chain of speed_down behaviors takes to stop the ego, measured in a SUMO episode.

A lawful driver stops for a light that turns yellow when it can: from speed ``v`` [m/s], reacting
within ``REACTION_S`` and braking at ``LAWFUL_DECEL``, it needs at most::

    lawful_stopping_distance(v) = v * REACTION_S + v^2 / (2 * LAWFUL_DECEL)     [m]

(46 m from 50 km/h). An agent that stops in a longer distance is forced through some reds (at
13.9 m/s a 3 s yellow covers 42 m). For the behavior layer the reaction time is the decision
latency: a need that arises just after a decision is seen at the next one.

:func:`measure_stop` drives the ego of a real episode on an empty road: ``speed_up`` until it
drives at the lane's speed limit, one ``keep`` decision there (the cruise decision), then
``speed_down`` at every decision until standstill. The :class:`StopTrace` holds every
simulation step and two distances: from the first ``speed_down`` decision, and from the start
of the cruise decision before it (the worst case of the decision latency: a yellow that
appears just after the ego chose to cruise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.world import EGO_ID, DrivingWorld
from hbmp_bench.planning.behaviors import Behavior
from hbmp_bench.scenarios import Episode, suite_episodes

__all__ = ["LAWFUL_DECEL", "REACTION_S", "STANDSTILL_MPS", "StopTrace", "lawful_stopping_distance",
           "measure_stop", "straight_episode"]

REACTION_S = 1.0
"""Reaction time of the lawful stopping distance [s]."""
LAWFUL_DECEL = 3.0
"""Deceleration of the lawful stopping distance [m/s²] (a comfortable stop)."""
STANDSTILL_MPS = 0.01
"""Below this speed the ego stands [m/s]."""
AT_LIMIT_MPS = 0.1
"""The ego drives at the limit when its speed is this close to it [m/s]."""


def lawful_stopping_distance(v: float, reaction_s: float = REACTION_S, decel: float = LAWFUL_DECEL) -> float:
    """``v * reaction_s + v^2 / (2 decel)`` [m] from speed ``v`` [m/s]."""
    if not (np.isfinite(v) and v >= 0):
        raise ValueError(f"v must be finite and >= 0 [m/s], got {v!r}")
    if not (reaction_s >= 0 and decel > 0):
        raise ValueError(f"reaction_s must be >= 0 [s] and decel > 0 [m/s²], got {reaction_s!r}, {decel!r}")
    return float(v * reaction_s + v * v / (2.0 * decel))


@dataclass(frozen=True, eq=False)
class StopTrace:
    """One measured stop: every simulation step of the episode (N of them, plus the start).

    Attributes:
        town / fidelity: where and how it was driven.
        speed_limit: the lane's speed limit when braking began [m/s].
        time_s: (N,) simulation time [s].
        xy: (N, 2) ego footprint centre [m].
        speed: (N,) ego speed [m/s].
        cruise_start: index of the sample at the start of the cruise decision.
        brake_start: index of the sample at the first ``speed_down`` decision.
        speed_down_durations: duration of each ``speed_down`` behavior [s], in order.
    """

    town: str
    fidelity: str
    speed_limit: float
    time_s: np.ndarray
    xy: np.ndarray
    speed: np.ndarray
    cruise_start: int
    brake_start: int
    speed_down_durations: tuple[float, ...]

    @property
    def travelled_m(self) -> np.ndarray:
        """(N,) distance driven since the first sample [m] (sum of the step chords)."""
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.xy, axis=0).T))])

    @property
    def v_start(self) -> float:
        """Speed at the first ``speed_down`` decision [m/s]."""
        return float(self.speed[self.brake_start])

    @property
    def distance_m(self) -> float:
        """Distance from the first ``speed_down`` decision to standstill [m]."""
        d = self.travelled_m
        return float(d[-1] - d[self.brake_start])

    @property
    def distance_with_latency_m(self) -> float:
        """Distance from the start of the cruise decision before it to standstill [m]."""
        d = self.travelled_m
        return float(d[-1] - d[self.cruise_start])

    @property
    def latency_s(self) -> float:
        """Duration of the cruise decision: the worst-case decision latency [s]."""
        return float(self.time_s[self.brake_start] - self.time_s[self.cruise_start])

    @property
    def bound_m(self) -> float:
        """:func:`lawful_stopping_distance` from :attr:`v_start` [m]."""
        return lawful_stopping_distance(self.v_start)

    def summary(self) -> dict[str, float | int | str]:
        """The numbers of the stop, rounded for a table."""
        return {"town": self.town, "fidelity": self.fidelity, "speed_limit_mps": round(self.speed_limit, 2),
                "v_start_mps": round(self.v_start, 2), "distance_m": round(self.distance_m, 2),
                "distance_with_latency_m": round(self.distance_with_latency_m, 2),
                "latency_s": round(self.latency_s, 2), "bound_m": round(self.bound_m, 2),
                "speed_down_decisions": len(self.speed_down_durations),
                "stop_time_s": round(float(self.time_s[-1] - self.time_s[self.brake_start]), 2)}


def straight_episode(town: str, suite: str = "corl2017") -> Episode:
    """The suite's Straight episode of ``town`` with the longest route (room to reach the limit
    and stop)."""
    return max(suite_episodes(suite, town, "Straight"), key=lambda e: e.route_length_m)


def measure_stop(config: WorldConfig, town: str = "Town01", episode: Episode | None = None, seed: int = 0,
                 max_decisions: int = 400) -> StopTrace:
    """Reach the speed limit, ``keep`` one decision, then ``speed_down`` until standstill.

    Args:
        config: world options (fidelity, behavior rule, planner); the episode's traffic is used
            as it is, so give an episode on an empty road.
        town: map name.
        episode: default :func:`straight_episode` of ``town`` (empty road).
        seed: SUMO seed of the episode.
        max_decisions: give up after this many decisions of either phase.

    Raises:
        RuntimeError: the episode ended, or the ego did not reach the limit or standstill, within
            ``max_decisions`` (route too short for the stop).
    """
    episode = straight_episode(town) if episode is None else episode
    world = DrivingWorld(town, config)
    samples: list[tuple[float, float, float, float]] = []

    def sample() -> None:
        state = world.ego_driver.observe(world.sim.vehicle_state(EGO_ID))
        samples.append((world.sim.time, float(state.xy[0]), float(state.xy[1]), float(state.speed)))

    def decide(behavior: int) -> dict:
        _, _, terminated, truncated, infos = world.step({EGO_ID: behavior}, on_substep=sample)
        if terminated[EGO_ID] or truncated[EGO_ID]:
            raise RuntimeError(f"{episode.key} ended ({world.ego.end_reason}) before the ego stood still")
        return infos[EGO_ID]

    try:
        world.start(episode, seed)
        sample()
        for _ in range(max_decisions):
            info = decide(Behavior.SPEED_UP)
            limit = info["scene"]["speed_limit_mps"]
            if abs(info["scene"]["speed_mps"] - limit) < AT_LIMIT_MPS:
                break
        else:
            raise RuntimeError(f"the ego did not reach the speed limit in {max_decisions} decisions")
        cruise_start = len(samples) - 1
        decide(Behavior.KEEP)  # the cruise decision
        brake_start = len(samples) - 1
        durations = []
        while samples[-1][3] >= STANDSTILL_MPS:
            if len(durations) >= max_decisions:
                raise RuntimeError(f"the ego did not stop in {max_decisions} speed_down decisions")
            info = decide(Behavior.SPEED_DOWN)
            if info["behavior_executed"] != "speed_down":
                raise RuntimeError(f"speed_down was executed as {info['behavior_executed']}")
            durations.append(info["duration_s"])
    finally:
        world.close()
    arr = np.array(samples)
    return StopTrace(town=town, fidelity=config.fidelity, speed_limit=float(limit), time_s=arr[:, 0],
                     xy=arr[:, 1:3], speed=arr[:, 3], cruise_start=cruise_start, brake_start=brake_start,
                     speed_down_durations=tuple(durations))
