"""The lawful expert's rules, each in a crafted situation, and a few real SUMO episodes.

The crafted situations are ``(observation, info)`` pairs as the world builds them, with only the
``info["scene"]`` fields a rule reads set; distances are from the ego's front bumper [m].
"""

import numpy as np
import pytest

from hbmp_bench.agents import agent_env_kwargs
from hbmp_bench.agents.expert import CHANGE_LEFT, CHANGE_RIGHT, KEEP, SPEED_DOWN, SPEED_UP, ExpertAgent, Timing
from hbmp_bench.envs.observation import LANE_WIDTH_M, ObservationConfig
from hbmp_bench.planning.executor import ExecutorConfig

GRID = ObservationConfig()
INF = float("inf")


def situation(*, occupancy=None, duration_s=1.0, mask=(1, 1, 1, 1, 1), road=None, **scene):
    """(observation, info) of an ego on a free straight road at 10 m/s, limit 50 km/h, far from any
    junction, in continuous fidelity (behaviors of ~1 s), with ``scene`` fields overridden."""
    base = {
        "speed_mps": 10.0, "speed_limit_mps": 13.89, "in_junction": False, "route_lane_offset": 0,
        "stop_distance_m": 300.0, "light": "", "turn_ahead": "", "goal_distance_m": 500.0,
        "leader_gap_m": INF, "leader_speed_mps": 0.0, "pedestrians": (), "lights_ahead": (),
        "junction_exit_m": INF, "junction_foes": (), "fidelity": "continuous",
    }
    base.update(scene)
    grid = np.zeros((1, GRID.rows, GRID.cols), np.float32) if occupancy is None else occupancy
    r = np.zeros(10, np.float32) if road is None else np.asarray(road, np.float32)
    info = {"scene": base, "action_mask": np.asarray(mask, np.int8), "duration_s": duration_s}
    return {"occupancy": grid, "road": r}, info


def act(**kwargs) -> int:
    return ExpertAgent().act(*situation(**kwargs))


def rules(**kwargs) -> set[str]:
    """The rules that set a target now."""
    return {g.rule for g in ExpertAgent().targets(*situation(**kwargs))}


def light(state: str, distance_m: float, schedule=None, **kwargs) -> dict:
    """The next light on the route ``distance_m`` ahead, also the one ending the ego's lane."""
    schedule = schedule if schedule is not None else ((0.0, state),)
    return dict(light=state, stop_distance_m=distance_m, lights_ahead=((distance_m, state, schedule),),
                junction_exit_m=distance_m + 20.0, **kwargs)


def foe(ego_dist_m, foe_dist_m, foe_speed_mps, *, ego_yields=False, foe_yields=False, foe_signal="", length_m=4.0):
    return {"ego_dist_m": ego_dist_m, "ego_exit_m": ego_dist_m + length_m, "foe_dist_m": foe_dist_m,
            "foe_exit_m": foe_dist_m + length_m, "foe_speed_mps": foe_speed_mps, "ego_yields": ego_yields,
            "foe_yields": foe_yields, "foe_signal": foe_signal}


# ------------------------------------------------------------------ speed limit
def test_speed_limit_cruises_near_the_limit():
    assert act(speed_mps=5.0) == SPEED_UP
    assert act(speed_mps=12.4) == KEEP  # 90 % of 13.89 m/s
    assert act(speed_mps=15.0) == SPEED_DOWN
    assert act(speed_mps=0.0) == SPEED_UP  # a standing ego on a free road drives off


def test_speed_limit_reaches_a_turn_at_turn_speed():
    assert "turn" in rules(turn_ahead="l", stop_distance_m=15.0, junction_exit_m=35.0)
    assert act(turn_ahead="l", stop_distance_m=15.0, junction_exit_m=35.0, speed_mps=12.0) == SPEED_DOWN
    assert act(turn_ahead="s", stop_distance_m=15.0, junction_exit_m=35.0, speed_mps=12.0) == KEEP


# -------------------------------------------------------------------- red light
def test_red_light_stops_before_the_line():
    # keeping 8 m/s for a keep (1 s, 8 m) leaves 10 m to stop in: too little (8²/6 = 10.7 m)
    assert act(**light("r", 20.0), speed_mps=8.0) == SPEED_DOWN
    assert act(**light("r", 40.0), speed_mps=8.0) in (KEEP, SPEED_UP)
    # standing before a red that stays red: waits, and does not creep into the junction
    assert act(**light("r", 3.0, ((0.0, "r"), (20.0, "G"))), speed_mps=0.0) == KEEP


def test_red_light_drives_off_when_it_turns_green_before_the_ego_gets_there():
    # red for 2 more seconds, 30 m ahead at 8 m/s: it is green when the ego arrives
    assert act(**light("r", 30.0, ((0.0, "r"), (2.0, "G"), (30.0, "y"))), speed_mps=8.0) in (KEEP, SPEED_UP)
    # green now, yellow in 20 s: drive off from the line
    assert act(**light("G", 2.0, ((0.0, "G"), (20.0, "y"), (23.0, "r"))), speed_mps=0.0) == SPEED_UP


def test_red_light_stops_for_a_yellow_it_can_stop_for_and_goes_through_one_it_cannot():
    yellow = ((0.0, "y"), (3.0, "r"), (20.0, "G"))
    assert act(**light("y", 20.0, yellow), speed_mps=8.0) == SPEED_DOWN  # 8 m for a keep, 8²/6 = 11 m of braking
    assert act(**light("y", 8.0, yellow), speed_mps=12.0) != SPEED_DOWN  # 24 m of braking: go through
    assert "red_light" not in rules(**light("y", 8.0, yellow), speed_mps=12.0)


def test_red_light_waits_at_the_line_through_a_yellow_when_standing():
    yellow = ((0.0, "y"), (3.0, "r"), (20.0, "G"))
    assert act(**light("y", 0.6, yellow), speed_mps=0.0) == KEEP  # no "too close to stop" for a standing car


def test_red_light_slows_for_a_green_that_turns_red_before_the_ego_gets_there():
    turning = ((0.0, "G"), (2.0, "y"), (5.0, "r"), (25.0, "G"))
    assert act(**light("G", 35.0, turning), speed_mps=12.0) == SPEED_DOWN  # there in ~2.9 s: yellow or red
    assert act(**light("G", 15.0, turning), speed_mps=12.0) in (KEEP, SPEED_UP)  # there in 1.3 s: green


def test_red_light_also_stops_for_a_light_beyond_the_next_one():
    # in a junction at 8 m/s: the next light, 12 m ahead, stays green; the one after it, 19 m ahead,
    # is red for a while: a keep (1 s) must not take the ego where it can no longer stop before it
    green = ((0.0, "G"), (40.0, "y"))
    red = ((0.0, "r"), (30.0, "G"))
    scene = dict(in_junction=True, stop_distance_m=12.0, junction_exit_m=5.0, speed_mps=8.0)
    assert act(**scene, lights_ahead=((12.0, "G", green),)) in (KEEP, SPEED_UP)
    assert act(**scene, lights_ahead=((12.0, "G", green), (19.0, "r", red))) == SPEED_DOWN


def test_red_light_without_privileged_lights_reads_the_lane_light():
    obs, info = situation(light="r", stop_distance_m=20.0, speed_mps=8.0)
    del info["scene"]["lights_ahead"]
    assert ExpertAgent().act(obs, info) == SPEED_DOWN


def test_red_light_plans_stops_with_the_behaviors_the_fidelity_runs():
    # 20 m before a red at 8 m/s: a keep of the motion planner runs 1 s, so it brakes now; with
    # SUMO's 0.1 s decisions it need not brake yet (8²/7 = 9 m), only when the line comes close
    assert act(**light("r", 20.0), speed_mps=8.0) == SPEED_DOWN
    assert act(**light("r", 20.0), speed_mps=8.0, fidelity="event", duration_s=0.1) != SPEED_DOWN
    assert act(**light("r", 10.0), speed_mps=8.0, fidelity="event", duration_s=0.1) == SPEED_DOWN
    # standing 2 m before the line of a green light with yellow in 6 s: drive off (speeding up
    # 0.26 m/s per decision, it is well past the line by then)
    green = ((0.0, "G"), (6.0, "y"), (9.0, "r"))
    assert act(**light("G", 2.0, green), speed_mps=0.0, fidelity="event", duration_s=0.1) == SPEED_UP
    # at a crawl at the line: no creeping over it 0.26 m/s at a time
    assert act(**light("r", 1.5), speed_mps=0.33, fidelity="event", duration_s=0.1) == SPEED_DOWN
    assert act(**light("r", 1.5), speed_mps=0.0, fidelity="event", duration_s=0.1) == KEEP


# ------------------------------------------------------------------- leader gap
def test_leader_gap_stops_behind_a_standing_leader_and_follows_a_moving_one():
    assert act(leader_gap_m=20.0, leader_speed_mps=0.0) == SPEED_DOWN
    assert act(leader_gap_m=60.0, leader_speed_mps=10.0, speed_mps=10.0) == SPEED_UP
    assert act(leader_gap_m=2.5, leader_speed_mps=0.0, speed_mps=0.0) == KEEP  # queued: stays
    # a time gap: 15 m behind a leader at the ego's 10 m/s is too close
    assert act(leader_gap_m=13.0, leader_speed_mps=10.0, speed_mps=10.0) == SPEED_DOWN


def test_leader_gap_reads_the_occupancy_grid_without_a_privileged_leader():
    grid = np.zeros((1, GRID.rows, GRID.cols), np.float32)
    row = int(GRID.back_m + 12.0)  # an obstacle 12 m ahead of the ego's centre, in its lane
    grid[0, row, GRID.cols // 2 - 2: GRID.cols // 2 + 2] = 1.0
    obs, info = situation(occupancy=grid)
    del info["scene"]["leader_gap_m"], info["scene"]["leader_speed_mps"]
    assert ExpertAgent().act(obs, info) == SPEED_DOWN


# ---------------------------------------------------------------- junction clear
def test_junction_clear_waits_at_the_line_while_the_exit_is_blocked():
    at_line = light("G", 2.0, ((0.0, "G"), (30.0, "y")), speed_mps=0.0)  # junction exit 22 m ahead
    assert act(**at_line, leader_gap_m=24.0, leader_speed_mps=0.0) == KEEP  # no room behind it
    assert "junction_clear" in rules(**at_line, leader_gap_m=24.0, leader_speed_mps=0.0)
    assert act(**at_line, leader_gap_m=24.0, leader_speed_mps=6.0) == SPEED_UP  # it drives away
    assert act(**at_line, leader_gap_m=40.0, leader_speed_mps=0.0) == SPEED_UP  # room for the ego


# ------------------------------------------------------------------------ yield
def test_yield_waits_for_a_foe_that_would_be_in_the_conflict_area_with_the_ego():
    at_line = dict(stop_distance_m=2.0, junction_exit_m=20.0, speed_mps=0.0)
    assert act(**at_line, junction_foes=(foe(8.0, 25.0, 10.0, ego_yields=True),)) == KEEP
    assert "yield" in rules(**at_line, junction_foes=(foe(8.0, 25.0, 10.0, ego_yields=True),))
    assert act(**at_line, junction_foes=(foe(8.0, 200.0, 10.0, ego_yields=True),)) == SPEED_UP  # far
    assert act(**at_line, junction_foes=(foe(8.0, -10.0, 10.0, ego_yields=True),)) == SPEED_UP  # passed


def test_yield_passes_a_foe_that_gives_way_or_is_held_by_its_light():
    at_line = dict(stop_distance_m=2.0, junction_exit_m=20.0, speed_mps=0.0)
    waiting = foe(8.0, 6.0, 0.0, foe_yields=True)
    assert act(**at_line, junction_foes=(waiting,)) == SPEED_UP
    held = foe(8.0, 15.0, 8.0, foe_signal="r")
    assert act(**at_line, junction_foes=(held,)) == SPEED_UP
    # a waiting foe with the right of way may start at any time: the ego waits at the line ...
    assert act(**at_line, junction_foes=(foe(8.0, 6.0, 0.0, ego_yields=True),)) == KEEP
    # ... but not inside the junction, where that foe waits for the ego to clear it
    inside = dict(in_junction=True, stop_distance_m=60.0, junction_exit_m=8.0, speed_mps=0.0)
    assert act(**inside, junction_foes=(foe(2.0, 6.0, 0.0, ego_yields=True),)) == SPEED_UP
    # a standing foe without the right of way waits for the ego
    assert act(**at_line, junction_foes=(foe(8.0, 6.0, 0.0),)) == SPEED_UP


def test_yield_slows_before_the_junction_for_a_foe_arriving_with_the_ego():
    approach = dict(stop_distance_m=25.0, junction_exit_m=40.0, speed_mps=10.0)
    assert act(**approach, junction_foes=(foe(31.0, 35.0, 10.0),)) == SPEED_DOWN
    assert act(**approach, junction_foes=(foe(31.0, 300.0, 10.0),)) in (KEEP, SPEED_UP)
    # a conflict at the junction after the next one is judged once the ego has crossed this one
    assert act(**approach, junction_foes=(foe(60.0, 60.0, 10.0),)) in (KEEP, SPEED_UP)


# ------------------------------------------------------------------ pedestrians
def test_pedestrians_stops_for_one_walking_into_the_path():
    crossing = (15.0, -4.0, 0.0, 1.3, False)  # 15 m ahead, 4 m to the right, walking left across
    assert act(pedestrians=(crossing,), speed_mps=8.0) == SPEED_DOWN
    assert act(pedestrians=((15.0, 0.3, 0.0, 0.0, False),), speed_mps=8.0) == SPEED_DOWN  # standing in the path


def test_pedestrians_ignores_walkers_beside_the_path_and_waiting_at_the_kerb():
    along = (15.0, -4.0, 1.3, 0.0, False)  # on the sidewalk, walking along the road
    kerb = (4.0, -1.75, 0.0, 0.0, False)  # standing at the kerb, at the lane's edge
    leaving = (15.0, 2.5, 0.0, 1.3, False)  # left of the path, walking away from it
    for p in (along, kerb, leaving):
        assert "pedestrian" not in rules(pedestrians=(p,), speed_mps=8.0)
    assert act(pedestrians=(along, kerb, leaving), speed_mps=8.0) == SPEED_UP


def test_pedestrians_passes_one_a_red_signal_holds_at_the_kerb():
    """Standing at the line on green: a pedestrian 10 m ahead, 4 m to the right, walks diagonally
    towards the crossing it turns over (Town02 NavigationDynamic 19, at a corner): waited for,
    unless the crossing's red signal holds them at the kerb. Within half a lane of its corridor, or
    in the path, they are waited for all the same (Town01 NavigationDynamic 21: a corner's kerb lay
    2 m from the path of a right turn, and a held pedestrian walked on into the car)."""
    crossing = {"ego_dist_m": 5.0, "ego_exit_m": 10.0, "signal": "r", "waiting_m": (4.0,)}
    at_line = dict(stop_distance_m=2.0, junction_exit_m=20.0, speed_mps=0.0, crossings=(crossing,))
    assert act(**at_line, pedestrians=((10.0, -4.0, -1.0, 0.7, False),)) == KEEP
    assert act(**at_line, pedestrians=((10.0, -4.0, -1.0, 0.7, True),)) == SPEED_UP
    assert act(**at_line, pedestrians=((10.0, -2.5, -1.0, 0.7, True),)) == KEEP
    assert act(**at_line, pedestrians=((6.0, -0.5, 0.0, 1.0, True),)) == KEEP


def test_pedestrians_waits_for_one_about_to_step_onto_a_crossing_of_its_path():
    # turning over a crossing 5 m ahead; a pedestrian waits 3 m from the ego's path at its end
    crossing = {"ego_dist_m": 5.0, "ego_exit_m": 9.0, "signal": "G", "waiting_m": (3.0,)}
    at_line = dict(stop_distance_m=2.0, junction_exit_m=20.0, speed_mps=0.0)
    assert act(**at_line, crossings=(crossing,)) == KEEP
    assert "pedestrian" in rules(**at_line, crossings=(crossing,))
    # their signal is red: they stay; nobody waits; the ego is over the crossing already
    for other in ({**crossing, "signal": "r"}, {**crossing, "waiting_m": ()}, {**crossing, "ego_dist_m": -1.0}):
        assert act(**at_line, crossings=(other,)) == SPEED_UP


def test_pedestrians_it_turns_over_a_crossing_before_a_waiting_pedestrian_can_step_onto_it():
    """Standing at the line, a pedestrian waits 11 m from the crossing's stretch of its path (on it
    in 4.7 s at a brisk 1.5 m/s, less a second). Driving off (1.5 m/s² to the speed a chain of
    speed_up reaches) clears the stretch in 4.2 s on a gentle curve, where the planner's curve cap
    (2 m/s², 0.6 rad/s at 0.05 1/m: 6.3 m/s) allows it; not in a tight one (0.5 1/m: 1.2 m/s), nor
    where the path's curvature is unknown (no further speed_up counted on: 7.4 s at 2 m/s)."""
    crossing = {"ego_dist_m": 5.0, "ego_exit_m": 9.0, "signal": "G", "waiting_m": (11.0,)}
    at_line = dict(stop_distance_m=2.0, junction_exit_m=20.0, speed_mps=0.0, crossings=(crossing,))
    assert act(**at_line, curvature_ahead=0.05) == SPEED_UP
    assert act(**at_line, curvature_ahead=0.5) == KEEP
    assert act(**at_line) == KEEP
    # SUMO's 0.1 s decisions keep speeding up (to 8 m/s)
    assert act(**at_line, fidelity="event", duration_s=0.1) == SPEED_UP


def test_pedestrians_on_a_crossing_are_waited_for_before_the_crossing_not_on_it():
    # a turn over a crossing whose stretch of the path runs 5..11 m ahead; a pedestrian walks it
    # obliquely to the path: 8 m ahead, 5 m to the left, coming across (Town04 NavigationDynamic 6)
    crossing = {"ego_dist_m": 5.0, "ego_exit_m": 11.0, "signal": "G", "waiting_m": ()}
    walker = (8.0, 5.0, -0.3, -1.2, False)
    stops = [g for g in ExpertAgent().targets(*situation(pedestrians=(walker,), crossings=(crossing,), speed_mps=4.0))
             if g.rule == "pedestrian"]
    assert [g.at_m for g in stops] == [pytest.approx(5.0 - ExpertAgent().stop_margin_m)]
    # and off a crossing it has begun to pass too, when the two lie less than a car length apart
    first = {"ego_dist_m": 1.0, "ego_exit_m": 4.0, "signal": "r", "waiting_m": ()}
    stops = [g for g in ExpertAgent().targets(*situation(pedestrians=(walker,), crossings=(first, crossing),
                                                         speed_mps=4.0)) if g.rule == "pedestrian"]
    assert [g.at_m for g in stops] == [pytest.approx(1.0 - ExpertAgent().stop_margin_m)]


def test_route_lane_changes_before_the_goal_on_the_goal_edge():
    # the goal lane is on the right, 20 m ahead on this edge, which goes on for 100 m; the right
    # lane is taken (Town05 NavigationDynamic 1)
    taken = np.zeros((1, GRID.rows, GRID.cols), np.float32)
    right = int(GRID.cols / 2 - LANE_WIDTH_M / GRID.cell_lat_m)
    taken[0, :, right - 1:right + 2] = 1.0
    scene = dict(route_lane_offset=-1, stop_distance_m=100.0, speed_mps=8.0, fidelity="event", duration_s=0.1,
                 occupancy=taken, road=(1, 1, 0, 0, 1, 0, 0, 0, 1, 0.6))
    assert act(**scene, goal_distance_m=20.0) == SPEED_DOWN  # waits for a gap before the goal
    assert act(**scene, goal_distance_m=500.0) == SPEED_UP  # the lane's end is far: drives on


def test_pedestrians_beside_the_ego_do_not_stop_it():
    beside = (-1.5, -1.2, 0.0, 1.3, False)  # next to the car, behind its front bumper
    assert "pedestrian" not in rules(pedestrians=(beside,), speed_mps=3.0)


# ------------------------------------------------------------------- chooser
def test_the_expert_stops_rather_than_creeps():
    # a crawl converges slowly (a behavior may run 8 s): not kept near a stop
    assert act(**light("r", 6.0), speed_mps=0.4) == SPEED_DOWN
    assert act(speed_mps=0.4) == SPEED_UP  # free road: drive off


def test_it_plans_with_the_longest_run_of_each_behavior():
    """With the motion planner, speed_up / speed_down run at most 2 s, keep exactly 1 s and a lane
    change at most 8 s: 40 m before a red at 6 m/s it may keep its speed (6 m, then a 6 m stop) but
    not begin a lane change (48 m), unless the target lane's light is green long enough."""
    t = Timing.for_period(1.0, continuous=True)
    assert (t.hard_s, t.keep_hard_s, t.lane_change_hard_s) == (2.0, 1.0, 8.0)
    red = light("r", 40.0)
    assert act(**red, speed_mps=6.0) in (KEEP, SPEED_UP)
    assert act(**red, speed_mps=6.0, route_lane_offset=1) != CHANGE_LEFT
    green = (40.0, "G", ((0.0, "G"), (30.0, "y"), (34.0, "r")))
    assert act(**red, speed_mps=6.0, route_lane_offset=1, route_lane_light=green) == CHANGE_LEFT


def test_it_checks_stop_lines_over_the_run_of_the_behavior_it_chooses():
    """A keep ends after exactly ``min_duration`` (1 s), a speed_up may run 2 s: 25 m before a red
    at 8 m/s it may keep its speed (8 m, then a 10.7 m stop, before the line's 23 m) but not speed
    up to 10 m/s (up to 20 m, then a 16.7 m stop); 20 m before the red it brakes (18.7 > 18 m)."""
    assert Timing.for_period(1.0, continuous=True).keep_hard_s == ExecutorConfig().min_duration
    assert act(**light("r", 25.0), speed_mps=8.0) == KEEP
    assert act(**light("r", 20.0), speed_mps=8.0) == SPEED_DOWN
    # the same for a yield line (1 m before the junction) with a foe arriving with the ego
    approach = dict(stop_distance_m=25.0, junction_exit_m=50.0, speed_mps=8.0)
    assert act(**approach, junction_foes=(foe(35.0, 35.0, 10.0),)) == KEEP
    assert act(**{**approach, "stop_distance_m": 19.0}, junction_foes=(foe(29.0, 29.0, 10.0),)) == SPEED_DOWN


def test_standing_before_a_red_line_it_moves_up_to_the_line():
    red_ahead = light("r", 14.0, ((0.0, "r"), (30.0, "G")))
    assert act(**red_ahead, speed_mps=0.0) == SPEED_UP  # 2 s at 3.5 m/s and a stop: 9 m < 12 m
    assert act(**light("r", 6.0, ((0.0, "r"), (30.0, "G"))), speed_mps=0.0) == KEEP


# ------------------------------------------------------------------- route lane
def _left_lane_occupied():
    grid = np.zeros((1, GRID.rows, GRID.cols), np.float32)
    centre = GRID.cols // 2 + int(3.5 / GRID.cell_lat_m)
    grid[0, int(GRID.back_m): int(GRID.back_m) + 5, centre - 2: centre + 2] = 1.0
    return grid


def test_route_lane_changes_toward_the_route_when_the_lane_is_free():
    assert act(route_lane_offset=1) == CHANGE_LEFT
    assert act(route_lane_offset=1, occupancy=_left_lane_occupied()) != CHANGE_LEFT
    assert act(route_lane_offset=1, mask=(1, 1, 0, 1, 1)) != CHANGE_LEFT  # lane changes closed


def test_route_lane_does_not_start_a_change_it_cannot_finish_before_a_stop():
    # a lane change holds the speed for a whole behavior: not 20 m before a red line at 8 m/s
    assert act(route_lane_offset=1, **light("r", 20.0), speed_mps=8.0) == SPEED_DOWN


def test_route_lane_waits_for_a_gap_before_the_lanes_end():
    road = np.zeros(10, np.float32)  # a_c = 0: the lane does not continue the route
    blocked = dict(route_lane_offset=1, occupancy=_left_lane_occupied(), road=road, stop_distance_m=25.0,
                   junction_exit_m=45.0, speed_mps=6.0)
    assert "route_lane" in {g.rule for g in ExpertAgent().targets(*situation(**blocked))} or \
        act(**blocked) == SPEED_DOWN
    assert act(**blocked) == SPEED_DOWN


# ------------------------------------------------------------ stopping distance
@pytest.mark.slow
@pytest.mark.parametrize("fidelity", ["continuous", "event"])
def test_the_planned_stop_is_longer_than_the_measured_speed_down_chain(fidelity):
    """The expert plans stops with ``Timing.stop_decel``: no shorter than a chain of speed_down
    really stops (measured in SUMO from the speed limit)."""
    from hbmp_bench.envs.stopping import measure_stop
    from hbmp_bench.envs.config import WorldConfig

    trace = measure_stop(WorldConfig(fidelity=fidelity), town="Town01")
    timing = Timing.for_period(1.0 if fidelity == "continuous" else 0.1, fidelity == "continuous")
    planned = trace.v_start ** 2 / (2.0 * timing.stop_decel)
    assert trace.distance_m <= planned <= 1.35 * trace.distance_m


# ------------------------------------------------------------ real episodes
@pytest.mark.slow
@pytest.mark.parametrize("town, task, episode, fidelity", [
    ("Town01", "NavigationDynamic", 0, "continuous"),   # lights, traffic, pedestrians
    ("Town01", "NavigationDynamic", 0, "event"),        # a permissive left turn across oncoming traffic
    ("Town05", "OneTurn", 0, "event"),                  # waits at the line through a red, no creeping
    ("Town05", "OneTurn", 1, "continuous"),             # two lane changes in time for the goal lane
])
def test_the_expert_drives_real_episodes_lawfully(town, task, episode, fidelity):
    from hbmp_bench.envs import BehaviorEnv

    agent = ExpertAgent()
    env = BehaviorEnv(town=town, task=task, suite="hbmp", fidelity=fidelity, **agent_env_kwargs(agent))
    try:
        obs, info = env.reset(seed=episode, options={"episode_index": episode})
        agent.reset(info)
        for _ in range(5000):
            obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
            if terminated or truncated:
                break
    finally:
        env.close()
    record = info["hbmp_record"]
    assert record["end_reason"] == "goal", record
    assert record["red_light"] == record["collision_vehicle"] == record["collision_pedestrian"] == 0


def test_route_lane_changes_while_cruising_a_little_above_the_cruise_speed():
    # event fidelity: speed_up steps overshoot the cruise speed (12.5 m/s) by a few tenths
    assert act(route_lane_offset=-1, speed_mps=13.3, fidelity="event", duration_s=0.1) == CHANGE_RIGHT


def test_the_expert_yields_to_a_foe_that_speeds_at_its_red():
    """A foe held by its red is passed, unless it comes at it well over its limit (it will run it)."""
    from hbmp_bench.agents.expert import ExpertAgent

    expert = ExpertAgent()
    foe = {"ego_dist_m": 20.0, "ego_exit_m": 24.0, "foe_dist_m": 30.0, "foe_exit_m": 34.0, "foe_speed_mps": 17.0,
           "ego_yields": False, "foe_yields": True, "foe_signal": "r", "foe_speeding": False}
    scene = {"in_junction": False, "stop_distance_m": 15.0, "junction_foes": (foe,)}
    timing = None  # the yield rule reads the scene only
    assert expert._rule_yield(scene, timing) == []
    scene["junction_foes"] = ({**foe, "foe_speeding": True},)
    (target,) = expert._rule_yield(scene, timing)
    assert target.speed_mps == 0.0 and target.at_m < 20.0
