"""The highway-env scenes the sharable representation is evaluated on (cross-simulator transfer).

Each :class:`TransferScene` names a highway-env environment class, the configuration overrides the
adapter runs it with, and what success means there. Pure data: importing this module does not
import highway-env.

Common settings (all scenes): decisions at 10 Hz (``policy_frequency`` 10, as the SUMO behavior env
decides every 0.1 s) on a 10 Hz simulation (highway-env's "fast" settings use 5 Hz; 10 Hz keeps a
0.1 s decision = one simulation step); the ego is a DiscreteMetaAction vehicle whose target speeds
are a uniform grid 0, 2, 4, ... [m/s] up to the scene's speed limit (so ``speed_down`` can stop the
car, as in SUMO); highway-env's own observation is switched off (the adapter builds M_t and R_t).

Scenes highway-env ships that are NOT registered, and why:

- ``parking``: goal-conditioned continuous control in a car park; no lane graph to follow, so no
  R_t, and no discrete behaviors.
- ``racetrack``, ``lane-keeping``: continuous steering tasks (lateral control only); lane keeping is
  what HBMP's motion planner does below the behavior layer, there is no behavior decision to make.
- ``two-way``: overtaking uses the lane of the opposite direction, which belongs to another road
  with the opposite heading; R_t's e_l / e_r / a_* cannot express it (no wrong-lane R_t entry).
- ``exit``, ``u-turn``: the representation applies (lane graph, DiscreteMetaAction); left out to
  keep the suite small. Adding one is a new :class:`TransferScene` entry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from hbmp_bench.errors import ConfigError, UnknownNameError


@dataclass(frozen=True)
class TransferScene:
    """One highway-env scene driven through the adapter.

    Attributes:
        name: scene name (``highway``, ``merge``, ...); also the record's town and task.
        env_class: highway-env environment as ``module:Class``.
        overrides: highway-env config entries set on top of the class defaults and the common
            settings (read-only mapping).
        spawn_per_s: for scenes that spawn traffic once per highway-env step (intersection-v0:
            probability 0.6 per step, 1 s by default), that probability per second; it is scaled to
            the decision period (0.06 per 0.1 s step) so the traffic rate stays highway-env's.
        speed_limit_mps: the scene's speed limit [m/s] (R_t's dv and the expert's cruise speed);
            highway-env lanes carry a 20 m/s default where a scene does not set one, so each scene
            states its own.
        duration_s: episode time limit [s]; at the limit a ``survive`` scene succeeds, the others
            time out.
        goal_road: ``(from, to)`` road of the network the ego must reach for success; None: the
            scene is a ``survive`` scene (success = no collision until ``duration_s``).
        goal_s_m: how far along ``goal_road`` [m] the ego must be.
        junction_from_nodes: roads starting at these nodes are junction interiors (R_t as inside
            a SUMO junction: e_l = e_r = 0, a_c = 1, d_s = 0).
        description: one line for listings and docs.
    """

    name: str
    env_class: str
    overrides: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    speed_limit_mps: float = 30.0
    duration_s: float = 30.0
    goal_road: tuple[str, str] | None = None
    goal_s_m: float = 0.0
    spawn_per_s: float | None = None
    junction_from_nodes: tuple[str, ...] = ()
    description: str = ""

    def __post_init__(self):
        if ":" not in self.env_class:
            raise ConfigError(f"env_class must be 'module:Class', got {self.env_class!r}")
        if not self.speed_limit_mps > 0 or not self.duration_s > 0:
            raise ConfigError("speed_limit_mps and duration_s must be > 0")
        if not isinstance(self.overrides, MappingProxyType):
            object.__setattr__(self, "overrides", MappingProxyType(dict(self.overrides)))

    @property
    def success_rule(self) -> str:
        """Human-readable success definition."""
        if self.goal_road is None:
            return f"no collision for {self.duration_s:g} s"
        return f"reach road {self.goal_road[0]}->{self.goal_road[1]} (+{self.goal_s_m:g} m) within {self.duration_s:g} s"

    def highway_config(self, decision_hz: int, speed_step_mps: float) -> dict[str, Any]:
        """A fresh highway-env config dict for this scene: ``decision_hz`` decisions (= simulation
        steps) per second, target speeds a uniform grid from 0 to the speed limit with a step of
        about ``speed_step_mps`` [m/s] (highway-env's speed index assumes a uniform grid)."""
        n_speeds = max(int(round(self.speed_limit_mps / speed_step_mps)), 1) + 1
        config: dict[str, Any] = {
            "observation": {"type": "AttributesObservation", "attributes": ["time"]},
            "action": {
                "type": "DiscreteMetaAction",
                "longitudinal": True,
                "lateral": True,
                "target_speeds": [self.speed_limit_mps * k / (n_speeds - 1) for k in range(n_speeds)],
            },
            "policy_frequency": decision_hz,
            "simulation_frequency": decision_hz,
            "duration": self.duration_s,
        }
        if self.spawn_per_s is not None:
            config["spawn_probability"] = min(self.spawn_per_s / decision_hz, 1.0)
        config.update(dict(self.overrides))
        return config


SCENES: dict[str, TransferScene] = {
    s.name: s
    for s in (
        TransferScene(
            "highway",
            "highway_env.envs.highway_env:HighwayEnvFast",
            speed_limit_mps=30.0,
            duration_s=30.0,
            description="highway-fast-v0: 3 lanes, 20 IDM/MOBIL vehicles; survive 30 s",
        ),
        TransferScene(
            "merge",
            "highway_env.envs.merge_env:MergeEnv",
            speed_limit_mps=30.0,
            duration_s=30.0,
            goal_road=("c", "d"),
            goal_s_m=60.0,
            description="merge-v0: 2-lane highway with an on-ramp merging from the right; pass the merge (x > 370 m)",
        ),
        TransferScene(
            "roundabout",
            "highway_env.envs.roundabout_env:RoundaboutEnv",
            speed_limit_mps=16.0,
            duration_s=20.0,
            goal_road=("nx", "nxs"),
            goal_s_m=0.0,
            description="roundabout-v0: 2-lane roundabout, enter from the south, leave by the north exit",
        ),
        TransferScene(
            "intersection",
            "highway_env.envs.intersection_env:IntersectionEnv",
            overrides=MappingProxyType({"destination": "o1"}),
            spawn_per_s=0.6,
            speed_limit_mps=10.0,
            duration_s=20.0,
            goal_road=("il1", "o1"),
            goal_s_m=25.0,
            junction_from_nodes=("ir0", "ir1", "ir2", "ir3"),
            description="intersection-v0: unsignalised 4-way crossing, left turn from the minor road",
        ),
    )
}
"""Registered scenes. Success: highway = survive the duration (highway-env's own episode end);
merge = pass the end of the ramp, x > 370 m (highway-env's termination); roundabout = enter the
north exit road (the ego's planned route); intersection = highway-env's ``has_arrived`` (25 m into
the exit road of the planned left turn). Durations: highway-env's for highway (30 s); merge has
none in highway-env (30 s here); roundabout (11 s) and intersection (13 s) are lengthened to 20 s
so that a yielding agent is not failed by the clock alone."""

def get_scene(name: str) -> TransferScene:
    """The scene called ``name``; unknown names list the valid ones."""
    if name not in SCENES:
        raise UnknownNameError("transfer scene", name, SCENES)
    return SCENES[name]
