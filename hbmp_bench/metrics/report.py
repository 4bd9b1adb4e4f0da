"""Evaluation reports as pandas DataFrames, for notebooks and for ``hbmp-bench report``.

Input is one or more *result sets*: JSON-lines records files, leaderboard results files (or
folders of either). Each set is labelled by its agent (plus the fidelity when sets differ in it,
plus the folder when two sets would share a label). Per episode key the last record wins.
Episodes recorded as ``sim_error`` (the simulator failed, not the agent) or ``decision_cap``
(smoke runs) are not scored; the sim errors are shown as a ``sim_errors`` count in ``failures``,
``driving`` and ``coverage`` and at the top of ``report.md``. ``agent_error`` episodes are the agent's
failures and count everywhere.

Views (``build_report``):
    success        success % in the paper's layout: task rows × town columns; with several sets
                   the columns are (town, set).
    failures       per (set, town) the number of *episodes* with each outcome: success, wrong lane
                   (opposite lane or off-road: the paper's "out of lanes"), collision, red light,
                   timeout, left the network, and agent errors. An episode with a collision and a red light counts
                   in both; under CoRL2017 rules a successful episode can also have infractions.
    driving        CARLA Leaderboard driving score and route completion (means over episodes, %),
                   per (set, town) and over all towns.
    km_between     km driven per infraction event, per set and kind (inf: no such event; printed
                   and in markdown as "no event").
    route_length   per (set, town, task) the distance driven ÷ route length of the episodes that
                   reached the goal (median, min, max): about 1 when route lengths are what a
                   car drives, since the goal is reached within a couple of metres.
    coverage       per set: episodes in the views, sim errors left out, agent errors.
    paired         per pair of sets, on the episodes both scored (same suite, town, task, index and vehicle):
                   both succeeded, only the first, only the second, neither, the success difference
                   and the exact two-sided McNemar p on the episodes where they differ; whether a gap
                   between two agents is more than the luck of these episodes (not of training seeds).
    multi          (multi-agent scenes only: records that name their vehicle) per (set, town) and over all
                   towns: scenes, agents, % of agents that reached their goal, pairs of controlled agents
                   that collided (each pair once), % of agents in such a collision, collision events with
                   the other road users, red lights, wrong lane, off-road, timeouts, agent errors, and the
                   throughput: agents arrived per minute of scene time (a scene lasts until its last
                   vehicle's episode ended).
    multi_scenes   (multi-agent scenes only) the same per scene.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from hbmp_bench.errors import UserError
from hbmp_bench.metrics.records import (
    AGENT_ERROR,
    DECISION_CAP,
    DRIVING_SCORE_DEFINITION,
    DRIVING_SCORE_LB2_DEFINITION,
    SIM_ERROR,
    EpisodeRecord,
    read_records,
    record_driving_score_lb2,
)
from hbmp_bench.scenarios.scenario_types import all_tasks
from hbmp_bench.scenarios.spec import TASK_LABELS
from hbmp_bench.vocabulary import COLLISION_KINDS, DETECTED_KINDS, VIOLATION_KINDS

OUTCOMES = ("success", "wrong_lane", "collision", "red_light", "timeout", "left_network", "agent_error")
"""Columns of the failure-count view, in the paper's figure order, then the two ends the paper's figure
has no bar for: ``left_network`` (the ego left the road network, e.g. drove past its goal a lane off)
and agent errors. An episode's outcome is what ended it (:func:`episode_outcomes`), so each scored
episode has exactly one, under every suite's rules; the infractions along the way are counted by
:func:`km_between_infractions`."""

INFRACTIONS = ("collision", *DETECTED_KINDS)
"""Event kinds of the km-between-infractions view (``collision`` = all collisions)."""

EXCLUDED = (SIM_ERROR, DECISION_CAP)

NO_EVENT = "no event"
"""How printed and markdown tables show a km-between-infractions value with no such event (inf
in the CSV, null in JSON)."""

VIEW_LEGENDS: dict[str, str] = {
    "success": "Success %: episodes that reached the goal, of the scored episodes, per task and town.",
    "failures": "Number of EPISODES with each outcome (an episode that ran three red lights counts once "
                "under red_light; one episode can count under several outcomes; wrong_lane includes off-road).",
    "driving": "Means over episodes: " + DRIVING_SCORE_DEFINITION + "; route_completion_pct: % of the route "
               "driven; success_pct: % of episodes that reached the goal.",
    "km_between": "km driven per infraction EVENT of each kind (three red lights in one episode are three "
                  f"events); '{NO_EVENT}': none of that kind happened (inf in the CSV).",
    "route_length": "Episodes that reached the goal: distance driven / route length (about 1 when route "
                    "lengths are what a car drives).",
    "coverage": "Episodes scored per result set; simulator errors and decision-capped smoke episodes are left "
                "out of every table; agent errors count as failed episodes.",
    "paired": "Two result sets on the episodes both scored: only_first / only_second = episodes only that one "
              "reached the goal; diff_pp = success % first - second; p_mcnemar = exact two-sided McNemar test on "
              "those discordant episodes (small: the gap is more than the luck of these episodes; it says "
              "nothing of training seeds).",
    "scenarios": "Per scenario type (its ability in brackets): episodes, success %, mean "
                 + DRIVING_SCORE_LB2_DEFINITION + ", the Leaderboard 1.0 driving score of the other tables, route "
                 "completion %; only for results that hold scenario types.",
    "abilities": "Success % per ability: the episodes of its scenario types together (Bench2Drive's grouping); "
                 "only for results that hold scenario types.",
    "multi": "Multi-agent scenes, per town: agents = goal-directed vehicles (one record each); agent_success_pct = "
             "% of them that reached their goal; agent_collision_pairs = pairs of goal-directed vehicles that "
             "collided with each other, each pair once; agents_in_agent_collision_pct = % of agents in such a "
             "collision; other_collisions = collision EVENTS with other road users; red_light, wrong_lane, off_road "
             "= events; timeouts, agent_errors = agents; throughput_per_min = agents arrived per minute of scene "
             "time (a scene lasts until its last vehicle's episode ended).",
    "multi_scenes": "The multi view per scene (town, episode index).",
}
"""One-line meaning and units of each view of :func:`build_report`, printed above it."""


def records_files(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """The result files named by ``paths``: JSON-lines records files (``.jsonl``) and leaderboard
    results files (``.json``), or folders of either (searched non-recursively: the ``.jsonl``
    files, else the ``.json`` ones, so ``leaderboards/<suite>`` reads a whole board). A named file
    of another kind raises ValueError."""
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob("*.jsonl")) or sorted(p.glob("*.json"))
            if not found:
                raise FileNotFoundError(f"no .jsonl records or .json results files in {p}")
            files.extend(found)
        elif p.is_file():
            if p.suffix not in (".jsonl", ".json"):
                raise UserError(f"{p} is not a records file (.jsonl) or a leaderboard results file (.json)")
            files.append(p)
        else:
            raise FileNotFoundError(f"no records file or folder {p}")
    return files


def load_results(paths: Iterable[str | os.PathLike]) -> pd.DataFrame:
    """One row per episode of every result set, with a ``result_set`` label column.

    A file holding several agents or fidelities gives one set for each; a leaderboard results
    file is one set (:func:`~hbmp_bench.metrics.results_file.results_records`).
    """
    frames = []
    for path in records_files(paths):
        if path.suffix == ".json":
            from hbmp_bench.metrics.results_file import results_records

            records = results_records(path)
        else:
            records = latest_records(read_records(path))
        if not records:
            continue
        df = pd.DataFrame([r.to_dict() for r in records])
        df["source"] = str(path.parent if path.parent.name else path)
        frames.append(df)
    if not frames:
        raise UserError("the records files hold no records")
    return label_result_sets(pd.concat(frames, ignore_index=True))


def label_result_sets(df: pd.DataFrame) -> pd.DataFrame:
    """Add ``result_set``: the agent, `` [fidelity]`` when fidelities differ, `` (folder)`` when
    the same label comes from several folders."""
    df = df.copy()
    label = df["agent"].astype(str)
    if df["fidelity"].nunique() > 1:
        label = label + " [" + df["fidelity"].astype(str) + "]"
    sources_per_label = df.assign(label=label).groupby("label")["source"].nunique()
    clash = label.map(sources_per_label) > 1
    label = label.where(~clash, label + " (" + df["source"].map(lambda s: Path(s).name) + ")")
    df["result_set"] = label
    return df


def latest_records(records: Iterable[EpisodeRecord]) -> list[EpisodeRecord]:
    """One record per episode run and vehicle (``EpisodeRecord.key`` and ``vehicle``: a scene's N records are
    N): the last one written wins (a rerun of a ``sim_error`` replaces it), in first-seen order."""
    latest: dict[tuple, EpisodeRecord] = {}
    for record in records:
        latest[(*record.key, record.vehicle)] = record
    return list(latest.values())


def records_frame(records: Iterable[EpisodeRecord], label: str | None = None) -> pd.DataFrame:
    """A report frame from records in memory (``result_set`` = ``label`` or the agent)."""
    df = pd.DataFrame([r.to_dict() for r in latest_records(records)])
    if df.empty:
        raise UserError("no records")
    df["source"] = ""
    if label is not None:
        df["result_set"] = label
        return df
    return label_result_sets(df)


def scored(df: pd.DataFrame) -> pd.DataFrame:
    """The episodes the views count: without ``sim_error`` and ``decision_cap`` records."""
    return df[~df["end_reason"].isin(EXCLUDED)]


def _sets(df: pd.DataFrame) -> list[str]:
    return list(dict.fromkeys(df["result_set"]))


def _towns(df: pd.DataFrame) -> list[str]:
    return sorted(df["town"].unique())


def success_table(df: pd.DataFrame) -> pd.DataFrame:
    """Success % (0–100, one decimal): task rows (paper labels) × town columns, or (town, set)
    columns when ``df`` holds several result sets."""
    df = scored(df)
    if df.empty:
        return pd.DataFrame()
    sets = _sets(df)
    columns = ["town"] if len(sets) == 1 else ["town", "result_set"]
    table = df.pivot_table(index="task", columns=columns, values="success", aggfunc="mean") * 100.0
    table = table.loc[[t for t in all_tasks() if t in table.index]].round(1)
    if len(sets) > 1:
        order = [(town, s) for town in _towns(df) for s in sets if (town, s) in table.columns]
        table = table[order]
        table.columns.names = ["town", "agent"]
    else:
        table.columns.name = "town"
    table.index = pd.Index([TASK_LABELS[t] for t in table.index], name="task")
    return table


def episode_outcomes(df: pd.DataFrame) -> pd.Series:
    """One of ``OUTCOMES`` per row of ``df``: what ended the episode. ``end_reason`` names it, in the
    world's own precedence (a collision in the step of a violation ends the episode as a collision);
    an end by ``violation`` is ``wrong_lane`` (wrong lane or off-road) unless only a red light was
    counted. Sim errors and capped episodes (not scored) get ``""``."""
    reason = df["end_reason"]
    lane = (df["wrong_lane"] + df["off_road"]) > 0
    label = pd.Series("", index=df.index, dtype=object)
    label[reason == "goal"] = "success"
    label[reason == "collision"] = "collision"
    label[(reason == "violation") & lane] = "wrong_lane"
    label[(reason == "violation") & ~lane] = "red_light"
    for end in ("timeout", "left_network", AGENT_ERROR):  # (AGENT_ERROR is "agent_error")
        label[reason == end] = end
    return label


def failure_counts(df: pd.DataFrame) -> pd.DataFrame:
    """Scored episodes per outcome (``OUTCOMES`` columns, each episode in exactly one: what ended it,
    :func:`episode_outcomes`) plus ``episodes``, index (result_set, town), and ``sim_errors``:
    episodes not scored because the simulator failed (a town whose episodes all ended so has a row
    with 0 episodes)."""
    rows = []
    for result_set in _sets(df):
        for town in _towns(df):
            everything = df[(df["result_set"] == result_set) & (df["town"] == town)]
            if everything.empty:
                continue
            part = scored(everything)
            outcome = episode_outcomes(part)
            rows.append({
                "result_set": result_set, "town": town, "episodes": len(part),
                **{name: int((outcome == name).sum()) for name in OUTCOMES},
                "sim_errors": int((everything["end_reason"] == SIM_ERROR).sum()),
            })
    columns = ["result_set", "town", "episodes", *OUTCOMES, "sim_errors"]
    return pd.DataFrame(rows, columns=columns).set_index(["result_set", "town"])


def driving_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per (result_set, town) and (result_set, ``all``): episodes, success %, mean driving score
    (CARLA Leaderboard, 0–100), mean route completion % (NaN without scored episodes) and the
    sim errors left out."""
    rows = []
    for result_set in _sets(df):
        everything = df[df["result_set"] == result_set]
        towns = [(town, everything[everything["town"] == town]) for town in _towns(everything)]
        for town, group in [*towns, ("all", everything)]:
            part = scored(group)
            rows.append({
                "result_set": result_set, "town": town, "episodes": len(part),
                "sim_errors": int((group["end_reason"] == SIM_ERROR).sum()),
                "success_pct": round(100.0 * float(part["success"].mean()), 1),
                "driving_score": round(float(part["driving_score"].mean()), 2),
                "route_completion_pct": round(100.0 * float(part["route_completion"].mean()), 1),
            })
    columns = ["result_set", "town", "episodes", "sim_errors", "success_pct", "driving_score", "route_completion_pct"]
    return pd.DataFrame(rows, columns=columns).set_index(["result_set", "town"])


def km_between_infractions(df: pd.DataFrame) -> pd.DataFrame:
    """Per result set: km driven and km per event of each kind in ``INFRACTIONS`` plus ``any``
    (CoRL2017's "average distance between infractions"); inf where no such event happened."""
    rows = []
    for result_set in _sets(df):
        part = scored(df[df["result_set"] == result_set])
        km = float(part["distance_m"].sum()) / 1000.0
        counts = {
            "collision": int(part[list(COLLISION_KINDS)].to_numpy().sum()),
            **{k: int(part[k].sum()) for k in INFRACTIONS if k != "collision"},
        }
        counts["any"] = counts["collision"] + sum(counts[k] for k in VIOLATION_KINDS)
        row = {"result_set": result_set, "km_driven": round(km, 3)}
        row.update({kind: (round(km / n, 3) if n else math.inf) for kind, n in counts.items()})
        rows.append(row)
    return pd.DataFrame(rows, columns=["result_set", "km_driven", *INFRACTIONS, "any"]).set_index("result_set")


def route_length_check(df: pd.DataFrame) -> pd.DataFrame:
    """Per (result_set, town, task): episodes that reached the goal and their distance driven ÷
    route length (median, min, max). An agent that drives to the goal covers the route's length, so
    the ratio checks the route lengths that timeouts and route completion rest on."""
    df = scored(df)
    goals = df[df["success"].astype(bool) & (df["route_length_m"] > 0)]
    rows = []
    for (result_set, town, task), group in goals.groupby(["result_set", "town", "task"], sort=False):
        ratio = group["distance_m"] / group["route_length_m"]
        rows.append({"result_set": result_set, "town": town, "task": task, "goal_episodes": len(group),
                     "distance_over_route_median": round(float(ratio.median()), 3),
                     "distance_over_route_min": round(float(ratio.min()), 3),
                     "distance_over_route_max": round(float(ratio.max()), 3)})
    if not rows:
        return pd.DataFrame()
    sets = _sets(df)
    rows.sort(key=lambda r: (sets.index(r["result_set"]), r["town"], all_tasks().index(r["task"])))
    return pd.DataFrame(rows).set_index(["result_set", "town", "task"])


def coverage(df: pd.DataFrame) -> pd.DataFrame:
    """Per result set: episodes counted, sim errors and decision-capped episodes left out, agent errors."""
    rows = []
    for result_set in _sets(df):
        part = df[df["result_set"] == result_set]
        rows.append({
            "result_set": result_set,
            "episodes": int((~part["end_reason"].isin(EXCLUDED)).sum()),
            "sim_errors_left_out": int((part["end_reason"] == SIM_ERROR).sum()),
            "capped_left_out": int((part["end_reason"] == DECISION_CAP).sum()),
            "agent_errors": int((part["end_reason"] == AGENT_ERROR).sum()),
            "fidelity": ",".join(sorted(part["fidelity"].astype(str).unique())),
            "suite": ",".join(sorted(part["suite"].astype(str).unique())),
        })
    return pd.DataFrame(rows).set_index("result_set")


EPISODE_KEY = ("suite", "town", "task", "episode", "vehicle")
"""The columns that name one episode of a suite and its vehicle (the same in every result set; ``vehicle``
is "" in a single-ego episode, a scene's goal-directed vehicle in a multi-agent one)."""


def mcnemar_p(only_first: int, only_second: int) -> float:
    """Exact two-sided McNemar p-value of ``only_first`` against ``only_second`` discordant pairs: the
    binomial probability, at one half, of a split at least this uneven (1.0 without discordant pairs)."""
    n = only_first + only_second
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, k) for k in range(min(only_first, only_second) + 1)) / 2.0 ** n
    return min(1.0, 2.0 * tail)


def paired_comparison(df: pd.DataFrame) -> pd.DataFrame:
    """Per pair of result sets (in their order), on the episodes both scored: ``episodes``,
    ``both_success``, ``only_first``, ``only_second``, ``neither``, ``diff_pp`` (success % of the
    first minus the second's over those episodes, one decimal) and ``p_mcnemar`` (:func:`mcnemar_p`, three
    significant digits).
    Empty with fewer than two sets or none sharing an episode."""
    df = scored(df)
    key = [k for k in EPISODE_KEY if k in df]
    success = {s: part.set_index(key)["success"].astype(bool) for s, part in df.groupby("result_set")}
    sets = _sets(df)
    rows = []
    for i, first in enumerate(sets):
        for second in sets[i + 1:]:
            a, b = success[first].align(success[second], join="inner")
            if a.empty:
                continue
            only_first, only_second = int((a & ~b).sum()), int((~a & b).sum())
            rows.append({"first": first, "second": second, "episodes": len(a), "both_success": int((a & b).sum()),
                         "only_first": only_first, "only_second": only_second, "neither": int((~a & ~b).sum()),
                         "diff_pp": round(100.0 * (only_first - only_second) / len(a), 1),
                         "p_mcnemar": float(f"{mcnemar_p(only_first, only_second):.3g}")})
    if not rows:
        return pd.DataFrame()
    return pd.DataFrame(rows).set_index(["first", "second"])


@dataclass(frozen=True)
class Report:
    """Every view of a set of results (see the module docstring); ``views`` maps name → DataFrame."""

    views: dict[str, pd.DataFrame]

    def __getitem__(self, name: str) -> pd.DataFrame:
        return self.views[name]


def scenario_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per (result_set, scenario type): ability, episodes, success %, mean Leaderboard 2.0 driving score
    (:func:`~hbmp_bench.metrics.records.driving_score_lb2`), mean Leaderboard 1.0 driving score, route
    completion %. Empty when ``df`` holds no scenario type."""
    from hbmp_bench.scenarios import SCENARIO_TYPES

    part = scored(df[df["task"].isin(list(SCENARIO_TYPES))])
    rows = []
    for result_set in _sets(part):
        mine = part[part["result_set"] == result_set]
        for task in [t for t in SCENARIO_TYPES if t in set(mine["task"])]:
            group = mine[mine["task"] == task]
            lb2 = [record_driving_score_lb2(r) for r in group.to_dict(orient="records")]
            rows.append({
                "result_set": result_set, "task": task, "ability": SCENARIO_TYPES[task].ability, "episodes": len(group),
                "success_pct": round(100.0 * float(group["success"].mean()), 1),
                "driving_score_lb2": round(sum(lb2) / len(lb2), 2),
                "driving_score": round(float(group["driving_score"].mean()), 2),
                "route_completion_pct": round(100.0 * float(group["route_completion"].mean()), 1),
            })
    columns = ["result_set", "task", "ability", "episodes", "success_pct", "driving_score_lb2", "driving_score",
               "route_completion_pct"]
    return pd.DataFrame(rows, columns=columns).set_index(["result_set", "task"]) if rows else pd.DataFrame()


def ability_table(df: pd.DataFrame) -> pd.DataFrame:
    """Success % (one decimal) of each ability (rows, in the order of the scenario types) × result set
    (columns): the episodes of its types together. Empty when ``df`` holds no scenario type."""
    from hbmp_bench.scenarios import SCENARIO_TYPES

    part = scored(df[df["task"].isin(list(SCENARIO_TYPES))])
    if part.empty:
        return pd.DataFrame()
    part = part.assign(ability=part["task"].map(lambda t: SCENARIO_TYPES[t].ability))
    table = part.pivot_table(index="ability", columns="result_set", values="success", aggfunc="mean") * 100.0
    order = list(dict.fromkeys(k.ability for k in SCENARIO_TYPES.values()))
    return table.loc[[a for a in order if a in table.index], _sets(part)].round(1)


def build_report(source: pd.DataFrame | Sequence[str | os.PathLike]) -> Report:
    """All views of ``source``: a frame from ``load_results``/``records_frame`` or records paths (the
    ``scenarios`` and ``abilities`` views only where it holds scenario types)."""
    df = source if isinstance(source, pd.DataFrame) else load_results(source)
    views = {
        "success": success_table(df),
        "failures": failure_counts(df),
        "driving": driving_table(df),
        "km_between": km_between_infractions(df),
        "route_length": route_length_check(df),
        "coverage": coverage(df),
        "paired": paired_comparison(df),
    }
    scenarios = scenario_table(df)
    if not scenarios.empty:
        views.update(scenarios=scenarios, abilities=ability_table(df))
    if "vehicle" in df and (df["vehicle"].astype(str) != "").any():
        views.update(multi=multi_table(df), multi_scenes=multi_scene_table(df))
    return Report(views)


SCENE_KEY = ("suite", "town", "task", "episode", "agent", "fidelity")
"""The columns that name one scene run (its N vehicles' records share them)."""


def _frame_records(part: pd.DataFrame) -> list[EpisodeRecord]:
    names = set(EpisodeRecord.__dataclass_fields__)
    return [EpisodeRecord(**{k: v for k, v in row.items() if k in names}) for row in part.to_dict(orient="records")]


def _multi_row(group: pd.DataFrame) -> dict:
    """The multi view's figures of a frame's rows (:func:`~hbmp_bench.metrics.summary.scene_summary` of the
    scored ones) and the sim errors left out."""
    from hbmp_bench.metrics.summary import scene_summary

    return {**scene_summary(_frame_records(scored(group))),
            "sim_errors": int((group["end_reason"] == SIM_ERROR).sum())}


def multi_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per (result_set, town) and (result_set, ``all``): the multi-agent figures of the scenes
    (:func:`~hbmp_bench.metrics.summary.scene_summary`; agents scored, sim errors left out). Only the records
    that name their vehicle (a scene's)."""
    df = df[df["vehicle"].astype(str) != ""]
    rows = []
    for result_set in _sets(df):
        everything = df[df["result_set"] == result_set]
        towns = [(town, everything[everything["town"] == town]) for town in _towns(everything)]
        for town, group in [*towns, ("all", everything)]:
            rows.append({"result_set": result_set, "town": town, **_multi_row(group)})
    return pd.DataFrame(rows).set_index(["result_set", "town"]) if rows else pd.DataFrame()


def multi_scene_table(df: pd.DataFrame) -> pd.DataFrame:
    """The multi view per scene: index (result_set, town, task, episode), ordered so."""
    df = df[df["vehicle"].astype(str) != ""]
    rows = []
    for result_set in _sets(df):
        mine = df[df["result_set"] == result_set]
        for (town, task, episode), group in mine.groupby(["town", "task", "episode"], sort=True):
            row = _multi_row(group)
            del row["scenes"]
            rows.append({"result_set": result_set, "town": town, "task": task, "episode": int(episode), **row})
    return pd.DataFrame(rows).set_index(["result_set", "town", "task", "episode"]) if rows else pd.DataFrame()


def flat_frame(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with its index as columns and (town, agent) column pairs joined as ``town / agent``."""
    flat = df.copy()
    if isinstance(flat.columns, pd.MultiIndex):
        flat.columns = [" / ".join(map(str, c)) for c in flat.columns]
    return flat.reset_index()


def view_rows(df: pd.DataFrame) -> list[dict]:
    """JSON-ready rows of a view (``flat_frame``); inf and NaN become None."""
    rows = flat_frame(df).to_dict(orient="records")
    return [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()} for row in rows]


def readable(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` for printing: inf (no such infraction event) shown as :data:`NO_EVENT`."""
    return df.mask(df.isin([math.inf]), NO_EVENT)


def to_markdown(df: pd.DataFrame) -> str:
    """A GitHub markdown table of ``df`` (index included; floats in their shortest form)."""
    flat = flat_frame(df)
    header = [str(c) for c in flat.columns]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for row in flat.itertuples(index=False):
        lines.append("| " + " | ".join(_cell(v) for v in row) + " |")
    return "\n".join(lines) + "\n"


def _cell(value) -> str:
    if isinstance(value, float):
        if math.isinf(value):
            return NO_EVENT
        if math.isnan(value):
            return ""
        return f"{value:g}"
    return str(value).replace("|", "\\|")


def plot_failures(counts: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Grouped bar chart of ``failure_counts``: per town one bar per outcome (one panel per
    result set), like the paper's tests-in-5-towns figure. Writes a PNG; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    sets = list(dict.fromkeys(counts.index.get_level_values("result_set")))
    fig, axes = plt.subplots(len(sets), 1, figsize=(9, 3.4 * len(sets)), squeeze=False)
    width = 0.8 / len(OUTCOMES)
    for ax, result_set in zip(axes[:, 0], sets):
        part = counts.xs(result_set, level="result_set")
        x = np.arange(len(part))
        for k, outcome in enumerate(OUTCOMES):
            ax.bar(x + (k - (len(OUTCOMES) - 1) / 2) * width, part[outcome], width, label=outcome.replace("_", " "))
        ax.set_xticks(x, list(part.index))
        ax.set_ylabel("episodes")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_title(f"{result_set}: outcomes per town ({int(part['episodes'].sum())} episodes)")
        ax.legend(ncol=len(OUTCOMES), fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.12))
    fig.tight_layout()
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    os.replace(tmp, path)
    return path


def write_report(report: Report, out_dir: str | os.PathLike) -> list[Path]:
    """Write every view as ``<name>.csv`` and ``<name>.md``, ``failures.png``, and ``report.md``
    with all tables; each file written to a temporary name and renamed. Returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    sections = ["# Evaluation report\n"]
    sims = int(report["coverage"]["sim_errors_left_out"].sum()) if not report["coverage"].empty else 0
    if sims:
        sections.append(f"**{sims} episode(s) ended in a simulator error** (not the agent's fault): they are not "
                        "scored in these tables (see `sim_errors`); evaluating again reruns them.\n")
    for name, view in report.views.items():
        written.append(_write_text(out / f"{name}.csv", view.to_csv()))
        markdown = to_markdown(view) if not view.empty else "(no episodes)\n"
        written.append(_write_text(out / f"{name}.md", markdown))
        sections.append(f"## {name}\n\n{VIEW_LEGENDS[name]}\n\n{markdown}")
    if not report["failures"].empty:
        written.append(plot_failures(report["failures"], out / "failures.png"))
        sections.append("![failures per town](failures.png)\n")
    written.append(_write_text(out / "report.md", "\n".join(sections)))
    return written


def _write_text(path: Path, text: str) -> Path:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


def scores(suite: str, records: Sequence[EpisodeRecord], *, towns: Sequence[str], tasks: Sequence[str],
           episodes: Sequence[int], agent: str = "", aggregates: bool = True) -> dict:
    """What a results file derives from its episode records and its selection of ``suite``:
    ``complete``, ``subset``, ``selection``, ``expected_episodes``, ``sim_errors``, ``summary`` and
    ``aggregates`` (the report views; only ``success_pct_by_task`` and, for a multi-agent suite,
    ``multi_by_town`` when ``aggregates`` is False: what the board's tables show). One function for ``submit``,
    ``add`` and ``render``, so a file's claims are checked by recomputing them (``results_check``).
    ``expected_episodes`` counts records: one per episode, a multi-agent suite's one per vehicle of each
    (``Suite.agents``), whose summary has the scene figures too (``summary.scene_summary``)."""
    from hbmp_bench.metrics.summary import summarize
    from hbmp_bench.scenarios import get_suite

    spec = get_suite(suite)
    full = (set(towns) == set(spec.towns) and set(tasks) == set(spec.tasks)
            and list(episodes) == list(range(spec.episodes_per_task)))
    from hbmp_bench.scenarios import selection_size

    expected = selection_size(spec.name, towns, tasks, episodes) * spec.agents
    sim_errors = sum(r.end_reason == SIM_ERROR for r in records)
    frame = records_frame(records, label=agent) if records else None
    views = {}
    if frame is not None:
        if aggregates:
            views = {name: view_rows(view) for name, view in build_report(frame).views.items()}
        per_task = scored(frame).groupby("task")["success"].mean() * 100.0
        views["success_pct_by_task"] = {t: round(float(per_task[t]), 1) for t in all_tasks() if t in per_task.index}
    scored_records = [r for r in records if r.end_reason not in EXCLUDED]
    summary = summarize(scored_records)
    km = float(sum(r.distance_m for r in scored_records)) / 1000.0
    events = sum(r.collisions + r.wrong_lane + r.off_road + r.red_light for r in scored_records)
    summary["success_pct"] = round(100.0 * summary["success_rate"], 2)
    summary["km_per_infraction"] = round(km / events, 3) if events else None
    if spec.agents > 1:
        from hbmp_bench.metrics.summary import scene_summary

        summary.update({k: v for k, v in scene_summary(scored_records).items() if k not in summary})
        views["multi_by_town"] = {town: scene_summary([r for r in scored_records if r.town == town])
                                  for town in towns if any(r.town == town for r in scored_records)}
    return {
        "complete": full and len(records) == expected and sim_errors == 0,
        "subset": not full,
        "selection": {"towns": list(towns), "tasks": list(tasks), "episodes": list(episodes)},
        "expected_episodes": expected,
        "sim_errors": sim_errors,
        "summary": summary,
        "aggregates": views,
    }
