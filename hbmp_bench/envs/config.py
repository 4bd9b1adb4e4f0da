"""The frozen configurations of an environment: which scenario (:class:`ScenarioConfig`) and how
its world runs (:class:`WorldConfig`). Each validates its fields in one place, at construction.

:func:`env_configs` is the keyword form every env of the package accepts (``gym.make(id, **kwargs)``,
``traffic_v0.parallel_env(**kwargs)``): it builds both configs, with their own defaults, so that
every front door has the same options and the same defaults."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from hbmp_bench.envs.drivers import FIDELITIES, ContinuousConfig
from hbmp_bench.envs.observation import ObservationConfig
from hbmp_bench.planning.behaviors import BehaviorConfig
from hbmp_bench.maps import available_maps
from hbmp_bench.scenarios import (SCENARIO_TYPES, Episode, Traffic, check_task, check_town, get_suite, sample_episode,
                                  suite_episodes, traffic_for, with_agents)
from hbmp_bench.errors import ConfigError
from hbmp_bench.vocabulary import ENV_REWARDS

EGO_DRIVERS = ("behavior", "control")


@dataclass(frozen=True)
class ScenarioConfig:
    """Which episodes an env runs.

    Attributes:
        town: map name (``Town01``..``Town05`` or an imported map).
        task: ``Straight``, ``OneTurn``, ``Navigation`` or ``NavigationDynamic`` (default: the
            category with traffic, so that the parallel env has background agents by default), or a
            scenario type (``HardBrake`` ...: ``scenarios.scenario_types``, with a ``scenarios`` suite).
        suite: episode list and rules (``corl2017``, ``hbmp``, ``nocrash-*``).
        episode_index: fix one episode of the list; None draws one per reset from the env's
            generator (the reset seed).
        random_goals: ignore the suite's list and draw a fresh start and goal every reset (training).
        density: override the background traffic (``empty``, ``corl``, ``regular``, ``dense``);
            None: each episode's own.
        agents: goal-directed vehicles per episode, the ego included (``ego``, ``ego1`` ...: each its own
            start, goal and route, drawn from the episode's seed, ``scenarios.suites.with_agents``); None:
            the suite's (``Suite.agents``: 1, or 8 in ``multi``).

    Raises:
        UnknownNameError: an unknown town, task, suite or density (naming the valid ones).
        ConfigError: ``episode_index`` outside the list, or given with ``random_goals`` (a ValueError); a
            scenario type the town cannot host (naming those that can) or with ``random_goals``; ``agents``
            below 1, or above 1 with a scenario type.
    """

    town: str = "Town01"
    task: str = "NavigationDynamic"
    suite: str = "corl2017"
    episode_index: int | None = None
    random_goals: bool = False
    density: str | None = None
    agents: int | None = None

    def __post_init__(self):
        check_town(self.town)
        check_task(self.task)
        object.__setattr__(self, "suite", get_suite(self.suite).name)
        if self.agents is not None and (isinstance(self.agents, bool) or not isinstance(self.agents, (int, np.integer))
                                        or self.agents < 1):
            raise ConfigError(f"agents must be an int >= 1 or None, got {self.agents!r}")
        if self.task in SCENARIO_TYPES and self.goal_agents > 1:
            raise ConfigError(f"{self.task} is a scenario type: its episodes have one goal-directed vehicle")
        if self.density is not None:
            traffic_for(self.town, self.task, self.density)
        if self.task in SCENARIO_TYPES:
            if self.random_goals:
                raise ConfigError(f"{self.task} is a scenario type: its episodes are the suite's, not random goals")
            if not self.episodes:
                hosts = [t for t in available_maps() if suite_episodes(self.suite, t, self.task)]
                raise ConfigError(f"{self.town} cannot host {self.task} ({SCENARIO_TYPES[self.task].description}); "
                                  f"towns that can: {', '.join(hosts)}")
        if self.episode_index is not None:
            if self.random_goals:
                raise ConfigError("episode_index and random_goals exclude each other")
            if not 0 <= self.episode_index < len(self.episodes):
                raise ConfigError(f"episode_index must be in [0, {len(self.episodes)}), got {self.episode_index}")

    @property
    def goal_agents(self) -> int:
        """Goal-directed vehicles per episode, the ego included (``agents``, else the suite's)."""
        return int(self.agents) if self.agents is not None else get_suite(self.suite).agents

    def _with_agents(self, episode: Episode) -> Episode:
        if len(episode.agents) == self.goal_agents:
            return episode
        return with_agents(episode, self.goal_agents, get_suite(self.suite))

    @cached_property
    def traffic(self) -> Traffic | None:
        """The traffic ``density`` sets for every episode (None: each episode's own)."""
        return None if self.density is None else traffic_for(self.town, self.task, self.density)

    @cached_property
    def episodes(self) -> tuple[Episode, ...]:
        """The suite's episode list with the traffic override applied (empty with ``random_goals``)."""
        if self.random_goals:
            return ()
        episodes = suite_episodes(self.suite, self.town, self.task)
        if self.traffic is not None:
            episodes = tuple(dataclasses.replace(e, traffic=self.traffic,
                                                 others=tuple(dataclasses.replace(o, traffic=self.traffic)
                                                              for o in e.others))
                             for e in episodes)
        return tuple(self._with_agents(e) for e in episodes)

    @property
    def least_vehicles(self) -> int:
        """The fewest background vehicles any episode of this config has."""
        if self.random_goals:
            return (self.traffic or traffic_for(self.town, self.task, None)).vehicles
        pool = self.episodes if self.episode_index is None else self.episodes[self.episode_index:self.episode_index + 1]
        return min(e.traffic.vehicles for e in pool)

    def pick(self, rng: np.random.Generator, episode_index: int | None = None) -> Episode:
        """The episode of one reset: ``episode_index`` (else the configured one) of the list, else
        one drawn with ``rng``; with ``random_goals`` a fresh one drawn with ``rng``."""
        if self.random_goals:
            traffic = self.traffic if self.traffic is not None else traffic_for(self.town, self.task, None)
            seed = int(rng.integers(2**31))
            pose_task = "Navigation" if self.task == "NavigationDynamic" else self.task
            episode = sample_episode(self.town, pose_task, np.random.default_rng(seed), suite=get_suite(self.suite),
                                     index=0, seed=seed, traffic=traffic)
            return self._with_agents(episode)
        index = self.episode_index if episode_index is None else episode_index
        if index is None:
            index = int(rng.integers(len(self.episodes)))
        if not 0 <= index < len(self.episodes):
            raise ValueError(f"episode_index must be in [0, {len(self.episodes)}), got {index}")
        return self.episodes[index]


@dataclass(frozen=True)
class WorldConfig:
    """Options of a driving world.

    Attributes:
        fidelity: the ego's: ``continuous`` (default: the paper's behavior-conditioned sampling
            motion planner drives a bicycle model whose pose is pushed into SUMO every step; one
            behavior lasts until it converges, 1-8 s) or ``event`` (the paper's SUMO stage: SUMO's
            speed and lane-change commands complete a behavior within ``decision_period_s``).
        ego_driver: ``behavior`` (default: the fidelity's behavior driver) or ``control`` (no
            behavior layer: the flat baseline sets acceleration and steering of the bicycle model,
            :class:`~hbmp_bench.envs.drivers.ControlDriver`; continuous fidelity only).
        background_fidelity: the background agents' (default ``event``).
        reward: ``dense`` (r_k + r_T, HBMP: r_k = lambda(c~_total) of the executed trajectory,
            0 in event fidelity), ``sparse`` (r_T only, HBMP-S) or ``carla`` (CARLA's reinforcement-learning
            baseline reward, paid every step: route progress, speed gained, overlap events; no r_T:
            :data:`~hbmp_bench.metrics.episode.CARLA_RL_REWARD`).
        decision_period_s: simulated time per decision in event fidelity [s] (paper: 10 Hz).
        behavior: the v_ref rule of speed_up / speed_down, shared by both fidelities.
        continuous: planner, executor and vehicle-model options of the continuous fidelity.
        observation: M_t grid options.
        background_route_m: length of the chained route each background vehicle gets, long
            enough that it circulates for the whole episode [m].
        step_length_s: SUMO step [s] (the planner's control period in continuous fidelity).
        privileged: add the privileged fields of :mod:`hbmp_bench.envs.privileged` to the ego's
            ``info["scene"]`` (light schedules, junction foes, pedestrians, leader, crossings:
            what the rule-based expert, a demonstrator, reads). Off by default: a learned agent
            sees M_t, R_t and the scene's R_t quantities only, and no step pays for the rest. An
            evaluated agent asks for it through its ``env_kwargs``; its results are marked.
    """

    fidelity: str = "continuous"
    ego_driver: str = "behavior"
    background_fidelity: str = "event"
    reward: str = "dense"
    decision_period_s: float = 0.1
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    behavior: BehaviorConfig = field(default_factory=BehaviorConfig)
    continuous: ContinuousConfig = field(default_factory=ContinuousConfig)
    background_route_m: float = 4000.0
    step_length_s: float = 0.1
    privileged: bool = False

    def __post_init__(self):
        if not isinstance(self.privileged, bool):
            raise ConfigError(f"privileged must be True or False, got {self.privileged!r}")
        if self.fidelity not in FIDELITIES:
            raise ConfigError(f"fidelity must be one of {FIDELITIES}, got {self.fidelity!r}")
        if self.ego_driver not in EGO_DRIVERS:
            raise ConfigError(f"ego_driver must be one of {EGO_DRIVERS}, got {self.ego_driver!r}")
        if self.ego_driver == "control" and self.fidelity != "continuous":
            raise ConfigError(f"the control driver runs the bicycle model: fidelity must be 'continuous', "
                             f"got {self.fidelity!r}")
        if self.background_fidelity not in FIDELITIES:
            raise ConfigError(f"background_fidelity must be one of {FIDELITIES}, got {self.background_fidelity!r}")
        if self.reward not in ENV_REWARDS:
            raise ConfigError(f"reward must be one of {ENV_REWARDS}, got {self.reward!r}")
        if self.decision_period_s < self.step_length_s - 1e-9:
            raise ConfigError("decision_period_s must be >= step_length_s")
        if abs(self.continuous.executor.dt - self.step_length_s) > 1e-9:
            raise ConfigError("continuous.executor.dt must equal step_length_s (one control period per SUMO step)")

    @property
    def steps_per_decision(self) -> int:
        return max(1, int(round(self.decision_period_s / self.step_length_s)))


def env_configs(*, town: str = ScenarioConfig.town, task: str = ScenarioConfig.task,
                suite: str = ScenarioConfig.suite, episode_index: int | None = ScenarioConfig.episode_index,
                random_goals: bool = ScenarioConfig.random_goals, density: str | None = ScenarioConfig.density,
                agents: int | None = ScenarioConfig.agents,
                fidelity: str | None = WorldConfig.fidelity, ego_driver: str = WorldConfig.ego_driver,
                background_fidelity: str = WorldConfig.background_fidelity, reward: str = WorldConfig.reward,
                decision_period_s: float = WorldConfig.decision_period_s, observation: str | None = None,
                road_profile: str | None = None, observation_config: ObservationConfig | None = None,
                privileged: bool = WorldConfig.privileged) -> tuple[ScenarioConfig, WorldConfig]:
    """The (scenario, world) configs of the keyword form of every env (defaults: the configs' own).

    Args:
        town, task, suite, episode_index, random_goals, density, agents: :class:`ScenarioConfig`.
        fidelity, ego_driver, background_fidelity, reward, decision_period_s, privileged:
            :class:`WorldConfig` (``fidelity`` is the ego's; None: the default).
        observation: ``deformed`` or ``vehicle_centric`` M_t (:attr:`ObservationConfig.kind`).
        road_profile: R_t's entries, ``paper`` or ``metric`` (:attr:`ObservationConfig.road`).
        observation_config: every grid option at once (``observation`` / ``road_profile``, if given, must agree).

    Raises:
        ConfigError / UnknownNameError: a bad value, from the configs' own checks (both ValueErrors).
        TypeError: an unknown keyword (a typo is never swallowed).
    """
    if observation_config is None:
        observation_config = ObservationConfig(**{k: v for k, v in (("kind", observation), ("road", road_profile))
                                                  if v is not None})
    elif observation not in (None, observation_config.kind) or road_profile not in (None, observation_config.road):
        raise ConfigError(f"observation={observation!r} / road_profile={road_profile!r} contradict observation_config "
                         f"(kind={observation_config.kind!r}, road={observation_config.road!r})")
    if fidelity is None:
        fidelity = WorldConfig.fidelity
    scenario = ScenarioConfig(town=town, task=task, suite=suite, episode_index=episode_index,
                              random_goals=random_goals, density=density, agents=agents)
    world = WorldConfig(fidelity=fidelity, ego_driver=ego_driver, background_fidelity=background_fidelity,
                        reward=reward, decision_period_s=decision_period_s, observation=observation_config,
                        privileged=privileged)
    return scenario, world
