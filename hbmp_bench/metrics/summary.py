"""pandas views of episode records: summary counts and the paper's success table."""

from __future__ import annotations

from collections.abc import Iterable

import pandas as pd

from hbmp_bench.metrics.records import DRIVING_SCORE_DEFINITION, EpisodeRecord
from hbmp_bench.scenarios.scenario_types import all_tasks
from hbmp_bench.scenarios.spec import TASK_LABELS
from hbmp_bench.vocabulary import COLLISION_KINDS


def records_frame(records: Iterable[EpisodeRecord]) -> pd.DataFrame:
    """One row per episode."""
    return pd.DataFrame([r.to_dict() for r in records])


def summarize(records: Iterable[EpisodeRecord]) -> dict:
    """Totals over episodes: success rate, infraction events, timeouts, decisions."""
    df = records_frame(records)
    if df.empty:
        return {"episodes": 0, "success_rate": 0.0, "collisions": 0, "wrong_lane": 0, "red_light": 0, "off_road": 0, "timeouts": 0}
    collisions = df[list(COLLISION_KINDS)].sum(axis=1)
    return {
        "episodes": int(len(df)),
        "success_rate": float(df["success"].mean()),
        "collisions": int(collisions.sum()),
        "collision_vehicle": int(df["collision_vehicle"].sum()),
        "collision_pedestrian": int(df["collision_pedestrian"].sum()),
        "wrong_lane": int(df["wrong_lane"].sum()),
        "red_light": int(df["red_light"].sum()),
        "off_road": int(df["off_road"].sum()),
        "timeouts": int(df["timeout"].sum()),
        "mean_route_completion": float(df["route_completion"].mean()),
        "mean_driving_score": float(df["driving_score"].mean()),
        "decisions": int(df["decisions"].sum()),
        "distance_km": float(df["distance_m"].sum() / 1000.0),
    }


def agent_contacts(record: EpisodeRecord) -> int:
    """How many other goal-directed vehicles of its scene a record's vehicle collided with (``agent_collisions``)."""
    return len(record.agent_collisions.split())


def other_collisions(record: EpisodeRecord) -> int:
    """A record's collision events with road users other than the scene's goal-directed vehicles (SUMO's
    vehicles, pedestrians, obstacles): its collisions less those with controlled agents, which
    ``collision_vehicle`` counts too (``EpisodeRecord.agent_collisions``)."""
    return max(record.collisions - agent_contacts(record), 0)


def scene_length_s(records: Iterable[EpisodeRecord]) -> float:
    """How long a scene ran [s]: until its last goal-directed vehicle's episode ended (the longest
    ``duration_s`` of its records; every vehicle starts with the scene)."""
    return max((r.duration_s for r in records), default=0.0)


def scene_summary(records: Iterable[EpisodeRecord]) -> dict:
    """The multi-agent figures of scene records (one per goal-directed vehicle; the scored ones): ``scenes``,
    ``agents``, ``agent_success_pct`` (% of agents that reached their goal), ``agent_collision_pairs`` (pairs of
    controlled agents that collided, each pair once), ``agents_in_agent_collision_pct`` (% of agents in a
    collision with another controlled agent), ``other_collisions`` (collision events with the other road
    users), ``red_light`` / ``wrong_lane`` / ``off_road`` (events), ``timeouts`` (agents), ``agent_errors``
    (agents), ``scene_minutes`` (the scenes' time, :func:`scene_length_s`, summed [min]) and
    ``throughput_per_min`` (agents arrived per minute of scene time)."""
    from hbmp_bench.metrics.records import AGENT_ERROR, agent_collision_pairs

    records = list(records)
    scenes: dict[tuple, list[EpisodeRecord]] = {}
    for r in records:
        scenes.setdefault((r.suite, r.town, r.task, r.episode, r.agent, r.fidelity), []).append(r)
    minutes = sum(scene_length_s(rows) for rows in scenes.values()) / 60.0
    arrived = sum(r.success for r in records)
    n = len(records)
    return {
        "scenes": len(scenes),
        "agents": n,
        "agent_success_pct": round(100.0 * arrived / n, 2) if n else 0.0,
        "agent_collision_pairs": len(agent_collision_pairs(records)),
        "agents_in_agent_collision_pct": round(100.0 * sum(agent_contacts(r) > 0 for r in records) / n, 2) if n else 0.0,
        "other_collisions": sum(other_collisions(r) for r in records),
        "red_light": sum(r.red_light for r in records),
        "wrong_lane": sum(r.wrong_lane for r in records),
        "off_road": sum(r.off_road for r in records),
        "timeouts": sum(bool(r.timeout) for r in records),
        "agent_errors": sum(r.end_reason == AGENT_ERROR for r in records),
        "scene_minutes": round(minutes, 3),
        "throughput_per_min": round(arrived / minutes, 3) if minutes > 0 else 0.0,
    }


SUMMARY_LEGEND: dict[str, str] = {
    "episodes": "episodes run",
    "success_rate": "fraction of episodes that reached the goal (0-1)",
    "collisions": "collision events (vehicles, pedestrians, other obstacles), summed over episodes",
    "collision_vehicle": "collision events with vehicles",
    "collision_pedestrian": "collision events with pedestrians",
    "wrong_lane": "wrong-lane events (entries into a lane running the other way)",
    "red_light": "red-light events (stop lines crossed on red; an episode can have several)",
    "off_road": "off-road events",
    "timeouts": "episodes that ran out of time",
    "mean_route_completion": "fraction of the route driven, mean over episodes (0-1)",
    "mean_driving_score": "mean over episodes of the " + DRIVING_SCORE_DEFINITION,
    "decisions": "behavior decisions taken, all episodes",
    "distance_km": "km driven, all episodes",
    "scenes": "multi-agent episodes (scenes) run",
    "agents": "goal-directed vehicles' episodes (one record each), all scenes",
    "agent_success_pct": "% of the goal-directed vehicles that reached their goal",
    "agent_collision_pairs": "pairs of goal-directed vehicles that collided with each other (each pair once)",
    "agents_in_agent_collision_pct": "% of the goal-directed vehicles in a collision with another goal-directed one",
    "other_collisions": "collision events of goal-directed vehicles with other road users (SUMO's traffic, "
                        "pedestrians, obstacles)",
    "agent_errors": "goal-directed vehicles whose scene the agent broke (raised, hung, bad reply)",
    "scene_minutes": "minutes of scene time (each scene until its last vehicle's episode ended), summed",
    "throughput_per_min": "goal-directed vehicles arrived per minute of scene time",
}
"""What each :func:`summarize` key means, with its unit (the legend of printed summaries)."""


def summary_lines(summary: dict) -> list[str]:
    """``key  value  (meaning)`` lines of a summary dict, the meaning from :data:`SUMMARY_LEGEND`
    (keys without one, such as paths and counts named in full, get none)."""
    lines = []
    for key, value in summary.items():
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        meaning = SUMMARY_LEGEND.get(key)
        lines.append(f"{key:24s} {text:>10s}" + (f"   {meaning}" if meaning else ""))
    return lines


SUCCESS_TABLE_TITLE = "success % (episodes that reached the goal), task rows x town columns:"


def success_table(records: Iterable[EpisodeRecord]) -> pd.DataFrame:
    """Success % in the paper's layout: task rows × town columns."""
    df = records_frame(records)
    if df.empty:
        return pd.DataFrame()
    table = df.pivot_table(index="task", columns="town", values="success", aggfunc="mean") * 100.0
    order = [t for t in all_tasks() if t in table.index]
    table = table.loc[order].round(1)
    table.index = [TASK_LABELS[t] for t in table.index]
    return table
