"""The environment side of the training ``VecEnv``: one environment per worker process.

libsumo runs one simulation per process, so every environment lives in its own process and
talks to the trainer over a pipe (:func:`run_worker`) or as a Ray actor (:class:`EnvActor`).
This module does not import torch, so that the workers start fast; the torch side is
:mod:`hbmp_bench.training.vec_env`.

Protocol (parent → worker, worker → parent):
    ("reset", seed)  → ("ok", StepReply)   first reset of the worker's run
    ("step", action) → ("ok", StepReply)   one decision; auto-resets when the episode ends
    ("close", None)  → ("ok", None)        closes the environment; the worker then exits
    any failure      → ("error", text)     the exception and its traceback
"""

from __future__ import annotations

import dataclasses
import traceback
from dataclasses import dataclass
from typing import Any

import numpy as np

from hbmp_bench.envs.registration import RECORD_KEY
from hbmp_bench.errors import ConfigError
from hbmp_bench.vocabulary import INFRACTION_KINDS, TRAINING_REWARD_MODES


@dataclass(frozen=True)
class WorkerEnvConfig:
    """How every worker builds its environment and what it reports.

    Attributes:
        env_id: a registered id (``hbmp_bench/Training-v0``: Town03, random start and goal each reset).
        env_kwargs: options for the environment (``fidelity``, ``observation``, ``density`` ...) as
            ``(name, value)`` pairs, so the config stays immutable; see :attr:`kwargs`.
        entry_point: ``module:Class`` built instead of the id's own class, with the id's registered
            options plus ``env_kwargs`` (the flat baseline's control env); None: the id's class.
        reward: one of :data:`~hbmp_bench.vocabulary.TRAINING_REWARD_MODES`.
        expert_labels: also report the rule-based expert's behavior for every observation (DAgger);
            the env is then made with the options the expert asks for (``privileged=True``: its
            info, never the learner's observation, holds the privileged scene).
        reward_scale: factor on the training reward (the CSV log keeps r_T and r_k unscaled).
        expert_controls: also report the control ``[a, s]`` the expert's stack would apply in the ego's
            state (the flat baseline's DAgger: :class:`~hbmp_bench.training.expert_control.ExpertControl`);
            the env is made with the options the expert asks for, as for ``expert_labels``.
        agents: learners per simulation: each worker's scene holds this many goal-directed vehicles, each a
            slot of the VecEnv (:class:`SceneRunner`; 1: the single-ego :class:`EnvRunner`).
    """

    env_id: str = "hbmp_bench/Training-v0"
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    entry_point: str | None = None
    reward: str = "dense"
    expert_labels: bool = False
    reward_scale: float = 1.0
    expert_controls: bool = False
    agents: int = 1

    def __post_init__(self):
        if self.reward not in TRAINING_REWARD_MODES:
            raise ConfigError(f"reward must be one of {TRAINING_REWARD_MODES}, got {self.reward!r}")
        if isinstance(self.agents, bool) or not isinstance(self.agents, int) or self.agents < 1:
            raise ConfigError(f"agents must be an int >= 1, got {self.agents!r}")
        if self.agents > 1 and self.expert_controls:
            raise ConfigError("expert controls label one ego; with agents > 1 use expert_labels")
        if not self.reward_scale > 0:
            raise ConfigError(f"reward_scale must be > 0, got {self.reward_scale}")
        object.__setattr__(self, "env_kwargs", tuple(sorted((str(k), v) for k, v in dict(self.env_kwargs).items())))

    @property
    def kwargs(self) -> dict[str, Any]:
        return dict(self.env_kwargs)


def make_env(config: WorkerEnvConfig):
    """The environment a worker runs (constructing it starts no simulation)."""
    import hbmp_bench  # noqa: F401  (registers the ids)
    from hbmp_bench.envs import make

    if config.entry_point is None:
        return make(config.env_id, **config.kwargs)
    import gymnasium as gym

    from hbmp_bench.envs import env_ids
    from hbmp_bench.errors import UnknownNameError

    if config.env_id not in env_ids():
        raise UnknownNameError("env id", config.env_id, env_ids())
    from hbmp_bench.plugins import resolve

    factory = resolve(config.entry_point, "environment class")
    return factory(**{**gym.spec(config.env_id).kwargs, **config.kwargs})


@dataclass
class EpisodeTally:
    """Running sums of one episode: r_T, r_k and the training reward, and the decision count."""

    r_T: float = 0.0
    r_k: float = 0.0
    reward: float = 0.0
    length: int = 0

    def add(self, env_reward: float, train_reward: float, info: dict, decision: bool = True) -> None:
        """Add one step: r_T and r_k from ``info["reward_components"]`` (else r_T = env reward); ``decision``:
        the step ended one of the agent's decisions (False: a step of an asynchronous scene that another
        vehicle's decision ended, while this one's behavior runs on)."""
        parts = info.get("reward_components", {})
        self.r_T += float(parts.get("r_T", env_reward))
        self.r_k += float(parts.get("r_k", 0.0))
        self.reward += train_reward
        self.length += int(decision)

    def summary(self, info: dict) -> dict[str, Any]:
        """One training-log row (without the episode counter): rewards, outcome, infractions, length."""
        record = info.get(RECORD_KEY, {})
        return {
            "r_T": self.r_T,
            "r_T_plus_r_t": self.r_T + self.r_k,
            "train_return": self.reward,
            "success": bool(record.get("success", False)),
            "infractions": int(sum(record.get(f, 0) for f in INFRACTION_KINDS)),
            "length": self.length,
            "end_reason": str(record.get("end_reason", "")),
            "route_completion": float(record.get("route_completion", 0.0)),
            "sim_time_s": float(record.get("duration_s", 0.0)),
            "episode_key": str(info.get("episode_key", "")),
        }


def training_reward(mode: str, reward: float, info: dict, scale: float = 1.0) -> float:
    """The reward the learner sees under ``mode`` (see :data:`~hbmp_bench.vocabulary.TRAINING_REWARD_MODES`), times ``scale``."""
    if mode == "env":
        return scale * float(reward)
    parts = info["reward_components"]
    value = float(parts["r_T"]) if mode == "sparse" else float(parts["r_T"]) + float(parts["r_k"])
    return scale * value


@dataclass
class StepReply:
    """What a worker sends back after a reset or a step.

    obs: the current observation (after an auto-reset: the new episode's first one).
    reward: training reward of the step [-] (0 after a reset).
    terminated / truncated: the step ended the episode (goal or violation / the env's timeout).
    action_mask: (5,) int8 feasible behaviors of ``obs``, None if the env has none.
    expert_action: the expert's behavior for ``obs`` (-1 when labels are off).
    episode: the finished episode's summary when the step ended one.
    expert_control: (2,) float32 the control the expert's stack applies in ``obs``'s state (None when
        ``expert_controls`` is off).
    completes / decides: an asynchronous scene's slot (:meth:`SceneRunner.step` with a dict): the reply
        completes the slot's last transition (``reward`` since its last decision, the ends) / asks for a
        decision on ``obs``. Both True in every other reply.
    """

    obs: dict[str, np.ndarray]
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    action_mask: np.ndarray | None = None
    expert_action: int = -1
    episode: dict[str, Any] | None = None
    expert_control: np.ndarray | None = None
    completes: bool = True
    decides: bool = True


class EnvRunner:
    """The worker's state: its environment, the expert (for labels) and the running episode."""

    def __init__(self, config: WorkerEnvConfig):
        self.expert = self.controls = None
        if config.expert_labels or config.expert_controls:
            from hbmp_bench.agents import agent_env_kwargs, load_agent

            expert = load_agent("expert")
            config = dataclasses.replace(config, env_kwargs={**agent_env_kwargs(expert), **config.kwargs})
            if config.expert_controls:
                from hbmp_bench.training.expert_control import ExpertControl

                self.controls = ExpertControl(expert)
            else:
                self.expert = expert
        self.config = config
        self.env = make_env(config)
        self.tally = EpisodeTally()

    def _reply(self, obs: dict, info: dict, new_episode: bool, **fields) -> StepReply:
        expert_action, expert_control = -1, None
        if self.expert is not None:
            if new_episode:
                self.expert.reset(info)
            expert_action = int(self.expert.act(obs, info))
        if self.controls is not None:
            if new_episode:
                self.controls.reset(info)
            expert_action, expert_control = self.controls.label(self.env, obs, info)
        mask = info.get("action_mask")
        return StepReply(obs={k: np.asarray(v) for k, v in obs.items()},
                         action_mask=None if mask is None else np.asarray(mask, dtype=np.int8),
                         expert_action=expert_action, expert_control=expert_control, **fields)

    def reset(self, seed: int | None) -> StepReply:
        obs, info = self.env.reset(seed=seed)
        self.tally = EpisodeTally()
        return self._reply(obs, info, new_episode=True)

    def step(self, action) -> StepReply:
        obs, env_reward, terminated, truncated, info = self.env.step(action)
        reward = training_reward(self.config.reward, float(env_reward), info, self.config.reward_scale)
        self.tally.add(float(env_reward), reward, info)
        if not (terminated or truncated):
            return self._reply(obs, info, new_episode=False, reward=reward)
        summary = self.tally.summary(info)
        reply = self.reset(None)
        return dataclasses.replace(reply, reward=reward, terminated=bool(terminated), truncated=bool(truncated),
                                   episode=summary)

    def close(self) -> None:
        self.env.close()


class EnvActor:
    """Ray actor body (:class:`~hbmp_bench.training.vec_env.RayVecEnv`): one :class:`EnvRunner` (one
    env, one libsumo) in the actor's own process, answering the same requests as a pipe worker."""

    def __init__(self, config: WorkerEnvConfig):
        self.runner = make_runner(config)

    def request(self, command: str, arg) -> StepReply | None:
        if command == "step":
            return self.runner.step(arg)
        if command == "reset":
            return self.runner.reset(arg)
        if command == "close":
            self.runner.close()
            return None
        raise ValueError(f"unknown worker command {command!r}")


def run_worker(conn, config: WorkerEnvConfig) -> None:
    """Process entry point: serve reset/step/close requests on ``conn`` until closed."""
    runner = None
    try:
        runner = make_runner(config)
        while True:
            command, arg = conn.recv()
            if command == "step":
                conn.send(("ok", runner.step(arg)))
            elif command == "reset":
                conn.send(("ok", runner.reset(arg)))
            elif command == "close":
                runner.close()
                runner = None
                conn.send(("ok", None))
                return
            else:
                raise ValueError(f"unknown worker command {command!r}")
    except (EOFError, KeyboardInterrupt):
        pass
    except BaseException as exc:  # report anything to the parent, then exit
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
        except (BrokenPipeError, OSError):
            pass
    finally:
        if runner is not None:
            runner.close()
        conn.close()


def make_runner(config: WorkerEnvConfig) -> "EnvRunner | SceneRunner":
    """The runner of one worker: :class:`SceneRunner` with ``agents`` > 1, else :class:`EnvRunner`."""
    return SceneRunner(config) if config.agents > 1 else EnvRunner(config)


def asynchronous_scene(config: WorkerEnvConfig) -> bool:
    """Whether the learners of a worker's scene decide at different times: several learners with the
    behavior driver in continuous fidelity (behaviors of 1-8 s); event fidelity and the control driver
    decide every 0.1 s step."""
    import gymnasium as gym

    import hbmp_bench  # noqa: F401  (registers the ids)

    options = {**gym.spec(config.env_id).kwargs, **config.kwargs}
    control = (config.entry_point or "").endswith(":ControlEnv") or options.get("ego_driver") == "control"
    return config.agents > 1 and not control and (options.get("fidelity") or "continuous") != "event"


RESPAWN_ATTEMPTS = 50
"""Draws of a new start for a finished learner before the slot waits a step and tries again."""


class SceneRunner:
    """``config.agents`` learners in one simulation: the goal-directed vehicles ``ego``, ``ego1`` ... of one
    scene of the id's town (random starts and goals, SUMO's traffic and pedestrians around them), each a slot.

    ``reset`` / ``step`` take and return one entry per slot, in slot order. A learner's episode ends by the
    env's rules (its goal, a violation, its timeout), as a single ego's; the slot then gets a new start, goal
    and route at once (``DrivingWorld.respawn``, a start no vehicle stands on), so the scene stays full and an
    episode in the budget stays one learner's episode from its start to its end. SUMO inserts the new vehicle
    at the next simulation step: the step after an end is the slot's *arrival* (its action is ignored, reward
    0, and it ends there, so no return or value crosses from one episode into the next); its observation is
    the new episode's first.

    Synchronous scenes (event fidelity, the control driver: every vehicle decides at every step) take and
    return a list, one entry per slot. Asynchronous ones (continuous behaviors, 1-8 s, ending at different
    times: :attr:`asynchronous`) take ``{slot: action}`` for the slots that decide and return ``[(slot,
    reply)]`` for the slots whose transition completed or that must decide now (``StepReply.completes`` /
    ``decides``); a slot running its behavior is absent and gathers its rewards until its next reply. The
    arrival after an end is then a reply that decides without completing anything.
    """

    def __init__(self, config: WorkerEnvConfig):
        import gymnasium as gym

        import hbmp_bench  # noqa: F401  (registers the ids)
        from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv

        self.config = config
        options = {**gym.spec(config.env_id).kwargs, **config.kwargs}
        if config.entry_point is not None and config.entry_point.endswith(":ControlEnv"):
            options["ego_driver"] = "control"
        self.experts: list | None = None
        if config.expert_labels:
            from hbmp_bench.agents import agent_env_kwargs, load_agent

            self.experts = [load_agent("expert") for _ in range(config.agents)]
            options = {**agent_env_kwargs(self.experts[0]), **options}
        self.env = TrafficParallelEnv(**options, agents=config.agents, controlled="none")
        self.asynchronous = asynchronous_scene(config)
        """Behaviors end at different times (continuous fidelity): slots decide when theirs ends."""
        self.slots = list(self.env.goal_agents)
        self._gathered = [0.0] * len(self.slots)
        self.tallies = [EpisodeTally() for _ in self.slots]
        self._last: list[StepReply | None] = [None] * len(self.slots)
        self._arriving: set[str] = set()
        self._rng = np.random.default_rng()

    def _reply(self, k: int, obs: dict, info: dict, new_episode: bool, **fields) -> StepReply:
        expert_action = -1
        if self.experts is not None:
            if new_episode:
                self.experts[k].reset(info)
            expert_action = int(self.experts[k].act(obs, info))
        mask = info.get("action_mask")
        reply = StepReply(obs={key: np.asarray(v) for key, v in obs.items()},
                          action_mask=None if mask is None else np.asarray(mask, dtype=np.int8),
                          expert_action=expert_action, **fields)
        self._last[k] = reply
        return reply

    def reset(self, seed: int | None) -> list[StepReply]:
        self._rng = np.random.default_rng(seed)
        obs, infos = self.env.reset(seed=seed)
        self.tallies = [EpisodeTally() for _ in self.slots]
        self._arriving = set()
        return [self._reply(k, obs[v], infos[v], new_episode=True) for k, v in enumerate(self.slots)]

    def step(self, actions):
        """One step of the scene: see the class docstring (a list for a synchronous scene, a dict for an
        asynchronous one)."""
        if self.asynchronous:
            return self._step_async(actions)
        return self._step_sync(actions)

    def _advance(self, actions: dict[str, Any]):
        live = set(self.env.agents)
        if live:
            return self.env.step({v: a for v, a in actions.items() if v in live})
        out = self.env.world.step({})  # every slot is arriving: one simulation step inserts them
        self.env.agents = list(self.env.world.live)
        return out

    def _step_async(self, actions: dict[int, Any]) -> list[tuple[int, StepReply]]:
        obs, rewards, terms, truncs, infos = self._advance({self.slots[k]: a for k, a in actions.items()})
        out = []
        for k, v in enumerate(self.slots):
            if v in self._arriving and v in self.env.agents:  # inserted: decides on its new episode's first obs
                self._arriving.discard(v)
                self.tallies[k], self._gathered[k] = EpisodeTally(), 0.0
                out.append((k, dataclasses.replace(self._reply(k, obs[v], infos[v], new_episode=True),
                                                   completes=False)))
                continue
            if v not in obs:
                if v not in self._arriving:
                    self._respawn(v)  # no free start at its end: try again
                continue
            reward = training_reward(self.config.reward, float(rewards[v]), infos[v], self.config.reward_scale)
            ended = terms[v] or truncs[v]
            completes = ended or infos[v]["decision_required"]
            self.tallies[k].add(float(rewards[v]), reward, infos[v], decision=completes)
            self._gathered[k] += reward
            if completes:
                reply = self._reply(k, obs[v], infos[v], new_episode=False, reward=self._gathered[k],
                                    terminated=bool(terms[v]), truncated=bool(truncs[v] and not terms[v]),
                                    episode=self.tallies[k].summary(infos[v]) if ended else None, decides=not ended)
                self._gathered[k] = 0.0
                out.append((k, reply))
                if ended:
                    self._respawn(v)
        return out

    def _step_sync(self, actions: list) -> list[StepReply]:
        obs, rewards, terms, truncs, infos = self._advance({v: actions[k] for k, v in enumerate(self.slots)})
        replies = []
        for k, v in enumerate(self.slots):
            if v in self._arriving and v in self.env.agents:  # inserted: the new episode's first observation
                self._arriving.discard(v)
                self.tallies[k] = EpisodeTally()
                reply = self._reply(k, obs[v], infos[v], new_episode=True)
                replies.append(dataclasses.replace(reply, terminated=True))
            elif v not in obs:  # still waiting for a free start or for SUMO's insertion
                self._respawn(v)
                replies.append(dataclasses.replace(self._last[k], reward=0.0, terminated=True, truncated=False,
                                                   episode=None))
            else:
                reward = training_reward(self.config.reward, float(rewards[v]), infos[v], self.config.reward_scale)
                self.tallies[k].add(float(rewards[v]), reward, infos[v])
                ended = terms[v] or truncs[v]
                reply = self._reply(k, obs[v], infos[v], new_episode=False, reward=reward, terminated=bool(terms[v]),
                                    truncated=bool(truncs[v] and not terms[v]),
                                    episode=self.tallies[k].summary(infos[v]) if ended else None)
                if ended:
                    self._respawn(v)
                replies.append(reply)
        return replies

    def _respawn(self, vehicle: str) -> None:
        """A new episode for ``vehicle`` from a free start (none found: it tries again at the next step)."""
        world = self.env.world
        if vehicle in self._arriving:
            return
        for _ in range(RESPAWN_ATTEMPTS):
            leg = self.env.scenario.pick(self._rng)
            if world.start_is_free(leg):
                world.respawn(vehicle, dataclasses.replace(leg, others=()))
                self._arriving.add(vehicle)
                return

    def close(self) -> None:
        self.env.close()
