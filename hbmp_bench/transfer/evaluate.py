"""Zero-shot evaluation on highway-env: episodes of any agent, and the transfer table.

``run_transfer_episodes`` is the library call behind ``hbmp-bench transfer evaluate`` (and the
``highway-transfer`` suite): it returns ordinary :class:`EpisodeRecord` rows with suite
``highway-transfer``, town = task = the scene, and fidelity ``highway-env:<observation kind>``
(the record has no observation column; the fidelity keeps deformed and vehicle-centric runs
apart, also in :mod:`hbmp_bench.metrics.report`).
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from hbmp_bench.agents import load_agent
from hbmp_bench.envs.observation import ObservationConfig
from hbmp_bench.errors import UserError
from hbmp_bench.metrics.records import AGENT_ERROR, EpisodeRecord, latest_per_key, read_records
from hbmp_bench.rollout import AgentFailed, EnvFailed, run_episode
from hbmp_bench.transfer.env import HighwayTransferEnv
from hbmp_bench.transfer.scenes import SCENES, get_scene

OBSERVATIONS = ("deformed", "vehicle_centric")


def run_transfer_episodes(agent: str, scene: str, episodes: int, observation: str = "deformed",
                          progress: bool = False) -> list[EpisodeRecord]:
    """Run ``agent`` (registry name or ``module:Class``) for ``episodes`` episodes of a highway-env
    scene; episode k is reset with seed k, so every agent and observation kind sees the same
    traffic. An agent that raises during an episode gets an ``agent_error`` record for it (the
    run goes on); an agent that cannot be loaded (unknown name, missing checkpoint) raises here.

    Returns:
        One record per episode, in episode order, ``agent`` set to ``agent``.
    """
    get_scene(scene)
    ObservationConfig(kind=observation)
    if episodes <= 0:
        raise UserError(f"episodes must be > 0, got {episodes}")
    policy = load_agent(agent)
    road_profile = dict(getattr(policy, "env_kwargs", {})).get("road_profile", "paper")  # R_t it was trained on
    env = HighwayTransferEnv(scene=scene, observation=observation, road_profile=road_profile)
    records: list[EpisodeRecord] = []
    from tqdm import tqdm

    try:
        for index in tqdm(range(episodes), desc=f"{agent} {scene} {observation}", unit="ep", disable=not progress):
            try:
                record = EpisodeRecord(**run_episode(env, policy, seed=index, options={"episode_index": index}).record(env))
            except EnvFailed as exc:
                if exc.phase == "reset":
                    raise exc.__cause__ from None
                error = f"invalid action: {exc.__cause__}" if isinstance(exc.__cause__, ValueError) else repr(exc.__cause__)
                record = dataclasses.replace(env.record(), success=False, end_reason=AGENT_ERROR, error=error)
            except AgentFailed as exc:  # a plug-in agent's failure is its episode's result
                record = dataclasses.replace(env.record(), success=False, end_reason=AGENT_ERROR, error=repr(exc.__cause__))
            records.append(dataclasses.replace(record, agent=agent))
    finally:
        env.close()
    return records


def observation_of(record: EpisodeRecord | str) -> str:
    """The M_t kind of a transfer record (from its fidelity ``highway-env:<kind>``)."""
    fidelity = record if isinstance(record, str) else record.fidelity
    return fidelity.partition(":")[2] or fidelity


def _frame(records: Iterable[EpisodeRecord]) -> pd.DataFrame:
    df = pd.DataFrame([r.to_dict() for r in latest_per_key(records)])
    if df.empty:
        raise UserError("no records")
    df["M_t"] = df["fidelity"].map(observation_of)
    return df


def _layout(stats: pd.DataFrame, df: pd.DataFrame) -> pd.DataFrame:
    """(agent, M_t, town) x metric -> (agent, M_t) rows x (scene, metric) columns, in scene order,
    agents in first-seen order, deformed before vehicle_centric."""
    table = stats.unstack("town").swaplevel(axis=1)
    scenes = [s for s in SCENES if s in set(df["town"])] + sorted(set(df["town"]) - set(SCENES))
    table = table.reindex(columns=pd.MultiIndex.from_product([scenes, list(stats.columns)]))
    kinds = [k for k in OBSERVATIONS if k in set(df["M_t"])] + sorted(set(df["M_t"]) - set(OBSERVATIONS))
    rows = [(a, k) for a in dict.fromkeys(df["agent"]) for k in kinds if (a, k) in table.index]
    return table.reindex(pd.MultiIndex.from_tuples(rows, names=["agent", "M_t"]))


def transfer_table(records: Iterable[EpisodeRecord]) -> pd.DataFrame:
    """Success and collision rates [%] (one decimal): (agent, M_t) rows x (scene, ``success %`` /
    ``collision %``) columns. Collision % counts episodes with any collision (vehicle or obstacle)."""
    df = _frame(records)
    df["collided"] = (df["collision_vehicle"] + df["collision_pedestrian"] + df["collision_other"]) > 0
    grouped = df.groupby(["agent", "M_t", "town"], sort=False)
    stats = pd.DataFrame({"success %": grouped["success"].mean() * 100.0,
                          "collision %": grouped["collided"].mean() * 100.0})
    return _layout(stats, df).round(1)


def throughput_table(records: Iterable[EpisodeRecord], timing: pd.DataFrame) -> pd.DataFrame:
    """Episodes and decisions per wall-clock second: (agent, M_t) rows x (scene, ``episodes`` /
    ``dec/s``) columns; ``timing`` has columns agent, observation, scene, decisions_per_s (the
    ``.timing.json`` files of :func:`save_run`)."""
    df = _frame(records)
    grouped = df.groupby(["agent", "M_t", "town"], sort=False)
    stats = pd.DataFrame({"episodes": grouped.size().astype(float)})
    if not timing.empty:
        t = timing.rename(columns={"observation": "M_t", "scene": "town"}).set_index(["agent", "M_t", "town"])
        stats["dec/s"] = t["decisions_per_s"].reindex(stats.index)
    return _layout(stats, df).round(0)


# ------------------------------------------------------------- result files
def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "." for c in name)


def result_stem(agent: str, scene: str, observation: str) -> str:
    """File name stem of one (agent, scene, observation) run."""
    return f"highway-transfer__{_safe(agent)}__{scene}__{observation}"


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temp file beside ``path``, then rename it over ``path``."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def save_run(out_dir: str | os.PathLike, agent: str, scene: str, observation: str,
             records: list[EpisodeRecord], wall_s: float) -> Path:
    """Write a run's records (``<stem>.jsonl``) and timing (``<stem>.timing.json``), each replaced
    atomically; returns the records path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = result_stem(agent, scene, observation)
    lines = "".join(json.dumps(r.to_dict(), sort_keys=True) + "\n" for r in records)
    path = out / f"{stem}.jsonl"
    write_atomic(path, lines)
    decisions = sum(r.decisions for r in records)
    timing = {"agent": agent, "scene": scene, "observation": observation, "episodes": len(records),
              "decisions": decisions, "wall_s": round(wall_s, 3),
              "decisions_per_s": round(decisions / wall_s, 1) if wall_s > 0 else None}
    write_atomic(out / f"{stem}.timing.json", json.dumps(timing, indent=2) + "\n")
    return path


def load_runs(out_dir: str | os.PathLike) -> tuple[list[EpisodeRecord], pd.DataFrame]:
    """Every transfer record and timing under ``out_dir`` (files written by :func:`save_run`)."""
    out = Path(out_dir)
    files = sorted(out.glob("highway-transfer__*.jsonl"))
    if not files:
        raise FileNotFoundError(f"no highway-transfer records in {out}")
    records = [r for f in files for r in read_records(f)]
    timing = [json.loads(f.read_text(encoding="utf-8")) for f in sorted(out.glob("highway-transfer__*.timing.json"))]
    return records, pd.DataFrame(timing)


def timed_run(agent: str, scene: str, episodes: int, observation: str) -> tuple[list[EpisodeRecord], float]:
    """``run_transfer_episodes`` and its wall time [s] (a picklable job for worker processes)."""
    start = time.perf_counter()
    records = run_transfer_episodes(agent, scene, episodes, observation)
    return records, time.perf_counter() - start
