"""The centreline the motion planner tracks (``followed_path`` as the continuous drivers build it)."""

import numpy as np
import pytest

from hbmp_bench.envs.observation import followed_path
from hbmp_bench.scenarios import road_network


@pytest.mark.parametrize("town", ["Town01", "Town02"])
def test_rounded_centrelines_have_no_kinks_at_lane_joints(town):
    """Every lane followed onto each edge it leads to: the rounded centreline bends no sharper than
    the towns' tightest corners (R ~ 4 m), where the lanes meet the junction lanes included."""
    net = road_network(town)
    worst = 0.0
    for lane in sorted(net.lanes):
        for _, edge in net.lane_next.get(lane, ()):
            path = followed_path(net, lane, (edge,), 10.0, 30.0, max_spacing=1.0, round_corners=3)
            worst = max(worst, float(np.abs(path.kappa).max()))
    assert 0.1 < worst < 0.3
