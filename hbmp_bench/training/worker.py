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
            state (the flat baseline's DAgger: :class:`~hbmp_bench.training.control_dagger.ExpertControl`);
            the env is made with the options the expert asks for, as for ``expert_labels``.
    """

    env_id: str = "hbmp_bench/Training-v0"
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    entry_point: str | None = None
    reward: str = "dense"
    expert_labels: bool = False
    reward_scale: float = 1.0
    expert_controls: bool = False

    def __post_init__(self):
        if self.reward not in TRAINING_REWARD_MODES:
            raise ConfigError(f"reward must be one of {TRAINING_REWARD_MODES}, got {self.reward!r}")
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

    def add(self, env_reward: float, train_reward: float, info: dict) -> None:
        """Add one decision: r_T and r_k from ``info["reward_components"]`` (else r_T = env reward)."""
        parts = info.get("reward_components", {})
        self.r_T += float(parts.get("r_T", env_reward))
        self.r_k += float(parts.get("r_k", 0.0))
        self.reward += train_reward
        self.length += 1

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
    """

    obs: dict[str, np.ndarray]
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    action_mask: np.ndarray | None = None
    expert_action: int = -1
    episode: dict[str, Any] | None = None
    expert_control: np.ndarray | None = None


class EnvRunner:
    """The worker's state: its environment, the expert (for labels) and the running episode."""

    def __init__(self, config: WorkerEnvConfig):
        self.expert = self.controls = None
        if config.expert_labels or config.expert_controls:
            from hbmp_bench.agents import agent_env_kwargs, load_agent

            expert = load_agent("expert")
            config = dataclasses.replace(config, env_kwargs={**agent_env_kwargs(expert), **config.kwargs})
            if config.expert_controls:
                from hbmp_bench.training.control_dagger import ExpertControl

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
        self.runner = EnvRunner(config)

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
        runner = EnvRunner(config)
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
