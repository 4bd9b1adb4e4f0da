"""A small multi-agent suite for the evaluation tests: importing this module registers ``tiny-scene``.

Three goal-directed vehicles per scene on short Town01 Straight routes among SUMO's traffic, two scenes.
Child processes learn the suite by importing this module through the env factory ``tiny_scene:make_env``
(``RunnerLimits(env_factory=...)``), as ``tiny_suite``'s do.
"""

from __future__ import annotations

from hbmp_bench.envs.scene_env import SceneEnv
from hbmp_bench.scenarios import SUITES, Suite, register_suite

NAME = "tiny-scene"
FACTORY = "tiny_scene:make_env"

if NAME not in SUITES:
    register_suite(Suite(name=NAME, towns=("Town01",), tasks=("Straight",), episodes_per_task=2, seed=11, agents=3,
                         end_on_violation=True, density="regular",
                         description="Two Town01 Straight scenes of three goal-directed vehicles (tests only)."))


def make_env(**kwargs):
    return SceneEnv(**kwargs)
