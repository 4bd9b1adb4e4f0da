"""One episode of an agent in a gymnasium env: the one loop every runner uses (evaluation, the
in-process runner, videos, the highway-env transfer, the benchmark).

``run_episode(env, agent, seed=...)`` resets, asks the agent, steps, until the episode ends, the
decision cap, or a hook says stop. What differs between callers goes through
:class:`EpisodeHooks`; failures come out as :class:`AgentFailed` (the agent's ``reset`` / ``act``
or the action check raised) or :class:`EnvFailed` (the env's ``reset`` / ``step`` raised), each
with the original exception as ``__cause__`` and its message, so a caller can score them
differently.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


class AgentFailed(Exception):
    """The agent raised in ``reset`` or ``act``, or its action failed the check."""

    def __init__(self, message: str, decisions: int):
        super().__init__(message)
        self.decisions = decisions


class EnvFailed(Exception):
    """The env raised in ``reset`` or ``step`` (``phase``)."""

    def __init__(self, message: str, phase: str, decisions: int):
        super().__init__(message)
        self.phase, self.decisions = phase, decisions


@dataclass
class EpisodeHooks:
    """What a caller adds to the loop; every field is optional.

    Attributes:
        on_reset: called with (observation, info) after the env's reset.
        check_action: called with (action, decisions so far) before the step; returns the action
            to step with (e.g. converted), raises to reject it (an :class:`AgentFailed`).
        on_step: called with (observation, reward, terminated, truncated, info) after every step.
        stop: called with the run so far before every decision; True ends the loop there (the
            episode left running).
    """

    on_reset: Callable[[Any, dict], None] | None = None
    check_action: Callable[[Any, int], Any] | None = None
    on_step: Callable[[Any, float, bool, bool, dict], None] | None = None
    stop: Callable[["EpisodeRun"], bool] | None = None


@dataclass
class EpisodeRun:
    """What one call of :func:`run_episode` did.

    Attributes:
        ended: the episode ended (terminated or truncated); False: cut by the cap or ``stop``.
        decisions: steps taken.
        info: the last info (``info["hbmp_record"]`` holds the record when ``ended`` for the package's envs).
        reset_s: wall time of the env's reset [s].
        act_s / step_s: wall time of each ``agent.act`` / ``env.step`` call [s].
        stepping_s: their sum over ``env.step`` [s].
    """

    ended: bool = False
    decisions: int = 0
    info: dict = field(default_factory=dict)
    reset_s: float = 0.0
    act_s: list[float] = field(default_factory=list)
    step_s: list[float] = field(default_factory=list)
    stepping_s: float = 0.0

    def record(self, env) -> dict:
        """The episode record: the final one when the episode ended, else the env's record so far."""
        from hbmp_bench.envs.registration import RECORD_KEY

        if self.ended and RECORD_KEY in self.info:
            return dict(self.info[RECORD_KEY])
        return env.unwrapped.record().to_dict()


def run_episode(env, agent, *, seed: int | None = None, options: dict | None = None,
                max_decisions: int | None = None, hooks: EpisodeHooks | None = None) -> EpisodeRun:
    """Run ``agent`` (``reset(info)``, ``act(observation, info)``) in ``env`` for one episode.

    Raises:
        AgentFailed / EnvFailed: see the module docstring (``decisions`` says where).
    """
    hooks = hooks or EpisodeHooks()
    run = EpisodeRun()
    start = time.perf_counter()
    try:
        obs, info = env.reset(seed=seed, options=options)
    except Exception as exc:
        raise EnvFailed(str(exc), "reset", 0) from exc
    run.reset_s = time.perf_counter() - start
    run.info = info
    if hooks.on_reset is not None:
        hooks.on_reset(obs, info)
    try:
        agent.reset(info)
    except Exception as exc:
        raise AgentFailed(str(exc), 0) from exc
    while max_decisions is None or run.decisions < max_decisions:
        if hooks.stop is not None and hooks.stop(run):
            break
        start = time.perf_counter()
        try:
            action = agent.act(obs, info)
            if hooks.check_action is not None:
                action = hooks.check_action(action, run.decisions)
        except Exception as exc:
            raise AgentFailed(str(exc), run.decisions) from exc
        run.act_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        try:
            obs, reward, terminated, truncated, info = env.step(action)
        except Exception as exc:
            raise EnvFailed(str(exc), "step", run.decisions) from exc
        run.step_s.append(time.perf_counter() - start)
        run.stepping_s += run.step_s[-1]
        run.decisions += 1
        run.info = info
        if hooks.on_step is not None:
            hooks.on_step(obs, reward, terminated, truncated, info)
        if terminated or truncated:
            run.ended = True
            break
    return run
