"""pandas report views computed from records with known outcomes."""

import dataclasses
import json
import math

import pandas as pd
import pytest

from hbmp_bench.metrics.records import EpisodeRecord, append_record, latest_per_key, read_records, repair_records
from hbmp_bench.metrics.report import (
    build_report,
    driving_table,
    failure_counts,
    km_between_infractions,
    load_results,
    records_frame,
    success_table,
    to_markdown,
    write_report,
)

BASE = EpisodeRecord(
    suite="corl2017", town="Town01", task="Straight", episode=0, seed=1, agent="a", package_version="0",
    fidelity="event", success=True, route_completion=1.0, collision_vehicle=0, collision_pedestrian=0,
    collision_other=0, wrong_lane=0, off_road=0, red_light=0, timeout=False, duration_s=30.0, distance_m=500.0,
    route_length_m=500.0, decisions=300, driving_score=100.0, end_reason="goal",
)


def rec(**changes) -> EpisodeRecord:
    return dataclasses.replace(BASE, **changes)


def failed(**changes) -> EpisodeRecord:
    return rec(**{"success": False, "route_completion": 0.5, "driving_score": 50.0, "end_reason": "timeout",
                  "timeout": True, **changes})


@pytest.fixture
def two_sets():
    a = [
        rec(episode=0),
        failed(episode=1, collision_vehicle=1, red_light=2, distance_m=250.0, driving_score=21.0),
        rec(task="OneTurn", episode=0, wrong_lane=1, off_road=1, driving_score=80.0),
        rec(town="Town02", episode=0),
        rec(town="Town02", episode=1, success=False, end_reason="agent_error", error="boom", route_completion=0.1,
            driving_score=10.0, distance_m=50.0),
        rec(town="Town02", episode=2, success=False, end_reason="sim_error", error="SUMO died", distance_m=9999.0),
    ]
    b = [rec(agent="b", episode=0), failed(agent="b", episode=1), rec(agent="b", town="Town02", episode=0)]
    return records_frame(a + b)


def test_success_table_paper_layout_with_a_column_per_agent(two_sets):
    table = success_table(two_sets)
    assert list(table.index) == ["Straight", "One turn"]
    assert list(table.columns) == [("Town01", "a"), ("Town01", "b"), ("Town02", "a"), ("Town02", "b")]
    assert table.loc["Straight", ("Town01", "a")] == 50.0
    assert table.loc["One turn", ("Town01", "a")] == 100.0
    assert table.loc["Straight", ("Town02", "a")] == 50.0  # the sim_error episode is left out
    assert table.loc["Straight", ("Town02", "b")] == 100.0
    single = success_table(two_sets[two_sets["result_set"] == "a"])
    assert list(single.columns) == ["Town01", "Town02"]


def test_failure_counts_count_episodes_per_outcome(two_sets):
    counts = failure_counts(two_sets)
    a1 = counts.loc[("a", "Town01")]  # what ended each episode: the infractions on the way are not ends
    assert a1.to_dict() == {"episodes": 3, "success": 2, "wrong_lane": 0, "collision": 0, "red_light": 0,
                            "timeout": 1, "left_network": 0, "agent_error": 0, "sim_errors": 0}
    assert counts.loc[("a", "Town02"), "agent_error"] == 1 and counts.loc[("a", "Town02"), "episodes"] == 2
    assert counts.loc[("a", "Town02"), "sim_errors"] == 1  # not scored, but shown
    assert list(counts.index) == [("a", "Town01"), ("a", "Town02"), ("b", "Town01"), ("b", "Town02")]


def test_driving_score_route_completion_and_km_between_infractions(two_sets):
    driving = driving_table(two_sets)
    assert driving.loc[("a", "Town01"), "driving_score"] == pytest.approx((100 + 21 + 80) / 3, abs=0.01)
    assert driving.loc[("a", "Town01"), "route_completion_pct"] == pytest.approx(100 * (1 + 0.5 + 1) / 3, abs=0.1)
    assert driving.loc[("a", "all"), "episodes"] == 5
    km = km_between_infractions(two_sets)
    driven = (500 + 250 + 500 + 500 + 50) / 1000.0  # sim_error episode not counted
    assert km.loc["a", "km_driven"] == pytest.approx(driven)
    assert km.loc["a", "collision"] == pytest.approx(driven / 1)
    assert km.loc["a", "red_light"] == pytest.approx(driven / 2)
    assert km.loc["a", "any"] == pytest.approx(driven / 5)  # 1 collision + 2 red + 1 wrong lane + 1 off-road
    assert math.isinf(km.loc["b", "red_light"])


def test_report_files_and_markdown(two_sets, tmp_path):
    report = build_report(two_sets)
    assert report["coverage"].loc["a"].to_dict()["sim_errors_left_out"] == 1
    written = write_report(report, tmp_path / "report")
    names = {p.name for p in written}
    assert {"success.csv", "success.md", "failures.png", "report.md", "km_between.md"} <= names
    assert not list((tmp_path / "report").glob("*.tmp*"))
    md = to_markdown(report["success"])
    assert md.splitlines()[0] == "| task | Town01 / a | Town01 / b | Town02 / a | Town02 / b |"
    assert "| Straight | 50 | 50 | 50 | 100 |" in md
    assert pd.read_csv(tmp_path / "report" / "failures.csv").shape[0] == 4


def test_load_results_labels_sets_dedupes_keys_and_tolerates_a_torn_line(tmp_path):
    for folder, agent in (("run1", "expert"), ("run2", "expert")):
        (tmp_path / folder).mkdir()
        path = tmp_path / folder / "corl2017__expert.jsonl"
        append_record(path, failed(agent=agent, end_reason="sim_error", timeout=False))
        append_record(path, rec(agent=agent))  # a rerun of the same key: the latest wins
    with open(tmp_path / "run2" / "corl2017__expert.jsonl", "a") as fh:
        fh.write('{"suite": "corl20')
    df = load_results([tmp_path / "run1", tmp_path / "run2"])
    assert sorted(df["result_set"].unique()) == ["expert (run1)", "expert (run2)"]
    assert len(df) == 2 and df["success"].all()
    assert repair_records(tmp_path / "run2" / "corl2017__expert.jsonl") == len('{"suite": "corl20')
    assert [json.loads(l)["end_reason"] for l in (tmp_path / "run2" / "corl2017__expert.jsonl").open()] == ["sim_error", "goal"]


def test_records_keep_reading_old_lines_without_the_error_field(tmp_path):
    path = tmp_path / "old.jsonl"
    row = BASE.to_dict()
    del row["error"]
    path.write_text(json.dumps(row) + "\n")
    (record,) = read_records(path)
    assert record.error == "" and record.key == ("corl2017", "Town01", "Straight", 0, "a", "event")
    assert latest_per_key([record, dataclasses.replace(record, success=False)])[0].success is False


def test_route_length_view_takes_the_episodes_that_reached_the_goal():
    from hbmp_bench.metrics.report import route_length_check

    df = records_frame([
        rec(episode=0, distance_m=510.0), rec(episode=1, distance_m=680.0), rec(episode=2, distance_m=495.0),
        failed(episode=3, distance_m=900.0),
        rec(task="OneTurn", episode=0, distance_m=250.0, route_length_m=200.0),
    ])
    view = route_length_check(df)
    assert list(view.index) == [("a", "Town01", "Straight"), ("a", "Town01", "OneTurn")]
    straight = view.loc[("a", "Town01", "Straight")]
    assert straight["goal_episodes"] == 3
    assert straight["distance_over_route_median"] == pytest.approx(1.02)
    assert straight["distance_over_route_min"] == pytest.approx(0.99)
    assert straight["distance_over_route_max"] == pytest.approx(1.36)
    assert view.loc[("a", "Town01", "OneTurn"), "distance_over_route_median"] == pytest.approx(1.25)
    assert "route_length" in build_report(df).views


def test_printed_views_say_what_they_count(two_sets, tmp_path):
    from hbmp_bench.metrics.records import DRIVING_SCORE_DEFINITION, PENALTIES
    from hbmp_bench.metrics.report import NO_EVENT, VIEW_LEGENDS, readable

    report = build_report(two_sets)
    # scenarios and abilities only for scenario types, multi and multi_scenes only for multi-agent scenes
    assert set(VIEW_LEGENDS) - set(report.views) == {"scenarios", "abilities", "multi", "multi_scenes"}
    assert "EPISODES" in VIEW_LEGENDS["failures"] and "EVENT" in VIEW_LEGENDS["km_between"]
    assert DRIVING_SCORE_DEFINITION in VIEW_LEGENDS["driving"]
    assert all(f"{factor:g} per" in DRIVING_SCORE_DEFINITION for factor in PENALTIES.values())
    km = report["km_between"]
    assert math.isinf(km.loc["b", "red_light"])  # the frame and its CSV keep inf (JSON: null)
    assert readable(km).loc["b", "red_light"] == NO_EVENT
    assert readable(km).loc["a", "red_light"] == km.loc["a", "red_light"]
    assert NO_EVENT in to_markdown(km) and "inf" not in to_markdown(km)
    write_report(report, tmp_path / "report")
    md = (tmp_path / "report" / "report.md").read_text()
    assert all(VIEW_LEGENDS[name] in md for name in report.views)


def test_summary_lines_explain_every_summary_key():
    from hbmp_bench.metrics.summary import SUMMARY_LEGEND, scene_summary, summarize, summary_lines

    summary = summarize([rec(red_light=2), rec(episode=1)])
    assert set(summary) | set(scene_summary([rec()])) == set(SUMMARY_LEGEND)
    lines = summary_lines({"records": "x.jsonl", **summary})
    assert lines[0].split() == ["records", "x.jsonl"]
    red = next(line for line in lines if line.startswith("red_light"))
    assert red.split()[1] == "2" and "events" in red
    score = next(line for line in lines if line.startswith("mean_driving_score"))
    assert "route completion" in score and "penalty" in score


def test_a_file_that_is_not_records_is_named_in_a_clear_error(tmp_path):
    """The evaluator's provenance sidecar (pretty-printed JSON) passed to the report by a glob: a ValueError
    naming the file, not an AttributeError from deep inside."""
    path = tmp_path / "hbmp__expert.jsonl.provenance.json"
    path.write_text(json.dumps({"code": "abc", "episodes": [1, 2, 3]}, indent=2) + "\n")
    with pytest.raises(ValueError, match="provenance.json: line 6 is not an episode record"):
        read_records(path)
    with pytest.raises(ValueError, match="provenance.json is not a leaderboard results file"):
        load_results([path])


def test_mcnemar_p_is_the_exact_two_sided_binomial_tail():
    from hbmp_bench.metrics.report import mcnemar_p

    assert mcnemar_p(8, 1) == pytest.approx(2 * (1 + 9) / 2 ** 9)  # 0.039
    assert mcnemar_p(1, 8) == mcnemar_p(8, 1)
    assert mcnemar_p(10, 0) == pytest.approx(2 / 2 ** 10)
    assert mcnemar_p(5, 5) == 1.0 and mcnemar_p(1, 0) == 1.0 and mcnemar_p(0, 0) == 1.0


def test_paired_view_counts_the_episodes_both_sets_scored_and_tests_where_they_differ(two_sets):
    from hbmp_bench.metrics.report import paired_comparison

    first = [rec(agent="first", episode=i) for i in range(10)]
    second = [rec(agent="second", episode=i) if i < 2 else failed(agent="second", episode=i) for i in range(10)]
    extra = [rec(agent="second", town="Town02", episode=0),  # only the second has it: not paired
             rec(agent="first", town="Town03", episode=0),
             rec(agent="second", town="Town03", episode=0, success=False, end_reason="sim_error")]  # not scored
    view = paired_comparison(records_frame(first + second + extra))
    row = view.loc[("first", "second")].to_dict()
    assert row == {"episodes": 10, "both_success": 2, "only_first": 8, "only_second": 0, "neither": 0,
                   "diff_pp": 80.0, "p_mcnemar": 0.00781}
    # the fixture's sets share three scored episodes (Town01 Straight 0 and 1, Town02 Straight 0)
    shared = build_report(two_sets)["paired"].loc[("a", "b")].to_dict()
    assert (shared["episodes"], shared["both_success"], shared["neither"], shared["p_mcnemar"]) == (3, 2, 1, 1.0)
    assert paired_comparison(records_frame(first)).empty  # one set: nothing to pair


def test_an_episode_that_left_the_network_has_its_own_outcome():
    counts = failure_counts(records_frame([
        rec(episode=0),
        failed(episode=1, end_reason="left_network", timeout=False, route_completion=1.0),
    ]))
    row = counts.loc[("a", "Town01")]
    assert (row["success"], row["left_network"], row["timeout"]) == (1, 1, 0)


def test_an_episode_has_one_outcome_when_two_events_share_its_last_step():
    """Under the paper's protocol the first violation ends the episode, but a car that leaves the road
    onto a pedestrian collides and goes off-road in one 0.1 s step: the world ends it as a collision
    (its precedence), and so does the count; an end by violation is a wrong lane unless only a red
    light was counted."""
    counts = failure_counts(records_frame([
        failed(episode=0, end_reason="collision", timeout=False, collision_pedestrian=1, off_road=1),
        failed(episode=1, end_reason="violation", timeout=False, off_road=1, red_light=1),
        failed(episode=2, end_reason="violation", timeout=False, red_light=1),
        failed(episode=3, end_reason="violation", timeout=False, wrong_lane=1),
    ]))
    row = counts.loc[("a", "Town01")].to_dict()
    assert row == {"episodes": 4, "success": 0, "wrong_lane": 2, "collision": 1, "red_light": 1, "timeout": 0,
                   "left_network": 0, "agent_error": 0, "sim_errors": 0}


def test_every_paper_protocol_episode_on_the_committed_board_has_exactly_one_outcome():
    """An auditor's check on the shipped `hbmp` board: the outcomes of every (agent, town) row add up
    to its episodes, and each count matches the records' own end reasons."""
    from pathlib import Path

    board = Path(__file__).resolve().parents[2] / "leaderboards" / "hbmp"
    counts = failure_counts(load_results(sorted(board.glob("*.json"))))
    outcomes = ["success", "wrong_lane", "collision", "red_light", "timeout", "left_network", "agent_error"]
    assert len(counts) >= 25
    mismatched = counts[counts[outcomes].sum(axis=1) != counts["episodes"]]
    assert mismatched.empty, mismatched
    episodes = [e for path in board.glob("*.json") for e in json.loads(path.read_text())["episodes"]
                if e["end_reason"] not in ("sim_error", "decision_cap")]
    by_reason = pd.Series([e["end_reason"] for e in episodes]).value_counts()
    assert counts["success"].sum() == by_reason.get("goal", 0)
    assert counts["collision"].sum() == by_reason.get("collision", 0)
    assert counts["wrong_lane"].sum() + counts["red_light"].sum() == by_reason.get("violation", 0)
