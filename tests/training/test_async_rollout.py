"""The rollout of learners that decide at different times (``training.async_rollout``): every slot's own
decisions in order, with the rewards gathered over each behavior, fill rsl-rl's storage row by row; a slot
that completes its quota early carries its further transitions into the next rollout."""

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from hbmp_bench.training.async_rollout import AsyncRollout
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


class FakePPO:
    """The parts of rsl-rl's PPO the rollout uses; the storage is a list of rows."""

    class Transition:
        def clear(self):
            self.__dict__.clear()

    def __init__(self):
        self.transition = self.Transition()
        self.rows = []

    def act(self, obs):
        n = obs.batch_size[0]
        self.transition.values = obs["road"][:, 1:2] * 100.0
        self.transition.actions_log_prob = obs["road"][:, 1] * -1.0
        self.transition.distribution_params = (obs["road"][:, :1],)
        self.acted = obs["road"].clone()
        return obs["road"][:, :1] + 0.5 * torch.ones(n, 1)

    def process_env_step(self, obs, rewards, dones, extras):
        t = self.transition
        self.rows.append({"obs": t.observations["road"].clone(), "rewards": rewards.clone(), "dones": dones.clone(),
                          "values": t.values.clone()})


def test_each_slot_fills_its_column_with_its_own_decisions_in_order():
    env, alg = FakeScene(), FakePPO()
    rollout = AsyncRollout(env, alg, steps_per_slot=2)
    last = rollout.collect()
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
    rollout.collect()
    assert alg.rows[0]["obs"].tolist() == [[0.0, 2.0], [1.0, 2.0]]
    assert alg.rows[0]["dones"].tolist() == [1, 0]  # slot 0's third decision ended its episode


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
