"""Closed-loop behavior execution (executor + tracker + bicycle model, no SUMO)."""

import numpy as np
import pytest

from hbmp_bench.planning import (Behavior, BehaviorExecutor, ExecutorConfig, Obstacles, Path,
                                 PlannerConfig, ReferencePaths, VehicleParams, VehicleState, reward_from_cost,
                                 simulate_behavior, step)
from hbmp_bench.planning.planner import _sat_overlap

LANE = 3.5
XS = np.linspace(-100.0, 900.0, 201)


def lane(y):
    return Path(np.stack([XS, np.full_like(XS, y)], axis=1))


STRAIGHT = ReferencePaths(lane(LANE), lane(0.0), lane(-LANE))


def keep_deciding(ex, behavior, ego, refs, speed_limit, seconds=8.0):
    """``behavior`` once, then keep decisions until ``seconds`` [s] have passed; the last rollout."""
    r = simulate_behavior(ex, behavior, ego, refs, speed_limit)
    elapsed = r.outcome.duration
    while elapsed < seconds - 1e-9:
        r = simulate_behavior(ex, Behavior.KEEP, r.final, refs, speed_limit)
        elapsed += r.outcome.duration
    return r


def curved_refs(R=60.0):
    """Straight 50 m, left arc of radius R (+ offset lanes), straight again."""
    def shape(off):
        r = R - off  # the left lane (off > 0) is on the inside
        a = np.linspace(-np.pi / 2, 0.0, 60)
        straight1 = np.stack([np.linspace(-50, 0, 26), np.full(26, off)], axis=1)
        arc = np.stack([r * np.cos(a), R + r * np.sin(a)], axis=1)
        straight2 = np.stack([np.full(40, r), np.linspace(R, R + 200, 40)], axis=1)
        return Path.concat([straight1, arc, straight2])
    return ReferencePaths(shape(LANE), shape(0.0), shape(-LANE))


def errors(path, s: VehicleState):
    """Lateral and heading error of the footprint centre's direction of travel (body yaw plus
    the bicycle's slip angle), the heading the executor's finish check uses."""
    vp = VehicleParams()
    course = s.yaw + np.arctan(vp.rear_to_cg / vp.wheelbase * np.tan(s.steer))
    _, e, th, _ = path.project(s.xy, course)
    return e, th


@pytest.mark.parametrize("v", [5.0, 10.0])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_converges_to_the_lane_on_a_straight(v, sign):
    """2 m off the lane heading 0.3 rad away: within 8 s of keep decisions (1 s each) on the lane."""
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 2.0 * sign, 0.3 * sign, v)
    first = simulate_behavior(ex, Behavior.KEEP, ego, STRAIGHT, 20.0)
    assert first.outcome.reason == "converged" and first.outcome.duration == pytest.approx(1.0)
    r = keep_deciding(ex, Behavior.KEEP, ego, STRAIGHT, 20.0)
    e, th = errors(STRAIGHT.current, r.final)
    assert abs(e) < 0.3 and abs(th) < 0.05
    assert r.outcome.collision_free


@pytest.mark.parametrize("v", [6.0, 10.0])
def test_converges_to_the_lane_on_a_curve(v):
    refs = curved_refs()
    # start on the arc, 2 m outside the lane and heading 0.3 rad away from it
    a = -np.pi / 2 + 0.3
    R = 62.0
    ego = VehicleState(R * np.cos(a), 60.0 + R * np.sin(a), a + np.pi / 2 - 0.3, v)
    e0, th0 = errors(refs.current, ego)
    assert e0 == pytest.approx(-2.0, abs=0.01) and th0 == pytest.approx(-0.3, abs=0.01)
    ex = BehaviorExecutor()
    r = keep_deciding(ex, Behavior.KEEP, ego, refs, 20.0)
    e, th = errors(refs.current, r.final)
    assert abs(e) < 0.3 and abs(th) < 0.05, (e, th)
    # and it keeps tracking the curve afterwards
    for _ in range(3):
        r = simulate_behavior(ex, Behavior.KEEP, r.final, refs, 20.0)
        e, th = errors(refs.current, r.final)
        assert abs(e) < 0.3 and abs(th) < 0.05


@pytest.mark.parametrize("v", [5.0, 10.0, 15.0, 25.0])
def test_lane_change_left_completes(v):
    ex = BehaviorExecutor()
    r = simulate_behavior(ex, Behavior.CHANGE_LEFT, VehicleState(0.0, 0.0, 0.0, v), STRAIGHT, 30.0)
    assert r.outcome.behavior == Behavior.CHANGE_LEFT
    assert r.outcome.reason == "converged" and r.outcome.duration < ExecutorConfig().max_duration
    assert abs(r.final.y - LANE) < 0.3
    assert r.states[:, 1].max() < LANE + 0.5  # little overshoot
    assert r.final.v == pytest.approx(v, abs=0.5)


def test_lane_change_on_a_curve_and_to_the_right():
    refs = curved_refs()
    ex = BehaviorExecutor()
    r = simulate_behavior(ex, Behavior.CHANGE_RIGHT, VehicleState(-20.0, 0.0, 0.0, 10.0), refs, 20.0)
    assert r.outcome.reason == "converged"
    e, th = errors(refs.right, r.final)
    assert abs(e) < 0.3 and abs(th) < 0.05


def test_missing_lane_becomes_keep():
    refs = ReferencePaths(None, STRAIGHT.current, None)
    ex = BehaviorExecutor()
    for b in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT):
        r = simulate_behavior(ex, b, VehicleState(0.0, 0.0, 0.0, 10.0), refs, 20.0)
        assert r.outcome.requested == b and r.outcome.behavior == Behavior.KEEP
        assert abs(r.final.y) < 1e-6


def test_speed_up_tracks_the_new_reference():
    ex = BehaviorExecutor()
    r = simulate_behavior(ex, Behavior.SPEED_UP, VehicleState(0.0, 0.0, 0.0, 5.0), STRAIGHT, 20.0)
    assert r.outcome.v_ref == pytest.approx(7.0)  # 5 + max(20 %, 2 m/s)
    assert r.outcome.reason == "converged"
    assert abs(r.final.v - 7.0) < 0.5
    # keeps holding it afterwards (a keep at the new speed)
    r2 = simulate_behavior(ex, Behavior.KEEP, r.final, STRAIGHT, 20.0)
    assert r2.final.v == pytest.approx(r.final.v, abs=0.3)


def test_speed_down_and_speed_limit():
    ex = BehaviorExecutor()
    r = simulate_behavior(ex, Behavior.SPEED_DOWN, VehicleState(0.0, 0.0, 0.0, 12.0), STRAIGHT, 20.0)
    assert r.outcome.v_ref == pytest.approx(7.8)  # 12 - max(35 %, 3.5 m/s)
    assert r.outcome.reason == "converged" and abs(r.final.v - 7.8) < 0.5
    r = simulate_behavior(ex, Behavior.SPEED_UP, VehicleState(0.0, 0.0, 0.0, 12.0), STRAIGHT, 13.0)
    assert r.outcome.v_ref == pytest.approx(13.0)


def test_keep_lasts_the_minimum_duration():
    ex = BehaviorExecutor()
    r = simulate_behavior(ex, Behavior.KEEP, VehicleState(0.0, 0.0, 0.0, 10.0), STRAIGHT, 20.0)
    assert r.outcome.reason == "converged"
    assert r.outcome.duration == pytest.approx(1.0)
    assert r.outcome.n_steps == 10 and len(r.states) == 11


def test_each_behavior_ends_on_its_own_condition_or_its_longest_run():
    """Off the lane, keep ends at min_duration (lane errors are not waited on); a speed_down from
    25 m/s (an 8.75 m/s step at 3 m/s²) is cut at ``lane_keeping_max_duration``; a lane change
    waits for the lane, up to ``max_duration``."""
    ex = BehaviorExecutor()
    off_lane = simulate_behavior(ex, Behavior.KEEP, VehicleState(0.0, 2.0, 0.3, 10.0), STRAIGHT, 20.0)
    assert off_lane.outcome.reason == "converged" and off_lane.outcome.duration == pytest.approx(1.0)
    fast = simulate_behavior(ex, Behavior.SPEED_DOWN, VehicleState(0.0, 0.0, 0.0, 25.0), STRAIGHT, 25.0)
    assert fast.outcome.reason == "timeout" and fast.outcome.duration == pytest.approx(2.0)
    assert fast.final.v > fast.outcome.v_ref + ex.cfg.v_thresh
    lc = simulate_behavior(ex, Behavior.CHANGE_LEFT, VehicleState(0.0, 0.0, 0.0, 10.0), STRAIGHT, 20.0)
    assert lc.outcome.reason == "converged" and lc.outcome.duration > 2.0
    short = BehaviorExecutor(config=ExecutorConfig(max_duration=2.0))
    cut = simulate_behavior(short, Behavior.CHANGE_LEFT, VehicleState(0.0, 0.0, 0.0, 10.0), STRAIGHT, 20.0)
    assert cut.outcome.reason == "timeout" and cut.outcome.duration == pytest.approx(2.0)


def test_cost_and_reward_bookkeeping():
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 0.0, 0.0, 10.0)
    ex.start(Behavior.CHANGE_LEFT, ego, STRAIGHT, 20.0)
    totals = []
    while True:
        control, p = ex.step(ego, None)
        if ex.done:
            break
        totals.append(p.c_total)
        ego = step(ego, control, 0.1)
    assert ex.c_total == pytest.approx(np.mean(totals))
    assert ex.reward() == pytest.approx(-ex.cfg.reward_scale * ex.c_total)
    assert ex.reward(scale=2.0) == pytest.approx(-2.0 * ex.c_total)
    out = ex.outcome()
    assert out.c_total == pytest.approx(ex.c_total) and len(out.c_terms) == 3
    assert out.n_steps == len(totals)
    # stepping after done still returns a control and does not change the cost
    ex.step(ego, None)
    assert ex.c_total == pytest.approx(np.mean(totals)) and ex.done


def test_reward_from_cost():
    assert reward_from_cost(0.5) == pytest.approx(-0.5)
    assert reward_from_cost(0.5, scale=10.0) == pytest.approx(-5.0)
    np.testing.assert_allclose(reward_from_cost(np.array([0.0, 1.0, 2.0]), 2.0), [0.0, -2.0, -4.0])
    with pytest.raises(ValueError):
        reward_from_cost(1.0, scale=0.0)


def test_executor_errors():
    ex = BehaviorExecutor()
    with pytest.raises(RuntimeError):
        ex.step(VehicleState(0, 0, 0, 1))
    with pytest.raises(ValueError):
        ex.start(Behavior.KEEP, VehicleState(0, 0, 0, 1), (None, None, None), 10.0)
    with pytest.raises(ValueError):
        ex.start(Behavior.KEEP, VehicleState(0, 0, 0, 1), STRAIGHT, 0.0)
    with pytest.raises(ValueError):
        ExecutorConfig(min_duration=10.0, max_duration=8.0)
    with pytest.raises(ValueError):
        ExecutorConfig(replan_every=0)


def _overlap(ego: VehicleState, obs: Obstacles, cfg=PlannerConfig()):
    c, s = np.cos(ego.yaw), np.sin(ego.yaw)
    return _sat_overlap(obs.x - ego.x, obs.y - ego.y, c, s, cfg.length / 2, cfg.width / 2,
                        np.cos(obs.yaw), np.sin(obs.yaw), obs.length / 2, obs.width / 2).any()


def test_repeated_keep_stops_behind_a_stopped_car():
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 0.0, 0.0, 10.0)
    obs = Obstacles.from_rows([(60.0, 0.0, 0.0, 0.0, 4.6, 1.9)])
    for _ in range(15):  # ~1 Hz decisions, always keep
        r = simulate_behavior(ex, Behavior.KEEP, ego, STRAIGHT, 20.0, obs)
        ego = r.final
        for x, y, yaw, v, _ in r.states:
            assert not _overlap(VehicleState(x, y, yaw, v), obs)
    assert ego.v < 0.5 and 60.0 - ego.x > 4.6


def test_change_left_passes_a_slow_car_without_collision():
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 0.0, 0.0, 10.0)
    obs = Obstacles.from_rows([(20.0, 0.0, 0.0, 4.0, 4.6, 1.9)])
    r = simulate_behavior(ex, Behavior.CHANGE_LEFT, ego, STRAIGHT, 20.0, obs)
    assert r.outcome.reason == "converged" and r.outcome.collision_free
    assert abs(r.final.y - LANE) < 0.3
    # cost of the executed lane change is lower than keeping behind the slow car
    ex2 = BehaviorExecutor()
    r2 = simulate_behavior(ex2, Behavior.KEEP, ego, STRAIGHT, 20.0, obs)
    assert r2.outcome.c_total > r.outcome.c_total


@pytest.mark.parametrize("v0", [8.0, 13.89, 25.0])
def test_a_chain_of_speed_down_stops_within_the_lawful_distance(v0):
    """keep for one decision (the latency: a need that arises just after it is acted on at the
    next decision), then speed_down at every decision: the stop, latency included, fits in
    v * 1 s + v^2 / (2 * 3 m/s^2) and never uses the full-brake sample (6 m/s^2)."""
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 0.0, 0.0, v0)
    cruise = simulate_behavior(ex, Behavior.KEEP, ego, STRAIGHT, max(v0, 13.89))
    assert cruise.outcome.duration == pytest.approx(1.0)
    speeds, ego, decisions = list(cruise.states[:, 3]), cruise.final, 0
    while ego.v > 0.0 and decisions < 20:
        r = simulate_behavior(ex, Behavior.SPEED_DOWN, ego, STRAIGHT, max(v0, 13.89))
        # a 35 % step from 25 m/s needs more than the 2 s a lane-keeping behavior may run
        assert r.outcome.reason == "converged" or r.outcome.duration == pytest.approx(2.0)
        speeds += list(r.states[1:, 3])
        ego, decisions = r.final, decisions + 1
    assert ego.v == 0.0 and decisions <= 6
    bound = v0 * 1.0 + v0 ** 2 / (2 * 3.0)
    assert ego.x - cruise.states[0, 0] <= bound
    decel = -np.diff(speeds) / ex.cfg.dt
    assert decel.max() < 4.5


@pytest.mark.parametrize("behavior", [Behavior.KEEP, Behavior.SPEED_DOWN])
def test_a_standing_car_asked_to_stand_decides_again_after_the_minimum_duration(behavior):
    """At rest off the lane centre, a behavior with v_ref = 0 cannot reduce e or theta_e; it ends
    after min_duration (not max_duration), and the car has not moved."""
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 0.8, 0.15, 0.0)
    r = simulate_behavior(ex, behavior, ego, STRAIGHT, 13.89)
    assert r.outcome.v_ref == 0.0
    assert r.outcome.reason == "converged" and r.outcome.duration == pytest.approx(1.0)
    np.testing.assert_allclose(r.states[:, :4], np.tile([0.0, 0.8, 0.15, 0.0], (len(r.states), 1)), atol=1e-9)
    e, th = errors(STRAIGHT.current, r.final)
    assert abs(e) > 0.3 and abs(th) > 0.05  # it would never have met the lane condition


def test_a_standing_car_asked_to_move_still_converges_to_the_lane():
    r = simulate_behavior(BehaviorExecutor(), Behavior.SPEED_UP, VehicleState(0.0, 0.8, 0.15, 0.0), STRAIGHT, 13.89)
    assert r.outcome.v_ref == pytest.approx(2.0) and r.outcome.reason == "converged"
    r = keep_deciding(BehaviorExecutor(), Behavior.SPEED_UP, VehicleState(0.0, 0.8, 0.15, 0.0), STRAIGHT, 13.89)
    e, th = errors(STRAIGHT.current, r.final)
    assert abs(e) < 0.3 and abs(th) < 0.05
    with pytest.raises(ValueError, match="lane_keeping_max_duration"):
        ExecutorConfig(lane_keeping_max_duration=0.0)
    with pytest.raises(ValueError, match="min_duration"):
        ExecutorConfig(lane_keeping_max_duration=0.5)


def _drift_beside_a_car(corridor, decisions=10):
    """The ego at 20 m/s in the rightmost lane, a car alongside in the lane to its left at the same speed;
    keep decisions. Returns the ego's lateral offsets [m] over the run."""
    ex = BehaviorExecutor()
    ego = VehicleState(0.0, 0.0, 0.0, 20.0)
    others = Obstacles.from_rows(np.array([[1.0, LANE, 0.0, 20.0, 4.6, 2.0]]))
    offsets = []
    for _ in range(decisions):
        r = simulate_behavior(ex, Behavior.KEEP, ego, ReferencePaths(lane(LANE), lane(0.0), None, corridor), 25.0,
                              others)
        ego, others = r.final, r.obstacles
        offsets.extend(r.states[:, 1])
    return np.array(offsets)


def test_the_corridor_stops_the_swerve_ratchet_at_the_road_edge():
    """Re-planning at 10 Hz, the sample that swerves away from a car alongside first is the cheapest
    every time, and each executes only its first step: without a road edge the ego ends up 1.3 m right of
    its lane's centre (its footprint 0.5 m off a 3.5 m lane). With the corridor of a lane that has no lane
    to its right (the footprint inside the lane: 0.8 m each side for the planner's 1.9 m wide car) it stays on the road."""
    half = LANE / 2 - PlannerConfig().width / 2
    free = _drift_beside_a_car((-np.inf, np.inf, np.inf))
    bounded = _drift_beside_a_car((-half, np.inf, np.inf))
    assert free.min() < -1.0
    assert bounded.min() >= -half - 0.1


def test_on_road_bounds_only_the_lane_and_never_what_the_ego_already_is():
    from hbmp_bench.planning.planner import NO_CORRIDOR, on_road

    s = np.tile(np.linspace(0.0, 30.0, 4), (3, 1))
    e = np.array([[0.0, -0.5, -0.9, -1.5],    # leaves the road at s = 20 m
                  [0.0, -0.5, -0.7, -0.7],    # stays on it
                  [0.0, 0.5, 3.0, 3.0]])      # into the open left lane
    frenet = np.stack([s, e], axis=2)
    assert on_road(frenet, (-0.8, np.inf, np.inf)).tolist() == [False, True, True]
    assert on_road(frenet, (-0.8, np.inf, 15.0)).tolist() == [True, True, True]   # the lane ends at 15 m
    assert on_road(frenet, NO_CORRIDOR).all()
    back = np.array([[-1.0, -0.9, -0.8, -0.7],   # the ego starts 1 m right of the centre: returning,
                     [-1.0, -1.0, -1.0, -1.0],   # holding,
                     [-1.0, -1.2, -1.3, -1.3]])  # or going further out
    assert on_road(np.stack([s, back], axis=2), (-0.8, np.inf, np.inf)).tolist() == [True, True, False]


def test_the_control_laws_own_swing_does_not_leave_the_road():
    """Recorded in ``hbmp-s``'s Town02 episode 13 of ``nocrash-regular``: the ego stood 0.86 m left of its
    lane's centre, beyond the 0.85 m corridor, heading out. From a standstill every moving sample swings
    further out before the control law turns it back, so only the two stop samples stayed on the road and it
    stood 41 s asking to go. Each sample may stray as far as its speed's lane-following sample."""
    from hbmp_bench.planning.planner import PlanningProblem, on_road, plan

    corridor = (-0.85, 0.85, 1000.0)
    p = PlanningProblem(VehicleState(0.0, 0.86, 0.2, 0.0), lane(0.0), 2.0, 10.0, corridor=corridor)
    r = plan(p)
    assert on_road(r.frenet, corridor).sum() == 2  # without the allowance: the stop samples alone
    assert r.on_road.sum() > 2 and r.on_road[r.chosen] and r.collision_free
    assert r.trajectory[10, 3] > 1.0  # it moves off
    # samples that swerve further out than the law does stay off the road
    assert not r.on_road[np.argmax(r.frenet[:, 1:, 1].max(axis=1))]


def test_on_road_allows_each_sample_its_lane_following_samples_excursion():
    from hbmp_bench.planning.planner import on_road

    s = np.tile(np.linspace(0.0, 30.0, 4), (3, 1))
    e = np.array([[0.9, 1.0, 0.9, 0.5],    # the law's own swing, 0.1 m past where the ego is
                  [0.9, 1.1, 1.0, 0.6],    # further out than the law
                  [0.9, 0.9, 0.8, 0.4]])   # never further out than the ego
    frenet = np.stack([s, e], axis=2)
    corridor = (-0.8, 0.8, np.inf)
    assert on_road(frenet, corridor).tolist() == [False, False, True]
    assert on_road(frenet, corridor, np.array([0, 0, 0])).tolist() == [True, False, True]
