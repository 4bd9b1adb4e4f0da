"""The planner figure: its file, and costs that are the planner's own."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from hbmp_bench.cli import main
from hbmp_bench.planning import (Behavior, PlannerConfig, PlanningProblem, plan, reference_speed,
                                 target_path)
from hbmp_bench.render.planner_figure import (network_situation, pick_multilane_edge, planner_figure,
                                              synthetic_situation)
from hbmp_bench.scenarios import road_network


def _direct_costs(situation, cfg=PlannerConfig()):
    out = {}
    for b in (Behavior.CHANGE_LEFT, Behavior.KEEP, Behavior.CHANGE_RIGHT):
        effective, path = target_path(b, situation.refs)
        v_ref = reference_speed(effective, situation.ego.v, situation.speed_limit)
        r = plan(PlanningProblem(situation.ego, path, v_ref, situation.speed_limit, situation.obstacles), cfg)
        out[b.name.lower()] = (*r.costs[r.chosen], r.total[r.chosen])
    return out


def _check_png(path, min_bytes=20_000):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > min_bytes
    with Image.open(path) as im:
        assert im.size[0] > 1000 and im.size[1] > 400
        assert np.asarray(im.convert("RGB")).std() > 10


def test_figure_on_a_real_town_reports_the_planners_costs(tmp_path):
    path = tmp_path / "planner.png"
    costs = planner_figure(path, town="Town05")
    _check_png(path)
    assert list(path.parent.iterdir()) == [path]
    direct = _direct_costs(network_situation(road_network("Town05"), name="Town05"))
    assert set(costs) == set(direct) == {"change_left", "keep", "change_right"}
    for name, (c_vel, c_dist, c_obs, c_total) in direct.items():
        got = costs[name]
        assert (got["c_velocity"], got["c_dist"], got["c_obs"], got["c_total"]) == pytest.approx(
            (c_vel, c_dist, c_obs, c_total), rel=1e-12, abs=1e-15)
        assert got["effective"] == name  # the middle of three lanes: both lane changes exist
    # the slower car ahead in the ego lane makes keep the most expensive behavior
    assert costs["keep"]["c_obs"] > max(costs["change_left"]["c_obs"], costs["change_right"]["c_obs"])
    assert costs["keep"]["c_total"] > max(costs["change_left"]["c_total"], costs["change_right"]["c_total"])


def test_default_situation_is_on_a_real_multilane_lane():
    net = road_network("Town05")
    situation = network_situation(net)
    edge = pick_multilane_edge(net)
    assert len(net.edge_lanes[edge]) >= 3
    lane = net.edge_lanes[edge][len(net.edge_lanes[edge]) // 2]
    np.testing.assert_allclose(situation.refs.current.xy[[0, -1]], net.lanes[lane].shape[[0, -1]])
    s, e, _, _ = situation.refs.current.project(np.array([situation.ego.x, situation.ego.y]), situation.ego.yaw)
    assert abs(e) < 1e-6
    with pytest.raises(ValueError, match="no straight edge"):
        pick_multilane_edge(road_network("Town01"))


def test_synthetic_figure(tmp_path):
    path = tmp_path / "synthetic.png"
    costs = planner_figure(path, synthetic=True)
    _check_png(path)
    direct = _direct_costs(synthetic_situation())
    for name, values in direct.items():
        got = costs[name]
        assert (got["c_velocity"], got["c_dist"], got["c_obs"], got["c_total"]) == pytest.approx(values, rel=1e-12)


def test_plot_planner_command(tmp_path, capsys):
    path = tmp_path / "fig.png"
    assert main(["plot-planner", "--synthetic", "--out", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"change_left", "keep", "change_right"}
    assert path.stat().st_size > 0
    assert main(["plot-planner", "--out", str(tmp_path / "fig.jpg")]) == 2
    assert ".png" in capsys.readouterr().err
    assert main(["plot-planner", "--town", "Town9", "--out", str(tmp_path / "x.png")]) == 2
    assert "Town05" in capsys.readouterr().err
    assert main(["plot-planner", "--town", "Town01", "--out", str(tmp_path / "x.png")]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]
