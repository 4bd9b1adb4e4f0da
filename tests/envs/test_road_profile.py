"""R_t's ``metric`` profile: the paper's ten entries unchanged, then the stop distance and the speed in
metric units, in every env that builds R_t (SUMO worlds, the control env, the highway-env transfer), and
carried from a training run to the evaluation of its checkpoint."""

import numpy as np
import pytest

import hbmp_bench  # noqa: F401  (registers the ids)
from hbmp_bench.envs import make
from hbmp_bench.envs.observation import (ROAD_FEATURES, ROAD_PROFILES, SPEED_SCALE_MPS, STOP_SCALE_M,
                                         ObservationConfig, road_vector, route_lane_features)
from hbmp_bench.errors import UnknownNameError

ENV_ID = "hbmp_bench/Town01-NavigationDynamic-v0"


def test_unknown_road_profile_lists_the_valid_ones():
    with pytest.raises(UnknownNameError, match="valid: metric, paper"):
        ObservationConfig(road="absolute")
    with pytest.raises(UnknownNameError):
        make(ENV_ID, road_profile="absolute")


def test_road_vector_scales_and_clips():
    paper = np.arange(10, dtype=np.float32) / 10
    np.testing.assert_array_equal(road_vector(ObservationConfig(), paper, 30.0, 10.0), paper)
    metric = ObservationConfig(road="metric")
    r = road_vector(metric, paper, 30.0, 10.0)
    assert r.dtype == np.float32 and r.shape == (len(ROAD_PROFILES["metric"]),) == (12,)
    np.testing.assert_array_equal(r[:10], paper)
    assert r[10] == pytest.approx(30.0 / STOP_SCALE_M) and r[11] == pytest.approx(10.0 / SPEED_SCALE_MPS)
    r = road_vector(metric, paper, float("inf"), 100.0)  # no stop line ahead (junction), far too fast
    assert r[10] == 2.0 and r[11] == 2.0


@pytest.mark.parametrize("fidelity", ["event", "continuous"])
def test_metric_profile_in_sumo_extends_the_papers_entries(fidelity):
    """Same episode, same behaviors: the metric R_t is the paper's R_t with the scene's stop distance
    and speed appended, at every decision."""
    paper_env = make(ENV_ID, fidelity=fidelity, episode_index=0)
    metric_env = make(ENV_ID, fidelity=fidelity, episode_index=0, road_profile="metric")
    try:
        assert paper_env.observation_space["road"].shape == (len(ROAD_FEATURES),)
        assert metric_env.observation_space["road"].shape == (12,)
        (p_obs, _), (m_obs, m_info) = paper_env.reset(seed=0), metric_env.reset(seed=0)
        seen_finite_stop = False
        for _ in range(15):
            assert metric_env.observation_space.contains(m_obs)
            np.testing.assert_array_equal(m_obs["road"][:10], p_obs["road"])
            np.testing.assert_array_equal(m_obs["occupancy"], p_obs["occupancy"])
            scene = m_info["scene"]
            stop = scene["stop_distance_m"]
            seen_finite_stop |= np.isfinite(stop)
            assert m_obs["road"][10] == pytest.approx(min(stop / STOP_SCALE_M, 2.0) if np.isfinite(stop) else 2.0,
                                                      abs=1e-6)
            assert m_obs["road"][11] == pytest.approx(min(scene["speed_mps"] / SPEED_SCALE_MPS, 2.0), abs=1e-6)
            p_obs, _, p_term, _, _ = paper_env.step(0)
            m_obs, _, m_term, _, m_info = metric_env.step(0)
            assert p_term == m_term
            if m_term:
                break
        assert seen_finite_stop
    finally:
        paper_env.close()
        metric_env.close()


def test_control_env_appends_its_two_entries_after_the_metric_profile():
    from hbmp_bench.envs.control_env import ControlEnv

    env = ControlEnv(town="Town01", task="Straight", episode_index=0, road_profile="metric")
    try:
        obs, _ = env.reset(seed=0)
        assert env.observation_space["road"].shape == (14,) and obs["road"].shape == (14,)
        assert env.observation_space.contains(obs)
    finally:
        env.close()


def test_transfer_env_builds_the_metric_profile():
    pytest.importorskip("highway_env")
    from hbmp_bench.transfer.env import HighwayTransferEnv

    env = HighwayTransferEnv(scene="highway", road_profile="metric")
    try:
        obs, info = env.reset(seed=0)
        assert env.observation_space["road"].shape == (12,) and env.observation_space.contains(obs)
        assert obs["road"][11] == pytest.approx(min(info["scene"]["speed_mps"] / SPEED_SCALE_MPS, 2.0), abs=1e-6)
    finally:
        env.close()


@pytest.mark.parametrize("here, good, sides, expected", [
    (1, {0, 1, 2}, (True, True), (True, True, True, 0)),   # every lane continues
    (1, {0}, (True, True), (False, False, True, -1)),      # the right neighbour is the route lane
    (3, {0}, (False, True), (False, False, True, -3)),     # three lanes away: change right
    (0, {3}, (True, False), (True, False, False, 3)),      # three lanes away: change left
    (3, {0}, (False, False), (False, False, False, -3)),   # no neighbour to change to (inside a junction)
    (2, {0, 4}, (True, True), (False, False, True, -2)),   # equally far both ways: the right one
    (1, frozenset(), (True, True), (False, False, False, 0)),  # no route lane known
])
def test_route_lane_features_point_towards_the_nearest_route_lane(here, good, sides, expected):
    assert route_lane_features(here, frozenset(good), *sides) == expected


def test_a_motorway_start_three_lanes_off_the_route_shows_the_way():
    """hbmp Town04 Straight 19: a start in the left lane of four, the goal on the right lane behind the
    next junction. Under the literal a_l/a_c/a_r all three were 0 and the shipped il stood for
    the whole episode; R_t now says change right."""
    env = make("hbmp_bench/Town04-Straight-v0", suite="hbmp", fidelity="event", episode_index=19)
    try:
        obs, info = env.reset(seed=0)
        ego = env.unwrapped.parallel.world.ego
        assert ego.state.lane.endswith("_3") and ego.route.episode.goal_lane.endswith("_0")
        road = dict(zip(ROAD_FEATURES, obs["road"]))
        assert (road["e_l"], road["e_r"], road["a_l"], road["a_c"], road["a_r"]) == (0, 1, 0, 0, 1)
        assert info["scene"]["route_lane_offset"] == -2  # the two right lanes reach the goal lane in time
    finally:
        env.close()
