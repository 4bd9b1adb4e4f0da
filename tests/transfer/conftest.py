"""Helpers: hand-placed highway-env scenes."""

import numpy as np
import pytest


def place_vehicle(vehicle, lane_index, s: float, lateral: float = 0.0, speed: float | None = None):
    """Put a highway-env vehicle at lane coordinates (s, lateral) [m] of ``lane_index``, aligned with
    the lane (highway-env's lateral is positive to the right of travel)."""
    lane = vehicle.road.network.get_lane(lane_index)
    vehicle.position = np.array(lane.position(s, lateral), dtype=float)
    vehicle.heading = float(lane.heading_at(s))
    if speed is not None:
        vehicle.speed = speed
    vehicle.on_state_update()
    if hasattr(vehicle, "target_lane_index"):
        vehicle.target_lane_index = vehicle.lane_index
    return vehicle


@pytest.fixture
def straight_road():
    """A 3-lane straight highway-env road, no vehicles."""
    from highway_env.road.road import Road, RoadNetwork

    return Road(network=RoadNetwork.straight_road_network(3, speed_limit=30), np_random=np.random.RandomState(0))


@pytest.fixture
def place():
    """``place(vehicle, lane_index, s, lateral=0.0, speed=None)``: see :func:`place_vehicle`."""
    return place_vehicle
