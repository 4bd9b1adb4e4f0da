"""``hbmp-bench agreement``: other policies' choices in one driver's states."""

import json

import pytest

from hbmp_bench.cli import main
from hbmp_bench.evaluation.agreement import agreement, merged_env_kwargs, situation

ONE = dict(suite="corl2017", town="Town01", task="Straight", episodes=1, fidelity="event", progress=False)


@pytest.mark.slow
def test_a_driver_agrees_with_itself_and_every_difference_is_counted():
    same, keep = agreement("expert", ["expert", "keep"], **ONE)
    assert same.decisions > 50 and same.differ == 0 and not same.pairs
    assert keep.decisions == same.decisions
    assert sum(keep.pairs.values()) == keep.differ > 0
    assert {other for _, other, _ in keep.pairs} == {"keep"} and all(mine != "keep" for mine, _, _ in keep.pairs)


def test_situation_names_the_light_near_and_standing():
    assert situation({"scene": {"light": "r", "stop_distance_m": 12.0, "speed_mps": 0.0}}) == "light r standing"
    assert situation({"scene": {"light": "G", "stop_distance_m": 30.0, "speed_mps": 8.0}}) == "light G"
    assert situation({"scene": {"light": "r", "stop_distance_m": 80.0, "speed_mps": 8.0}}) == "no light near"
    assert situation({}) == "no light near"


def test_agents_on_different_observations_cannot_be_compared():
    class Deformed:
        env_kwargs = {"observation": "deformed", "privileged": False}

    class Centric:
        env_kwargs = {"observation": "vehicle_centric"}

    class Expert:
        env_kwargs = {"privileged": True}

    assert merged_env_kwargs({"a": Deformed(), "e": Expert()}) == {"observation": "deformed", "privileged": True}
    with pytest.raises(ValueError, match="a and c need different observations"):
        merged_env_kwargs({"a": Deformed(), "c": Centric()})


def test_cli_prints_json_and_refuses_a_task_the_suite_lacks(capsys):
    assert main(["agreement", "--agent", "expert", "--with", "keep", "--suite", "corl2017", "--town", "Town01",
                 "--task", "Straight", "--episodes", "1", "--fidelity", "event", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["agent"] == "keep" and 0 < row["differ"] <= row["decisions"]
    assert 0 < sum(p["count"] for p in row["pairs"]) <= row["differ"]  # the 10 commonest pairs
    assert main(["agreement", "--with", "keep", "--suite", "hbmp-val", "--task", "Straight"]) == 2
    assert "NavigationDynamic" in capsys.readouterr().err
