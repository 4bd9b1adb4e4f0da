"""A chain of speed_down decisions stops the ego within the lawful distance (real SUMO episodes).

Lawful: ``v * 1 s + v^2 / (2 * 3 m/s^2)`` from the speed ``v`` at which braking begins, 46 m from
50 km/h. The distance is measured from the ego's own positions at every 0.1 s step, both from
the first speed_down decision and from the start of the decision before it (the latency of a
need that arises just after the ego chose to cruise).
"""

import numpy as np
import pytest

from hbmp_bench.envs.stopping import STANDSTILL_MPS, lawful_stopping_distance, measure_stop
from hbmp_bench.envs.config import WorldConfig

KMH_50 = 50.0 / 3.6


def test_lawful_stopping_distance():
    assert lawful_stopping_distance(KMH_50) == pytest.approx(13.889 + 32.150, abs=0.01)  # 46 m
    assert lawful_stopping_distance(0.0) == 0.0
    assert lawful_stopping_distance(10.0, reaction_s=0.0, decel=5.0) == pytest.approx(10.0)
    for bad in ({"v": -1.0}, {"v": float("nan")}, {"v": 1.0, "decel": 0.0}, {"v": 1.0, "reaction_s": -0.1}):
        with pytest.raises(ValueError):
            lawful_stopping_distance(**bad)


def _path_length(xy: np.ndarray) -> float:
    return float(np.hypot(*np.diff(xy, axis=0).T).sum())


@pytest.mark.slow
@pytest.mark.parametrize("town, fidelity, decision_period_s, limit_mps", [
    ("Town01", "continuous", 0.1, KMH_50),
    ("Town01", "event", 0.1, KMH_50),
    ("Town01", "event", 1.0, KMH_50),
    ("Town04", "continuous", 0.1, 25.0),  # the highway's 90 km/h
    ("Town04", "event", 0.1, 25.0),
])
def test_speed_down_chain_stops_within_the_lawful_distance(town, fidelity, decision_period_s, limit_mps):
    trace = measure_stop(WorldConfig(fidelity=fidelity, decision_period_s=decision_period_s), town=town)
    assert trace.speed_limit == pytest.approx(limit_mps, abs=0.01)
    v = trace.v_start
    assert limit_mps - 0.2 <= v <= limit_mps + 0.01  # braking begins at the speed limit
    braking = trace.speed[trace.brake_start:]
    stopped = np.flatnonzero(braking < STANDSTILL_MPS)
    assert len(stopped) and np.all(braking[stopped[0]:] < STANDSTILL_MPS)  # stops and stays stopped
    assert np.all(np.diff(braking) <= 1e-6)  # it only slows down
    expected_latency = 1.0 if fidelity == "continuous" else decision_period_s  # keep at the limit: min_duration
    assert trace.latency_s == pytest.approx(expected_latency)

    bound = lawful_stopping_distance(v)
    from_first_speed_down = _path_length(trace.xy[trace.brake_start:])
    with_latency = _path_length(trace.xy[trace.cruise_start:])
    assert from_first_speed_down == pytest.approx(trace.distance_m)
    assert with_latency == pytest.approx(trace.distance_with_latency_m)
    assert with_latency >= from_first_speed_down + 0.9 * v * expected_latency
    assert from_first_speed_down <= bound
    assert with_latency <= bound
    if limit_mps == KMH_50:
        assert bound == pytest.approx(46.0, abs=0.5)
