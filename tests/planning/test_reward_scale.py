"""λ's scale (``ExecutorConfig.reward_scale``) against the paper's terminal rewards: with episodes that end
at the first violation, lawful waiting must cost less than the cheapest violation, or PPO learns to run red
lights (it did at scale 1: see the ``reward_scale`` docstring)."""

import numpy as np
import pytest

from hbmp_bench.maps.registry import net_path
from hbmp_bench.maps.signals import signal_stats
from hbmp_bench.metrics.episode import TERMINAL_REWARD
from hbmp_bench.planning import Behavior, BehaviorExecutor, Path, ReferencePaths, VehicleState, simulate_behavior

TOWNS = ("Town01", "Town02", "Town03", "Town04", "Town05")


def test_waiting_through_the_longest_red_costs_less_than_the_cheapest_violation():
    longest_red_s = max(signal_stats(net_path(town))["red_s"][1] for town in TOWNS)
    assert longest_red_s > 20.0  # the programs were read
    # a car standing at the stop line, asked to stand: one decision and its r_k
    x = np.linspace(-100.0, 300.0, 81)
    road = ReferencePaths(*(Path(np.stack([x, np.full_like(x, y)], axis=1)) for y in (3.5, 0.0, -3.5)))
    r = simulate_behavior(ex := BehaviorExecutor(), Behavior.SPEED_DOWN, VehicleState(0.0, 0.0, 0.0, 0.0), road, 13.89)
    assert r.outcome.v_ref == 0.0 and r.outcome.c_total == pytest.approx(1.0, abs=0.05)  # c_dist of standing
    waiting = ex.reward() * longest_red_s / r.outcome.duration
    cheapest_violation = max(v for v in TERMINAL_REWARD.values() if v < 0)
    assert cheapest_violation < waiting < 0.0
