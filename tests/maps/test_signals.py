"""Signal timing of the shipped towns: the yellow rule per junction, all-red clearances, greens, and
the program model against SUMO's own lights."""

from __future__ import annotations

import functools
import math
import re
import shutil
import xml.etree.ElementTree as ET

import libsumo
import pytest
import sumo

from hbmp_bench.envs.stopping import lawful_stopping_distance
from hbmp_bench.maps import TOWNS, map_stats, net_path
from hbmp_bench.maps.netconvert import run_netconvert
from hbmp_bench.maps.signals import (
    ALL_RED_TIME_S,
    Program,
    queue_cleared,
    read_programs,
    retime_yellows,
    signal_stats,
    yellow_time,
)
from hbmp_bench.maps.towns import town_spec


def _vehicle_links(net) -> dict[str, tuple[set[int], float]]:
    """Per traffic light of a sumolib net: its vehicle link indices and fastest approach [m/s]."""
    out = {}
    for tls in net.getTrafficLights():
        links, speed = set(), 0.0
        for from_lane, _to_lane, index in tls.getConnections():
            if from_lane.getEdge().getFunction() == "" and from_lane.allows("passenger"):
                links.add(index)
                speed = max(speed, from_lane.getSpeed())
        out[tls.getID()] = (links, speed)
    return out


@functools.lru_cache(maxsize=None)
def _logics(town: str) -> dict[str, list[tuple[float, str]]]:
    """(duration [s], state) of each phase of each light's program, read from the town's net file."""
    return {t.get("id"): [(float(p.get("duration")), p.get("state")) for p in t.iter("phase")]
            for t in ET.parse(net_path(town)).getroot().iter("tlLogic")}


def _phases(town: str, tls_id: str) -> list[tuple[float, str]]:
    return _logics(town)[tls_id]


def test_yellow_time_rule():
    assert yellow_time(13.89) == pytest.approx(3.4)   # 1 + 2.315 s, rounded up
    assert yellow_time(16.67) == pytest.approx(3.8)
    assert yellow_time(25.0) == pytest.approx(5.2)
    assert yellow_time(12.0) == pytest.approx(3.0)    # exact multiples stay
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            yellow_time(bad)


@pytest.mark.parametrize("speed", [8.33, 11.11, 13.89, 16.67, 19.44, 25.0])
def test_no_dilemma_zone(speed):
    """A driver at the limit who sees the yellow begin can stop lawfully or clear the line in it."""
    assert speed * yellow_time(speed) >= lawful_stopping_distance(speed) - 1e-9


def test_queue_cleared():
    assert queue_cleared(20) == 9
    assert queue_cleared(12) == 5
    assert queue_cleared(1) == 0


@pytest.mark.parametrize("town", TOWNS)
def test_yellow_per_junction_from_its_fastest_approach(nets, town):
    net = nets[town]
    for tls_id, (links, speed) in _vehicle_links(net).items():
        assert links and speed > 0, tls_id
        rule = 1.0 + speed / (2 * 3.0)
        yellows = [d for d, state in _phases(town, tls_id) if "y" in state]
        assert yellows, tls_id
        for d in yellows:
            assert rule <= d < rule + 0.1 + 1e-6, (tls_id, speed, d)


def test_town04_yellows_follow_the_ramp_speed(nets):
    yellows = {}
    for tls_id, (_links, speed) in _vehicle_links(nets["Town04"]).items():
        yellows.setdefault(round(speed, 2), set()).update(d for d, s in _phases("Town04", tls_id) if "y" in s)
    assert yellows == {13.89: {3.4}, 16.67: {3.8}}


@pytest.mark.parametrize("town", TOWNS)
def test_all_red_after_every_yellow(nets, town):
    net = nets[town]
    for tls_id, (links, _speed) in _vehicle_links(net).items():
        phases = _phases(town, tls_id)
        for i, (_d, state) in enumerate(phases):
            if "y" not in state:
                continue
            after, after_state = phases[(i + 1) % len(phases)]
            assert all(after_state[k] == "r" for k in links), (tls_id, i, after_state)
            assert after == pytest.approx(ALL_RED_TIME_S), (tls_id, i)
            assert 1.0 <= after <= 2.0  # an all-red clearance of 1-2 s


@pytest.mark.parametrize("town", TOWNS)
def test_green_and_stats(nets, town):
    green = town_spec(town).green_s
    s = map_stats(town)
    assert s["tls_green_s"] == [green, green]
    assert s["tls_all_red_s"] == [ALL_RED_TIME_S, ALL_RED_TIME_S]
    assert s["tls_yellow_s"][0] == pytest.approx(yellow_time(13.89))
    # a two-phase junction: green, yellow and all-red of each phase
    assert s["tls_cycle_s"][0] == pytest.approx(2 * (green + yellow_time(13.89) + ALL_RED_TIME_S))
    assert s["tls_red_s"][0] == pytest.approx(s["tls_cycle_s"][0] - green)
    for tls_id, program in read_programs(net_path(town)).items():
        assert program.cycle == pytest.approx(sum(d for d, _ in _phases(town, tls_id)))
        assert program.offset == 0.0


def test_program_windows_and_wait():
    # link 0: green 0-10, yellow 10-13, red 13-30; link 1: red 0-15, green 15-27, yellow 27-30
    p = Program("J", 0.0, (10.0, 3.0, 2.0, 12.0, 3.0), ("Gr", "yr", "rr", "rG", "ry"), (0, 1), 13.89)
    assert p.cycle == 30.0
    assert p.green(0) == 10.0 and p.green(1) == 12.0
    assert p.red_windows(0) == ((10.0, 30.0),)
    assert p.red_windows(1) == ((27.0, 45.0),)  # wraps past the cycle's end
    assert p.longest_red(0) == 20.0 and p.longest_red(1) == 18.0
    assert p.wait(0, 5.0) == 0.0
    assert p.wait(0, 12.0) == pytest.approx(18.0)
    assert p.wait(0, 42.0) == pytest.approx(18.0)  # next cycle
    assert p.wait(1, 2.0) == pytest.approx(13.0)
    assert p.wait(1, 28.0) == pytest.approx(17.0)
    assert p.wait(1, 20.0) == 0.0


@pytest.mark.parametrize("town", ["Town02", "Town04"])
def test_program_model_matches_sumo(town):
    """Whether a link may go, as :class:`Program` says, is what SUMO shows, every 0.1 s of a cycle.

    SUMO switches a phase in the step that begins at the switch time: the state read at time ``t``
    is the program's during the step that ended then, (t - 0.1 s, t]; the model is asked mid-step."""
    programs = read_programs(net_path(town))
    horizon = max(p.cycle for p in programs.values()) + 5.0
    libsumo.start([str(sumo.SUMO_HOME) + "/bin/sumo", "-n", str(net_path(town)), "--step-length", "0.1",
                   "--no-step-log", "true", "--no-warnings", "true"])
    try:
        libsumo.simulationStep()
        while libsumo.simulation.getTime() < horizon:
            t = libsumo.simulation.getTime() - 0.05
            for tls_id, program in programs.items():
                state = libsumo.trafficlight.getRedYellowGreenState(tls_id)
                for k in program.vehicle_links:
                    assert (state[k] in "Gg") == (program.wait(k, t) == 0.0), (tls_id, k, t, state)
            libsumo.simulationStep()
    finally:
        libsumo.close()


def _cross_net(tmp_path):
    """A plain four-leg signalised cross (one approach at 70 km/h) with netconvert's default program."""
    (tmp_path / "x.nod.xml").write_text(
        '<nodes><node id="C" x="0" y="0" type="traffic_light"/><node id="N" x="0" y="100"/>'
        '<node id="S" x="0" y="-100"/><node id="E" x="100" y="0"/><node id="W" x="-100" y="0"/></nodes>')
    edges = "".join(f'<edge id="{a}{b}" from="{a}" to="{b}" numLanes="1" speed="{v}"/>'
                    for a, b, v in (("N", "C", 13.89), ("C", "N", 13.89), ("S", "C", 13.89), ("C", "S", 13.89),
                                    ("E", "C", 19.44), ("C", "E", 19.44), ("W", "C", 13.89), ("C", "W", 13.89)))
    (tmp_path / "x.edg.xml").write_text(f"<edges>{edges}</edges>")
    run_netconvert(["-n", "x.nod.xml", "-e", "x.edg.xml", "-o", "x.net.xml", "--no-turnarounds", "true"],
                   cwd=tmp_path)
    return tmp_path / "x.net.xml"


def test_retime_yellows_on_a_netconvert_default_program(tmp_path):
    path = _cross_net(tmp_path)
    before = signal_stats(path)
    assert before["cycle_s"] == [90.0, 90.0]  # netconvert's default cycle
    assert before["yellow_s"][0] != yellow_time(19.44)
    original = path.read_text(encoding="utf-8")
    retime_yellows(path)
    after = path.read_text(encoding="utf-8")
    assert signal_stats(path)["yellow_s"] == [yellow_time(19.44)] * 2  # the junction's fastest approach
    # only the yellow durations changed
    assert re.sub(r'duration="[^"]+"\s+', "", original) == re.sub(r'duration="[^"]+"\s+', "", after)
    assert len(original.splitlines()) == len(after.splitlines())
    copy = tmp_path / "again.net.xml"
    shutil.copy(path, copy)
    retime_yellows(copy)
    assert copy.read_text(encoding="utf-8") == after  # idempotent
    ET.parse(path)  # still well-formed


def test_retime_yellows_refuses_a_phase_it_cannot_read(tmp_path):
    path = _cross_net(tmp_path)
    text = path.read_text(encoding="utf-8")
    odd = re.sub(r'(<phase duration="[^"]+")(\s+state="y)', r'\1 name="amber"\2', text, count=1)
    assert odd != text
    path.write_text(odd, encoding="utf-8")
    with pytest.raises(RuntimeError, match="not re-timed"):
        retime_yellows(path)
