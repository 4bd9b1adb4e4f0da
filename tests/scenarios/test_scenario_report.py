"""The Leaderboard 2.0 driving score, the scenario and ability views of a report, and the scenario board."""

import dataclasses

import pytest

from hbmp_bench.metrics.records import PENALTIES, PENALTIES_LB2, EpisodeRecord, driving_score, driving_score_lb2
from hbmp_bench.metrics.report import build_report, records_frame
from hbmp_bench.scenarios import SCENARIO_TYPES

BASE = EpisodeRecord(
    suite="scenarios", town="Town03", task="HardBrake", episode=0, seed=1, agent="a", package_version="0",
    fidelity="event", success=True, route_completion=1.0, collision_vehicle=0, collision_pedestrian=0,
    collision_other=0, wrong_lane=0, off_road=0, red_light=0, timeout=False, duration_s=30.0, distance_m=200.0,
    route_length_m=200.0, decisions=300, driving_score=100.0, end_reason="goal",
)


def rec(**changes) -> EpisodeRecord:
    return dataclasses.replace(BASE, **changes)


def test_the_leaderboard_2_penalties_are_carlas():
    assert PENALTIES_LB2 == {"collision_pedestrian": 0.5, "collision_vehicle": 0.6, "collision_other": 0.65,
                             "red_light": 0.7, "timeout": 0.7}
    counts = {"collision_vehicle": 1, "collision_other": 1, "red_light": 2}
    assert driving_score_lb2(0.8, {**counts, "timeout": 1}) == pytest.approx(80 * 0.6 * 0.65 * 0.7**2 * 0.7)
    # Leaderboard 1.0 has no static-collision or timeout penalty
    assert driving_score(0.8, counts) == pytest.approx(80 * 0.6 * 0.7**2) and "collision_other" not in PENALTIES


def test_the_scenario_and_ability_views_group_the_types():
    records = [
        rec(episode=0), rec(episode=1, success=False, collision_vehicle=1, end_reason="collision", route_completion=0.5),
        rec(task="CutIn", episode=0), rec(task="Merge", episode=0, success=False, timeout=True, end_reason="timeout",
                                          route_completion=0.9),
        rec(task="Merge", episode=0, agent="b"),
    ]
    report = build_report(records_frame(records))
    table = report["scenarios"]
    assert table.loc[("a", "HardBrake"), "success_pct"] == 50.0
    assert table.loc[("a", "HardBrake"), "driving_score_lb2"] == pytest.approx((100 + 50 * 0.6) / 2)
    assert table.loc[("a", "Merge"), "driving_score_lb2"] == pytest.approx(90 * 0.7)
    assert table.loc[("a", "HardBrake"), "ability"] == SCENARIO_TYPES["HardBrake"].ability
    abilities = report["abilities"]
    assert SCENARIO_TYPES["CutIn"].ability == SCENARIO_TYPES["Merge"].ability == "Merging"
    assert abilities.loc["Merging", "a"] == 50.0 and abilities.loc["Merging", "b"] == 100.0
    assert list(abilities.columns) == ["a", "b"]
    # a report without scenario types has neither view
    plain = build_report(records_frame([rec(suite="hbmp", task="Straight")]))
    assert "scenarios" not in plain.views and "abilities" not in plain.views


def test_a_scenario_board_shows_its_types_and_both_driving_scores():
    from hbmp_bench.evaluation.leaderboard import header

    columns = header(("HardBrake", "CutIn"))
    assert "HardBrake %" in columns and "CutIn %" in columns and "Straight %" not in columns
    assert "driving score (LB 1.0)" in columns and "driving score (LB 2.0)" in columns
    assert "driving score (LB 2.0)" not in header(("Straight", "OneTurn"))
