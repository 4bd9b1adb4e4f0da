"""What a training run leaves in its folder: the per-episode CSV, curves (PNG) and a model card.

``episodes.csv`` has one row per finished episode (columns :data:`EPISODE_COLUMNS`, plus
``beta`` and ``expert_share`` for DAgger); r_T is the episode's summed terminal reward, and
``r_T_plus_r_t`` adds the summed per-behavior rewards r_k (the paper's two ablation indicators).
"""

from __future__ import annotations

import csv
import os
import platform
from collections.abc import Sequence
from typing import Any

import numpy as np

from hbmp_bench.errors import UserError

EPISODE_COLUMNS = ("episode", "worker", "r_T", "r_T_plus_r_t", "train_return", "success", "infractions", "length",
                   "end_reason", "route_completion", "sim_time_s", "wall_s")
DAGGER_COLUMNS = ("beta", "expert_share")
ITERATION_COLUMNS = ("iteration", "episode", "decisions", "actor_frozen", "value", "surrogate", "entropy", "wall_s",
                     "kl_init", "actor_lr")
"""PPO's ``iterations.csv``: after each rsl-rl iteration, the episodes finished by its end, the losses
(mean over the update's mini-batches), whether the actor was frozen (critic warm-up), the mean KL between the
initial (IL) actor and the current one in the run's ``anchor_kl`` direction (empty without an initial actor) and
the actor's learning rate."""
ROUND_COLUMNS = ("round", "episodes", "dataset", "holdout", "loss", "train_agreement", "holdout_agreement", "wall_s")


class CsvLog:
    """Append-only CSV with a fixed header; reopening an existing file checks the header matches (a header
    that is a prefix of ``columns``, written by an older version, gains the new columns).

    ``keep_through``: on reopening for a resume, drop the rows whose ``key`` column (``episode``)
    is beyond this number first (they were logged after the checkpoint the run resumes from, and
    will be run again), so every episode appears once.
    """

    def __init__(self, path: str, columns: Sequence[str], keep_through: int | None = None, key: str = "episode"):
        self.path = path
        self.columns = tuple(columns)
        exists = os.path.isfile(path) and os.path.getsize(path) > 0
        if exists:
            with open(path, newline="") as f:
                header = next(csv.reader(f), [])
            older = len(header) < len(self.columns) and tuple(header) == self.columns[:len(header)]
            if tuple(header) != self.columns and not older:
                raise UserError(f"{path!r} has columns {header}, expected {list(self.columns)}")
            if keep_through is not None or older:  # an older log gains the new columns, empty in its rows
                with open(path, newline="") as f:
                    rows = [r for r in csv.DictReader(f) if keep_through is None or int(r[key]) <= keep_through]
                tmp = path + ".tmp"
                with open(tmp, "w", newline="") as f:
                    writer = csv.DictWriter(f, fieldnames=self.columns)
                    writer.writeheader()
                    writer.writerows(rows)
                os.replace(tmp, path)
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self._file = open(path, "a", newline="")
        self._writer = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="ignore")
        if not exists:
            self._writer.writeheader()
            self._file.flush()

    def write(self, row: dict[str, Any]) -> None:
        self._writer.writerow({k: _fmt(row.get(k, "")) for k in self.columns})
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> CsvLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _fmt(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, float):  # 4 decimals; small rates (1e-5) keep 4 significant digits
        return round(value, 4) if value == 0 or abs(value) >= 1e-3 else float(f"{value:.4g}")
    return value


def read_csv(path: str) -> dict[str, np.ndarray]:
    """Columns of a training CSV as arrays (numeric where possible)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out: dict[str, np.ndarray] = {}
    for key in rows[0] if rows else ():
        values = [r[key] for r in rows]
        try:
            out[key] = np.array([float(v) if v != "" else np.nan for v in values])
        except ValueError:
            out[key] = np.array(values)
    return out


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over up to ``window`` points (same length as ``x``)."""
    x = np.asarray(x, dtype=float)
    if len(x) == 0:
        return x
    c = np.cumsum(np.insert(x, 0, 0.0))
    idx = np.arange(1, len(x) + 1)
    lo = np.maximum(idx - window, 0)
    return (c[idx] - c[lo]) / (idx - lo)


def plot_run(folder: str, title: str, window: int = 50) -> str:
    """``curves.png`` of a run folder: r_T and r_T + Σr_t per episode, success rate, and for DAgger
    the loss and held-out agreement per round. Returns the PNG path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    eps = read_csv(os.path.join(folder, "episodes.csv"))
    rounds_path = os.path.join(folder, "rounds.csv")
    rounds = read_csv(rounds_path) if os.path.isfile(rounds_path) else {}
    panels = 3 if rounds else 2
    fig, axes = plt.subplots(1, panels, figsize=(5 * panels, 3.6))
    ax = axes[0]
    if "episode" in eps:
        for key, label, color in (("r_T", "r_T", "C0"), ("r_T_plus_r_t", "r_T + Σr_t", "C1")):
            ax.plot(eps["episode"], eps[key], color=color, alpha=0.15, lw=0.8)
            ax.plot(eps["episode"], moving_average(eps[key], window), color=color, label=f"{label} (mean of {window})")
        axes[1].plot(eps["episode"], moving_average(eps["success"], window), color="C2", label="success")
        if "beta" in eps:
            axes[1].plot(eps["episode"], eps["beta"], color="C7", ls="--", label="P(expert) β")
    ax.set(xlabel="episode", ylabel="reward", title=title)
    ax.legend(fontsize=8)
    axes[1].set(xlabel="episode", ylabel="rate", ylim=(-0.02, 1.02), title=f"success (mean of {window})")
    axes[1].legend(fontsize=8)
    if rounds:
        ax = axes[2]
        ax.plot(rounds["episodes"], rounds["loss"], color="C3", label="cross-entropy")
        ax.set(xlabel="episode", ylabel="loss", title="DAgger")
        ax2 = ax.twinx()
        ax2.plot(rounds["episodes"], rounds["holdout_agreement"], color="C4", label="held-out agreement")
        ax2.set(ylabel="agreement with expert", ylim=(0, 1))
        ax.legend(loc="upper left", fontsize=8)
        ax2.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    path = os.path.join(folder, "curves.png")
    _save_fig(fig, path)
    plt.close(fig)
    return path


COMPARISON_PANELS = (("r_T", "r_T", None), ("r_T_plus_r_t", "r_T + Σr_t", None),
                     ("success", "success rate", (-0.02, None)), ("timeout", "timeout rate", (-0.02, 1.02)))
"""The ablation figure's panels: (series, y label, y limits or None)."""


def comparison_series(episodes: dict[str, np.ndarray], window: int) -> dict[str, np.ndarray]:
    """The ablation figure's panels for one run (:data:`COMPARISON_PANELS` order): trailing means over
    ``window`` episodes of r_T, r_T + Σr_t, success and ending at the timeout, each (episodes,), from
    :func:`read_csv`'s columns."""
    columns = {**episodes, "timeout": (episodes["end_reason"] == "timeout").astype(float)}
    return {key: moving_average(columns[key], window) for key, _, _ in COMPARISON_PANELS}


def validation_series(folder: str) -> dict[str, np.ndarray] | None:
    """A run's greedy validations from its ``validation.csv`` (None without one): ``episode`` (V,), ``success``
    (V,) in [0, 1] and ``stderr`` (V,), the binomial standard error ``sqrt(p (1 - p) / n)`` of each success over
    its ``n`` validation episodes: how far apart two validations of the same policy fall by the luck of the
    episodes alone."""
    path = os.path.join(folder, "validation.csv")
    if not os.path.isfile(path):
        return None
    rows = read_csv(path)
    success, n = rows["success"].astype(float), np.maximum(rows["episodes"].astype(float), 1.0)
    return {"episode": rows["episode"], "success": success, "stderr": np.sqrt(success * (1.0 - success) / n)}


def comparison_figure(folders: Sequence[str], labels: Sequence[str], window: int = 50):
    """The figure of :func:`plot_comparison` (a matplotlib ``Figure``): the :data:`COMPARISON_PANELS` of every
    run and, when any run has a ``validation.csv``, a last panel of its greedy validation success per validated
    episode with a band of one standard error (:func:`validation_series`); a run's episode-0 validation is its
    initial actor's (for PPO from ``il``: ``il``'s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if len(folders) != len(labels):
        raise UserError("give one label per run folder")
    validations = [validation_series(folder) for folder in folders]
    n_panels = len(COMPARISON_PANELS) + any(v is not None for v in validations)
    fig, axes = plt.subplots(1, n_panels, figsize=(5 * n_panels, 3.8), sharey=False)
    for k, (folder, label) in enumerate(zip(folders, labels)):
        eps = read_csv(os.path.join(folder, "episodes.csv"))
        for ax, series in zip(axes, comparison_series(eps, window).values()):
            ax.plot(eps["episode"], series, color=f"C{k}", label=label)
    for ax, (_, name, limits) in zip(axes, COMPARISON_PANELS):
        ax.set(xlabel="episode", ylabel=f"{name} (mean of {window})")
        if limits is not None:
            ax.set_ylim(*limits)
    if n_panels > len(COMPARISON_PANELS):
        ax = axes[-1]
        for k, (label, v) in enumerate(zip(labels, validations)):
            if v is None:
                continue
            ax.plot(v["episode"], v["success"], color=f"C{k}", marker="o", markersize=3, label=label)
            ax.fill_between(v["episode"], np.maximum(v["success"] - v["stderr"], 0.0),
                            np.minimum(v["success"] + v["stderr"], 1.0), color=f"C{k}", alpha=0.15, linewidth=0)
        ax.set(xlabel="episode", ylabel="greedy validation success (± 1 s.e.)")
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_comparison(folders: Sequence[str], labels: Sequence[str], out: str, window: int = 50) -> str:
    """The paper's ablation figure: r_T and r_T + Σr_t per episode for several runs, plus their
    success rates and the share of their episodes that end at the timeout (a run that learns to
    stand shows there), and the greedy validations of the runs that have them (:func:`comparison_figure`);
    one PNG (trailing means over ``window`` episodes); ``out``."""
    import matplotlib.pyplot as plt

    fig = comparison_figure(folders, labels, window)
    _save_fig(fig, out)
    plt.close(fig)
    return out


def _save_fig(fig, path: str) -> None:
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    tmp = os.path.join(folder, f".{os.path.basename(path)}.tmp.png")
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, path)


def machine_description() -> str:
    """OS, CPU and core count of this machine, and the torch build (no host names or paths)."""
    import torch

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (f"{platform.system()} {platform.machine()}, {cpu}, {cores} cores available, "
            f"Python {platform.python_version()}, torch {torch.__version__} (CPU)")


def write_model_card(path: str, kind: str, command: str, seed: int, progress: dict[str, Any],
                     options: dict[str, Any], results: dict[str, Any]) -> None:
    """A markdown model card: command, seed, episodes, wall time, machine, options and final stats."""
    lines = [
        f"# `{kind}` policy",
        "",
        f"- command: `{command}`",
        f"- seed: {seed}",
        f"- episodes: {progress.get('episodes', 0)}",
        f"- decisions: {progress.get('decisions', 0)}",
        f"- wall time: {progress.get('wall_s', 0.0) / 60:.1f} min",
        f"- machine: {machine_description()}",
    ]
    hours = progress.get("wall_s", 0.0) / 3600.0
    if hours > 0:
        lines.append(f"- episodes per hour: {progress.get('episodes', 0) / hours:.0f} (wall time, validation included)")
    agents, workers = int(options.get("env.agents", 1)), int(options.get("workers", 1))
    if agents > 1:
        lines.append(f"- learners: {agents} per simulation x {workers} workers = {agents * workers} slots of one shared "
                     f"policy; the traffic each learner met included the {agents - 1} other learners of its scene, "
                     "which drive as it does (the same policy, while it learns), besides SUMO's drivers and "
                     "pedestrians (a single-ego run meets SUMO's only)")
    lines += [
        "",
        "## Training options",
        "",
    ]
    lines += [f"- {k}: {v}" for k, v in options.items()]
    lines += ["", "## Results at the end of training", ""]
    lines += [f"- {k}: {v}" for k, v in results.items()]
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(tmp, path)
