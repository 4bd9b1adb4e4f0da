"""pandas views of episode records: summary counts and the paper's success table."""

from __future__ import annotations

from collections.abc import Iterable

import pandas as pd

from hbmp_bench.metrics.records import EpisodeRecord
from hbmp_bench.scenarios.spec import TASK_LABELS, TASKS


def records_frame(records: Iterable[EpisodeRecord]) -> pd.DataFrame:
    """One row per episode."""
    return pd.DataFrame([r.to_dict() for r in records])


def summarize(records: Iterable[EpisodeRecord]) -> dict:
    """Totals over episodes: success rate, infraction events, timeouts, decisions."""
    df = records_frame(records)
    if df.empty:
        return {"episodes": 0, "success_rate": 0.0, "collisions": 0, "wrong_lane": 0, "red_light": 0, "off_road": 0, "timeouts": 0}
    collisions = df["collision_vehicle"] + df["collision_pedestrian"] + df["collision_other"]
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


def success_table(records: Iterable[EpisodeRecord]) -> pd.DataFrame:
    """Success % in the paper's layout: task rows × town columns."""
    df = records_frame(records)
    if df.empty:
        return pd.DataFrame()
    table = df.pivot_table(index="task", columns="town", values="success", aggfunc="mean") * 100.0
    order = [t for t in TASKS if t in table.index]
    table = table.loc[order].round(1)
    table.index = [TASK_LABELS[t] for t in table.index]
    return table
