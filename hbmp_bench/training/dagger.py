"""DAgger (Ross et al. 2011) from the rule-based expert: the ``il`` policy.

The paper (Sec. "Initialization by IL"): behaviors are demonstrated in SUMO, where a behavior
completes in one step; DAgger picks the demonstrator's behavior with probability α (0.95 at the
start, decaying to 0 after the first 3000 episodes) and the learner's otherwise; the learner
minimises the distance between its behavior and the demonstrated one.

Fidelity. The paper's stage is event fidelity (``train il`` without ``--fidelity``: a decision
every 0.1 s, SUMO completes it). A policy learnt there brakes where SUMO's 4.5 m/s² and 10 Hz
decisions make that possible, too late for the motion planner's 1-2 s behaviors: the metric-R_t
policy of 500 event episodes reached the goal in 82 % of its last training episodes, and in 11 %
of the hbmp suite's Navigation episodes in continuous fidelity (78 of 100 ended at a red light).
The shipped ``il`` is therefore trained in continuous fidelity (``--fidelity continuous``), where it
is evaluated; the event-fidelity policy is the paper's variant. Here:

- the demonstrator is :class:`hbmp_bench.agents.expert.ExpertAgent`, run inside each env worker
  on the same observation and info, so every visited state gets its label;
- per decision and per environment the expert's behavior is executed with probability
  β = :func:`expert_probability` (the paper's α): ``beta_start`` for the first ``hold_fraction``
  of the episode budget, then linear to 0 at the end of the budget (the paper's schedule,
  scaled to the budget); otherwise the learner's most likely behavior;
- every visited state with the expert's label joins one aggregated dataset; after every
  ``decisions_per_round`` decisions the learner takes ``updates_per_round`` Adam steps of
  cross-entropy on mini-batches drawn uniformly from the whole dataset;
- whole episodes (chosen with probability ``holdout_fraction``, up to ``holdout_capacity``
  states) are kept out of training: the agreement of the learner with the expert on them is
  logged per round (``rounds.csv``);
- the learner is the PPO actor itself (:class:`~hbmp_bench.policies.networks.BehaviorNetwork` with
  the categorical distribution), so ``train hbmp --init`` loads its weights as they are.

M_t is binary, so the dataset stores it bit-packed (2304 cells → 288 bytes per state).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tensordict import TensorDict

from hbmp_bench.errors import ConfigError, UserError
from hbmp_bench.policies.networks import behavior_model_cfgs, build_model, observation_shapes
from hbmp_bench.training.ppo import MASK_GROUP, input_groups, model_info
from hbmp_bench.training.run import RunConfig
from hbmp_bench.training.runlog import DAGGER_COLUMNS, EPISODE_COLUMNS, ROUND_COLUMNS
from hbmp_bench.training.session import TrainingSession
from hbmp_bench.training.worker import WorkerEnvConfig
from hbmp_bench.vocabulary import BEHAVIORS, NUM_BEHAVIORS


@dataclass(frozen=True)
class DaggerConfig:
    """DAgger options.

    Attributes:
        beta_start: P(expert) at the start (paper: 0.95).
        hold_fraction: part of the episode budget at ``beta_start`` before the linear decay to 0.
        learning_rate: Adam learning rate (the paper gives none for IL).
        batch_size: states per gradient step.
        decisions_per_round: decisions collected (over all workers) between training rounds.
        updates_per_round: gradient steps per round.
        holdout_fraction: probability that an episode is held out (not trained on).
        holdout_capacity: most held-out states kept.
        mask_actions: mask infeasible behaviors in the policy (see :mod:`hbmp_bench.policies.networks`).
    """

    beta_start: float = 0.95
    hold_fraction: float = 0.3
    learning_rate: float = 1e-3
    batch_size: int = 128
    decisions_per_round: int = 1024
    updates_per_round: int = 48
    holdout_fraction: float = 0.05
    holdout_capacity: int = 8192
    mask_actions: bool = False

    def __post_init__(self):
        if not 0 <= self.beta_start <= 1 or not 0 <= self.hold_fraction <= 1 or not 0 <= self.holdout_fraction < 1:
            raise ConfigError("beta_start and hold_fraction must be in [0, 1], holdout_fraction in [0, 1)")
        if min(self.batch_size, self.decisions_per_round, self.updates_per_round) < 1 or self.learning_rate <= 0:
            raise ConfigError("batch_size, decisions_per_round, updates_per_round and learning_rate must be > 0")


def expert_probability(episode: int, budget: int, beta_start: float = 0.95, hold_fraction: float = 0.3) -> float:
    """β, the probability of executing the expert's behavior during episode ``episode`` (0-based).

    ``beta_start`` for episodes < hold_fraction·budget, then linear to 0 at ``budget``.
    """
    if budget < 1:
        raise ConfigError(f"budget must be >= 1, got {budget}")
    hold = hold_fraction * budget
    if episode < hold:
        return float(beta_start)
    return float(beta_start * max(0.0, 1.0 - (episode - hold) / max(budget - hold, 1e-9)))


class DemoDataset:
    """Aggregated (observation, expert behavior) pairs, growing without bound.

    Groups with more than one dimension per state (M_t) must be binary and are stored
    bit-packed; 1-D groups (R_t, the action mask) as float32.

    Args:
        shapes: per-group shape of one state, e.g. ``{"occupancy": (1, 64, 36), "road": (10,)}``.
        label_shape: shape of one label: ``()`` for a behavior index (int8), ``(2,)`` for a control
            vector (float32, the flat baseline's ``[a, s]``: :mod:`hbmp_bench.training.control_dagger`).
    """

    def __init__(self, shapes: dict[str, tuple[int, ...]], label_shape: tuple[int, ...] = ()):
        self.shapes = {k: tuple(v) for k, v in shapes.items()}
        self.packed = {k: len(v) > 1 for k, v in self.shapes.items()}
        self.size = 0
        self.label_shape = tuple(label_shape)
        self._label_dtype = np.float32 if self.label_shape else np.int8
        self._data: dict[str, np.ndarray] = {k: self._empty(k, 1024) for k in self.shapes}
        self._labels = np.zeros((1024, *self.label_shape), dtype=self._label_dtype)

    def _width(self, key: str) -> int:
        n = int(np.prod(self.shapes[key]))
        return (n + 7) // 8 if self.packed[key] else n

    def _empty(self, key: str, capacity: int) -> np.ndarray:
        return np.zeros((capacity, self._width(key)), dtype=np.uint8 if self.packed[key] else np.float32)

    def __len__(self) -> int:
        return self.size

    def add(self, obs: dict[str, np.ndarray], labels: np.ndarray) -> None:
        """Append n states: ``obs[group]`` of shape (n, *shape), ``labels`` (n, *label_shape)."""
        n = len(labels)
        if n == 0:
            return
        if self.size + n > len(self._labels):
            capacity = max(2 * len(self._labels), self.size + n)
            for k, arr in self._data.items():
                grown = self._empty(k, capacity)
                grown[: self.size] = arr[: self.size]
                self._data[k] = grown
            labels_grown = np.zeros((capacity, *self.label_shape), dtype=self._label_dtype)
            labels_grown[: self.size] = self._labels[: self.size]
            self._labels = labels_grown
        for k in self.shapes:
            flat = np.asarray(obs[k]).reshape(n, -1)
            if self.packed[k]:
                if not np.isin(flat, (0.0, 1.0)).all():
                    raise ValueError(f"group {k!r} must be binary (0/1) to be stored bit-packed")
                flat = np.packbits(flat.astype(np.uint8), axis=1)
            self._data[k][self.size: self.size + n] = flat
        self._labels[self.size: self.size + n] = labels
        self.size += n

    def get(self, index: np.ndarray) -> tuple[TensorDict, torch.Tensor]:
        """States ``index`` as a TensorDict (len(index),) of float32 groups, and their labels (long behavior
        indices, or float32 control vectors)."""
        groups = {}
        for k, shape in self.shapes.items():
            rows = self._data[k][index]
            if self.packed[k]:
                rows = np.unpackbits(rows, axis=1, count=int(np.prod(shape))).astype(np.float32)
            groups[k] = torch.from_numpy(np.ascontiguousarray(rows).reshape(len(index), *shape))
        labels = self._labels[index]
        labels = labels.astype(np.float32 if self.label_shape else np.int64)
        return TensorDict(groups, batch_size=[len(index)]), torch.from_numpy(labels)

    def label_counts(self) -> np.ndarray:
        return np.bincount(self._labels[: self.size], minlength=NUM_BEHAVIORS)

    def state_dict(self, prefix: str) -> dict[str, np.ndarray]:
        out = {f"{prefix}/{k}": v[: self.size] for k, v in self._data.items()}
        out[f"{prefix}/labels"] = self._labels[: self.size]
        return out

    def load_state_dict(self, arrays: dict[str, np.ndarray], prefix: str) -> None:
        self._data = {k: np.array(arrays[f"{prefix}/{k}"]) for k in self.shapes}
        self._labels = np.array(arrays[f"{prefix}/labels"], dtype=self._label_dtype)
        self.size = len(self._labels)


def agreement(actor, data: DemoDataset, batch: int = 1024, limit: int | None = None) -> float:
    """Fraction of ``data``'s states (the first ``limit``) where the actor's most likely behavior is the expert's."""
    n = len(data) if limit is None else min(limit, len(data))
    if n == 0:
        return float("nan")
    hits = 0
    with torch.inference_mode():
        for start in range(0, n, batch):
            obs, labels = data.get(np.arange(start, min(start + batch, n)))
            hits += int((actor.distribution_input(obs).argmax(-1) == labels).sum())
    return hits / n


def save_datasets(path: str, train: DemoDataset, holdout: DemoDataset) -> None:
    """Both datasets in one compressed ``.npz`` (written to a temp file, then renamed). Consecutive
    states of an episode differ little: the bit-packed M_t compresses about 30-fold (45 k states,
    15 MB raw, 0.5 MB compressed), so a run's aggregate can travel with its checkpoint."""
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, **train.state_dict("train"), **holdout.state_dict("holdout"))
    os.replace(tmp, path)


def train_dagger(run: RunConfig, env_config: WorkerEnvConfig, dagger: DaggerConfig) -> dict[str, Any]:
    """Train the ``il`` policy with DAgger until ``run.episodes`` episodes.

    Args:
        run: budget, workers, seed, folder, resume (``checkpoint.pt`` with ``dataset.npz`` beside it).
        env_config: the workers' environment (``expert_labels`` is switched on here); use event fidelity.
        dagger: DAgger options.

    Returns:
        The run's progress dict, the path of the final policy (``policy``) and the held-out agreement.
    """
    if run.kind != "il":
        raise ConfigError(f"DAgger trains the 'il' policy, not {run.kind!r}")
    env_config = dataclasses.replace(env_config, expert_labels=True)
    session = TrainingSession(run)
    resume, progress = session.resume, session.progress
    data_path = os.path.join(os.path.dirname(os.path.abspath(run.resume)), "dataset.npz") if resume else ""
    if resume and not os.path.isfile(data_path):
        raise UserError(f"DAgger goes on from its aggregated demonstrations, but {data_path} is missing beside the "
                        f"checkpoint (keep or commit dataset.npz with checkpoint.pt); without them the run would "
                        f"train on a new dataset only: start a new run instead")
    with session:
        env = session.start(env_config)
        rng = np.random.default_rng([run.seed, progress.episodes])
        obs = env.get_observations()
        groups = input_groups(obs)
        actor_cfg, critic_cfg = behavior_model_cfgs(dagger.mask_actions)
        info = model_info(env, actor_cfg, critic_cfg, groups)
        shapes = observation_shapes(obs)
        actor = build_model(actor_cfg, shapes, info["obs_groups"], "actor", env.num_actions)
        optimizer = torch.optim.Adam(actor.parameters(), lr=dagger.learning_rate)
        stored = {k: v for k, v in shapes.items() if k in groups or (dagger.mask_actions and k == MASK_GROUP)}
        train_set, holdout = DemoDataset(stored), DemoDataset(stored)
        if resume is not None:
            actor.load_state_dict(resume["actor_state_dict"])
            optimizer.load_state_dict(resume["optimizer_state_dict"])
            with np.load(data_path) as arrays:
                train_set.load_state_dict(arrays, "train")
                holdout.load_state_dict(arrays, "holdout")
        options = session.options(info["env"], after={f"dagger.{k}": v for k, v in dataclasses.asdict(dagger).items()})

        def checkpoint() -> dict[str, Any]:
            return session.checkpoint(info, {"actor_state_dict": actor.state_dict(),
                                             "optimizer_state_dict": optimizer.state_dict()}, options)

        session.open_episodes(EPISODE_COLUMNS + DAGGER_COLUMNS)
        rounds_log = session.log("rounds.csv", ROUND_COLUMNS, key="round")
        bar = session.start_bar()
        learner = _Learner(actor, train_set, holdout, dagger, rng, env)
        while not session.budget_reached:
            beta, obs = learner.collect(env, obs, session)
            progress.iterations += 1
            loss, hits = _train_round(actor, optimizer, train_set, dagger, rng)
            rounds_log.write({"round": progress.iterations, "episodes": progress.episodes, "dataset": len(train_set),
                              "holdout": len(holdout), "loss": loss, "train_agreement": hits,
                              "holdout_agreement": agreement(actor, holdout, limit=dagger.holdout_capacity),
                              "wall_s": round(progress.to_dict()["wall_s"], 1)})
            bar.set_postfix(loss=f"{loss:.3f}", beta=f"{beta:.2f}", data=len(train_set))
            if session.save_due():
                save_datasets(session.path("dataset.npz"), train_set, holdout)
                session.save(checkpoint())
        save_datasets(session.path("dataset.npz"), train_set, holdout)
        final = session.finish(checkpoint())
    held_out = agreement(actor, holdout)
    summary = session.write_outputs("il (DAgger)", final, options, {
        "held-out agreement with the expert": f"{held_out:.1%} on {len(holdout)} states",
        f"expert label counts ({', '.join(BEHAVIORS)})": train_set.label_counts().tolist(),
    })
    return {**summary, "holdout_agreement": held_out}


class _Learner:
    """DAgger's collection of one round: per decision and worker the expert's behavior with probability β,
    else the learner's most likely one; every visited state joins the training set or, for held-out
    episodes, the holdout set, once the round's decisions are made."""

    def __init__(self, actor, train_set: DemoDataset, holdout: DemoDataset, dagger: DaggerConfig,
                 rng: np.random.Generator, env):
        self.actor, self.train_set, self.holdout, self.dagger, self.rng = actor, train_set, holdout, dagger, rng
        self.W = env.num_envs
        self.labels = env.expert_actions
        self.expert_steps = np.zeros(self.W, dtype=np.int64)
        self.steps = np.zeros(self.W, dtype=np.int64)
        self.held_out = rng.random(self.W) < dagger.holdout_fraction
        actor.eval()

    def collect(self, env, obs, session: TrainingSession):
        """Run one round's decisions; returns (the last β, the current observation)."""
        dagger, rng, W, progress = self.dagger, self.rng, self.W, session.progress
        stored = self.train_set.shapes
        pending: list[tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]] = []
        beta = float("nan")
        for _ in range(max(1, dagger.decisions_per_round // W)):
            beta = expert_probability(progress.episodes, session.run.episodes, dagger.beta_start, dagger.hold_fraction)
            use_expert = rng.random(W) < beta
            actions = self.labels.clone()
            if not use_expert.all():
                with torch.inference_mode():
                    learner = self.actor(obs).squeeze(-1).long()
                actions = torch.where(torch.from_numpy(use_expert), self.labels, learner)
            pending.append(({k: obs[k].numpy() for k in stored}, self.labels.numpy().astype(np.int8),
                            self.held_out.copy()))
            self.expert_steps += use_expert
            self.steps += 1
            obs, _, _, extras = env.step(actions.to(torch.float32).unsqueeze(-1))
            self.labels = extras["expert_actions"]
            progress.decisions += W
            for worker, summary in env.pop_episodes():
                session.record_episode(worker, summary, beta=round(beta, 4),
                                       expert_share=round(self.expert_steps[worker] / max(self.steps[worker], 1), 4))
                self.expert_steps[worker] = self.steps[worker] = 0
                self.held_out[worker] = (len(self.holdout) < dagger.holdout_capacity
                                         and rng.random() < dagger.holdout_fraction)
            if session.budget_reached:
                break
        add_states(pending, self.train_set, self.holdout, dagger.holdout_capacity)
        return beta, obs


def add_states(pending, train_set: DemoDataset, holdout: DemoDataset, holdout_capacity: int) -> None:
    """Add the round's ``pending`` (states, labels, held-out mask) rows: held-out episodes' states to ``holdout``
    while it has room (then to ``train_set`` too), the others to ``train_set``."""
    for states, y, hold in pending:
        if len(holdout) >= holdout_capacity:
            hold = np.zeros_like(hold)
        train_set.add({k: v[~hold] for k, v in states.items()}, y[~hold])
        if hold.any():
            holdout.add({k: v[hold] for k, v in states.items()}, y[hold])


def _train_round(actor, optimizer, data: DemoDataset, dagger: DaggerConfig,
                 rng: np.random.Generator) -> tuple[float, float]:
    """``updates_per_round`` cross-entropy steps on uniform mini-batches; (mean loss, mean batch agreement)."""
    if len(data) < dagger.batch_size:
        return float("nan"), float("nan")
    actor.train()
    losses, hits = [], []
    for _ in range(dagger.updates_per_round):
        obs, labels = data.get(rng.integers(0, len(data), dagger.batch_size))
        logits = actor.distribution_input(obs)
        loss = F.cross_entropy(logits, labels)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        hits.append((logits.argmax(-1) == labels).float().mean().item())
    actor.eval()
    return float(np.mean(losses)), float(np.mean(hits))
