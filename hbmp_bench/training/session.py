"""One training run's lifecycle, the same for every algorithm: :class:`TrainingSession`.

An algorithm (:func:`~hbmp_bench.training.dagger.train_dagger`, :func:`~hbmp_bench.training.ppo.train_ppo`)
writes only its own loop; the session does the rest, in this order::

    session = TrainingSession(run)                     # reads the resumed checkpoint, the progress so far
    with session:                                      # closes workers, logs and the bar, however it ends
        env = session.start(env_config)                # folder, seeds, torch threads, workers
        session.open_episodes(columns)                 # episodes.csv (and session.log(...) for its own logs)
        ...                                            # the algorithm's loop:
        session.record_episode(worker, summary)        #   a finished episode -> episodes.csv, progress bar
        if session.save_due(): session.save(ckpt)      #   checkpoint.pt every run.save_every episodes
        session.finish(session.checkpoint(...))        # checkpoint.pt and policy.pt
    return session.write_outputs(title, final, options, results)   # curves.png and MODEL_CARD.md

Seeding (fresh and resumed runs alike, so a resumed run does not replay the random streams of its start):
torch with ``run.seed + episodes``, the workers' environments with ``run.seed * 1_000_003 + episodes``,
where ``episodes`` is the number finished before this part of the run (0 for a fresh run). A resumed run's
logs are cut back to the checkpoint's progress first, so every episode, iteration and round appears once.

A new training algorithm touches one place: its own module, a loop that calls these.
"""

from __future__ import annotations

import os
from typing import Any

from hbmp_bench.errors import ConfigError
from hbmp_bench.policies.checkpoints import load_checkpoint, policy_only, save_checkpoint
from hbmp_bench.training.run import Progress, RunConfig, episode_row, final_results, progress_bar
from hbmp_bench.training.runlog import CsvLog, plot_run, write_model_card

COUNTERS = {"episode": "episodes", "iteration": "iterations", "round": "iterations"}
"""Which :class:`~hbmp_bench.training.run.Progress` counter a log's key column counts (rounds are DAgger's
iterations)."""


class TrainingSession:
    """Resume, seeding, workers, logs, progress, checkpoints, ``policy.pt``, curves and the model card of one run.

    Args:
        run: the run's options (budget, workers, seed, folder, resume).
        resume_kinds: the kinds a resumed checkpoint may hold (default: ``run.kind``).

    Attributes:
        resume: the checkpoint resumed from (None for a fresh run).
        progress: counters carried across resumes.
        env: the training ``VecEnv`` once :meth:`start` made it.

    Raises:
        ConfigError: the resumed checkpoint already has ``run.episodes`` episodes.
    """

    def __init__(self, run: RunConfig, resume_kinds: tuple[str, ...] | None = None):
        self.run = run
        self.resume = load_checkpoint(run.resume, kinds=resume_kinds or (run.kind,)) if run.resume else None
        self.progress = Progress.from_dict(self.resume["progress"]) if self.resume else Progress()
        if self.progress.episodes >= run.episodes:
            raise ConfigError(f"the checkpoint already has {self.progress.episodes} episodes; ask for more than that")
        self.started_at = self.progress.episodes
        self.env = None
        self.bar = None
        self._episodes: CsvLog | None = None
        self._closing: list[Any] = []
        self._last_save = self.progress.episodes

    @property
    def resumed(self) -> bool:
        return self.resume is not None

    @property
    def torch_seed(self) -> int:
        return self.run.seed + self.started_at

    @property
    def env_seed(self) -> int:
        return self.run.seed * 1_000_003 + self.started_at

    def path(self, name: str) -> str:
        return self.run.path(name)

    def start(self, env_config) -> Any:
        """Make the run folder, seed torch, set its threads and start the workers; returns the ``VecEnv``."""
        import torch

        from hbmp_bench.training.vec_env import make_vec_env

        os.makedirs(self.run.out, exist_ok=True)
        torch.manual_seed(self.torch_seed)
        torch.set_num_threads(self.run.threads())
        self.env = make_vec_env(env_config, self.run.workers, seed=self.env_seed, backend=self.run.backend,
                                address=self.run.address)
        return self.env

    def open_episodes(self, columns) -> CsvLog:
        """Open ``episodes.csv`` (``columns``), where :meth:`record_episode` writes."""
        self._episodes = self.log("episodes.csv", columns)
        return self._episodes

    def log(self, name: str, columns, key: str = "episode") -> CsvLog:
        """An append-only CSV log of the run, closed with the session; on a resume, its rows whose ``key``
        column is past the checkpoint's progress (:data:`COUNTERS`) are dropped first."""
        keep = getattr(self.progress, COUNTERS[key]) if self.resumed else None
        return self.track(CsvLog(self.path(name), columns, keep_through=keep, key=key))

    def track(self, closable):
        """Close ``closable`` (a log, a validator) with the session; returns it."""
        self._closing.append(closable)
        return closable

    def start_bar(self):
        self.bar = progress_bar(self.run, self.progress.episodes)
        return self.bar

    def record_episode(self, worker: int, summary: dict[str, Any], **extra: Any) -> bool:
        """Log a finished episode (``extra``: the algorithm's own columns) and advance the counter and the
        bar; False, logging nothing, once the budget is reached."""
        if self.progress.episodes >= self.run.episodes:
            return False
        self._episodes.write(episode_row(self.progress, worker, summary, **extra))
        if self.bar is not None:
            self.bar.update(1)
        return True

    @property
    def budget_reached(self) -> bool:
        return self.progress.episodes >= self.run.episodes

    def options(self, env_options: dict[str, Any], *, before: dict[str, Any] | None = None,
                after: dict[str, Any] | None = None) -> dict[str, Any]:
        """The run's options for its checkpoints and model card: kind, workers, backend, ``before``, the
        environment's options (``env.<name>``), ``after`` (the algorithm's)."""
        return {"kind": self.run.kind, "workers": self.run.workers, "backend": self.run.backend, **(before or {}),
                **{f"env.{k}": v for k, v in env_options.items()}, **(after or {})}

    def checkpoint(self, model: dict[str, Any], states: dict[str, Any], options: dict[str, Any]) -> dict[str, Any]:
        """A checkpoint of the run now: ``model`` (how to rebuild the networks), the ``states`` (state dicts),
        the progress and the options with the command and seed."""
        return {"kind": self.run.kind, "model": model, **states, "progress": self.progress.to_dict(),
                "train": {"command": self.run.command, "seed": self.run.seed, **options}}

    def save_due(self) -> bool:
        return self.progress.episodes - self._last_save >= self.run.save_every

    def save(self, checkpoint: dict[str, Any]) -> None:
        """Write ``checkpoint.pt`` (what ``--resume`` continues from)."""
        save_checkpoint(self.path("checkpoint.pt"), checkpoint)
        self._last_save = self.progress.episodes

    def finish(self, final: dict[str, Any]) -> dict[str, Any]:
        """Write the final ``checkpoint.pt`` and ``policy.pt`` (without optimizer state); returns ``final``."""
        self.save(final)
        save_checkpoint(self.path("policy.pt"), policy_only(final))
        return final

    def close(self) -> None:
        """Stop the workers, close the logs and the bar (idempotent)."""
        env, self.env = self.env, None
        try:
            if env is not None:
                env.close()
        finally:
            for closable in self._closing:
                closable.close()
            self._closing = []
            if self.bar is not None:
                self.bar.close()
                self.bar = None

    def __enter__(self) -> TrainingSession:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def write_outputs(self, title: str, final: dict[str, Any], options: dict[str, Any],
                      results: dict[str, Any]) -> dict[str, Any]:
        """``curves.png`` and ``MODEL_CARD.md`` (the last episodes' results, then ``results``); returns the
        run's progress and the path of its policy."""
        plot_run(self.run.out, title)
        write_model_card(self.path("MODEL_CARD.md"), self.run.kind, self.run.command, self.run.seed,
                         final["progress"], options, {**final_results(self.path("episodes.csv")), **results})
        return {"progress": final["progress"], "policy": self.path("policy.pt")}
