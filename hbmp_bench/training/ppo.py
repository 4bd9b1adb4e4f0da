"""PPO with rsl-rl for the behavior policy (hbmp, hbmp-s) and the flat control baseline.

rsl-rl's ``OnPolicyRunner`` and ``PPO`` do the learning; this module supplies the environment
(:class:`~hbmp_bench.training.vec_env.SubprocVecEnv`, or Ray actors:
:class:`~hbmp_bench.training.vec_env.RayVecEnv`), the paper's network and hyper-parameters, and the
bookkeeping of a run (episode CSV, checkpoints, resume, curves, model card).

Deviations from the paper, and why:
- Two learning rates. rsl-rl's PPO has one optimizer; :class:`TwoRatePPO` gives it two Adam
  parameter groups, the actor's at ``LR_a`` = 1e-4 and the critic's at ``LR_c`` = 5e-4. Actor and
  critic share no weights, so this is the same as two Adam optimizers. Fixed by default; with
  ``desired_kl`` the actor's rate follows rsl-rl's adaptive rule (÷1.5 when the mini-batch KL to the
  roll-out policy exceeds 2 × desired, ×1.5 below ½ × desired), the critic's stays at ``LR_c``
  (rsl-rl's own schedule would set both groups to one rate).
- λ's scale (the env's ``ExecutorConfig.reward_scale``, 0.25): the paper leaves the scale of its
  cost-to-reward mapping open. At scale 1 the dense reward paid for violations: a standing car costs
  c_dist = 1 per decision, so waiting through a red (23-57 s in the towns) cost more than running it
  (r_T = −10) and a violation ends the episode. PPO from il found that: red-light ends per 100 training
  episodes 42 → 57 → 67, goals 49 → 32 → 29 (``hbmp-cont`` in ``training_runs/README.md``, scale 1). The drift the anchor
  below was built against is this reward, not only the clip: the same run at scale 0.01
  (``hbmp-scale001`` in ``training_runs/README.md``) rose from 57 % to 88 % training success within 200 PPO episodes,
  but there standing still was free and the greedy policy stood; 0.25 bounds both ways (see the
  ``reward_scale`` docstring).
- IL anchor (not in the paper; ``anchor_coef``, default 0): the loss gains ``anchor_coef`` times a KL
  between the policy and π_IL, the frozen ``--init`` actor, over the mini-batch's states:
  ``anchor_kl="forward"``: KL(π_IL ‖ π), mass-covering (π must keep probability wherever π_IL has some,
  so it cannot sharpen); ``"reverse"``: KL(π ‖ π_IL), mode-seeking (π may concentrate on π_IL's likely
  behaviors, but pays for mass where π_IL has little). Why: from a peaked IL policy, PPO's ratio clip
  is lopsided in probability space. A behavior the IL policy picks with p = 0.95 can lose up to 20 %
  of it after one failed episode
  (0.95 → 0.76) but gain at most 5 % after a success, so advantage noise alone (1-2 episodes per
  iteration, a ±100 terminal reward) flattens the policy: measured, the entropy rose 0.33 → 0.42 and
  training success fell 49 → 29 % over 200 episodes with the paper's settings
  (``hbmp-cont`` in ``training_runs/README.md``). The anchor keeps the policy where the data do not say otherwise; the
  KL to π_IL is logged per iteration (``kl_init``).
- Batch size 32 is the mini-batch: each iteration collects ``num_steps_per_env`` decisions in
  each worker and splits them into mini-batches of 32.
- Not given in the paper, rsl-rl's defaults kept: GAE λ = 0.95, 5 epochs per iteration, entropy
  coefficient 0.01, value-loss coefficient 1, gradient-norm clip 1, clipped value loss. Any field of
  :class:`PPOConfig` can be set with ``train --ppo NAME=VALUE``.
- Rewards are scaled by ``reward_scale`` = 0.01 for learning (r_T is ±100 / −50, which the
  clipped value loss would follow only slowly); advantages are normalised, so the policy
  gradient does not depend on the scale. Logs keep the unscaled rewards.
- Discounting is per decision (the paper's approximation γ^{t_k} ≈ γ^k).
- ``checkpoint.pt`` holds the actor, the critic and the run's progress, not Adam's moments (they
  would triple its size to ~7 MB, too large to commit every 30 minutes): a resume restarts Adam,
  a transient of a few updates at LR 1e-4 once per resume.
- Sampling temperature (not in the paper; ``temperature``, default 1): the behavior policy is
  softmax(logits / τ). The evaluated policy is the greedy one (its most likely behavior, which τ does
  not change); from ``il`` it succeeds in 95 % of the ``hbmp-val`` episodes while the policy PPO samples
  in training succeeds in ~55 %: most training failures are exploration the evaluated policy never
  does, and PPO improved the sampled policy while the greedy one wandered (``training_runs/hbmp-rules11``,
  ``hbmp-rev01``). With τ < 1 the roll-outs act closer to the greedy policy, so PPO learns from the
  failures of the policy that is evaluated. Measured at τ = 0.5 (``hbmp-t05`` in ``training_runs/README.md``): the sampled
  il succeeds in 84 % of the training episodes, and PPO did not raise that in 350 episodes.
- Critic warm-up (not in the paper): with an IL initialisation the actor starts good and the critic
  random, and PPO's first updates would follow the random critic's advantages away from the IL
  policy. For the first ``critic_warmup_episodes`` the actor's learning rate is 0, so only the
  critic learns (on roll-outs of the IL policy itself); those episodes count in the budget.

rsl-rl's ``OnPolicyRunner.learn`` drives the iterations (roll-out, returns, update); the run's own
bookkeeping (episode CSV, per-iteration losses, checkpoints, the warm-up switch, the episode budget)
happens after each iteration in :class:`RunLogger`, rsl-rl's logger with one hook.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import warnings
from dataclasses import dataclass
from typing import Any

import torch
from rsl_rl.algorithms import PPO
from torch import nn
from rsl_rl.utils import resolve_optimizer
from rsl_rl.utils.logger import Logger

from hbmp_bench.errors import ConfigError, UserError
from hbmp_bench.policies.checkpoints import load_checkpoint
from hbmp_bench.policies.networks import NETWORK, behavior_model_cfgs, control_model_cfgs, observation_shapes
from hbmp_bench.training.run import RunConfig
from hbmp_bench.training.runlog import EPISODE_COLUMNS, ITERATION_COLUMNS
from hbmp_bench.training.session import TrainingSession
from hbmp_bench.training.validation import Validator, validation_results
from hbmp_bench.training.worker import WorkerEnvConfig

MASK_GROUP = "action_mask"
ANCHOR_KL = ("forward", "reverse")
INIT_KINDS = {"behavior": ("il", "hbmp", "hbmp-s"), "flat": ("flat-il", "flat")}
"""The checkpoint kinds a PPO run's ``--init`` actor may come from: behavior policies for hbmp and hbmp-s,
control policies for flat (``flat-il``: PPO from the imitation of the expert's controls)."""


class TwoRatePPO(PPO):
    """rsl-rl PPO with separate learning rates for the actor and the critic, an optional adaptive actor
    rate and an optional KL anchor to the initial (IL) actor.

    Args:
        actor_learning_rate: Adam learning rate of the actor's parameters (paper: 1e-4); the start
            value when ``desired_kl`` is given.
        critic_learning_rate: Adam learning rate of the critic's parameters (paper: 5e-4).
        desired_kl: None (fixed actor rate) or the target KL per mini-batch of the adaptive actor rate.
        anchor_coef: weight of the KL between π and π_anchor in the loss; the anchor is set by
            :meth:`set_anchor`.
        anchor_kl: ``forward`` (KL(π_anchor ‖ π)) or ``reverse`` (KL(π ‖ π_anchor)).
        schedule: must be ``fixed`` (the adaptive rule here is the actor's only: ``desired_kl``).
        other arguments: as ``rsl_rl.algorithms.PPO``.
    """

    ACTOR_LR_BOUNDS = (1e-6, 1e-3)
    """Range of the adaptive actor rate [1/step] (rsl-rl's is 1e-5..1e-2, for from-scratch locomotion)."""

    def __init__(self, actor, critic, storage, actor_learning_rate: float = 1e-4, critic_learning_rate: float = 5e-4,
                 desired_kl: float | None = None, anchor_coef: float = 0.0, anchor_kl: str = "forward",
                 optimizer: str = "adam",
                 schedule: str = "fixed", **kwargs: Any) -> None:
        if schedule != "fixed":
            raise ValueError("TwoRatePPO's adaptive rate is the actor's only: give desired_kl, keep schedule 'fixed'")
        if "learning_rate" in kwargs:
            raise ValueError("give actor_learning_rate and critic_learning_rate instead of learning_rate")
        super().__init__(actor, critic, storage, learning_rate=actor_learning_rate, optimizer=optimizer,
                         schedule="fixed", **kwargs)
        self.actor_learning_rate = actor_learning_rate
        self.actor_desired_kl = desired_kl
        self.anchor_coef = anchor_coef
        self.anchor_kl = anchor_kl
        self.anchor = None
        self.optimizer = resolve_optimizer(optimizer)([
            {"params": list(self.actor.parameters()), "lr": actor_learning_rate},
            {"params": list(self.critic.parameters()), "lr": critic_learning_rate},
        ])
        self._frozen = False

    def set_anchor(self, state_dict: dict[str, torch.Tensor]) -> None:
        """Freeze a copy of the actor with ``state_dict`` as π_anchor (the IL policy)."""
        self.anchor = copy.deepcopy(self.actor)
        self.anchor.load_state_dict(state_dict)
        self.anchor.eval()
        for param in self.anchor.parameters():
            param.requires_grad_(False)

    def freeze_actor(self, frozen: bool) -> None:
        """Actor learning rate 0 (critic warm-up) or ``actor_learning_rate``; the critic's is unchanged."""
        self._frozen = frozen
        self.optimizer.param_groups[0]["lr"] = 0.0 if frozen else self.actor_learning_rate

    @property
    def actor_frozen(self) -> bool:
        return self._frozen

    def shuffle(self) -> torch.Tensor:
        """The order of the storage's transitions in the next update's mini-batches (a permutation, drawn from
        torch's global generator as rsl-rl's ``mini_batch_generator`` draws it)."""
        n = self.storage.num_envs * self.storage.num_transitions_per_env
        size = n // self.num_mini_batches
        return torch.randperm(self.num_mini_batches * size, requires_grad=False, device=self.device)

    def _mini_batches(self, indices: torch.Tensor):
        """rsl-rl's feed-forward ``mini_batch_generator`` over ``indices`` (the same permutation every epoch)."""
        from rsl_rl.storage.rollout_storage import RolloutStorage

        st = self.storage
        observations, actions = st.observations.flatten(0, 1), st.actions.flatten(0, 1)
        values, returns = st.values.flatten(0, 1), st.returns.flatten(0, 1)
        log_probs, advantages = st.actions_log_prob.flatten(0, 1), st.advantages.flatten(0, 1)
        params = tuple(p.flatten(0, 1) for p in st.distribution_params)
        size = len(indices) // self.num_mini_batches
        for _ in range(self.num_learning_epochs):
            for i in range(self.num_mini_batches):
                idx = indices[i * size:(i + 1) * size]
                yield RolloutStorage.Batch(observations=observations[idx], actions=actions[idx], values=values[idx],
                                           advantages=advantages[idx], returns=returns[idx],
                                           old_actions_log_prob=log_probs[idx],
                                           old_distribution_params=tuple(p[idx] for p in params))

    def update(self, indices: torch.Tensor | None = None) -> dict[str, float]:
        """rsl-rl's PPO update for what this package uses (feed-forward models, one process, no RND, no
        symmetry), with the actor-only adaptive rate and the anchor term. Returns the mean losses, the
        mean KL to the anchor (``kl_init``, 0 without one) and the actor's rate at the end (``actor_lr``).

        ``indices``: the mini-batches' order (:meth:`shuffle`; None: drawn here). The update draws no other
        random number (the distributions are evaluated, not sampled), so an update run in another thread
        while the next roll-out samples actions (``PPOConfig.overlap_update``) leaves the run deterministic."""
        if self.actor.is_recurrent or self.critic.is_recurrent or self.rnd or self.symmetry or self.is_multi_gpu:
            raise NotImplementedError("TwoRatePPO.update covers feed-forward models on one process only")
        sums = {"value": 0.0, "surrogate": 0.0, "entropy": 0.0, "kl_init": 0.0}
        updates = 0
        for batch in self._mini_batches(self.shuffle() if indices is None else indices):
            if self.normalize_advantage_per_mini_batch:
                with torch.no_grad():
                    batch.advantages = (batch.advantages - batch.advantages.mean()) / (batch.advantages.std() + 1e-8)
            self.actor.distribution.update(self.actor.distribution_input(batch.observations))
            log_prob = self.actor.get_output_log_prob(batch.actions)
            params = self.actor.output_distribution_params
            entropy = self.actor.output_entropy
            values = self.critic(batch.observations, masks=batch.masks)
            if self.actor_desired_kl is not None and not self._frozen:
                with torch.no_grad():
                    kl = self.actor.get_kl_divergence(batch.old_distribution_params, params).mean().item()
                low, high = self.ACTOR_LR_BOUNDS
                if kl > 2.0 * self.actor_desired_kl:
                    self.actor_learning_rate = max(low, self.actor_learning_rate / 1.5)
                elif 0.0 < kl < 0.5 * self.actor_desired_kl:
                    self.actor_learning_rate = min(high, self.actor_learning_rate * 1.5)
                self.optimizer.param_groups[0]["lr"] = self.actor_learning_rate
            ratio = torch.exp(log_prob - torch.squeeze(batch.old_actions_log_prob))
            advantages = torch.squeeze(batch.advantages)
            surrogate = torch.max(-advantages * ratio,
                                  -advantages * torch.clamp(ratio, 1.0 - self.clip_param, 1.0 + self.clip_param)).mean()
            if self.use_clipped_value_loss:
                clipped = batch.values + (values - batch.values).clamp(-self.clip_param, self.clip_param)
                value_loss = torch.max((values - batch.returns).pow(2), (clipped - batch.returns).pow(2)).mean()
            else:
                value_loss = (batch.returns - values).pow(2).mean()
            loss = surrogate + self.value_loss_coef * value_loss - self.entropy_coef * entropy.mean()
            if self.anchor is not None:
                with torch.no_grad():
                    self.anchor.distribution.update(self.anchor.distribution_input(batch.observations))
                    anchor_params = tuple(p.detach() for p in self.anchor.output_distribution_params)
                kl_init = (self.actor.get_kl_divergence(anchor_params, params) if self.anchor_kl == "forward"
                           else self.actor.get_kl_divergence(params, anchor_params)).mean()
                if self.anchor_coef > 0:
                    loss = loss + self.anchor_coef * kl_init
                sums["kl_init"] += kl_init.item()
            self.optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(self.actor.parameters(), self.max_grad_norm)
            nn.utils.clip_grad_norm_(self.critic.parameters(), self.max_grad_norm)
            self.optimizer.step()
            sums["value"] += value_loss.item()
            sums["surrogate"] += surrogate.item()
            sums["entropy"] += entropy.mean().item()
            updates += 1
        observations = self.storage.observations.flatten(0, 1)
        self.actor.update_normalization(observations)
        self.critic.update_normalization(observations)
        self.storage.clear()
        if self.anchor is None:
            del sums["kl_init"]
        return {**{k: v / max(updates, 1) for k, v in sums.items()}, "actor_lr": self.actor_learning_rate}


@dataclass(frozen=True)
class PPOConfig:
    """PPO hyper-parameters (paper's values where it gives them).

    Attributes:
        actor_learning_rate / critic_learning_rate: LR_a and LR_c (paper: 1e-4, 5e-4).
        clip_param: ε_clip (paper: 0.2).
        gamma: discount per decision (paper: 0.99).
        mini_batch_size: decisions per gradient step (paper's batch size 32).
        num_steps_per_env: decisions collected per worker and iteration; workers × this must be
            a multiple of ``mini_batch_size``.
        lam, num_learning_epochs, entropy_coef, value_loss_coef, max_grad_norm: rsl-rl's defaults.
        reward_scale: factor on the training reward (see the module notes).
        mask_actions: mask infeasible behaviors in the policy (see :mod:`hbmp_bench.policies.networks`).
        init_std: initial standard deviation of the flat baseline's Gaussian controls (an ``--init`` ``flat-il``
            actor's too: imitation fits only the mean, see :func:`with_initial_std`).
        critic_warmup_episodes: episodes at the start of a run during which only the critic
            learns (the actor's learning rate is 0); see the module notes.
        desired_kl: None (fixed LR_a) or the per-mini-batch KL the adaptive actor rate aims at.
        anchor_coef: weight of the KL to the ``--init`` actor in the loss (0: none); see the module notes.
        anchor_kl: direction of that KL: ``forward`` KL(π_IL ‖ π) or ``reverse`` KL(π ‖ π_IL).
        temperature: the behavior policy is softmax(logits / temperature) (1: the paper's); see the
            module notes.
        overlap_update: the workers collect the next roll-out while the update runs, with the policy the
            update starts from, so each update learns from a roll-out one update older than itself (see
            :func:`~hbmp_bench.training.async_rollout.learn_async`); for any scene: learners that decide at
            their own times (``--agents N`` in continuous fidelity) or at every step (``flat``'s controls, event
            fidelity). False (default): rsl-rl's order, each roll-out with the policy it then updates.
    """

    actor_learning_rate: float = 1e-4
    critic_learning_rate: float = 5e-4
    clip_param: float = 0.2
    gamma: float = 0.99
    mini_batch_size: int = 32
    num_steps_per_env: int = 64
    lam: float = 0.95
    num_learning_epochs: int = 5
    entropy_coef: float = 0.01
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0
    reward_scale: float = 0.01
    mask_actions: bool = False
    init_std: float = 0.5
    critic_warmup_episodes: int = 0
    desired_kl: float | None = None
    anchor_coef: float = 0.0
    anchor_kl: str = "forward"
    temperature: float = 1.0
    overlap_update: bool = False

    def __post_init__(self):
        if self.anchor_kl not in ANCHOR_KL:
            raise ConfigError(f"anchor_kl must be one of {', '.join(ANCHOR_KL)}, got {self.anchor_kl!r}")
        for name in ("actor_learning_rate", "critic_learning_rate", "clip_param", "reward_scale", "init_std",
                     "temperature"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("entropy_coef", "anchor_coef"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.desired_kl is not None and not self.desired_kl > 0:
            raise ConfigError(f"desired_kl must be > 0 or None, got {self.desired_kl}")
        if not 0 < self.gamma <= 1 or not 0 <= self.lam <= 1:
            raise ConfigError("gamma must be in (0, 1] and lam in [0, 1]")
        if self.mini_batch_size < 1 or self.num_steps_per_env < 1 or self.num_learning_epochs < 1:
            raise ConfigError("mini_batch_size, num_steps_per_env and num_learning_epochs must be >= 1")
        if self.critic_warmup_episodes < 0:
            raise ConfigError(f"critic_warmup_episodes must be >= 0, got {self.critic_warmup_episodes}")

    @classmethod
    def parse_assignments(cls, assignments: list[str]) -> dict[str, Any]:
        """``["name=value", ...]`` from the command line as typed field values (``none`` for None).

        Raises ValueError naming the valid fields for an unknown name, and for a malformed value.
        """
        fields = {f.name: f for f in dataclasses.fields(cls)}
        parsed: dict[str, Any] = {}
        for text in assignments:
            name, sep, value = text.partition("=")
            if not sep or name not in fields:
                raise UserError(f"--ppo takes NAME=VALUE with NAME one of {', '.join(fields)}; got {text!r}")
            default = fields[name].default
            if value.lower() == "none" and default is None:
                parsed[name] = None
            elif isinstance(default, str):
                parsed[name] = value
            elif isinstance(default, bool):
                if value.lower() not in ("true", "false", "1", "0"):
                    raise UserError(f"--ppo {name} takes true or false, got {value!r}")
                parsed[name] = value.lower() in ("true", "1")
            else:
                kind = int if isinstance(default, int) else float
                try:
                    parsed[name] = kind(value)
                except ValueError:
                    raise UserError(f"--ppo {name} takes a number ({kind.__name__}), got {value!r}") from None
        return parsed

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> PPOConfig:
        """The config a run recorded (its ``ppo.*`` options); fields it did not record keep their defaults."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k[4:]: v for k, v in options.items() if k.startswith("ppo.") and k[4:] in names})

    def runner_cfg(self, num_envs: int, obs_groups: dict[str, list[str]], actor: dict, critic: dict) -> dict:
        """The ``train_cfg`` dict of rsl-rl's ``OnPolicyRunner`` (a fresh dict: the runner mutates it)."""
        batch = num_envs * self.num_steps_per_env
        if batch % self.mini_batch_size:
            raise ConfigError(f"slots (workers × agents) × num_steps_per_env = {num_envs} × "
                              f"{self.num_steps_per_env} = {batch} is not a multiple of the mini-batch size "
                              f"{self.mini_batch_size}")
        return {
            "num_steps_per_env": self.num_steps_per_env,
            "save_interval": 10**9,
            "obs_groups": {k: list(v) for k, v in obs_groups.items()},
            "algorithm": {
                "class_name": "hbmp_bench.training.ppo:TwoRatePPO",
                "actor_learning_rate": self.actor_learning_rate,
                "critic_learning_rate": self.critic_learning_rate,
                "clip_param": self.clip_param,
                "gamma": self.gamma,
                "lam": self.lam,
                "num_learning_epochs": self.num_learning_epochs,
                "num_mini_batches": batch // self.mini_batch_size,
                "entropy_coef": self.entropy_coef,
                "value_loss_coef": self.value_loss_coef,
                "max_grad_norm": self.max_grad_norm,
                "schedule": "fixed",
                "desired_kl": self.desired_kl,
                "anchor_coef": self.anchor_coef,
                "anchor_kl": self.anchor_kl,
            },
            "actor": dict(actor),
            "critic": dict(critic),
        }


class BudgetReached(Exception):
    """Raised by :class:`RunLogger` after the iteration that completes the episode budget: rsl-rl's
    ``learn`` has no stop hook, and its iteration count cannot be known in advance (episodes vary)."""


class RunLogger(Logger):
    """rsl-rl's logger (no writer) that calls ``on_iteration(loss_dict)`` after every iteration."""

    def __init__(self, runner, on_iteration):
        super().__init__(log_dir=None, cfg=runner.cfg, env_cfg=runner.env.cfg, num_envs=runner.env.num_envs,
                         is_distributed=False, gpu_world_size=1, gpu_global_rank=0, device=runner.device)
        self.on_iteration = on_iteration

    def log(self, it: int, *args, loss_dict: dict | None = None, **kwargs) -> None:
        super().log(it, *args, loss_dict=loss_dict, **kwargs)
        self.on_iteration(loss_dict or {})


def input_groups(obs) -> list[str]:
    """Observation groups fed to the networks: all but the action mask."""
    return [k for k in obs.keys() if k != MASK_GROUP]


def model_info(env, actor_cfg: dict, critic_cfg: dict, groups: list[str]) -> dict[str, Any]:
    """The ``model`` entry of a checkpoint: how to rebuild the networks without the env."""
    from gymnasium import spaces

    return {
        "actor": actor_cfg,
        "critic": critic_cfg,
        "obs_shapes": {k: list(v) for k, v in observation_shapes(env.get_observations()).items()},
        "obs_groups": {"actor": list(groups), "critic": list(groups)},
        "num_actions": env.num_actions,
        "action_space": "discrete" if isinstance(env.action_space, spaces.Discrete) else "box",
        "env": {"env_id": env.config.env_id, **env.config.kwargs, "agents": env.config.agents},
    }


def check_init_compatible(init: dict, info: dict) -> None:
    """The init checkpoint's actor must fit this run's network (same inputs, same output)."""
    theirs = init["model"]
    for key in ("obs_groups", "num_actions", "action_space"):
        if theirs[key] != info[key]:
            raise ConfigError(f"--init checkpoint differs in {key}: {theirs[key]} vs this run's {info[key]}")
    for group in info["obs_groups"]["actor"]:
        if theirs["obs_shapes"].get(group) != info["obs_shapes"][group]:
            raise ConfigError(f"--init checkpoint has {group} of shape {theirs['obs_shapes'].get(group)}, "
                             f"this run {info['obs_shapes'][group]}")
    ours_obs, their_obs = info["env"].get("observation", "deformed"), theirs["env"].get("observation", "deformed")
    if ours_obs != their_obs:
        warnings.warn(f"--init policy was trained on {their_obs} M_t, this run uses {ours_obs}", stacklevel=2)


def train_ppo(run: RunConfig, env_config: WorkerEnvConfig, ppo: PPOConfig | None = None, init: str | None = None,
              init_label: str | None = None) -> dict[str, Any]:
    """Train ``run.kind`` (hbmp, hbmp-s or flat) with rsl-rl PPO until ``run.episodes`` episodes.

    Args:
        run: budget, workers, seed, folder, resume.
        env_config: environment and reward of the workers (``reward_scale`` is taken from ``ppo``).
        ppo: hyper-parameters (None: the defaults). A resumed run keeps the ones its checkpoint
            recorded (a warning names any given here that differ).
        init: checkpoint whose actor initialises the policy (an ``il`` one for hbmp, ``flat-il`` for flat:
            :data:`INIT_KINDS`), or None.
        init_label: how the model card and checkpoint name ``init`` (default: the path itself),
            e.g. ``il`` for the shipped checkpoint.

    Returns:
        The run's progress dict and the path of the final policy (``policy``).
    """
    if run.kind in ("il", "flat-il"):
        raise ConfigError(f"train {run.kind} with DAgger (hbmp_bench.training.dagger, hbmp_bench.training.control_dagger)")
    session = TrainingSession(run)
    resume = session.resume
    ppo = _recorded_ppo(resume, ppo) if resume is not None else ppo or PPOConfig()
    env_config = dataclasses.replace(env_config, reward_scale=ppo.reward_scale, expert_labels=False)
    init_kinds = INIT_KINDS["flat" if run.kind == "flat" else "behavior"]
    init_ckpt = (with_initial_std(load_checkpoint(init, kinds=init_kinds), ppo.init_std)
                 if init and resume is None else None)
    from rsl_rl.runners import OnPolicyRunner

    with session:
        env = session.start(env_config)
        actor_cfg, critic_cfg, groups = _model_cfgs(env, ppo, init_ckpt)
        cfg = ppo.runner_cfg(env.num_envs, {"actor": groups, "critic": groups}, actor_cfg, critic_cfg)
        with contextlib.redirect_stdout(io.StringIO()):
            runner = OnPolicyRunner(env, cfg, log_dir=None, device="cpu")
        info = model_info(env, actor_cfg, critic_cfg, groups)
        alg = runner.alg
        _load_weights(alg, resume, init_ckpt, info)
        if ppo.anchor_coef > 0 and alg.anchor is None:
            raise ConfigError("anchor_coef > 0 needs an --init actor to anchor to")
        init_option = (init_label or init) if resume is None else resume["train"].get("init")
        options = session.options(info["env"], before={"init": init_option},
                                  after={"reward": env_config.reward,
                                         **{f"ppo.{k}": v for k, v in dataclasses.asdict(ppo).items()}})

        def checkpoint() -> dict[str, Any]:
            anchor = {} if alg.anchor is None else {"anchor_state_dict": alg.anchor.state_dict()}
            return session.checkpoint(info, {"actor_state_dict": alg.get_policy().state_dict(),
                                             "critic_state_dict": alg.critic.state_dict(), **anchor}, options)

        progress = session.progress
        session.open_episodes(EPISODE_COLUMNS)
        iterations = session.log("iterations.csv", ITERATION_COLUMNS, key="iteration")
        validator = session.track(Validator(run.out, run.validate_every, run.workers, env_config.kwargs.get("fidelity"),
                                            resumed_at=progress.episodes if resume else None,
                                            episodes=run.validate_episodes))

        def validate_if_due(say) -> None:
            if validator.due(progress.episodes):
                say(f"validating the greedy policy at episode {progress.episodes} on hbmp-val ...")
                row = validator(progress.episodes, checkpoint())
                say(f"validation at episode {progress.episodes}: success {row['success']:.1%} "
                    f"(best {validator.best:.1%})")

        validate_if_due(lambda text: print(text, flush=True) if run.progress else None)  # a fresh run: the init
        bar = session.start_bar()
        alg.freeze_actor(progress.episodes < ppo.critic_warmup_episodes)

        def after_iteration(losses: dict[str, float]) -> None:
            progress.iterations += 1
            progress.decisions += cfg["num_steps_per_env"] * env.num_envs
            frozen = alg.actor_frozen
            for worker, summary in env.pop_episodes():
                if not session.record_episode(worker, summary):
                    break
            iterations.write({"iteration": progress.iterations, "episode": progress.episodes,
                              "decisions": progress.decisions, "actor_frozen": frozen,
                              **losses,  # value, surrogate, entropy, kl_init, actor_lr
                              "wall_s": progress.to_dict()["wall_s"]})
            alg.freeze_actor(progress.episodes < ppo.critic_warmup_episodes)
            if session.save_due():
                session.save(checkpoint())
            validate_if_due(bar.write)
            if session.budget_reached:
                raise BudgetReached

        runner.logger = RunLogger(runner, after_iteration)
        runner.current_learning_iteration = progress.iterations
        try:
            if env.asynchronous or ppo.overlap_update:  # learners deciding at their own times, or no update wait
                from hbmp_bench.training.async_rollout import learn_async

                learn_async(runner, env, cfg["num_steps_per_env"], after_iteration, overlap_update=ppo.overlap_update)
            else:
                runner.learn(num_learning_iterations=10**9)
        except BudgetReached:
            pass
        final = session.finish(checkpoint())
    return session.write_outputs(f"{run.kind} ({env_config.reward} reward)", final, options,
                                 validation_results(run.out))


def _recorded_ppo(resume: dict[str, Any], asked: PPOConfig | None) -> PPOConfig:
    """The PPO options a resumed run recorded (a warning names any asked for here that differ)."""
    recorded = PPOConfig.from_options(resume["train"])
    if asked is not None and recorded != asked:
        changed = {k: v for k, v in dataclasses.asdict(asked).items() if dataclasses.asdict(recorded)[k] != v}
        warnings.warn(f"resuming with the run's recorded PPO options, not {changed}", stacklevel=3)
    return recorded


def _model_cfgs(env, ppo: PPOConfig, init: dict[str, Any] | None = None) -> tuple[dict, dict, list[str]]:
    """The actor and critic configs for ``env``'s action space and the observation groups they read; with an
    ``init`` checkpoint, the actor has its layer sizes (``flat-il``'s compact trunk)."""
    from gymnasium import spaces

    groups = input_groups(env.get_observations())
    discrete = isinstance(env.action_space, spaces.Discrete)
    if ppo.mask_actions and not discrete:
        raise ConfigError("mask_actions needs a behavior env with an action mask")
    if ppo.temperature != 1.0 and not discrete:
        raise ConfigError("temperature is the behavior policy's (a categorical); "
                          "the flat baseline's controls are Gaussian")
    actor_cfg, critic_cfg = (behavior_model_cfgs(ppo.mask_actions, temperature=ppo.temperature) if discrete
                             else control_model_cfgs(ppo.init_std))
    if init is not None:
        sizes = init["model"]["actor"]
        actor_cfg = {**actor_cfg, **{k: sizes[k] for k in NETWORK if k in sizes}}
    return actor_cfg, critic_cfg, groups


def with_initial_std(init: dict[str, Any], std: float) -> dict[str, Any]:
    """``init`` with its Gaussian actor's standard deviation set to ``std`` (``PPOConfig.init_std``) when imitation
    made it (kind ``flat-il``): DAgger fits only the mean and keeps the std the actor was built with, so PPO from it
    explores with the run's own ``init_std`` (the anchor's too). A PPO actor's learnt std and a categorical actor
    (behaviors) are returned as they are."""
    state = init["actor_state_dict"]
    if init.get("kind") != "flat-il" or "distribution.log_std_param" not in state:
        return init
    value = torch.log(std * torch.ones_like(state["distribution.log_std_param"]))  # as rsl-rl builds it
    return {**init, "actor_state_dict": {**state, "distribution.log_std_param": value}}


def _load_weights(alg, resume: dict[str, Any] | None, init: dict[str, Any] | None, info: dict[str, Any]) -> None:
    """The resumed run's actor, critic, optimizer and anchor; or the ``--init`` actor, also as the anchor."""
    if resume is not None:
        alg.load(resume, {"actor": True, "critic": True, "optimizer": "optimizer_state_dict" in resume}, strict=True)
        if "anchor_state_dict" in resume:
            alg.set_anchor(resume["anchor_state_dict"])
    elif init is not None:
        check_init_compatible(init, info)
        alg.get_policy().load_state_dict(init["actor_state_dict"])
        alg.set_anchor(init["actor_state_dict"])
