"""Env factories that inject simulation faults, used as ``RunnerLimits(env_factory="faulty_envs:...")``.

Each wraps the real ``BehaviorEnv``. A fault fires on the first attempt of an episode only when
``HBMP_TEST_FAULT_DIR`` names a folder: a marker file per episode remembers that it fired, so
the retry runs clean.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import gymnasium as gym

from hbmp_bench.envs.behavior_env import BehaviorEnv

FAULT_AT_DECISION = 5


class _FaultOnce(gym.Wrapper):
    def __init__(self, env, fault):
        super().__init__(env)
        self.fault = fault
        self.decisions = 0
        self.marker: Path | None = None

    def reset(self, *, seed=None, options=None):
        self.decisions = 0
        folder = os.environ.get("HBMP_TEST_FAULT_DIR")
        e = self.env.unwrapped
        self.marker = Path(folder) / f"{e.town}-{e.task}-{(options or {}).get('episode_index')}" if folder else None
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        self.decisions += 1
        if self.decisions == FAULT_AT_DECISION and self.marker is not None and not self.marker.exists():
            self.marker.write_text("fired")
            self.fault()
        return self.env.step(action)


def _hang():
    time.sleep(10**6)


def _crash():
    os.kill(os.getpid(), signal.SIGKILL)


def _raise():
    raise RuntimeError("SUMO lost the plot")


def hang_once(**kwargs):
    """The simulation step hangs once per episode (the watchdog must kill and retry)."""
    return _FaultOnce(BehaviorEnv(**kwargs), _hang)


def crash_once(**kwargs):
    """The env process dies once per episode (the retry must run it again)."""
    return _FaultOnce(BehaviorEnv(**kwargs), _crash)


class _AlwaysRaise(gym.Wrapper):
    def step(self, action):
        raise RuntimeError("SUMO lost the plot")


def always_raise(**kwargs):
    """Every step raises: the episode ends as a sim_error after its retry."""
    return _AlwaysRaise(BehaviorEnv(**kwargs))
