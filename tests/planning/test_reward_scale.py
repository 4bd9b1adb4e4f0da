"""λ's scale (``ExecutorConfig.reward_scale``) against the paper's terminal rewards, with episodes that end at the
first violation: lawful waiting must cost less than a violation, and standing still must not be free (see the
``reward_scale`` docstring: PPO ran red lights at scale 1 and stood still at 0.01)."""

import numpy as np
import pytest

from hbmp_bench.maps.registry import net_path
from hbmp_bench.maps.signals import signal_stats
from hbmp_bench.metrics.episode import TERMINAL_REWARD
from hbmp_bench.planning import Behavior, BehaviorExecutor, Path, ReferencePaths, VehicleState, simulate_behavior
from hbmp_bench.training.ppo import PPOConfig

TOWNS = ("Town01", "Town02", "Town03", "Town04", "Town05")


def _standing_reward_per_second() -> float:
    """r_k of a car standing at a stop line and asked to stand, per second of the behavior."""
    x = np.linspace(-100.0, 300.0, 81)
    road = ReferencePaths(*(Path(np.stack([x, np.full_like(x, y)], axis=1)) for y in (3.5, 0.0, -3.5)))
    r = simulate_behavior(ex := BehaviorExecutor(), Behavior.SPEED_DOWN, VehicleState(0.0, 0.0, 0.0, 0.0), road, 13.89)
    assert r.outcome.v_ref == 0.0 and r.outcome.c_total == pytest.approx(1.0, abs=0.05)  # c_dist of standing
    return ex.reward() / r.outcome.duration


def test_waiting_through_the_longest_red_costs_less_than_a_violation_that_ends_the_episode():
    longest_red_s = max(signal_stats(net_path(town))["red_s"][1] for town in TOWNS)
    assert longest_red_s > 20.0  # the programs were read
    episode_ending = TERMINAL_REWARD["timeout"] + max(TERMINAL_REWARD[k] for k in ("red_light", "wrong_lane", "off_road"))
    assert episode_ending < _standing_reward_per_second() * longest_red_s < 0.0


def test_standing_still_for_good_costs_more_than_a_red_light():
    forever = _standing_reward_per_second() / (1.0 - PPOConfig().gamma)  # one decision a second, discounted
    assert forever < TERMINAL_REWARD["red_light"]
