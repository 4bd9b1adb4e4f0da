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
- the learner is the PPO actor itself (:class:`~hbmp_bench.training.models.BehaviorNetwork` with
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
from hbmp_bench.training.checkpoints import load_checkpoint, policy_only, save_checkpoint
from hbmp_bench.training.models import behavior_model_cfgs, build_model, observation_shapes
from hbmp_bench.training.ppo import MASK_GROUP, input_groups, model_info
from hbmp_bench.training.run import Progress, RunConfig, episode_row, final_results, progress_bar
from hbmp_bench.training.runlog import DAGGER_COLUMNS, EPISODE_COLUMNS, ROUND_COLUMNS, CsvLog, plot_run, write_model_card
from hbmp_bench.training.worker import WorkerEnvConfig


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
        mask_actions: mask infeasible behaviors in the policy (see :mod:`hbmp_bench.training.models`).
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
    """

    def __init__(self, shapes: dict[str, tuple[int, ...]]):
        self.shapes = {k: tuple(v) for k, v in shapes.items()}
        self.packed = {k: len(v) > 1 for k, v in self.shapes.items()}
        self.size = 0
        self._data: dict[str, np.ndarray] = {k: self._empty(k, 1024) for k in self.shapes}
        self._labels = np.zeros(1024, dtype=np.int8)

    def _width(self, key: str) -> int:
        n = int(np.prod(self.shapes[key]))
        return (n + 7) // 8 if self.packed[key] else n

    def _empty(self, key: str, capacity: int) -> np.ndarray:
        return np.zeros((capacity, self._width(key)), dtype=np.uint8 if self.packed[key] else np.float32)

    def __len__(self) -> int:
        return self.size

    def add(self, obs: dict[str, np.ndarray], labels: np.ndarray) -> None:
        """Append n states: ``obs[group]`` of shape (n, *shape), ``labels`` (n,) behavior indices."""
        n = len(labels)
        if n == 0:
            return
        if self.size + n > len(self._labels):
            capacity = max(2 * len(self._labels), self.size + n)
            for k, arr in self._data.items():
                grown = self._empty(k, capacity)
                grown[: self.size] = arr[: self.size]
                self._data[k] = grown
            labels_grown = np.zeros(capacity, dtype=np.int8)
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
        """States ``index`` as a TensorDict (len(index),) of float32 groups, and their labels (long)."""
        groups = {}
        for k, shape in self.shapes.items():
            rows = self._data[k][index]
            if self.packed[k]:
                rows = np.unpackbits(rows, axis=1, count=int(np.prod(shape))).astype(np.float32)
            groups[k] = torch.from_numpy(np.ascontiguousarray(rows).reshape(len(index), *shape))
        return TensorDict(groups, batch_size=[len(index)]), torch.from_numpy(self._labels[index].astype(np.int64))

    def label_counts(self) -> np.ndarray:
        return np.bincount(self._labels[: self.size], minlength=5)

    def state_dict(self, prefix: str) -> dict[str, np.ndarray]:
        out = {f"{prefix}/{k}": v[: self.size] for k, v in self._data.items()}
        out[f"{prefix}/labels"] = self._labels[: self.size]
        return out

    def load_state_dict(self, arrays: dict[str, np.ndarray], prefix: str) -> None:
        self._data = {k: np.array(arrays[f"{prefix}/{k}"]) for k in self.shapes}
        self._labels = np.array(arrays[f"{prefix}/labels"])
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
        The run's progress dict and the path of the final policy (``policy``).
    """
    if run.kind != "il":
        raise ConfigError(f"DAgger trains the 'il' policy, not {run.kind!r}")
    env_config = dataclasses.replace(env_config, expert_labels=True)
    resume = load_checkpoint(run.resume, kinds=("il",)) if run.resume else None
    progress = Progress.from_dict(resume["progress"]) if resume else Progress()
    if progress.episodes >= run.episodes:
        raise ConfigError(f"the checkpoint already has {progress.episodes} episodes; ask for more than that")
    data_path = os.path.join(os.path.dirname(os.path.abspath(run.resume)), "dataset.npz") if resume else ""
    if resume and not os.path.isfile(data_path):
        raise UserError(f"DAgger goes on from its aggregated demonstrations, but {data_path} is missing beside the "
                        f"checkpoint (keep or commit dataset.npz with checkpoint.pt); without them the run would "
                        f"train on a new dataset only: start a new run instead")
    os.makedirs(run.out, exist_ok=True)
    torch.manual_seed(run.seed)
    torch.set_num_threads(run.threads())
    rng = np.random.default_rng([run.seed, progress.episodes])

    env = run.vec_env(env_config, seed=run.seed * 1_000_003 + progress.episodes)
    logs: list[CsvLog] = []
    bar = None
    try:
        obs = env.get_observations()
        groups = input_groups(obs)
        actor_cfg, critic_cfg = behavior_model_cfgs(dagger.mask_actions)
        info = model_info(env, actor_cfg, critic_cfg, groups)
        shapes = observation_shapes(obs)
        actor = build_model(actor_cfg, shapes, info["obs_groups"], "actor", env.num_actions)
        optimizer = torch.optim.Adam(actor.parameters(), lr=dagger.learning_rate)
        stored = {k: v for k, v in shapes.items() if k in groups or (dagger.mask_actions and k == MASK_GROUP)}
        train_set, holdout = DemoDataset(stored), DemoDataset(stored)
        rounds = 0
        if resume is not None:
            actor.load_state_dict(resume["actor_state_dict"])
            optimizer.load_state_dict(resume["optimizer_state_dict"])
            rounds = int(resume["progress"].get("iterations", 0))
            with np.load(data_path) as arrays:
                train_set.load_state_dict(arrays, "train")
                holdout.load_state_dict(arrays, "holdout")
        options = {"kind": "il", "workers": run.workers, "backend": run.backend,
                   **{f"env.{k}": v for k, v in info["env"].items()},
                   **{f"dagger.{k}": v for k, v in dataclasses.asdict(dagger).items()}}

        def checkpoint() -> dict[str, Any]:
            return {"kind": "il", "model": info, "actor_state_dict": actor.state_dict(),
                    "optimizer_state_dict": optimizer.state_dict(), "progress": progress.to_dict(),
                    "train": {"command": run.command, "seed": run.seed, **options}}

        def save() -> None:
            save_datasets(run.path("dataset.npz"), train_set, holdout)
            save_checkpoint(run.path("checkpoint.pt"), checkpoint())

        episodes_log = CsvLog(run.path("episodes.csv"), EPISODE_COLUMNS + DAGGER_COLUMNS,
                              keep_through=progress.episodes if resume is not None else None)
        rounds_log = CsvLog(run.path("rounds.csv"), ROUND_COLUMNS)
        logs = [episodes_log, rounds_log]
        bar = progress_bar(run, progress.episodes)
        W = env.num_envs
        labels = env.expert_actions
        expert_steps = np.zeros(W, dtype=np.int64)
        steps = np.zeros(W, dtype=np.int64)
        held_out = rng.random(W) < dagger.holdout_fraction
        last_save = progress.episodes
        actor.eval()
        while progress.episodes < run.episodes:
            pending: list[tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]] = []
            for _ in range(max(1, dagger.decisions_per_round // W)):
                beta = expert_probability(progress.episodes, run.episodes, dagger.beta_start, dagger.hold_fraction)
                use_expert = rng.random(W) < beta
                actions = labels.clone()
                if not use_expert.all():
                    with torch.inference_mode():
                        learner = actor(obs).squeeze(-1).long()
                    actions = torch.where(torch.from_numpy(use_expert), labels, learner)
                pending.append(({k: obs[k].numpy() for k in stored}, labels.numpy().astype(np.int8), held_out.copy()))
                expert_steps += use_expert
                steps += 1
                obs, _, _, extras = env.step(actions.to(torch.float32).unsqueeze(-1))
                labels = extras["expert_actions"]
                progress.decisions += W
                for worker, summary in env.pop_episodes():
                    if progress.episodes < run.episodes:
                        row = episode_row(progress, worker, summary, beta=round(beta, 4),
                                          expert_share=round(expert_steps[worker] / max(steps[worker], 1), 4))
                        episodes_log.write(row)
                        bar.update(1)
                    expert_steps[worker] = steps[worker] = 0
                    held_out[worker] = len(holdout) < dagger.holdout_capacity and rng.random() < dagger.holdout_fraction
                if progress.episodes >= run.episodes:
                    break
            for states, y, hold in pending:
                if len(holdout) >= dagger.holdout_capacity:
                    hold = np.zeros_like(hold)
                train_set.add({k: v[~hold] for k, v in states.items()}, y[~hold])
                if hold.any():
                    holdout.add({k: v[hold] for k, v in states.items()}, y[hold])
            rounds += 1
            progress.iterations = rounds
            loss, hits = _train_round(actor, optimizer, train_set, dagger, rng)
            rounds_log.write({"round": rounds, "episodes": progress.episodes, "dataset": len(train_set),
                              "holdout": len(holdout), "loss": loss, "train_agreement": hits,
                              "holdout_agreement": agreement(actor, holdout, limit=dagger.holdout_capacity),
                              "wall_s": round(progress.to_dict()["wall_s"], 1)})
            bar.set_postfix(loss=f"{loss:.3f}", beta=f"{beta:.2f}", data=len(train_set))
            if progress.episodes - last_save >= run.save_every:
                save()
                last_save = progress.episodes
        save()
        final = checkpoint()
        save_checkpoint(run.path("policy.pt"), policy_only(final))
    finally:
        env.close()
        for log in logs:
            log.close()
        if bar is not None:
            bar.close()
    plot_run(run.out, "il (DAgger)")
    results = final_results(run.path("episodes.csv"))
    results["held-out agreement with the expert"] = f"{agreement(actor, holdout):.1%} on {len(holdout)} states"
    results["expert label counts (speed_up, speed_down, change_left, change_right, keep)"] = \
        train_set.label_counts().tolist()
    write_model_card(run.path("MODEL_CARD.md"), "il", run.command, run.seed, final["progress"], options, results)
    return {"progress": final["progress"], "policy": run.path("policy.pt"), "holdout_agreement": agreement(actor, holdout)}


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
