"""Agents that break a scene's rules, loaded as ``scene_agents:Class`` in the multi-agent evaluation tests.

Each has ``act_batch`` (``agents.scene.SceneAgent`` then gives it every deciding vehicle's observation in one
call and sends its dict back as it is) and drives every vehicle with the expert otherwise.
"""

from __future__ import annotations

from hbmp_bench.agents.expert import ExpertAgent

KEEP = 4


class _Batched:
    """The expert per vehicle, behind ``act_batch``."""

    name = "scene-test"
    env_kwargs = {"privileged": True}  # the expert's

    def __init__(self):
        self.experts: dict[str, ExpertAgent] = {}

    def reset(self, info):
        pass

    def act(self, observation, info):
        """A single-ego episode's decision (the expert's); a scene asks ``act_batch``."""
        return self.honest({"ego": observation}, {"ego": info})["ego"]

    def honest(self, observations, infos) -> dict:
        actions = {}
        for vehicle, observation in observations.items():
            if vehicle not in self.experts:
                self.experts[vehicle] = ExpertAgent()
                self.experts[vehicle].reset(infos[vehicle])
            actions[vehicle] = self.experts[vehicle].act(observation, infos[vehicle])
        return actions


class ActsForAnotherAgent(_Batched):
    """Acts, besides the deciding vehicles, for a goal-directed vehicle that does not decide now (or, when all
    decide, for one the scene has not)."""

    def act_batch(self, observations, infos):
        actions = self.honest(observations, infos)
        others = [f"ego{k}" for k in range(1, 9) if f"ego{k}" not in observations]
        actions[others[0]] = KEEP
        return actions


class LeavesOneOutAgent(_Batched):
    """Leaves the last deciding vehicle out of its reply."""

    def act_batch(self, observations, infos):
        actions = self.honest(observations, infos)
        actions.pop(sorted(actions)[-1])
        return actions


class HonestBatchedAgent(_Batched):
    """The expert per vehicle through ``act_batch``: the control case."""

    def act_batch(self, observations, infos):
        return self.honest(observations, infos)
