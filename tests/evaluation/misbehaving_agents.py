"""Agents that break the rules, loaded as ``misbehaving_agents:Class`` in the evaluation tests.

They are real agent classes (the Agent protocol), run in the agent process like any submission.
"""

from __future__ import annotations

import os
import time

from hbmp_bench.agents.expert import ExpertAgent

KEEP = 4


class _Base:
    name = "misbehaving"

    def __init__(self):
        self.decisions = 0

    def reset(self, info):
        self.decisions = 0


class RaisingAgent(_Base):
    """Raises in ``act`` at its fourth decision of every episode."""

    def act(self, observation, info):
        self.decisions += 1
        if self.decisions == 4:
            raise RuntimeError("the policy network exploded")
        return KEEP


class ThreadReportingAgent(_Base):
    """Fails its first decision with the size of torch's thread pool in the message."""

    def act(self, observation, info):
        import torch

        raise RuntimeError(f"torch threads={torch.get_num_threads()}")


class HangingAgent(_Base):
    """Never answers its third decision."""

    def act(self, observation, info):
        self.decisions += 1
        if self.decisions == 3:
            time.sleep(10**6)
        return KEEP


class InvalidActionAgent(_Base):
    """Returns behavior 7 (there are five)."""

    def act(self, observation, info):
        return 7


class FloatActionAgent(_Base):
    """Returns a float instead of a behavior index."""

    def act(self, observation, info):
        return 1.5


class DyingAgent(_Base):
    """Its process exits abruptly at the second decision."""

    def act(self, observation, info):
        self.decisions += 1
        if self.decisions == 2:
            os._exit(3)
        return KEEP


class BrokenInitAgent:
    """Cannot be built."""

    name = "broken"

    def __init__(self):
        raise ImportError("weights file missing")

    def reset(self, info):
        pass

    def act(self, observation, info):
        return KEEP


class SlowAgent(_Base):
    """Takes 0.3 s per decision."""

    def act(self, observation, info):
        time.sleep(0.3)
        return KEEP


class SlowExpert(ExpertAgent):
    """The expert, 2 ms slower per decision (so a run lasts long enough to be killed mid-way)."""

    def act(self, observation, info):
        time.sleep(0.002)
        return super().act(observation, info)


class CheatingAgent(_Base):
    """Tries to teleport the ego to its goal through libsumo, then keeps standing still.

    The goal comes from the public suite registry; the attempt's result is appended to the file
    named by ``HBMP_TEST_CHEAT_LOG`` when set.
    """

    def reset(self, info):
        super().reset(info)
        self.key = info.get("episode_key", "Town01/Straight/0")  # no longer in info: the tests run this one

    def act(self, observation, info):
        self.decisions += 1
        if self.decisions == 1:
            import libsumo

            from hbmp_bench.scenarios import suite_episodes

            town, task, index = self.key.split("/")
            episode = suite_episodes("corl2017", town, task)[int(index)]
            try:
                libsumo.vehicle.moveTo("ego", episode.goal_lane, episode.goal_pos)
                outcome = "moved"
            except Exception as exc:  # noqa: BLE001
                outcome = f"failed: {type(exc).__name__}: {exc}"
            log = os.environ.get("HBMP_TEST_CHEAT_LOG")
            if log:
                with open(log, "a", encoding="utf-8") as fh:
                    fh.write(outcome + "\n")
        return KEEP
