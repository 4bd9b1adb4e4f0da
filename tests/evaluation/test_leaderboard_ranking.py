"""The leaderboard README ranks complete entries only; partial runs follow by what they cover, not by score."""

import dataclasses

from hbmp_bench.evaluation.leaderboard import (
    NO_INFRACTION,
    entry_path,
    render_readme,
    results_document,
    write_json,
)
from hbmp_bench.metrics.records import DRIVING_SCORE_DEFINITION, EpisodeRecord
from hbmp_bench.scenarios import get_suite

SUITE = get_suite("corl2017")

BASE = EpisodeRecord(
    suite=SUITE.name, town="Town01", task="Straight", episode=0, seed=1, agent="a", package_version="0",
    fidelity="event", success=True, route_completion=1.0, collision_vehicle=0, collision_pedestrian=0,
    collision_other=0, wrong_lane=0, off_road=0, red_light=0, timeout=False, duration_s=30.0, distance_m=500.0,
    route_length_m=500.0, decisions=300, driving_score=100.0, end_reason="goal",
)


def _records(agent, towns, tasks, episodes, success_every=1, sim_error_at=None):
    """One record per (town, task, episode); every ``success_every``-th episode fails with a red light."""
    out = []
    for town in towns:
        for task in tasks:
            for k in episodes:
                failed = success_every > 1 and k % success_every == 0
                record = dataclasses.replace(
                    BASE, agent=agent, town=town, task=task, episode=k, success=not failed,
                    red_light=int(failed), driving_score=70.0 if failed else 100.0,
                    end_reason="timeout" if failed else "goal", timeout=failed)
                if (town, task, k) == sim_error_at:
                    record = dataclasses.replace(record, success=False, end_reason="sim_error", error="SUMO died")
                out.append(record)
    return out


def _enter(board, agent, towns, tasks, episodes, **kwargs):
    doc = results_document(SUITE.name, agent, _records(agent, towns, tasks, episodes, **kwargs),
                           towns=towns, tasks=tasks, episodes=episodes, fidelity="event")
    write_json(entry_path(board, SUITE.name, agent, doc["subset"], "event"), doc)
    return doc


def test_partial_runs_are_never_ranked_above_complete_ones_and_are_listed_by_size(tmp_path):
    everything = dict(towns=list(SUITE.towns), tasks=list(SUITE.tasks), episodes=list(range(SUITE.episodes_per_task)))
    assert _enter(tmp_path, "steady", **everything, success_every=5)["complete"]  # 80 %
    crashy = _enter(tmp_path, "crashy", **everything, sim_error_at=("Town02", "Straight", 3))  # ~100 %
    assert not crashy["complete"] and not crashy["subset"]
    big = _enter(tmp_path, "big", towns=["Town01"], tasks=list(SUITE.tasks), episodes=list(range(25)),
                 success_every=10)  # 100 episodes, 88 %
    tiny = _enter(tmp_path, "tiny", towns=["Town01"], tasks=["Straight"], episodes=[0, 1])  # 2 episodes, 100 %
    assert big["subset"] and tiny["subset"] and tiny["summary"]["success_pct"] > big["summary"]["success_pct"]

    readme = render_readme(tmp_path, SUITE.name).read_text()
    ranked, partial = readme.split("## Partial runs (not ranked)")
    ranked_rows = [line for line in ranked.splitlines() if line.startswith("| 1 ")]
    assert len(ranked_rows) == 1 and ranked_rows[0].startswith("| 1 | `steady` | no | 80.0")
    assert "| 2 " not in ranked  # nothing else is ranked
    order = [line.split("|")[2].strip() for line in partial.splitlines() if line.startswith("| – ")]
    assert order == ["`crashy`", "`big`", "`tiny`"]  # full suite first, then subsets by size, not by score
    rows = {line.split("|")[2].strip(): line for line in readme.splitlines() if line.startswith("| ")}
    assert "| 500 of 500 |" in rows["`steady`"] and "| 499 of 500 |" in rows["`crashy`"]
    assert "| 100 of 500 |" in rows["`big`"] and "| 2 of 500 |" in rows["`tiny`"]
    assert f"| {NO_INFRACTION} |" in rows["`tiny`"] and "| inf" not in readme and "∞" not in readme
    assert DRIVING_SCORE_DEFINITION in readme
