"""Top-down renderer on the shipped networks: frame format, where things land, colours."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hbmp_bench.maps.roadnet import point_along
from hbmp_bench.render import RenderConfig, SceneView, TopDownRenderer, palette
from hbmp_bench.render.static import read_walkways
from hbmp_bench.scenarios import road_network

MPP = 0.25
W = H = 400


def _pose(net, lane_id: str, s: float) -> tuple[np.ndarray, float]:
    shape = net.lane(lane_id).shape
    p, q = point_along(shape, s), point_along(shape, s + 1.0)
    return p, math.atan2(q[1] - p[1], q[0] - p[0])


def _close(pixel, colour, tol=0) -> bool:
    return bool(np.all(np.abs(np.asarray(pixel, dtype=int) - np.asarray(colour)) <= tol))


def _pixel(frame, col: float, row: float):
    return frame[int(math.floor(row)), int(math.floor(col))]


@pytest.fixture(scope="module")
def town03():
    return road_network("Town03")


@pytest.fixture(scope="module")
def heading_up(town03):
    return TopDownRenderer(town03, RenderConfig(width=W, height=H, metres_per_px=MPP))


@pytest.fixture(scope="module")
def scene(town03):
    xy, yaw = _pose(town03, town03.edge_lanes["AS_X230_95"][0], 20.0)
    return xy, yaw


@pytest.mark.parametrize("config", [RenderConfig(width=320, height=240), RenderConfig(heading_up=False),
                                    RenderConfig(view="map", width=300, height=200, supersample=1)])
def test_frame_shape_and_dtype(town03, scene, config):
    xy, yaw = scene
    frame = TopDownRenderer(town03, config).frame(SceneView(ego_xy=xy, ego_yaw=yaw))
    assert frame.shape == (config.height, config.width, 3)
    assert frame.dtype == np.uint8
    assert frame.flags.writeable


def test_ego_at_the_centre_when_following(heading_up, scene):
    xy, yaw = scene
    frame = heading_up.frame(SceneView(ego_xy=xy, ego_yaw=yaw))
    assert _close(frame[H // 2, W // 2], palette.EGO)
    # heading up: the ego box is long along the rows (4.5 m = 18 px), narrow along the columns (1.8 m)
    column = [_close(frame[H // 2 + d, W // 2], palette.EGO) or _close(frame[H // 2 + d, W // 2], palette.EGO_OUTLINE)
              for d in (-7, 7)]
    row = [_close(frame[H // 2, W // 2 + d], palette.EGO) for d in (-7, 7)]
    assert all(column) and not any(row)


def test_actors_land_at_their_offsets_heading_up(heading_up, scene):
    xy, yaw = scene
    fwd, left = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
    car = xy + 10.0 * fwd + 4.0 * left          # 10 m ahead, 4 m left
    walker = xy - 2.0 * fwd - 6.0 * left        # 2 m behind, 6 m right
    view = SceneView(ego_xy=xy, ego_yaw=yaw, actors_xy=[car, walker], actors_yaw=[yaw, 0.0],
                     actors_length=[4.5, 0.6], actors_width=[1.8, 0.6], actors_is_pedestrian=[False, True])
    frame = heading_up.frame(view)
    assert _close(_pixel(frame, W / 2 - 4.0 / MPP, H / 2 - 10.0 / MPP), palette.VEHICLE)
    assert _close(_pixel(frame, W / 2 + 6.0 / MPP, H / 2 + 2.0 / MPP), palette.PEDESTRIAN)


def test_actors_land_at_their_offsets_north_up(town03, scene):
    xy, yaw = scene
    renderer = TopDownRenderer(town03, RenderConfig(width=W, height=H, metres_per_px=MPP, heading_up=False))
    car = xy + np.array([-12.0, 5.0])  # 12 m west, 5 m north
    view = SceneView(ego_xy=xy, ego_yaw=yaw, actors_xy=[car], actors_yaw=[0.3], actors_length=[4.5],
                     actors_width=[1.8], actors_is_pedestrian=[False])
    frame = renderer.frame(view)
    assert _close(_pixel(frame, W / 2 - 12.0 / MPP, H / 2 - 5.0 / MPP), palette.VEHICLE)
    assert _close(frame[H // 2, W // 2], palette.EGO)


def test_static_layer_is_aligned_under_rotation(town03):
    """Sidewalk and lane centres of the rasterised net land where the view transform puts them."""
    renderer = TopDownRenderer(town03, RenderConfig(width=W, height=H, metres_per_px=MPP))
    def length(shape):
        return float(np.sum(np.hypot(*np.diff(shape, axis=0).T)))

    sidewalk = max((shape for shape, _ in read_walkways(str(town03.path)).sidewalks), key=length)
    mid = point_along(sidewalk, 0.5 * length(sidewalk))
    view = SceneView(ego_xy=mid + [30.0, 30.0], ego_yaw=0.7)  # the ego off the road, rotated view
    frame = renderer.frame(view)
    tf = renderer.transform(view)
    c, r = tf.to_px(mid)
    assert 0 <= c < W and 0 <= r < H
    assert _close(_pixel(frame, c, r), palette.SIDEWALK, tol=6)
    lane = town03.lanes[town03.edge_lanes["AS_X230_95"][1]]
    for s in np.linspace(5.0, lane.length - 5.0, 5):
        p = point_along(lane.shape, s)
        c, r = renderer.transform(SceneView(ego_xy=p + [0.0, 40.0], ego_yaw=-2.0)).to_px(p)
        lane_frame = renderer.frame(SceneView(ego_xy=p + [0.0, 40.0], ego_yaw=-2.0))
        assert _close(_pixel(lane_frame, c, r), palette.ROAD, tol=6)


def test_traffic_light_stop_bar_colour(town03, heading_up):
    lane_id = next(c.from_lane for e in town03.drivable_edges for c in town03.connections[e] if c.tls)
    lane = town03.lanes[lane_id]
    xy, yaw = _pose(town03, lane_id, max(lane.length - 15.0, 0.0))
    end, before = lane.shape[-1], lane.shape[-2]
    bar = end - 0.4 * (end - before) / np.hypot(*(end - before))
    for state, colour in (("r", palette.SIGNAL["r"]), ("G", palette.SIGNAL["G"]), ("y", palette.SIGNAL["y"])):
        view = SceneView(ego_xy=xy, ego_yaw=yaw, light_states={lane_id: state})
        c, r = heading_up.transform(view).to_px(bar)
        assert _close(_pixel(heading_up.frame(view), c, r), colour)
    plain = SceneView(ego_xy=xy, ego_yaw=yaw)
    c, r = heading_up.transform(plain).to_px(bar)
    assert not _close(_pixel(heading_up.frame(plain), c, r), palette.SIGNAL["r"], tol=40)


def test_plan_trajectories_drawn(heading_up, scene):
    xy, yaw = scene
    fwd, left = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
    t = np.linspace(0.0, 20.0, 21)[:, None]
    straight = xy + t * fwd
    swerve = xy + t * fwd + 5.0 * left * np.minimum(t / 5.0, 1.0)
    plans = np.stack([swerve, straight])
    view = SceneView(ego_xy=xy, ego_yaw=yaw, plan_trajectories=plans, plan_feasible=[False, True], plan_chosen=1)
    frame = heading_up.frame(view)
    assert _close(_pixel(frame, W / 2, H / 2 - 12.0 / MPP), palette.PLAN_CHOSEN)
    assert _close(_pixel(frame, W / 2 - 5.0 / MPP, H / 2 - 15.0 / MPP), palette.PLAN_INFEASIBLE)
    hidden = SceneView(ego_xy=xy, ego_yaw=yaw)
    assert not _close(_pixel(heading_up.frame(hidden), W / 2, H / 2 - 12.0 / MPP), palette.PLAN_CHOSEN, tol=40)


def test_route_goal_and_caption(town03, heading_up, scene):
    xy, yaw = scene
    edge = "AS_X230_95"
    fwd = np.array([math.cos(yaw), math.sin(yaw)])
    base = SceneView(ego_xy=xy, ego_yaw=yaw)
    view = SceneView(ego_xy=xy, ego_yaw=yaw, route_edges=(edge,), goal_xy=xy + 15.0 * fwd, caption="t=1.0 s  keep")
    plain, drawn = heading_up.frame(base), heading_up.frame(view)
    # the route band tints the ego's road towards blue, 6 m behind the ego
    behind = plain[int(H / 2 + 6 / MPP), W // 2].astype(int), drawn[int(H / 2 + 6 / MPP), W // 2].astype(int)
    assert behind[1][2] - behind[1][0] > behind[0][2] - behind[0][0] + 20
    assert _close(_pixel(drawn, W / 2, H / 2 - 15.0 / MPP), palette.GOAL)
    assert drawn[:12, :60].mean() < plain[:12, :60].mean() - 10  # the caption's dark bar
    assert not np.array_equal(drawn[:12, :60], plain[:12, :60])


def test_map_view_shows_the_whole_network(town03, scene):
    renderer = TopDownRenderer(town03, RenderConfig(view="map", width=300, height=300))
    xy, yaw = scene
    frame = renderer.frame(SceneView(ego_xy=xy, ego_yaw=yaw))
    tf = renderer.transform(SceneView(ego_xy=xy, ego_yaw=yaw))
    corners = tf.to_px(np.concatenate([lane.shape for lane in town03.lanes.values()]))
    assert corners.min() >= 0 and corners[:, 0].max() < 300 and corners[:, 1].max() < 300
    assert _close(_pixel(frame, *tf.to_px(xy)), palette.EGO)


def test_bad_input_errors(town03, heading_up, scene):
    xy, yaw = scene
    with pytest.raises(ValueError, match="actors_yaw"):
        SceneView(ego_xy=xy, ego_yaw=yaw, actors_xy=np.zeros((2, 2)), actors_yaw=[0.0], actors_length=[1.0, 1.0],
                  actors_width=[1.0, 1.0], actors_is_pedestrian=[False, False])
    with pytest.raises(ValueError, match="ego_xy"):
        SceneView(ego_xy=[1.0, 2.0, 3.0], ego_yaw=0.0)
    with pytest.raises(ValueError, match="light_states"):
        SceneView(ego_xy=xy, ego_yaw=yaw, light_states={"x": "q"})
    with pytest.raises(ValueError, match="plan_chosen"):
        SceneView(ego_xy=xy, ego_yaw=yaw, plan_trajectories=np.zeros((2, 5, 2)), plan_chosen=2)
    with pytest.raises(ValueError, match="not a drivable edge"):
        heading_up.frame(SceneView(ego_xy=xy, ego_yaw=yaw, route_edges=("no_such_edge",)))
    with pytest.raises(ValueError, match="not a lane"):
        heading_up.frame(SceneView(ego_xy=xy, ego_yaw=yaw, light_states={"no_such_lane_0": "r"}))
    with pytest.raises(ValueError, match="view"):
        RenderConfig(view="birdseye")
    with pytest.raises(ValueError, match="metres_per_px"):
        RenderConfig(metres_per_px=0.0)
