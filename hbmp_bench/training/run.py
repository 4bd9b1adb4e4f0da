"""What every training run shares: its options, its folder layout and its bookkeeping.

Folder of a run (``out``):
    episodes.csv     one row per finished episode (see :mod:`hbmp_bench.training.runlog`)
    rounds.csv       DAgger only: loss and agreement with the expert per training round
    iterations.csv   PPO only: losses per rsl-rl iteration and whether the actor was frozen (warm-up)
    validation.csv   PPO with validate_every: the greedy policy's success on held-out Town03 episodes
    best.pt          PPO with validate_every: the actor of the best validation so far
    checkpoint.pt    latest full checkpoint (weights + optimizer), for ``--resume``
    dataset.npz      DAgger only: the aggregated dataset, for ``--resume``
    policy.pt        the final policy without optimizer state (what ships in the package)
    curves.png       training curves
    MODEL_CARD.md    command, seed, episodes, wall time, machine, options, final results
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hbmp_bench.errors import ConfigError, UnknownNameError
from hbmp_bench.policies.checkpoints import KINDS

BACKENDS = ("process", "ray")
"""Where training workers run: local processes over pipes, or Ray actors (a local instance or a cluster)."""


@dataclass(frozen=True)
class RunConfig:
    """Options common to every training kind.

    Attributes:
        kind: ``il``, ``hbmp``, ``hbmp-s``, ``flat`` or ``flat-il``.
        episodes: episode budget of this run (total, counting episodes before a resume).
        out: run folder.
        workers: environment worker processes (one libsumo simulation each).
        backend: where the workers run: ``process`` (local processes) or ``ray`` (Ray actors).
        address: the Ray cluster (``ray://HEAD:10001``, ``auto``); None: a local Ray instance.
        seed: seeds torch, the workers' environments and DAgger's mixing.
        save_every: write ``checkpoint.pt`` every this many finished episodes.
        resume: a ``checkpoint.pt`` to continue from (its kind must match).
        command: the command line, for the model card.
        progress: show a tqdm bar.
        torch_threads: torch intra-op threads of the trainer (None: cores left by the workers, >= 1).
        validate_every: PPO: evaluate the greedy policy on the ``hbmp-val`` suite every this many
            episodes and keep the best as ``best.pt`` (0: never; see :mod:`hbmp_bench.training.validation`).
        validate_episodes: the first this many episodes per task of ``hbmp-val`` (None: 20 of its 50).
    """

    kind: str
    episodes: int
    out: str
    workers: int = 2
    backend: str = "process"
    address: str | None = None
    seed: int = 0
    save_every: int = 50
    resume: str | None = None
    command: str = ""
    progress: bool = True
    torch_threads: int | None = None
    validate_every: int = 0
    validate_episodes: int | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise UnknownNameError("training kind", self.kind, KINDS)
        if self.episodes < 1:
            raise ConfigError(f"episodes must be >= 1, got {self.episodes}")
        if self.workers < 1:
            raise ConfigError(f"workers must be >= 1, got {self.workers}")
        if self.backend not in BACKENDS:
            raise UnknownNameError("training backend", self.backend, BACKENDS)
        if self.address is not None and self.backend != "ray":
            raise ConfigError("address is for the ray backend only (--backend ray)")
        if self.save_every < 1:
            raise ConfigError(f"save_every must be >= 1, got {self.save_every}")
        if self.validate_every < 0:
            raise ConfigError(f"validate_every must be >= 0 (0: never), got {self.validate_every}")
        if self.validate_episodes is not None and self.validate_episodes < 1:
            raise ConfigError(f"validate_episodes must be >= 1, got {self.validate_episodes}")

    def path(self, name: str) -> str:
        return os.path.join(self.out, name)

    def threads(self) -> int:
        if self.torch_threads is not None:
            return max(1, self.torch_threads)
        local_workers = 0 if self.address is not None else self.workers  # a cluster's actors run elsewhere
        return max(1, (os.cpu_count() or 1) - local_workers)


@dataclass
class Progress:
    """Counters of a run, carried across resumes (``wall_s`` sums the wall time of every part)."""

    episodes: int = 0
    decisions: int = 0
    iterations: int = 0
    wall_s: float = 0.0
    _start: float = field(default_factory=time.perf_counter, repr=False)
    _wall_at_start: float = 0.0

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Progress:
        p = cls(int(d["episodes"]), int(d["decisions"]), int(d["iterations"]), float(d["wall_s"]))
        p._wall_at_start = p.wall_s
        return p

    def tick(self) -> None:
        self.wall_s = self._wall_at_start + time.perf_counter() - self._start

    def to_dict(self) -> dict[str, Any]:
        self.tick()
        return {"episodes": self.episodes, "decisions": self.decisions, "iterations": self.iterations,
                "wall_s": round(self.wall_s, 2)}


def episode_row(progress: Progress, worker: int, summary: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """A CSV row for a finished episode; advances the episode counter."""
    progress.episodes += 1
    progress.tick()
    return {"episode": progress.episodes, "worker": worker, **summary, "wall_s": round(progress.wall_s, 1), **extra}


def final_results(episodes_csv: str, last: int = 100) -> dict[str, Any]:
    """Success rate, mean r_T and mean length over the last ``last`` episodes of a run."""
    from hbmp_bench.training.runlog import read_csv

    eps = read_csv(episodes_csv)
    if not eps:
        return {}
    n = min(last, len(eps["episode"]))
    return {
        f"success rate, last {n} episodes": f"{np.mean(eps['success'][-n:]):.1%}",
        f"mean r_T, last {n} episodes": f"{np.mean(eps['r_T'][-n:]):.1f}",
        f"mean r_T + Σr_t, last {n} episodes": f"{np.mean(eps['r_T_plus_r_t'][-n:]):.1f}",
        f"mean length [decisions], last {n} episodes": f"{np.mean(eps['length'][-n:]):.0f}",
        "success rate, all episodes": f"{np.mean(eps['success']):.1%}",
    }


def progress_bar(config: RunConfig, initial: int):
    from tqdm import tqdm

    return tqdm(total=config.episodes, initial=min(initial, config.episodes), unit="ep", desc=f"train {config.kind}",
                disable=not config.progress, dynamic_ncols=True)
