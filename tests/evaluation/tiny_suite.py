"""A two-episode suite for leaderboard tests: importing this module registers ``tiny-test``.

Child processes learn the suite by importing this module through the env factory
``tiny_suite:make_env`` (``RunnerLimits(env_factory=...)``).
"""

from __future__ import annotations

from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.scenarios import SUITES, Suite, register_suite

NAME = "tiny-test"

if NAME not in SUITES:
    register_suite(Suite(name=NAME, towns=("Town01",), tasks=("Straight",), episodes_per_task=2, seed=7,
                         description="Two Town01 Straight episodes (tests only)."))


def make_env(**kwargs):
    return BehaviorEnv(**kwargs)
