"""DAgger on the flat baseline's controls: the ``flat-il`` policy (CIL, conditional imitation learning).

The end-to-end baselines of the paper's Tab. I include CIL (Codevilla et al. 2018): a network that
maps the observation and the route command to the vehicle's controls, learnt by imitating a
demonstrator's controls. Here it runs on the ``flat`` baseline's interface: the control env
(:class:`~hbmp_bench.envs.control_env.ControlEnv`, ``ego_driver="control"``, continuous fidelity),
acceleration and steering at 10 Hz from M_t and R_t plus the lateral and heading error to the
followed lane; the route command is R_t's (which lanes continue the route) and the followed lane
itself, which continues along the route through every junction.

The label (:class:`~hbmp_bench.training.expert_control.ExpertControl`): the control the expert's stack applies in the state the learner
is in. The rule-based expert (:class:`~hbmp_bench.agents.expert.ExpertAgent`) picks a behavior from
the privileged scene; the continuous fidelity's driver (:class:`~hbmp_bench.envs.drivers.ContinuousDriver`,
the behavior-conditioned sampling planner and its tracker) begins that behavior from the ego's
bicycle-model state and plans one control period among the same actors: its control
(``throttle - brake``, ``steer``) is the label. The planning call is a shadow: it never moves the
vehicle (the ego stays with its :class:`~hbmp_bench.envs.drivers.ControlDriver`), so every visited
state, the learner's included, gets the label the expert's stack would apply there. The behavior is
decided and begun afresh each 0.1 s, so the label is a function of the state now (what the learner
sees), not of when a behavior began.

DAgger as for ``il`` (:mod:`hbmp_bench.training.dagger`: the same β schedule, aggregated dataset,
held-out episodes and rounds): per decision and environment the expert's control with probability β,
else the learner's (the Gaussian's mean, clipped to [-1, 1], as the agent drives); after every
``decisions_per_round`` decisions ``updates_per_round`` Adam steps of the mean squared error between
the policy's mean and the expert's control on mini-batches drawn from the whole dataset. The learner
is the ``flat`` PPO actor itself (:func:`~hbmp_bench.policies.networks.control_model_cfgs`: the paper's
network with a Gaussian output), so ``train flat --init flat-il`` starts PPO from it (the Gaussian's
standard deviation stays at ``init_std``: imitation fits only the mean).

Validation: with ``run.validate_every`` the greedy policy is evaluated on the ``hbmp-val`` suite
(:mod:`hbmp_bench.training.validation`, held-out Town03 episodes, never a test suite) every that many
episodes, not at episode 0 (an untrained control policy stands until each episode's timeout), and the
best is kept as ``best.pt``: the checkpoint to ship.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from hbmp_bench.errors import ConfigError, UserError
from hbmp_bench.training.dagger import DemoDataset, add_states, expert_probability, save_datasets
from hbmp_bench.training.run import RunConfig
from hbmp_bench.training.runlog import DAGGER_COLUMNS, EPISODE_COLUMNS, ROUND_COLUMNS
from hbmp_bench.training.session import TrainingSession
from hbmp_bench.training.worker import WorkerEnvConfig

CONTROL_DIM = 2
"""``[a, s]``: throttle (> 0) or brake (< 0) fraction, steering fraction (left > 0)."""
CONTROL_ROUND_COLUMNS = (*ROUND_COLUMNS, "holdout_mse", "holdout_mae_accel", "holdout_mae_steer", "beta")
"""``rounds.csv`` of a ``flat-il`` run: DAgger's columns (``loss`` the mean squared error, the agreements the
share of states whose both controls are within ``DaggerControlConfig.tolerance`` of the expert's), then the
held-out mean squared error, the mean absolute error of each control and β."""


@dataclass(frozen=True)
class DaggerControlConfig:
    """DAgger options of ``flat-il`` (β as for ``il``: :class:`~hbmp_bench.training.dagger.DaggerConfig`).

    Attributes:
        beta_start: P(expert) per decision at the start.
        hold_fraction: part of the episode budget at ``beta_start`` before the linear decay to 0.
        learning_rate: Adam learning rate.
        batch_size: states per gradient step.
        decisions_per_round: decisions collected (over all workers) between training rounds (10 Hz:
            1024 are 102 s of driving).
        updates_per_round: gradient steps per round.
        steer_weight: weight of the steering's squared error against the acceleration's (1).
        tolerance: a control agrees with the expert's within this much (fractions of full scale).
        holdout_fraction: probability that an episode is held out (not trained on).
        holdout_capacity: most held-out states kept.
        init_std: the Gaussian's standard deviation (not learnt here; what ``train flat --init`` starts from).
        compact: the compact trunk (:data:`~hbmp_bench.policies.networks.COMPACT_NETWORK`, 81 k parameters, a
            0.3 MB checkpoint) instead of the paper's (282 k); the output is the same Gaussian.
    """

    beta_start: float = 0.95
    hold_fraction: float = 0.2
    learning_rate: float = 5e-4
    batch_size: int = 128
    decisions_per_round: int = 1024
    updates_per_round: int = 64
    steer_weight: float = 1.0
    tolerance: float = 0.1
    holdout_fraction: float = 0.05
    holdout_capacity: int = 8192
    init_std: float = 0.5
    compact: bool = True

    def __post_init__(self):
        if not 0 <= self.beta_start <= 1 or not 0 <= self.hold_fraction <= 1 or not 0 <= self.holdout_fraction < 1:
            raise ConfigError("beta_start and hold_fraction must be in [0, 1], holdout_fraction in [0, 1)")
        if min(self.batch_size, self.decisions_per_round, self.updates_per_round) < 1:
            raise ConfigError("batch_size, decisions_per_round and updates_per_round must be >= 1")
        for name in ("learning_rate", "steer_weight", "tolerance", "init_std"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)}")


def control_errors(actor, data: DemoDataset, batch: int = 1024, limit: int | None = None,
                   tolerance: float = 0.1) -> dict[str, float]:
    """The actor's mean (clipped to [-1, 1], as it drives) against the expert's controls on ``data`` (its
    first ``limit`` states): mean squared error, mean absolute error per control, and the share of states
    with both within ``tolerance``; NaN on an empty set."""
    n = len(data) if limit is None else min(limit, len(data))
    if n == 0:
        return {"mse": float("nan"), "mae_accel": float("nan"), "mae_steer": float("nan"), "agreement": float("nan")}
    squared, absolute, hits = 0.0, np.zeros(CONTROL_DIM), 0
    with torch.inference_mode():
        for start in range(0, n, batch):
            obs, labels = data.get(np.arange(start, min(start + batch, n)))
            error = (actor.distribution_input(obs).clamp(-1.0, 1.0) - labels).abs()
            squared += float(error.pow(2).mean(-1).sum())
            absolute += error.sum(0).numpy()
            hits += int((error <= tolerance).all(-1).sum())
    return {"mse": squared / n, "mae_accel": float(absolute[0] / n), "mae_steer": float(absolute[1] / n),
            "agreement": hits / n}


def train_control_dagger(run: RunConfig, env_config: WorkerEnvConfig, config: DaggerControlConfig) -> dict[str, Any]:
    """Train the ``flat-il`` policy with DAgger on the expert's controls until ``run.episodes`` episodes.

    Args:
        run: budget, workers, seed, folder, resume (``checkpoint.pt`` with ``dataset.npz`` beside it),
            validation (``validate_every``, ``validate_episodes``).
        env_config: the workers' control env (``entry_point`` the control env; ``expert_controls`` is
            switched on here).
        config: DAgger options.

    Returns:
        The run's progress dict, the path of the final policy (``policy``) and the held-out errors.
    """
    from hbmp_bench.policies.networks import COMPACT_NETWORK, build_model, control_model_cfgs, observation_shapes
    from hbmp_bench.training.ppo import input_groups, model_info
    from hbmp_bench.training.validation import Validator, validation_results

    if run.kind != "flat-il":
        raise ConfigError(f"DAgger on controls trains the 'flat-il' policy, not {run.kind!r}")
    env_config = dataclasses.replace(env_config, expert_controls=True, expert_labels=False)
    session = TrainingSession(run)
    resume, progress = session.resume, session.progress
    data_path = os.path.join(os.path.dirname(os.path.abspath(run.resume)), "dataset.npz") if resume else ""
    if resume and not os.path.isfile(data_path):
        raise UserError(f"DAgger goes on from its aggregated demonstrations, but {data_path} is missing beside the "
                        f"checkpoint (keep dataset.npz with checkpoint.pt); without them the run would train on a "
                        f"new dataset only: start a new run instead")
    with session:
        env = session.start(env_config)
        if env.num_actions != CONTROL_DIM:
            raise ConfigError(f"flat-il drives the control env ([a, s]); this env has {env.num_actions} actions")
        rng = np.random.default_rng([run.seed, progress.episodes])
        obs = env.get_observations()
        groups = input_groups(obs)
        actor_cfg, critic_cfg = control_model_cfgs(config.init_std, COMPACT_NETWORK if config.compact else None)
        info = model_info(env, actor_cfg, critic_cfg, groups)
        shapes = observation_shapes(obs)
        actor = build_model(actor_cfg, shapes, info["obs_groups"], "actor", env.num_actions)
        optimizer = torch.optim.Adam(actor.parameters(), lr=config.learning_rate)
        stored = {k: v for k, v in shapes.items() if k in groups}
        train_set, holdout = DemoDataset(stored, (CONTROL_DIM,)), DemoDataset(stored, (CONTROL_DIM,))
        if resume is not None:
            actor.load_state_dict(resume["actor_state_dict"])
            optimizer.load_state_dict(resume["optimizer_state_dict"])
            with np.load(data_path) as arrays:
                train_set.load_state_dict(arrays, "train")
                holdout.load_state_dict(arrays, "holdout")
        options = session.options(info["env"], after={f"dagger.{k}": v for k, v in dataclasses.asdict(config).items()})

        def checkpoint() -> dict[str, Any]:
            return session.checkpoint(info, {"actor_state_dict": actor.state_dict(),
                                             "optimizer_state_dict": optimizer.state_dict()}, options)

        session.open_episodes(EPISODE_COLUMNS + DAGGER_COLUMNS)
        rounds_log = session.log("rounds.csv", CONTROL_ROUND_COLUMNS, key="round")
        validator = session.track(Validator(run.out, run.validate_every, run.workers, None,
                                            resumed_at=progress.episodes if resume else None,
                                            episodes=run.validate_episodes))
        bar = session.start_bar()
        learner = _ControlLearner(actor, train_set, holdout, config, rng, env)
        while not session.budget_reached:
            beta, obs = learner.collect(env, obs, session)
            progress.iterations += 1
            loss, hits = _train_round(actor, optimizer, train_set, config, rng)
            held = control_errors(actor, holdout, limit=config.holdout_capacity, tolerance=config.tolerance)
            rounds_log.write({"round": progress.iterations, "episodes": progress.episodes, "dataset": len(train_set),
                              "holdout": len(holdout), "loss": loss, "train_agreement": hits,
                              "holdout_agreement": held["agreement"], "wall_s": round(progress.to_dict()["wall_s"], 1),
                              "holdout_mse": held["mse"], "holdout_mae_accel": held["mae_accel"],
                              "holdout_mae_steer": held["mae_steer"], "beta": round(beta, 4)})
            bar.set_postfix(loss=f"{loss:.4f}", beta=f"{beta:.2f}", data=len(train_set))
            if session.save_due():
                save_datasets(session.path("dataset.npz"), train_set, holdout)
                session.save(checkpoint())
            if _validation_due(validator, run, progress.episodes):
                row = validator(progress.episodes, checkpoint())
                bar.write(f"validation at episode {progress.episodes}: success {row['success']:.1%} "
                          f"(best {validator.best:.1%})")
        save_datasets(session.path("dataset.npz"), train_set, holdout)
        final = session.finish(checkpoint())
    held = control_errors(actor, holdout, tolerance=config.tolerance)
    summary = session.write_outputs("flat-il (DAgger on controls)", final, options, {
        "held-out error against the expert's controls": (
            f"MSE {held['mse']:.4f}, mean |Δa| {held['mae_accel']:.3f}, mean |Δs| {held['mae_steer']:.3f}, "
            f"both within {config.tolerance} on {held['agreement']:.1%} of {len(holdout)} states"),
        **validation_results(run.out),
    })
    return {**summary, "holdout": held}


def _validation_due(validator, run: RunConfig, episodes: int) -> bool:
    """Every ``run.validate_every`` episodes, the first after that many (not the untrained policy's)."""
    if validator.log is None:
        return False
    return episodes >= (validator.last or 0) + run.validate_every


class _ControlLearner:
    """DAgger's collection of one round on controls: per decision and worker the expert's control with
    probability β, else the learner's; every visited state with the expert's control joins the training
    set or, for held-out episodes, the holdout set, once the round's decisions are made."""

    def __init__(self, actor, train_set: DemoDataset, holdout: DemoDataset, config: DaggerControlConfig,
                 rng: np.random.Generator, env):
        self.actor, self.train_set, self.holdout, self.config, self.rng = actor, train_set, holdout, config, rng
        self.W = env.num_envs
        self.labels = env.expert_controls
        self.expert_steps = np.zeros(self.W, dtype=np.int64)
        self.steps = np.zeros(self.W, dtype=np.int64)
        self.held_out = rng.random(self.W) < config.holdout_fraction
        actor.eval()

    def collect(self, env, obs, session: TrainingSession):
        """Run one round's decisions; returns (the last β, the current observation)."""
        config, rng, W, progress = self.config, self.rng, self.W, session.progress
        stored = self.train_set.shapes
        pending: list[tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]] = []
        beta = float("nan")
        for _ in range(max(1, config.decisions_per_round // W)):
            beta = expert_probability(progress.episodes, session.run.episodes, config.beta_start, config.hold_fraction)
            use_expert = torch.from_numpy(rng.random(W) < beta).unsqueeze(-1)
            actions = self.labels
            if not bool(use_expert.all()):
                with torch.inference_mode():
                    learner = self.actor(obs).clamp(-1.0, 1.0)
                actions = torch.where(use_expert, self.labels, learner)
            pending.append(({k: obs[k].numpy() for k in stored}, self.labels.numpy().copy(), self.held_out.copy()))
            self.expert_steps += use_expert.squeeze(-1).numpy()
            self.steps += 1
            obs, _, _, extras = env.step(actions)
            self.labels = extras["expert_controls"]
            progress.decisions += W
            for worker, summary in env.pop_episodes():
                session.record_episode(worker, summary, beta=round(beta, 4),
                                       expert_share=round(self.expert_steps[worker] / max(self.steps[worker], 1), 4))
                self.expert_steps[worker] = self.steps[worker] = 0
                self.held_out[worker] = (len(self.holdout) < config.holdout_capacity
                                         and rng.random() < config.holdout_fraction)
            if session.budget_reached:
                break
        add_states(pending, self.train_set, self.holdout, config.holdout_capacity)
        return beta, obs


def _train_round(actor, optimizer, data: DemoDataset, config: DaggerControlConfig,
                 rng: np.random.Generator) -> tuple[float, float]:
    """``updates_per_round`` steps of the (steer-weighted) mean squared error on uniform mini-batches;
    (mean loss, mean share of the batch within ``tolerance``)."""
    if len(data) < config.batch_size:
        return float("nan"), float("nan")
    weights = torch.tensor([1.0, config.steer_weight])
    actor.train()
    losses, hits = [], []
    for _ in range(config.updates_per_round):
        obs, labels = data.get(rng.integers(0, len(data), config.batch_size))
        mean = actor.distribution_input(obs)
        loss = ((mean - labels).pow(2) * weights).sum(-1).mean() / weights.sum()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        hits.append(((mean.detach().clamp(-1.0, 1.0) - labels).abs() <= config.tolerance).all(-1).float().mean().item())
    actor.eval()
    return float(np.mean(losses)), float(np.mean(hits))
