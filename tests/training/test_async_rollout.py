"""The rollout of learners that decide at different times (``training.async_rollout``): every slot's own
decisions in order, with the rewards gathered over each behavior, fill rsl-rl's storage row by row; a slot
that completes its quota early carries its further transitions into the next rollout."""

import time
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from hbmp_bench.training.async_rollout import AsyncRollout, learn_async
from hbmp_bench.training.worker import StepReply


class FakeScene:
    """Two slots: slot 0's behavior lasts one step, slot 1's three; slot 0's episode ends at its 3rd decision.
    An observation's ``road`` holds (slot, decision number); the reward of a transition is 10 x slot + its
    decision number, gathered over its steps."""

    num_envs = 2

    def __init__(self):
        self.decisions = [0, 0]
        self.busy = [0, 0]
        self._replies = [self._reply(0, completes=False), self._reply(1, completes=False)]

    def _reply(self, slot, completes=True, done=False):
        obs = {"road": np.array([slot, self.decisions[slot]], dtype=np.float32)}
        return StepReply(obs=obs, reward=10.0 * slot + self.decisions[slot] if completes else 0.0, terminated=done,
                         completes=completes, decides=True)

    def stack(self, replies):
        return TensorDict({"road": torch.as_tensor(np.stack([r.obs["road"] for r in replies]))},
                          batch_size=[len(replies)])

    def step_slots(self, actions):
        for slot in actions:
            self.busy[slot] = 1 if slot == 0 else 3
        out = []
        for slot in (0, 1):
            self.busy[slot] -= 1
            if self.busy[slot] == 0:
                self.decisions[slot] += 1
                out.append((slot, self._reply(slot, done=slot == 0 and self.decisions[slot] == 3)))
        return out


class FakeActor(torch.nn.Module):
    """An actor whose ``version`` (a buffer an update raises by one) shows in what it returns: action = slot
    + 0.5, log-probability = -version, distribution parameter = the slot."""

    def __init__(self):
        super().__init__()
        self.register_buffer("version", torch.zeros(()))

    def forward(self, obs, stochastic_output=False):
        road = obs["road"]
        self.output_distribution_params = (road[:, :1],)
        self._n = road.shape[0]
        return road[:, :1] + 0.5

    def get_output_log_prob(self, actions):
        return -self.version * torch.ones(self._n)


class FakeCritic(FakeActor):
    def forward(self, obs):
        return obs["road"][:, 1:2] * 100.0


class FakePPO:
    """The parts of rsl-rl's PPO the rollout and the loop use; the storage is a list of rows. ``update`` raises
    the actor's and the critic's version by one and keeps what it learnt from."""

    class Transition:
        def clear(self):
            self.__dict__.clear()

    def __init__(self, update_s=0.0):
        self.transition = self.Transition()
        self.actor, self.critic = FakeActor(), FakeCritic()
        self.rows, self.updates, self.returns_critics = [], [], []
        self.update_s = update_s

    def train_mode(self):
        pass

    def process_env_step(self, obs, rewards, dones, extras):
        t = self.transition
        self.rows.append({"obs": t.observations["road"].clone(), "rewards": rewards.clone(), "dones": dones.clone(),
                          "values": t.values.clone(), "acted_by": float(-t.actions_log_prob[1])})  # slot 1: the slowest, never carried over

    def compute_returns(self, last):
        self.returns_critics.append(float(self.critic.version))

    def shuffle(self):
        return torch.randperm(4)

    def update(self, indices=None):
        time.sleep(self.update_s)
        self.updates.append({"from": float(self.actor.version), "rows": [r["acted_by"] for r in self.rows]})
        self.rows = []
        with torch.no_grad():
            self.actor.version += 1
            self.critic.version += 1
        return {"value": 0.0}


def test_each_slot_fills_its_column_with_its_own_decisions_in_order():
    env, alg = FakeScene(), FakePPO()
    rollout = AsyncRollout(env, alg, steps_per_slot=2)
    last = rollout.collect()
    rollout.fill(last)
    assert len(alg.rows) == 2
    for t, row in enumerate(alg.rows):
        # column k holds slot k's t-th decision (made on its observation after t decisions)
        assert row["obs"].tolist() == [[0.0, t], [1.0, t]]
        assert row["rewards"].tolist() == [t + 1.0, 10.0 + t + 1]
        assert row["values"][:, 0].tolist() == [100.0 * t, 100.0 * t]
    # slot 0 decided 6 times meanwhile: its 3rd transition (its episode's end) starts the next rollout
    assert last["road"].tolist() == [[0.0, 2.0], [1.0, 2.0]]
    assert [len(c) for c in rollout.completed] == [4, 0]
    alg.rows.clear()
    rollout.fill(rollout.collect())
    assert alg.rows[0]["obs"].tolist() == [[0.0, 2.0], [1.0, 2.0]]
    assert alg.rows[0]["dones"].tolist() == [1, 0]  # slot 0's third decision ended its episode


class Stop(Exception):
    pass


def _learn(overlap, iterations=4, update_s=0.0):
    env, alg = FakeScene(), FakePPO(update_s)

    def on_iteration(losses):
        if len(alg.updates) == iterations:
            raise Stop

    with pytest.raises(Stop):
        learn_async(SimpleNamespace(alg=alg), env, 2, on_iteration, overlap_update=overlap)
    return alg


def test_without_overlap_each_rollout_is_acted_by_the_policy_it_updates():
    alg = _learn(overlap=False)
    assert [u["from"] for u in alg.updates] == [0, 1, 2, 3]
    assert [u["rows"] for u in alg.updates] == [[0, 0], [1, 1], [2, 2], [3, 3]]
    assert alg.returns_critics == [0, 1, 2, 3]  # bootstrapped by the critic that acted


def test_with_overlap_update_k_learns_from_the_rollout_acted_by_the_policy_before_it():
    """The workers collect roll-out k+1 while update k runs (it sleeps here, so the roll-out really runs
    beside it): that roll-out is acted by the copies of θ_k, never by the networks being updated, and fills
    the storage only after the update; the schedule is the same however long the update takes."""
    alg = _learn(overlap=True, update_s=0.05)
    assert [u["from"] for u in alg.updates] == [0, 1, 2, 3]
    assert [u["rows"] for u in alg.updates] == [[0, 0], [0, 0], [1, 1], [2, 2]]  # two rows per update, one policy
    assert alg.returns_critics == [0, 0, 1, 2]  # the critic that acted bootstraps, not the updated one
    assert _learn(overlap=True, update_s=0.0).updates == alg.updates


@pytest.mark.slow
def test_learners_of_a_continuous_scene_decide_when_their_behavior_ends():
    from hbmp_bench.training.worker import SceneRunner, WorkerEnvConfig

    runner = SceneRunner(WorkerEnvConfig(env_kwargs={"density": "regular"}, agents=3))
    try:
        assert runner.asynchronous
        replies = runner.reset(3)
        assert len(replies) == 3
        pending, sizes, completed = {0: 0, 1: 0, 2: 0}, [], [0, 0, 0]
        for round_ in range(60):
            out = runner.step(pending)
            sizes.append(len(out))
            assert all(r.completes or r.decides for _, r in out)
            for k, r in out:
                completed[k] += r.completes
            # slot 0 speeds up, slot 1 keeps, slot 2 alternates: behaviors of different lengths
            pending = {k: (0, 4, round_ % 2)[k] for k, r in out if r.decides}
        assert min(completed) >= 3
        assert min(sizes) < 3  # some steps ended one slot's behavior and not the others'
        lengths = [t.length for t in runner.tallies]
        assert all(0 < n <= c for n, c in zip(lengths, completed))  # decisions, not simulation steps
    finally:
        runner.close()
