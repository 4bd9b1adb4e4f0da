"""The stopping-distance figure: measured in SUMO, drawn, and reported by its command."""

import json

import pytest
from PIL import Image

from hbmp_bench.cli import main


@pytest.mark.slow
def test_plot_stopping_command(tmp_path, capsys):
    path = tmp_path / "stop.png"
    assert main(["plot-stopping", "--out", str(path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    with Image.open(path) as image:
        assert image.format == "PNG" and image.size[0] > 500
    assert [r["fidelity"] for r in rows] == ["continuous", "event", "continuous"]
    current, previous = rows[0], rows[2]
    for r in rows[:2]:  # the current speed_down step, both fidelities
        assert r["distance_with_latency_m"] <= r["bound_m"]
    assert current["distance_with_latency_m"] < previous["distance_with_latency_m"]  # the step it replaced
    assert current["speed_down_decisions"] < previous["speed_down_decisions"]
    assert main(["plot-stopping", "--out", str(tmp_path / "stop.jpg")]) == 2
    assert ".png" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stop.png"]
