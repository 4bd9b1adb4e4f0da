"""The adapter's M_t and R_t on hand-placed highway-env scenes."""

import numpy as np
import pytest

from hbmp_bench.envs.observation import ROAD_FEATURES, ObservationConfig
from hbmp_bench.transfer.adapter import HighwayAdapter
from hbmp_bench.transfer.scenes import get_scene

R = {name: k for k, name in enumerate(ROAD_FEATURES)}


def expected_cells(cfg: ObservationConfig, lon: tuple[float, float], lat: tuple[float, float]) -> set[tuple[int, int]]:
    """Cells whose [lo, hi) extent meets the closed box lon x lat (ego frame: x ahead, y left) [m]."""
    rows = [i for i in range(cfg.rows)
            if -cfg.back_m + i * cfg.cell_long_m <= lon[1] and -cfg.back_m + (i + 1) * cfg.cell_long_m > lon[0]]
    cols = [j for j in range(cfg.cols)
            if -cfg.half_width_m + j * cfg.cell_lat_m <= lat[1] and -cfg.half_width_m + (j + 1) * cfg.cell_lat_m > lat[0]]
    return {(i, j) for i in rows for j in cols}


def occupied(grid: np.ndarray) -> set[tuple[int, int]]:
    return {(int(i), int(j)) for i, j in zip(*np.nonzero(grid[0]))}


@pytest.mark.parametrize("kind", ["deformed", "vehicle_centric"])
def test_hand_placed_highway_marks_exactly_the_expected_cells(straight_road, place, kind):
    from highway_env.vehicle.controller import MDPVehicle
    from highway_env.vehicle.kinematics import Vehicle

    road = straight_road
    ego = place(MDPVehicle(road, [0.0, 0.0], speed=20.0), ("0", "1", 1), 100.0)
    # highway-env lane 0 is the lane to the ego's LEFT (its lateral axis points right)
    left_ahead = place(Vehicle(road, [0.0, 0.0], speed=20.0), ("0", "1", 0), 120.3, lateral=-0.2)
    right_behind = place(Vehicle(road, [0.0, 0.0], speed=20.0), ("0", "1", 2), 89.6, lateral=0.3)
    road.vehicles.extend([ego, left_ahead, right_behind])
    cfg = ObservationConfig(kind=kind)
    grid = HighwayAdapter(road, get_scene("highway"), cfg).occupancy(ego)

    assert grid.shape == (1, 64, 36) and grid.dtype == np.float32
    ahead = expected_cells(cfg, (20.3 - 2.5, 20.3 + 2.5), (4.2 - 1.0, 4.2 + 1.0))
    behind = expected_cells(cfg, (-10.4 - 2.5, -10.4 + 2.5), (-4.3 - 1.0, -4.3 + 1.0))
    assert {i for i, _ in ahead} == set(range(33, 39)) and {j for _, j in ahead} == set(range(24, 29))
    assert occupied(grid) == ahead | behind


def test_empty_road_gives_an_empty_grid(straight_road, place):
    from highway_env.vehicle.controller import MDPVehicle

    ego = place(MDPVehicle(straight_road, [0.0, 0.0], speed=20.0), ("0", "1", 1), 100.0)
    straight_road.vehicles.append(ego)
    grid = HighwayAdapter(straight_road, get_scene("highway"), ObservationConfig()).occupancy(ego)
    assert not grid.any()


def test_road_profile_on_a_three_lane_highway(straight_road, place):
    from highway_env.vehicle.controller import MDPVehicle

    road = straight_road
    ego = place(MDPVehicle(road, [0.0, 0.0], speed=15.0), ("0", "1", 1), 100.0)
    road.vehicles.append(ego)
    adapter = HighwayAdapter(road, get_scene("highway"), ObservationConfig())
    r, scene = adapter.road_profile(ego)
    assert r.shape == (10,) and r.dtype == np.float32
    assert r[R["e_l"]] == r[R["e_r"]] == 1.0
    assert r[R["a_l"]] == r[R["a_c"]] == r[R["a_r"]] == 1.0  # end of the network: every lane continues
    assert r[R["l_g"]] == r[R["l_y"]] == r[R["l_r"]] == 0.0
    assert r[R["dv"]] == pytest.approx(0.5)
    assert r[R["d_s"]] == pytest.approx((10000.0 - 102.5) / 10000.0)
    assert scene["stop_distance_m"] == pytest.approx(10000.0 - 102.5)
    assert scene["route_lane_offset"] == 0 and not scene["in_junction"] and scene["light"] == ""
    np.testing.assert_array_equal(adapter.action_mask(ego), [1, 1, 1, 1, 1])

    place(ego, ("0", "1", 0), 100.0)  # leftmost lane
    r, _ = adapter.road_profile(ego)
    assert (r[R["e_l"]], r[R["e_r"]], r[R["a_l"]], r[R["a_r"]]) == (0.0, 1.0, 0.0, 1.0)
    np.testing.assert_array_equal(adapter.action_mask(ego), [1, 1, 0, 1, 1])


def _scene_env(name):
    from hbmp_bench.transfer.env import HighwayTransferEnv

    env = HighwayTransferEnv(scene=name)
    env.reset(seed=0)
    hw = env.highway_env
    hw.road.vehicles = [hw.vehicle]
    return env, hw.vehicle


def test_merge_lane_does_not_continue_and_cannot_be_entered(place):
    env, ego = _scene_env("merge")
    place(ego, ("b", "c", 1), 20.0)
    r, scene = env.adapter.road_profile(ego)
    assert r[R["e_r"]] == 0.0  # the merge lane is forbidden to enter
    assert (r[R["a_l"]], r[R["a_c"]], r[R["a_r"]]) == (1.0, 1.0, 0.0)
    place(ego, ("b", "c", 2), 20.0)  # on the ending merge lane itself
    r, scene = env.adapter.road_profile(ego)
    assert r[R["a_c"]] == 0.0 and r[R["a_l"]] == 1.0
    assert scene["route_lane_offset"] == 1  # one lane to the left
    env.close()


def test_roundabout_inner_lane_before_the_exit_asks_for_the_outer_lane(place):
    env, ego = _scene_env("roundabout")
    place(ego, ("ee", "nx", 0), 3.0)
    r, scene = env.adapter.road_profile(ego)
    assert (r[R["e_l"]], r[R["e_r"]]) == (0.0, 1.0)
    assert (r[R["a_c"]], r[R["a_r"]]) == (0.0, 1.0)  # only the outer lane leads to the north exit
    assert scene["route_lane_offset"] == -1
    place(ego, ("se", "ex", 0), 3.0)  # the exit ahead is not the route's: both ring lanes continue
    r, scene = env.adapter.road_profile(ego)
    assert (r[R["a_c"]], r[R["a_r"]]) == (1.0, 1.0) and scene["route_lane_offset"] == 0
    env.close()


def test_roundabout_deformed_grid_follows_the_ring(place):
    """A car ahead in the ego's ring lane lies on the centre columns of the deformed M_t, but to the
    left (the ring turns left) in the vehicle-centric one."""
    from highway_env.vehicle.kinematics import Vehicle

    env, ego = _scene_env("roundabout")
    place(ego, ("se", "ex", 1), 2.0)
    road = env.highway_env.road
    other = place(Vehicle(road, [0.0, 0.0], speed=10.0), ("se", "ex", 1), 14.0)
    road.vehicles.append(other)
    cols_c = (np.arange(36) + 0.5) * 0.5 - 9.0  # lateral centre of each column [m]
    rows_c = (np.arange(64) + 0.5) * 1.0 - 16.0
    for kind in ("deformed", "vehicle_centric"):
        adapter = HighwayAdapter(road, env.scene, ObservationConfig(kind=kind))
        cells = np.array(sorted(occupied(adapter.occupancy(ego))))
        lat, lon = cols_c[cells[:, 1]], rows_c[cells[:, 0]]
        if kind == "deformed":
            assert np.abs(lat).max() <= 1.5
            assert lon.mean() == pytest.approx(12.0, abs=0.6)
        else:
            assert lat.mean() > 2.0  # ~ s^2 / 2R = 144 / 48 = 3 m to the left
    env.close()


def test_intersection_interior_is_a_junction(place):
    env, ego = _scene_env("intersection")
    place(ego, ("ir0", "il1", 0), 5.0)
    r, scene = env.adapter.road_profile(ego)
    assert scene["in_junction"] and scene["stop_distance_m"] == float("inf")
    assert (r[R["e_l"]], r[R["e_r"]], r[R["a_c"]], r[R["d_s"]]) == (0.0, 0.0, 1.0, 0.0)
    np.testing.assert_array_equal(env.adapter.action_mask(ego), [1, 1, 0, 0, 1])
    env.close()
