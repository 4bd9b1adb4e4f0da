"""The compiled deformed M_t marks the same cells as its numpy form (``occupancy_grid_reference``), on
the followed lanes of Town03 (curves, junctions, a path's straight extensions) with crowds of cars,
trucks longer than the default sampling and pedestrians, near and past the grid's edges."""

import numpy as np
import pytest

from hbmp_bench.envs.observation import (ObservationBuilder, ObservationConfig, followed_path, occupancy_grid,
                                         occupancy_grid_reference)
from hbmp_bench.scenarios import road_network


@pytest.mark.parametrize("cfg", [ObservationConfig(), ObservationConfig(rows=32, cols=20, cell_long_m=2.0, cell_lat_m=1.0)])
def test_compiled_grid_equals_the_numpy_grid(cfg):
    net = road_network("Town03")
    rng = np.random.default_rng(3)
    lanes = sorted(net.lanes)
    marked = 0
    for _ in range(60):
        lane = lanes[rng.integers(len(lanes))]
        edges = tuple(e for _, e in net.lane_next.get(lane, ()))[:1]
        path = followed_path(net, lane, edges, cfg.back_m, cfg.ahead_m)
        ego_xy = path.xy[rng.integers(len(path.xy))] + rng.normal(0.0, 1.5, 2)
        k = int(rng.integers(0, 60))
        xy = ego_xy + rng.uniform(-80.0, 80.0, (k, 2))
        yaw = rng.uniform(-np.pi, np.pi, k)
        length = np.where(rng.random(k) < 0.2, 0.6, rng.uniform(3.0, 14.0, k))
        width = np.where(length < 1.0, 0.6, rng.uniform(1.6, 2.6, k))
        args = (cfg, ego_xy, float(rng.uniform(-np.pi, np.pi)), path, xy, yaw, length, width)
        grid = occupancy_grid(*args)
        np.testing.assert_array_equal(grid, occupancy_grid_reference(*args))
        assert grid.dtype == np.float32 and grid.shape == (1, cfg.rows, cfg.cols)
        marked += grid.any()
    assert marked >= 30


def test_pruned_search_marks_the_same_cells_beside_the_grid_edges():
    """The compiled grid skips segments that cannot be a sample's nearest and footprints that cannot mark a
    cell (``occupancy_kernel._candidate_segments`` / ``_marks_nothing``): footprints straddling the grid's
    side and end edges, on curved lanes, still mark what the numpy form marks."""
    cfg = ObservationConfig()
    net = road_network("Town03")
    rng = np.random.default_rng(11)
    lanes = sorted(net.lanes)
    for _ in range(80):
        lane = lanes[rng.integers(len(lanes))]
        edges = tuple(e for _, e in net.lane_next.get(lane, ()))[:1]
        path = followed_path(net, lane, edges, cfg.back_m, cfg.ahead_m)
        at = rng.integers(len(path.xy))
        ego_xy = path.xy[at]
        k = 40
        base = path.xy[rng.integers(len(path.xy), size=k)]
        normal = rng.normal(0.0, 1.0, (k, 2))
        normal /= np.hypot(*normal.T)[:, None]
        xy = base + normal * rng.uniform(cfg.half_width_m - 3.0, cfg.half_width_m + 3.0, (k, 1))
        yaw = rng.uniform(-np.pi, np.pi, k)
        length = rng.uniform(0.6, 12.0, k)
        width = rng.uniform(0.6, 2.6, k)
        args = (cfg, ego_xy, 0.0, path, xy, yaw, length, width)
        np.testing.assert_array_equal(occupancy_grid(*args), occupancy_grid_reference(*args))


def test_occupancy_of_many_vehicles_in_one_call_equals_one_call_each():
    """``ObservationBuilder.occupancy_all`` (one compiled call) gives each vehicle's ``occupancy``, also for a
    vehicle with no actor, or none near, among others."""
    net = road_network("Town03")
    builder = ObservationBuilder(net, ObservationConfig())
    rng = np.random.default_rng(5)
    lanes = sorted(net.lanes)
    for _ in range(10):
        requests = []
        for v in range(int(rng.integers(2, 9))):
            lane = lanes[rng.integers(len(lanes))]
            edges = tuple(e for _, e in net.lane_next.get(lane, ()))[:1]
            ego_xy = net.position(lane, float(rng.uniform(0.0, net.lane(lane).length)))
            k = 0 if v == 1 else int(rng.integers(0, 50))
            spread = 500.0 if v == 2 else 60.0  # vehicle 2: (almost) nobody near
            xy = ego_xy + rng.uniform(-spread, spread, (k, 2))
            yaw = rng.uniform(-np.pi, np.pi, k)
            length = np.where(rng.random(k) < 0.2, 0.6, rng.uniform(3.0, 14.0, k))
            width = np.where(length < 1.0, 0.6, rng.uniform(1.6, 2.6, k))
            requests.append((ego_xy, 0.0, lane, edges, xy, yaw, length, width, ()))
        grids = builder.occupancy_all(requests)
        assert len(grids) == len(requests)
        for grid, r in zip(grids, requests):
            np.testing.assert_array_equal(grid, builder.occupancy(*r))
            assert grid.dtype == np.float32 and grid.shape == (1, 64, 36)
