"""Curvilinear frame: projection, point_at, concat, windowed search."""

import numpy as np
import pytest

from hbmp_bench.planning import Path, round_corners, wrap_angle


def circle(R, n=361, ccw=True, center=(0.0, 0.0), a0=0.0, a1=2 * np.pi):
    a = np.linspace(a0, a1, n)
    if not ccw:
        a = -a
    return np.stack([center[0] + R * np.cos(a), center[1] + R * np.sin(a)], axis=1)


def test_wrap_angle_range():
    a = np.array([-3 * np.pi, -np.pi, 0.0, np.pi, 3 * np.pi, 7.0])
    w = wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    np.testing.assert_allclose(w, [np.pi, np.pi, 0.0, np.pi, np.pi, 7.0 - 2 * np.pi])


def test_straight_line_projection():
    p = Path([[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]])
    s, e, th, k = p.project(np.array([[10.0, 2.0], [50.0, -1.5], [99.0, 0.0]]),
                            np.array([0.1, -0.2, np.pi]))
    np.testing.assert_allclose(s, [10.0, 50.0, 99.0])
    np.testing.assert_allclose(e, [2.0, -1.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(th, [0.1, -0.2, np.pi])
    np.testing.assert_allclose(k, 0.0)
    assert p.length == pytest.approx(100.0)


def test_diagonal_line_and_scalar_point():
    p = Path([[0.0, 0.0], [10.0, 10.0]])
    s, e, th, k = p.project(np.array([0.0, 2.0]), np.pi / 2)  # left of a NE-going path
    assert isinstance(s, float)
    assert s == pytest.approx(np.sqrt(2.0))
    assert e == pytest.approx(np.sqrt(2.0))
    assert th == pytest.approx(np.pi / 4)
    assert k == 0.0


def test_extension_beyond_the_ends():
    p = Path([[0.0, 0.0], [10.0, 0.0]])
    s, e = p.frenet(np.array([[-5.0, 1.0], [15.0, -2.0]]))
    np.testing.assert_allclose(s, [-5.0, 15.0])
    np.testing.assert_allclose(e, [1.0, -2.0])
    x, y, h, k = p.point_at(np.array([-5.0, 15.0]))
    np.testing.assert_allclose(x, [-5.0, 15.0])
    np.testing.assert_allclose(y, 0.0, atol=1e-12)


@pytest.mark.parametrize("ccw", [True, False])
def test_circle_projection(ccw):
    R = 20.0
    p = Path(circle(R, n=721, ccw=ccw))
    ang = np.array([0.5, 1.7, 4.0])
    sign = 1.0 if ccw else -1.0
    # points inside (radius 18) are LEFT of a CCW circle, right of a CW one
    pts = np.stack([18.0 * np.cos(sign * ang), 18.0 * np.sin(sign * ang)], axis=1)
    tangent = sign * ang + sign * np.pi / 2
    yaw = tangent + 0.1
    s, e, th, k = p.project(pts, yaw)
    np.testing.assert_allclose(s, R * ang, rtol=1e-3)
    np.testing.assert_allclose(e, sign * 2.0, atol=5e-3)
    np.testing.assert_allclose(th, 0.1, atol=5e-3)
    np.testing.assert_allclose(k, sign / R, rtol=1e-3)
    # outside (radius 23): 3 m on the other side
    pts = np.stack([23.0 * np.cos(sign * ang), 23.0 * np.sin(sign * ang)], axis=1)
    _, e, _, _ = p.project(pts, tangent)
    np.testing.assert_allclose(e, -sign * 3.0, atol=5e-3)


def test_point_at_on_circle():
    R = 30.0
    p = Path(circle(R, n=361))
    s = np.array([5.0, 40.0, 100.0])
    x, y, h, k = p.point_at(s)
    np.testing.assert_allclose(np.hypot(x, y), R, atol=2e-3)
    np.testing.assert_allclose(wrap_angle(np.arctan2(y, x) - s / R), 0.0, atol=1e-3)
    np.testing.assert_allclose(wrap_angle(h - (s / R + np.pi / 2)), 0.0, atol=1e-3)
    np.testing.assert_allclose(k, 1 / R, rtol=1e-3)


def test_vectorised_matches_pointwise():
    rng = np.random.default_rng(1)
    p = Path(circle(25.0, n=200, a1=np.pi))
    pts = rng.uniform(-30, 30, size=(300, 2))
    yaw = rng.uniform(-np.pi, np.pi, 300)
    s, e, th, k = p.project(pts, yaw)
    for j in range(0, 300, 37):
        sj, ej, tj, kj = p.project(pts[j], yaw[j])
        assert (sj, ej, tj, kj) == pytest.approx((s[j], e[j], th[j], k[j]))
    # |e| is the distance to the polyline
    dense = p.resample(0.01)
    d = np.min(np.hypot(pts[:, None, 0] - dense.xy[None, :, 0], pts[:, None, 1] - dense.xy[None, :, 1]), axis=1)
    inside = (s > p.s[0]) & (s < p.s[-1])
    np.testing.assert_allclose(np.abs(e[inside]), d[inside], atol=0.02)


def test_concat_lane_junction_lane():
    lane1 = np.array([[0.0, 0.0], [50.0, 0.0]])
    arc = circle(10.0, n=19, center=(50.0, 10.0), a0=-np.pi / 2, a1=0.0)  # left turn, starts at (50, 0)
    lane2 = np.array([[60.0, 10.0], [60.0, 60.0]])
    p = Path.concat([lane1, arc, lane2], max_spacing=None)
    assert len(p.xy) == 2 + 19 + 2 - 2  # both joints dropped
    p = Path.concat([lane1, arc, lane2])  # densified to <= 1 m segments
    assert np.max(np.diff(p.s)) <= 1.0 + 1e-9
    assert np.all(np.diff(p.s) > 0)
    assert p.length == pytest.approx(50 + 50 + 10 * np.pi / 2, rel=1e-3)
    # curvature: 0 on the straights, ~1/10 in the middle of the arc, bounded at joints
    s_mid = 50 + 10 * np.pi / 4
    assert p.point_at(s_mid)[3] == pytest.approx(0.1, rel=0.02)
    assert abs(p.point_at(20.0)[3]) < 1e-9 and abs(p.point_at(p.s[-1] - 20)[3]) < 1e-9
    assert abs(p.point_at(45.0)[3]) < 1e-3  # no curvature leaking along the straight
    assert np.max(np.abs(p.kappa)) <= 0.1 * 1.01
    # heading continuous along the path
    ss = np.linspace(0, p.s[-1], 2000)
    h = np.unwrap(p.point_at(ss)[2])
    assert np.max(np.abs(np.diff(h))) < 0.02
    assert h[-1] - h[0] == pytest.approx(np.pi / 2, abs=1e-6)
    # a point that lies on the arc projects with e ~ 0 (a chord error only)
    q = np.array([50 + 10 * np.sin(0.7), 10 - 10 * np.cos(0.7)])
    assert abs(p.project(q, 0.7)[1]) < 0.03


def test_concat_skips_none_and_rejects_empty():
    p = Path.concat([None, [[0, 0], [1, 0]], np.zeros((0, 2)), [[1, 0], [2, 0]]], max_spacing=None)
    assert len(p.xy) == 3
    with pytest.raises(ValueError):
        Path.concat([None])


def test_hint_s_on_hairpin_picks_the_local_branch():
    out = np.stack([np.linspace(0, 100, 101), np.zeros(101)], axis=1)
    turn = circle(1.5, n=31, center=(100.0, 1.5), a0=-np.pi / 2, a1=np.pi / 2)[1:]
    back = np.stack([np.linspace(100, 0, 101), np.full(101, 3.0)], axis=1)[1:]
    p = Path.concat([out, turn, back])
    q = np.array([50.0, 1.4])
    s_glob, e_glob = p.frenet(q)
    assert s_glob == pytest.approx(50.0, abs=1e-6) and e_glob == pytest.approx(1.4)
    s_ret = 100 + 1.5 * np.pi + 50  # same x on the way back
    s_hint, e_hint = p.frenet(q, hint_s=s_ret, window=(5.0, 5.0))
    assert s_hint == pytest.approx(s_ret, abs=0.05)
    assert e_hint == pytest.approx(1.6, abs=1e-3)  # south = LEFT of the westbound branch


def test_resample_keeps_s_and_geometry():
    p = Path(circle(20.0, n=91, a1=np.pi))
    r = p.resample(0.5, 10.0, 30.0)
    assert r.s[0] == pytest.approx(10.0) and r.s[-1] == pytest.approx(30.0)
    np.testing.assert_allclose(np.diff(r.s), 0.5, rtol=1e-6)
    np.testing.assert_allclose(r.kappa, 1 / 20, rtol=1e-3)
    np.testing.assert_allclose(np.hypot(*r.xy.T), 20.0, atol=0.01)


@pytest.mark.parametrize("bad", [np.zeros((3, 3)), np.zeros(4), [[0, 0]], [[0, 0], [0, 0]],
                                 [[0, 0], [np.nan, 1]]])
def test_path_validation(bad):
    with pytest.raises(ValueError):
        Path(bad)


def test_duplicate_points_are_merged():
    p = Path([[0, 0], [0, 0], [1, 0], [1, 0], [2, 0]], max_spacing=None)
    assert len(p.xy) == 3
    assert not p.xy.flags.writeable


def test_resample_extrapolate():
    p = Path([[0.0, 0.0], [10.0, 0.0]])
    r = p.resample(1.0, -5.0, 15.0, extrapolate=True)
    assert r.s[0] == -5.0 and r.s[-1] == 15.0
    np.testing.assert_allclose(r.xy[:, 0], np.arange(-5.0, 16.0))
    c = p.resample(1.0, -5.0, 15.0)
    assert c.s[0] == 0.0 and c.s[-1] == 10.0


def _lane_joint():
    """A lane ending in a vertex repeated by the junction lane, which bends 23 degrees 4.97 m on
    and repeats the vertex 0.17 m after the bend, then turns on in 4 m chords (Town02's shapes
    where a lane meets a junction lane)."""
    heading = np.radians([0.0, 0.0, 0.0, 23.0, 23.0, 23.0, 51.0, 74.0, 82.0])
    length = np.array([20.0, 0.0, 4.97, 0.17, 0.0, 3.93, 4.1, 4.97, 20.0])
    steps = length[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


def test_round_corners_min_spacing_spreads_a_kink_next_to_a_short_segment():
    xy = _lane_joint()
    sharp = Path(round_corners(xy, 3), max_spacing=1.0)
    merged = Path(round_corners(xy, 3, min_spacing=1.0), max_spacing=1.0)
    assert np.abs(sharp.kappa).max() > 1.0  # a radius under 1 m where the corner has ~8 m
    assert np.abs(merged.kappa).max() < 0.3
    np.testing.assert_allclose(merged.xy[[0, -1]], xy[[0, -1]])
    _, e, _, _ = Path(xy, max_spacing=0.2).project(merged.xy, np.zeros(len(merged.xy)))
    assert np.abs(e).max() < 0.5  # still on the lane
    with pytest.raises(ValueError):
        round_corners(xy, 3, min_spacing=-1.0)
