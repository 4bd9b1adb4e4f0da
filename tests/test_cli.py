import json

from hbmp_bench.cli import main


def test_list_json(capsys):
    assert main(["list", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "hbmp_bench/Town01-Navigation-v0" in out["env_ids"]
    assert out["towns"] == ["Town01", "Town02", "Town03", "Town04", "Town05"]
    assert {"expert", "random", "keep"} <= set(out["agents"])
    assert {"corl2017", "hbmp", "nocrash-regular"} <= set(out["suites"])
    assert out["tasks"] == ["Straight", "OneTurn", "Navigation", "NavigationDynamic"]


def test_run_json(capsys):
    assert main(["run", "--env", "hbmp_bench/Town02-Straight-v0", "--agent", "expert", "--episodes", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("episodes", "success_rate", "collisions", "wrong_lane", "red_light", "timeouts"):
        assert key in out
    assert out["episodes"] == 2 and out["success_rate"] == 1.0


def test_bad_names_exit_2_with_valid_names(capsys):
    assert main(["run", "--env", "hbmp_bench/Town09-Straight-v0"]) == 2
    assert "Town01-Straight-v0" in capsys.readouterr().err
    assert main(["run", "--agent", "expret"]) == 2
    assert "expert" in capsys.readouterr().err
    assert main(["evaluate", "--suite", "corl2016"]) == 2
    assert "corl2017" in capsys.readouterr().err
    assert main(["evaluate", "--towns", "Town9"]) == 2
    assert "Town01" in capsys.readouterr().err


def test_maps_stats_json(capsys):
    assert main(["maps", "stats", "Town02", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["Town02"]
    for key in ("directed_road_length_m", "lanes_per_edge", "tls_junctions", "priority_junctions", "roundabouts",
                "extent_m", "has_sidewalks"):
        assert key in out
