"""PPO's rollout for learners that decide at different times: the learners of one scene in continuous fidelity.

In continuous fidelity a behavior lasts until the motion planner converges (1-8 s), so the learners of a scene
(``WorkerEnvConfig.agents``, :class:`~hbmp_bench.training.worker.SceneRunner`) finish theirs at different
moments, and each must decide the moment its behavior ends. rsl-rl's runner steps every env at once; here
instead, per simulation step of the workers (:meth:`~hbmp_bench.training.vec_env.WorkerVecEnv.step_slots`):

1. the slots that must decide now are batched through the policy (:meth:`ActingPolicy.act`, rsl-rl's
   ``PPO.act``: one forward pass; action, value, log-probability and distribution kept as that slot's *open*
   decision);
2. the workers run until some slot's behavior or episode ends; each reply completes that slot's open
   decision (the reward gathered since it, its ends) and, unless it ended, asks for the next;
3. once every slot has completed ``steps_per_slot`` transitions, row ``t`` of rsl-rl's storage is the ``t``-th
   transition of every slot (``alg.process_env_step``: its time-out bootstrapping as in rsl-rl), and the
   returns bootstrap from each slot's next observation.

A slot that completes its quota early keeps driving: its further transitions start the next rollout (taken
with the policy before the update, whose log-probabilities they carry: PPO's ratio is against the policy that
acted). A slot's transitions are its own decisions in order, so GAE runs along each learner's own episodes,
as in single-ego training; a decision's transition spans its whole behavior, as there.

With ``overlap_update`` (``--ppo overlap_update=true``) the workers do not wait for the update: see
:func:`learn_async`. A scene whose learners all decide at every step (``flat``'s controls, event fidelity) is
the case where every slot decides and completes at every step (``WorkerVecEnv.step_slots``), so the overlapped
update runs there by the same loop.
"""

from __future__ import annotations

import copy as _copy
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDict


@dataclass
class Decision:
    """One slot's decision and, once its transition completed, the outcome."""

    obs: TensorDict
    action: torch.Tensor
    value: torch.Tensor
    log_prob: torch.Tensor
    params: tuple[torch.Tensor, ...]
    reward: float = 0.0
    done: bool = False
    time_out: bool = False


class ActingPolicy:
    """The actor and critic a roll-out acts with: ``alg``'s own, or (``copy``) copies that follow them only
    at :meth:`sync`, so an update may change ``alg``'s networks in another thread while the copies act.

    :meth:`act` is rsl-rl's ``PPO.act`` (the same operations, so the same numbers) without its
    ``transition`` bookkeeping."""

    def __init__(self, alg, copy: bool = False):
        self.alg, self.copied = alg, bool(copy)
        self.actor = _copy.deepcopy(alg.actor) if copy else alg.actor
        self.critic = _copy.deepcopy(alg.critic) if copy else alg.critic

    def sync(self) -> None:
        """Copies: take ``alg``'s current weights (and normalisers); own networks: nothing to do."""
        if self.copied:
            self.actor.load_state_dict(self.alg.actor.state_dict())
            self.critic.load_state_dict(self.alg.critic.state_dict())

    def act(self, obs: TensorDict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...]]:
        """Sampled actions (B, num_actions), values (B, 1), log-probabilities (B,) and distribution parameters."""
        actions = self.actor(obs, stochastic_output=True).detach()
        values = self.critic(obs).detach()
        log_prob = self.actor.get_output_log_prob(actions).detach()
        return actions, values, log_prob, tuple(p.detach() for p in self.actor.output_distribution_params)


class AsyncRollout:
    """Collects ``steps_per_slot`` transitions of every slot of an asynchronous VecEnv, then fills ``alg.storage``.

    Args:
        env: a :class:`~hbmp_bench.training.vec_env.WorkerVecEnv` with ``asynchronous`` True, just reset.
        alg: rsl-rl's PPO (the package's subclass) whose storage is ``(steps_per_slot, env.num_envs)``.
        steps_per_slot: transitions per slot and rollout (``num_steps_per_env``).
        policy: what acts (default: ``alg``'s own networks).
    """

    def __init__(self, env, alg, steps_per_slot: int, policy: ActingPolicy | None = None):
        self.env, self.alg, self.T = env, alg, int(steps_per_slot)
        self.policy = policy or ActingPolicy(alg)
        n = env.num_envs
        self.completed: list[list[Decision]] = [[] for _ in range(n)]
        self.open: list[Decision | None] = [None] * n
        self.deciding: dict[int, Any] = dict(enumerate(env._replies))  # after the reset every slot decides

    def _decide(self) -> dict[int, Any]:
        """Actions for the deciding slots, one forward pass; each becomes that slot's open decision."""
        slots = sorted(self.deciding)
        obs = self.env.stack([self.deciding[k] for k in slots])
        actions, values, log_prob, params = self.policy.act(obs)
        for i, k in enumerate(slots):
            self.open[k] = Decision(obs[i], actions[i], values[i], log_prob[i], tuple(p[i] for p in params))
        self.deciding = {}
        return {k: actions[i].cpu().numpy() for i, k in enumerate(slots)}

    def collect(self) -> TensorDict:
        """Run until every slot has ``T`` completed transitions; returns (num_envs,) the observation after each
        slot's ``T``-th transition (for the returns' bootstrap). :meth:`fill` then moves them to the storage."""
        while min(len(c) for c in self.completed) < self.T:
            actions = self._decide() if self.deciding else {}
            for k, reply in self.env.step_slots(actions):
                if reply.completes:
                    decision = self.open[k]
                    decision.reward = float(reply.reward)
                    decision.done = bool(reply.terminated or reply.truncated)
                    decision.time_out = bool(reply.truncated and not reply.terminated)
                    self.completed[k].append(decision)
                    self.open[k] = None
                if reply.decides:
                    self.deciding[k] = reply
        return self._next_observations()

    def fill(self, last: TensorDict) -> None:
        """The storage's rows from the first ``T`` completed transitions of every slot (row ``t``: each slot's
        ``t``-th), then the returns and advantages, bootstrapped from ``last`` with the critic that acted (the
        one whose values the rows hold)."""
        self._fill()
        for c in self.completed:
            del c[:self.T]
        trained = self.alg.critic
        self.alg.critic = self.policy.critic  # rsl-rl's compute_returns evaluates alg.critic on ``last``
        try:
            self.alg.compute_returns(last)
        finally:
            self.alg.critic = trained

    def _fill(self) -> None:
        alg, n = self.alg, self.env.num_envs
        for t in range(self.T):
            rows = [self.completed[k][t] for k in range(n)]
            tr = alg.transition
            tr.observations = torch.stack([r.obs for r in rows])
            tr.actions = torch.stack([r.action for r in rows])
            tr.values = torch.stack([r.value for r in rows])
            tr.actions_log_prob = torch.stack([r.log_prob for r in rows])
            tr.distribution_params = tuple(torch.stack([r.params[i] for r in rows]) for i in range(len(rows[0].params)))
            tr.hidden_states = (None, None)
            rewards = torch.tensor([r.reward for r in rows], dtype=torch.float32)
            dones = torch.tensor([r.done for r in rows], dtype=torch.long)
            alg.process_env_step(tr.observations, rewards, dones,
                                 {"time_outs": torch.tensor([r.time_out for r in rows], dtype=torch.long)})

    def _next_observations(self) -> TensorDict:
        """Per slot, the observation its next transition starts from: the next completed one's, else its open
        decision's, else the one it is asked to decide on; after an end (masked by ``done``) its last."""
        out = []
        for k in range(self.env.num_envs):
            if len(self.completed[k]) > self.T:
                out.append(self.completed[k][self.T].obs)
            elif self.open[k] is not None:
                out.append(self.open[k].obs)
            elif k in self.deciding:
                out.append(self.env.stack([self.deciding[k]])[0])
            else:
                out.append(self.completed[k][self.T - 1].obs)
        return torch.stack(out)


def learn_async(runner, env, steps_per_slot: int, on_iteration, overlap_update: bool = False) -> None:
    """rsl-rl's learning loop (``OnPolicyRunner.learn``) with :class:`AsyncRollout` as its rollout: rollout,
    returns, update, then ``on_iteration(losses)`` (which ends the loop by raising), until it does.

    ``overlap_update``: the update runs in a thread while the workers collect the next roll-out, acted by
    copies of the networks the update starts from (:class:`ActingPolicy`); so update ``k`` (from the policy
    θ_k) learns from roll-out ``k``, collected with θ_{k-1} (PPO's ratio and clip are against the policy that
    acted, whose log-probabilities the roll-out holds). The schedule does not depend on timing and the update
    draws no random number in its thread (its mini-batch order is drawn before it starts), so a seed gives the
    same run. Without it the workers wait for every update (about a third of a continuous-fidelity iteration
    on 2 cores), with it they do not."""
    alg = runner.alg
    alg.train_mode()
    policy = ActingPolicy(alg, copy=overlap_update)
    rollout = AsyncRollout(env, alg, steps_per_slot, policy)
    with torch.inference_mode():
        last = rollout.collect()
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="ppo-update") as pool:
        while True:
            with torch.inference_mode():
                rollout.fill(last)
            if not overlap_update:
                on_iteration(alg.update())
                with torch.inference_mode():
                    last = rollout.collect()
                continue
            policy.sync()  # the next roll-out acts with the policy this update starts from
            # the order drawn here: the acting samples and the update's order stay in one sequence
            update = pool.submit(alg.update, alg.shuffle())
            try:
                with torch.inference_mode():
                    last = rollout.collect()
            finally:
                losses = update.result()
            on_iteration(losses)
