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
