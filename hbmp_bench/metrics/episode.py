"""Scoring one episode: the paper's terminal reward r_T, progress along the route, distance, and
the episode record. Shared by the SUMO worlds (:mod:`hbmp_bench.envs`) and the highway-env
transfer env (:mod:`hbmp_bench.transfer`), so both score the same way."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from hbmp_bench.maps.curves import CURVE_WINDOW_S
from hbmp_bench.metrics.detectors import StepEvents
from hbmp_bench.metrics.records import EpisodeRecord, driving_score

TERMINAL_REWARD = {
    "goal": 100.0,
    "collision": -50.0,
    "timeout": -50.0,
    "red_light": -10.0,
    "wrong_lane": -1.0,
    "off_road": -1.0,
}
"""The paper's r_T: +100 goal, −50 collision or overtime, −10 red light, −1 wrong lane (off-road
is counted like a wrong lane). Each event pays once, when it happens. An episode that ends before its goal
for any reason but a collision can no longer reach it and pays the overtime's −50 as well
(``GOAL_UNREACHABLE``): the car left the network (its route ended in a lane other than the goal's, or it
drove off the map: the paper has no such terminal state), or, under the paper's protocol, a violation
ended it (a red light then pays −60, a wrong lane −51). With the paper's values alone, ending an episode
by the cheapest violation (−1) beats every attempt that may time out (−50): a policy that cannot yet reach
the goal learns to leave the lane within two seconds, as the flat baseline did (``agents/checkpoints/flat.md``)."""

CARLA_RL_REWARD = {"progress_per_m": 1.0, "speed_gain_per_kmh": 0.05, "event": -2.0}
"""CARLA's reinforcement-learning baseline reward (Dosovitskiy et al. 2017, the A3C row of the paper's Tab. I):
``1000 (d_{t-1} - d_t) + 0.05 (v_t - v_{t-1}) - 2e-5 (c_t - c_{t-1}) - 2 (s_t - s_{t-1}) - 2 (o_t - o_{t-1})`` with
``d`` the distance to the goal [km], ``v`` the speed [km/h], ``c`` collision damage and ``s``, ``o`` the car's overlap
with the sidewalk and the opposite lane [0, 1]. Here ``d`` is progress along the route [m] (so 1 per metre), and
each collision, off-road or wrong-lane event counts as a whole overlap (``event``: the detectors give the onset of
an event, not an overlap fraction nor a damage). No goal term: an episode's end only stops the progress it pays."""

GOAL_UNREACHABLE = ("timeout", "left_network", "violation")
"""End reasons that pay ``TERMINAL_REWARD["timeout"]``: the goal can no longer be reached."""

PROGRESS_SLACK_M = 5.0
"""A progress reading more than this beyond the route's length is a mismatch, not progress [m]."""


def terminal_reward(*, goal: bool = False, collisions: int = 0, timed_out: bool = False, red_light: int = 0,
                    wrong_lane: int = 0, off_road: int = 0) -> float:
    """The paper's r_T of what happened (see ``TERMINAL_REWARD``)."""
    r = TERMINAL_REWARD
    return float(
        r["goal"] * goal
        + r["collision"] * collisions
        + r["timeout"] * timed_out
        + r["red_light"] * red_light
        + r["wrong_lane"] * wrong_lane
        + r["off_road"] * off_road
    )


def events_reward(ev: StepEvents, timed_out: bool = False) -> float:
    """r_T of the detectors' events ``ev``."""
    return terminal_reward(goal=ev.goal_reached, collisions=ev.collisions, timed_out=timed_out,
                           red_light=ev.red_light, wrong_lane=ev.wrong_lane, off_road=ev.off_road)


def carla_rl_reward(progress_m: float, speed_gain_mps: float, ev: StepEvents) -> float:
    """``CARLA_RL_REWARD`` of ``progress_m`` [m] along the route, ``speed_gain_mps`` [m/s] and the events ``ev``
    since the last payment."""
    w = CARLA_RL_REWARD
    events = ev.collisions + ev.off_road + ev.wrong_lane
    return float(w["progress_per_m"] * progress_m + w["speed_gain_per_kmh"] * 3.6 * speed_gain_mps + w["event"] * events)


def add_events(total: StepEvents, ev: StepEvents) -> None:
    """Add the events ``ev`` into ``total`` in place (counts add, flags or)."""
    for f in dataclasses.fields(StepEvents):
        value = getattr(ev, f.name)
        merged = (getattr(total, f.name) or value) if isinstance(value, bool) else getattr(total, f.name) + value
        setattr(total, f.name, merged)


@dataclass(frozen=True)
class EpisodeId:
    """What names an episode in its record."""

    suite: str
    town: str
    task: str
    episode: int
    seed: int
    fidelity: str
    route_length_m: float


LATERAL_WINDOW_S = CURVE_WINDOW_S
"""Lateral acceleration is measured as speed × yaw rate, both averaged over this window [s]: what a car's
occupants feel in a bend, not the steps of a polyline (SUMO's heading turns at a lane shape's vertices, and
its lane changes move a car sideways without turning it); the window of an import's curve speeds."""


class LateralAcceleration:
    """Peak lateral acceleration [m/s²] of a vehicle: its mean speed × its mean yaw rate over any
    ``window_s`` [s], from samples of (time [s], speed [m/s], yaw [rad])."""

    def __init__(self, window_s: float = LATERAL_WINDOW_S):
        self.window_s = float(window_s)
        self.peak_mps2 = 0.0
        self._samples: list[tuple[float, float, float]] = []  # (time [s], road driven [m], unwrapped yaw [rad])
        self._start = 0
        self._speed = 0.0

    def add(self, time_s: float, speed_mps: float, yaw: float) -> None:
        """A sample; raises the peak once the samples span the window."""
        driven = 0.0
        if self._samples:
            t_last, driven, last = self._samples[-1]
            yaw = last + (yaw - last + np.pi) % (2 * np.pi) - np.pi
            driven += 0.5 * (self._speed + speed_mps) * (time_s - t_last)  # the speeds' integral: the road driven
        self._speed = float(speed_mps)
        self._samples.append((float(time_s), float(driven), float(yaw)))
        while self._start + 1 < len(self._samples) and self._samples[self._start + 1][0] <= time_s - self.window_s + 1e-9:
            self._start += 1  # the newest sample at least a window old
        t0, s0, psi0 = self._samples[self._start]
        span = time_s - t0
        if span >= self.window_s - 1e-9:
            self.peak_mps2 = max(self.peak_mps2, abs((driven - s0) / span * (yaw - psi0) / span))
        if self._start > 64:  # keep the list short
            del self._samples[:self._start]
            self._start = 0


class EpisodeScorer:
    """Distance driven [m], progress along the route [m] (monotone), peak lateral acceleration [m/s²] and the
    episode record.

    Args:
        route_length_m: length of the route to drive [m].
        start_xy: (2,) where the vehicle starts [m].
    """

    def __init__(self, route_length_m: float, start_xy: np.ndarray):
        self.route_length_m = float(route_length_m)
        self.distance_m = 0.0
        self.progress_m = 0.0
        self._last_xy = np.asarray(start_xy, dtype=float)
        self.lateral: LateralAcceleration | None = None
        """Fed where :meth:`moved_to` is given the yaw and the time (-1 in the record where never)."""

    def moved_to(self, xy: np.ndarray, time_s: float | None = None, speed_mps: float | None = None,
                 yaw: float | None = None) -> None:
        """The vehicle's centre is now at ``xy`` (2,) [m]: adds the straight step to the distance; given the time
        [s], speed [m/s] and heading [rad] now, a sample of the lateral acceleration too."""
        self.distance_m += float(np.hypot(*(xy - self._last_xy)))
        self._last_xy = xy
        if time_s is not None and speed_mps is not None and yaw is not None:
            if self.lateral is None:
                self.lateral = LateralAcceleration()
            self.lateral.add(time_s, speed_mps, yaw)

    def progressed_to(self, progress_m: float) -> None:
        """A progress reading [m]: progress never goes back and stops at the route's length;
        readings past it by more than ``PROGRESS_SLACK_M`` are ignored."""
        if progress_m <= self.route_length_m + PROGRESS_SLACK_M:
            self.progress_m = max(self.progress_m, min(progress_m, self.route_length_m))

    def completion(self, success: bool) -> float:
        """Route completion in [0, 1]: 1 on success, otherwise progress / route length."""
        if success:
            return 1.0
        return float(np.clip(self.progress_m / max(self.route_length_m, 1e-6), 0.0, 1.0))

    def record(self, episode: EpisodeId, *, agent: str, package_version: str, totals: dict[str, int], success: bool,
               end_reason: str, duration_s: float, decisions: int, completion: float | None = None,
               traffic: tuple[int, int] = (-1, -1)) -> EpisodeRecord:
        """The episode record now (final once the episode has ended); ``completion`` overrides
        :meth:`completion` (e.g. a scene without a goal, scored by time survived); ``traffic``: the
        (vehicles, pedestrians) that spawned."""
        completion = self.completion(success) if completion is None else completion
        return EpisodeRecord(
            suite=episode.suite, town=episode.town, task=episode.task, episode=episode.episode, seed=episode.seed,
            agent=agent, package_version=package_version, fidelity=episode.fidelity, success=success,
            route_completion=round(completion, 4),
            collision_vehicle=totals.get("collision_vehicle", 0),
            collision_pedestrian=totals.get("collision_pedestrian", 0),
            collision_other=totals.get("collision_other", 0), wrong_lane=totals.get("wrong_lane", 0),
            off_road=totals.get("off_road", 0), red_light=totals.get("red_light", 0),
            timeout=end_reason == "timeout", duration_s=round(duration_s, 2), distance_m=round(self.distance_m, 2),
            route_length_m=episode.route_length_m, decisions=decisions,
            driving_score=round(driving_score(completion, totals), 3), end_reason=end_reason or "running",
            traffic_vehicles=int(traffic[0]), traffic_pedestrians=int(traffic[1]),
            peak_lateral_accel_mps2=round(self.lateral.peak_mps2, 2) if self.lateral is not None else -1.0,
        )
