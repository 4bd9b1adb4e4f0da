"""The replica attack (issue 41, finding 3), as agents loaded by the tests as ``replica_agents:Class``.

The agent rebuilds the episode it is driving in its own process, from the public suite and the
importable package, with ``privileged=True``, and drives the privileged expert on the replica in
lockstep: it sends the evaluator the expert's actions while its entry says ``privileged: false``.

Its episode's identity is no longer in ``info``, so it finds its episode the way any agent can: the
start pose (``info["scene"]["lane_pos_m"]`` at reset is the episode's ``start_pos``) matches one
public episode. In the public (unsalted) episodes the replica then runs in lockstep with the real
episode; in a salted evaluation the traffic, pedestrians and light phases of the real episode take
a salt the agent does not know, and the replica is another episode.
"""

from __future__ import annotations

import re

import numpy as np

from hbmp_bench.agents.expert import ExpertAgent

SUITE = "hbmp"
FIDELITY = "event"
TOWNS = ("Town01",)
"""Where the attacker looks for its episode (the towns of the tests, so the search stays quick)."""
TASKS = ("NavigationDynamic",)


def find_episode(info: dict, suite: str = SUITE, towns=TOWNS, tasks=TASKS) -> tuple[str, str, int]:
    """(town, task, index) of the public episode whose start pose is the one ``info`` (a reset's)
    shows: start position on its lane, then the straight-line distance to the goal."""
    from hbmp_bench.scenarios import road_network, suite_episodes

    scene = info["scene"]
    best, gap = None, None
    for town in towns:
        net = road_network(town)
        for task in tasks:
            for episode in suite_episodes(suite, town, task):
                if abs(episode.start_pos - scene["lane_pos_m"]) > 0.01:
                    continue
                start = np.asarray(net.position(episode.start_lane, episode.start_pos))
                goal = np.asarray(net.position(episode.goal_lane, episode.goal_pos))
                off = abs(float(np.hypot(*(start - goal))) - scene["goal_distance_m"])
                if gap is None or off < gap:
                    best, gap = (town, task, episode.index), off
    if best is None:
        raise RuntimeError(f"no public episode starts at {scene['lane_pos_m']} m of its lane")
    return best


def public_key(info: dict, suite: str = "corl2017", towns=("Town01",), tasks=("Straight",)) -> str:
    """``town/task/index`` of the public episode ``info`` starts (what ``info["episode_key"]`` said)."""
    return "/".join(map(str, find_episode(info, suite, towns, tasks)))


def _without_numba_cache() -> None:
    """Let the package's kernels compile where its folder is read-only (an agent in the sandbox):
    what an attacker who imports the simulation stack there does first."""
    import numba

    if getattr(numba, "_replica_no_cache", False):
        return
    original = numba.njit

    def njit(*args, **kwargs):
        kwargs["cache"] = False
        return original(*args, **kwargs)

    numba.njit, numba._replica_no_cache = njit, True


class ReplicaAttacker:
    """Drives the privileged expert on a replica of its episode; asks for nothing (unprivileged).

    ``STRICT``: compare the real observation with the replica's at every decision and stop (raise,
    so the record names the decision) at the first difference; otherwise drive the replica's
    expert blind, whatever the real episode does.
    """

    name = "replica"
    STRICT = True

    def __init__(self):
        self.replica = self.expert = None
        self.decisions = 0
        self.key = None

    def reset(self, info):
        _without_numba_cache()
        from hbmp_bench.envs.behavior_env import BehaviorEnv

        town, task, index = self.key = find_episode(info)
        if self.replica is None:
            self.replica = BehaviorEnv(town=town, task=task, suite=SUITE, fidelity=FIDELITY, privileged=True)
        self.expert = ExpertAgent()
        # what the evaluator's env process does (env_process.run_episode)
        self.obs, self.info = self.replica.reset(seed=index, options={"episode_index": index})
        self.expert.reset(self.info)
        self.decisions = 0

    def act(self, observation, info):
        if self.STRICT:
            same = all(np.array_equal(np.asarray(observation[k]), np.asarray(self.obs[k])) for k in self.obs)
            if not same:
                raise RuntimeError(f"replica desynced at decision {self.decisions} of {'/'.join(map(str, self.key))}")
        action = int(self.expert.act(self.obs, self.info))
        self.obs, _, _, _, self.info = self.replica.step(action)
        self.decisions += 1
        return action


class BlindReplicaAttacker(ReplicaAttacker):
    """The replica attack without the check: the replica's expert drives the real episode."""

    STRICT = False


HEX_RUN = re.compile(r"[0-9a-f]{32,64}")


class SaltHunter:
    """Looks for the salt in its own process: every string its interpreter holds (``gc``), its
    environment, its command line and its parent's, and sends every 32-64 hex digit run it found
    back as its error (the test checks that the evaluation's salt is not among them)."""

    name = "salt-hunter"

    def reset(self, info):
        import gc
        import os

        found = set()
        for obj in gc.get_objects():
            for value in (obj.values() if isinstance(obj, dict) else obj if isinstance(obj, (list, tuple)) else ()):
                if isinstance(value, str):
                    found.update(HEX_RUN.findall(value))
                elif isinstance(value, bytes):
                    found.update(HEX_RUN.findall(value.decode("latin-1")))
        found.update(HEX_RUN.findall(repr(info)))
        found.update(HEX_RUN.findall(" ".join(f"{k}={v}" for k, v in os.environ.items())))
        for pid in ("self", str(os.getppid())):
            for part in ("cmdline", "environ"):
                try:
                    with open(f"/proc/{pid}/{part}", "rb") as fh:
                        found.update(HEX_RUN.findall(fh.read().decode("latin-1")))
                except OSError:
                    pass
        raise RuntimeError("hex runs found: " + " ".join(sorted(found)))

    def act(self, observation, info):
        return 4
