"""PettingZoo environment: the ego and background traffic as agents of the behavior layer.

Usage::

    from hbmp_bench.envs import traffic_v0
    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", controlled=4)
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: policy(observations[a], infos[a]) for a in env.agents if infos[a]["decision_required"]}
        observations, rewards, terminations, truncations, infos = env.step(actions)

    aec = traffic_v0.env(...)   # the same through PettingZoo's parallel-to-AEC conversion

## Agents
``possible_agents = ["ego", "bg0", ..., "bg{N-1}"]``: the ego of the scenario's episode and N
controlled background vehicles (``controlled``: ``"none"``, an int N, or ``"all"`` of the episode's
background vehicles); the others stay with SUMO's own driver models. The slots are fixed for the
episode: background agents circulate (their routes are extended and re-planned, never finished),
so an agent never disappears and comes back. Pedestrians walk the sidewalks and cross at crossings;
they are obstacles in every agent's M_t.

## Spaces
Every agent: action ``Discrete(5)`` (speed_up, speed_down, change_left, change_right, keep;
infeasible lane changes run as keep, ``info["action_mask"]``), observation
``Dict(occupancy=Box(0, 1, (1, rows, cols)), road=Box(0, 2, (10,)))`` = M_t and R_t from the
agent's own point of view (R_t of a background agent follows its own circulating route).

## Decision timing
Behaviors last different times (continuous fidelity: 1-8 s; event: one decision period). ``step``
begins a behavior for every agent whose ``info["decision_required"]`` is True and returns as soon as
any agent's behavior has ended (or the episode ends, or an agent crashes). Agents still executing
their behavior get ``decision_required = False``; their entry in the next ``actions`` is optional
and ignored. The ego runs ``ego_fidelity`` (default continuous), background agents
``background_fidelity`` (default event: each behavior = one 0.1 s step).

## Rewards, ends, infos
Per agent, the single-ego definition: r_T when an event happens (collision −50, red light −10,
wrong lane / off-road −1; the ego also +100 goal and −50 timeout, and −50 when a violation ends its
episode or it leaves the network: ``metrics.episode.GOAL_UNREACHABLE``), plus, with ``reward="dense"``,
r_k = λ(c̃_total) when the agent's behavior ends (0 in event fidelity), and on its last step for
the part of the behavior its end cut short. The ego ends by its episode's rules (``DrivingWorld``);
a background agent is terminated by its own collision or by leaving the network (its vehicle then
leaves SUMO); when the ego's episode ends every other live agent is truncated.
``info``: ``decision_required``, ``action_mask``, ``events`` and ``infractions`` (its own),
``scene`` (R_t's quantities in metres and m/s, :class:`~hbmp_bench.envs.scene.Scene`; the ego's
with its straight-line goal distance, and with ``privileged=True`` the privileged fields the
expert reads), ``reward_components``, ``time_s``; at the end of the ego's episode the ego's
``info["hbmp_record"]`` (:data:`~hbmp_bench.envs.registration.RECORD_KEY`) holds its episode record
(``info["episode"]`` is left to the ecosystem's episode statistics: Gymnasium's
``RecordEpisodeStatistics``, SB3's ``Monitor``).

## Episode length
The ego's episode ends by its suite's rules (goal, violation, the suite's timeout in simulated
seconds). A trainer that wants shorter episodes in steps sets ``max_cycles`` (PettingZoo's name):
the ``max_cycles``-th step truncates every live agent (r_k of a behavior it cuts is paid, the ego's
record has ``end_reason="decision_cap"``); the gymnasium views take it too (or Gymnasium's own
``gym.make(id, max_episode_steps=N)``, a ``TimeLimit``, which leaves no record in the last info).

## Rendering
``render_mode="rgb_array"``: :meth:`render` draws the ego-centred top-down view when it is called,
and nothing is drawn or kept otherwise (Gymnasium's semantics; SB3's ``make_vec_env`` asks for this
mode and never calls ``render``). ``"rgb_array_list"``: a frame is drawn after every 0.1 s SUMO step
and :meth:`render` returns the frames since the last call or reset (the video recorder's mode).

## Copies
A copy (``pickle``, ``copy.deepcopy``) is the env before its first reset, with the same configs: a
running SUMO simulation cannot be copied (libsumo is one per process), so the copy starts its own at
its first ``reset``. Vector envs that copy an env (SuperSuit's ``concat_vec_envs_v1``) work so.

## Generic trainers
The env follows PettingZoo (Dict observations, every live agent in every dict, ``decision_required``
for agents still executing a behavior, whose actions are ignored). The wrappers of
:mod:`hbmp_bench.envs.ecosystem` give Box observations, a fixed agent set (SuperSuit) and RLlib's
convention of observing only agents with a decision; :func:`hbmp_bench.envs.rllib.rllib_env` is the
env for RLlib (see ``docs/recipes.md``).

## Bad input
An action for an agent that is not live (unknown or finished) raises ValueError naming the live
agents; a missing action for an agent with ``decision_required`` raises ValueError; an action
outside 0..4 raises ValueError.

## Implementation
The core of every SUMO env of the package: the gymnasium :class:`~hbmp_bench.envs.BehaviorEnv` is
this env with no background agent (``controlled="none"``), the flat control env this env with the
ego's ``ego_driver="control"``, and :func:`ego_env` this env seen from the ego with its background
agents driven by a given policy. All run :class:`hbmp_bench.envs.world.DrivingWorld`, whose
vehicles are :class:`hbmp_bench.envs.vehicle.ControlledVehicle`.

## Version history
v0: first release. The record moved from ``info["episode"]`` to ``info["hbmp_record"]``;
``render_mode="rgb_array"`` draws on demand and ``"rgb_array_list"`` keeps the frames between
decisions (both without a change of the episodes).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from hbmp_bench.envs.actions import CONTROL_SPACE, check_action
from hbmp_bench.envs.config import ScenarioConfig, WorldConfig, env_configs
from hbmp_bench.envs.ego_view import EgoView
from hbmp_bench.envs.observation import observation_space
from hbmp_bench.envs.world import EGO_ID, DrivingWorld, goal_vehicle_ids
from hbmp_bench.planning.behaviors import BEHAVIORS
from hbmp_bench.scenarios import check_salt
from hbmp_bench.errors import ConfigError


def _controlled_count(controlled: str | int, vehicles: int) -> int:
    if controlled == "none":
        return 0
    if controlled == "all":
        return vehicles
    if isinstance(controlled, (int, np.integer)) and not isinstance(controlled, bool):
        if not 0 <= int(controlled) <= vehicles:
            raise ConfigError(f"controlled must be in [0, {vehicles}] (the episode's background vehicles), "
                             f"got {controlled}")
        return int(controlled)
    raise ConfigError(f"controlled must be 'none', 'all' or an int, got {controlled!r}")


RENDER_MODES = (None, "rgb_array", "rgb_array_list")
"""None, ``rgb_array`` (a frame when :meth:`TrafficParallelEnv.render` is called) and
``rgb_array_list`` (every SUMO step's frame, returned and dropped by each ``render``)."""


def check_render_mode(render_mode: str | None) -> str | None:
    """``render_mode`` if the envs support it; ConfigError naming the valid ones."""
    if render_mode not in RENDER_MODES:
        raise ConfigError(f"render_mode {render_mode!r} is not supported; valid: {', '.join(map(repr, RENDER_MODES))}")
    return render_mode


def check_max_cycles(max_cycles: int | None) -> int | None:
    if max_cycles is not None and (isinstance(max_cycles, bool) or not isinstance(max_cycles, (int, np.integer))
                                   or max_cycles < 1):
        raise ConfigError(f"max_cycles must be an int >= 1 or None, got {max_cycles!r}")
    return None if max_cycles is None else int(max_cycles)


def build_configs(scenario: ScenarioConfig | None, world: WorldConfig | None,
                  options: dict[str, Any]) -> tuple[ScenarioConfig, WorldConfig]:
    """The configs of an env: the given ``scenario`` / ``world``, else those of the keyword form
    (:func:`~hbmp_bench.envs.config.env_configs`); a config and keywords for it at once is a TypeError."""
    if options and (scenario is not None or world is not None):
        raise TypeError(f"give scenario= / world= or their keyword form, not both (got {sorted(options)})")
    built_scenario, built_world = env_configs(**options)
    return scenario or built_scenario, world or built_world


class TrafficParallelEnv(ParallelEnv):
    """The multi-agent traffic environment; see the module docstring.

    Args:
        scenario / world: the frozen configs (:class:`~hbmp_bench.envs.config.ScenarioConfig`,
            :class:`~hbmp_bench.envs.config.WorldConfig`); or, instead, their keyword form
            (``town``, ``task``, ``suite``, ``episode_index``, ``random_goals``, ``density``,
            ``fidelity``, ``ego_driver``, ``background_fidelity``, ``reward``, ``decision_period_s``,
            ``observation``, ``road_profile``, ``observation_config``, ``privileged``: see
            :func:`~hbmp_bench.envs.config.env_configs`, the one place their defaults live).
            ``ego_fidelity`` is this env's name for ``fidelity`` (the ego's).
        controlled: ``"none"``, an int N or ``"all"``: background vehicles driven by agents.
        render_mode: None, ``rgb_array`` (:meth:`render` draws the ego-centred top-down view, with
            every vehicle and pedestrian, when called) or ``rgb_array_list`` (one picture per SUMO
            step, returned by :meth:`render`); see the module docstring.
        max_cycles: truncate every live agent at this step of an episode (None: the suite's rules only).

    An ego with ``ego_driver="control"`` acts with ``Box(-1, 1, (2,))`` = ``[accel, steer]`` and
    observes R_t with two more entries (see :mod:`hbmp_bench.envs.control_env`).
    """

    metadata = {"name": "hbmp_traffic_v0", "render_modes": ["rgb_array", "rgb_array_list"], "render_fps": 10,
                "is_parallelizable": True}

    def __init__(self, *, scenario: ScenarioConfig | None = None, world: WorldConfig | None = None,
                 controlled: str | int = "all", render_mode: str | None = None, max_cycles: int | None = None,
                 ego_fidelity: str | None = None, **options: Any):
        if ego_fidelity is not None:
            if "fidelity" in options:
                raise TypeError("give ego_fidelity or fidelity, not both")
            options["fidelity"] = ego_fidelity
        self.render_mode = check_render_mode(render_mode)
        self.max_cycles = check_max_cycles(max_cycles)
        self._cycles = 0
        self.scenario, self.config = build_configs(scenario, world, options)
        self.n_controlled = _controlled_count(controlled, self.scenario.least_vehicles)
        self.goal_agents = list(goal_vehicle_ids(self.scenario.goal_agents))
        """The goal-directed agents: ``ego`` and, with ``agents`` > 1 (or a multi-agent suite), ``ego1`` ..."""
        self.possible_agents = [*self.goal_agents, *(f"bg{k}" for k in range(self.n_controlled))]
        self.agents: list[str] = []
        behavior_obs = observation_space(self.config.observation)
        if self.config.ego_driver == "control":
            road = behavior_obs["road"]
            ego_obs = spaces.Dict(occupancy=behavior_obs["occupancy"],
                                  road=spaces.Box(-2.0, 2.0, (road.shape[0] + 2,), dtype=np.float32))
            ego_action = spaces.Box(CONTROL_SPACE.low, CONTROL_SPACE.high, CONTROL_SPACE.shape, CONTROL_SPACE.dtype)
        else:
            ego_obs, ego_action = behavior_obs, spaces.Discrete(len(BEHAVIORS))
        background_action = spaces.Discrete(len(BEHAVIORS))
        goal = set(self.goal_agents)
        self._observation_spaces = {a: ego_obs if a in goal else behavior_obs for a in self.possible_agents}
        self._action_spaces = {a: ego_action if a in goal else background_action for a in self.possible_agents}
        self._renderer = None
        self._frames: list[np.ndarray] = []
        self._last_behavior = ""
        self._world: DrivingWorld | None = None
        self._rng = np.random.default_rng()

    @property
    def town(self) -> str:
        return self.scenario.town

    @property
    def task(self) -> str:
        return self.scenario.task

    @property
    def episodes(self):
        return self.scenario.episodes

    def observation_space(self, agent: str) -> spaces.Dict:
        """The same object for every call (PettingZoo's rule); KeyError for an unknown agent."""
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self._action_spaces[agent]

    @property
    def world(self) -> DrivingWorld:
        """The world (built on first use; SUMO starts on the first reset)."""
        if self._world is None:
            self._world = DrivingWorld(self.scenario.town, self.config)
        return self._world

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode. ``options``: ``episode_index`` (an episode of the list) and ``salt``
        (a salted evaluation's secret, hex: the episode's traffic, pedestrians and light phases
        take it, see ``DrivingWorld.start``; "" or absent: the public episode)."""
        if seed is not None or self._world is None:
            self._rng = np.random.default_rng(seed)
        options = options or {}
        salt = check_salt(options.get("salt") or "")
        episode = self.scenario.pick(self._rng, options.get("episode_index"))
        obs, infos = self.world.start(episode, seed=int(self._rng.integers(2**31)), controlled=self.n_controlled,
                                      salt=salt)
        self.agents = list(self.world.live)
        self._frames, self._last_behavior, self._cycles = [], "", 0
        if self.render_mode == "rgb_array_list":
            self._capture()
        return obs, infos

    def check_actions(self, actions: dict[str, Any]) -> dict[str, int | np.ndarray]:
        """The actions of the agents that need a decision, in canonical form
        (:func:`~hbmp_bench.envs.actions.check_action`): the one place an action is validated.
        ValueError for bad input (see the module docstring)."""
        stray = sorted(set(actions) - set(self.agents))
        if stray:
            raise ValueError(f"actions for agents that are not live: {stray}; live agents: {self.agents}")
        world = self.world
        missing = [a for a in self.agents if world.needs_decision(a) and actions.get(a) is None]
        if missing:
            raise ValueError(f"agents {missing} need a decision (info['decision_required']) but got no action")
        single = len(self.possible_agents) == 1
        return {agent: check_action(self._action_spaces[agent], actions[agent],
                                    "action" if single else f"action of {agent}")
                for agent in self.agents if world.needs_decision(agent)}

    def step(self, actions: dict[str, Any]):
        if not self.agents:
            raise RuntimeError("call reset() before step() (and again after the episode ends)")
        clean = self.check_actions(actions)
        if EGO_ID in clean and self.config.ego_driver != "control":
            self._last_behavior = BEHAVIORS[clean[EGO_ID]]
        self._cycles += 1
        last = self.max_cycles is not None and self._cycles >= self.max_cycles
        result = self.world.step(clean, on_substep=self._capture if self.render_mode == "rgb_array_list" else None,
                                 last=last)
        self.agents = list(self.world.live)
        return result

    # ------------------------------------------------------------- pictures
    def _frame(self) -> np.ndarray:
        from hbmp_bench.render import TopDownRenderer
        from hbmp_bench.render.scene import scene_view

        if self._renderer is None:
            self._renderer = TopDownRenderer(self.world.net)
        w = self.world
        caption = f"{self.town} {self.task}  t={w.sim.time:5.1f} s  {w.ego.state.speed:4.1f} m/s  {self._last_behavior}"
        if self.n_controlled:
            caption += f"  {len(self.agents)} agents"
        return self._renderer.frame(scene_view(w, caption))

    def _capture(self) -> None:
        self._frames.append(self._frame())

    def render(self) -> np.ndarray | list[np.ndarray] | None:
        """``rgb_array``: the (H, W, 3) uint8 top-down view centred on the ego now, drawn by this
        call; ``rgb_array_list``: the frames of every 0.1 s SUMO step since the last call or reset,
        oldest first (:meth:`drain_frames`); None without a render mode."""
        if self.render_mode is None:
            return None
        if self._world is None or self._world.ego is None:
            raise RuntimeError("call reset() before render()")
        if self.render_mode == "rgb_array_list":
            return self.drain_frames()
        return self._frame()

    def drain_frames(self) -> list[np.ndarray]:
        """All frames rendered at every 0.1 s simulation step since the last call (the frames
        between decisions), oldest first; empty unless ``render_mode="rgb_array_list"``."""
        frames, self._frames = self._frames, []
        return frames

    def __getstate__(self) -> dict:
        """The env before its first reset (see the module docstring, Copies)."""
        state = self.__dict__.copy()
        state.update(_world=None, _renderer=None, _frames=[], agents=[], _cycles=0, _last_behavior="")
        return state

    def record(self, agent: str = ""):
        """The ego's episode record so far (:class:`~hbmp_bench.metrics.EpisodeRecord`); None before
        the first reset."""
        if self._world is None or self._world.episode is None:
            return None
        return self._world.record(agent)

    def records(self, agent: str = "") -> list:
        """Every goal-directed agent's episode record so far (``ego`` first; final once its episode has
        ended, as in its last ``info["hbmp_record"]``); [] before the first reset."""
        if self._world is None or self._world.episode is None:
            return []
        return self._world.records(agent)

    def close(self) -> None:
        if self._world is not None:
            self._world.close()
        self.agents = []


def parallel_env(**kwargs) -> TrafficParallelEnv:
    """The parallel env (see :class:`TrafficParallelEnv` for the arguments)."""
    return TrafficParallelEnv(**kwargs)


def env(**kwargs):
    """The AEC env through PettingZoo's ``parallel_to_aec``."""
    return parallel_to_aec(TrafficParallelEnv(**kwargs))


raw_env = TrafficParallelEnv


class EgoEnv(EgoView):
    """Single-ego gymnasium view of :class:`TrafficParallelEnv` with policy-driven background agents.

    ``step(action)`` acts for the ego; every background agent that needs a decision gets one from
    its own instance of ``background_policy`` (an agent name or ``module:Class``, see
    :func:`hbmp_bench.agents.load_agent`), and the parallel env is stepped until the ego needs its
    next decision or its episode ends. Rewards, ends and infos are the ego's. Made by :func:`ego_env`;
    arguments as :class:`TrafficParallelEnv` (``max_cycles`` counts the parallel env's steps, which
    any agent's decision ends, not the ego's). A copy is made before its first reset, as the
    parallel env's.
    """

    def __init__(self, background_policy: str = "expert", **kwargs):
        from hbmp_bench.agents import load_agent

        load_agent(background_policy)  # fail fast on a bad name
        self.background_policy = background_policy
        super().__init__(TrafficParallelEnv(**kwargs))
        self._policies: dict[str, Any] = {}
        self._obs: dict[str, Any] = {}
        self._infos: dict[str, Any] = {}

    def __getstate__(self) -> dict:
        """Before its first reset, as the parallel env's copies (the policies are made at reset)."""
        return {**self.__dict__, "_policies": {}, "_obs": {}, "_infos": {}}

    def _after_reset(self, obs: dict, infos: dict) -> None:
        from hbmp_bench.agents import load_agent

        self._obs, self._infos = obs, infos
        self._policies = {a: load_agent(self.background_policy) for a in self.parallel.possible_agents if a != EGO_ID}
        for a, policy in self._policies.items():
            if a in self._infos:
                policy.reset(self._infos[a])

    def _background_actions(self) -> dict[str, int]:
        return {a: int(self._policies[a].act(self._obs[a], self._infos[a])) for a in self.parallel.agents
                if a != EGO_ID and self._infos[a]["decision_required"]}

    def step(self, action):
        if EGO_ID not in self.parallel.agents:
            raise RuntimeError("call reset() before step() (and again after the episode ends)")
        actions = {**self._background_actions(), EGO_ID: action}
        total = 0.0
        while True:
            obs, rewards, terms, truncs, infos = self.parallel.step(actions)
            self._obs.update(obs)
            self._infos.update(infos)
            total += float(rewards.get(EGO_ID, 0.0))
            if terms.get(EGO_ID) or truncs.get(EGO_ID) or infos[EGO_ID]["decision_required"]:
                return obs[EGO_ID], total, bool(terms.get(EGO_ID)), bool(truncs.get(EGO_ID)), infos[EGO_ID]
            actions = self._background_actions()


def ego_env(background_policy: str = "expert", **kwargs) -> EgoEnv:
    """A single-ego gymnasium env whose controlled background vehicles are driven by
    ``background_policy`` (default: the expert, ``controlled="all"``); keyword arguments as
    :class:`TrafficParallelEnv`."""
    return EgoEnv(background_policy, **kwargs)
