"""Polyline helpers of the renderer."""

import numpy as np
import pytest

from hbmp_bench.render.geometry import box_corners, dashes, offset_polyline


def test_offset_of_a_bent_line_keeps_its_distance():
    line = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])  # east, then north (a left turn)
    left = offset_polyline(line, 1.0)
    np.testing.assert_allclose(left[0], [0.0, 1.0])
    np.testing.assert_allclose(left[1], [9.0, 1.0])  # miter corner inside the turn
    np.testing.assert_allclose(left[2], [9.0, 10.0])
    np.testing.assert_allclose(offset_polyline(line, -2.0)[1], [12.0, -2.0])


def test_dashes_cover_the_on_lengths():
    line = np.array([[0.0, 0.0], [20.0, 0.0]])
    pieces = dashes(line, 3.0, 2.0)
    assert len(pieces) == 4
    np.testing.assert_allclose([p[0, 0] for p in pieces], [0.0, 5.0, 10.0, 15.0])
    np.testing.assert_allclose([p[-1, 0] for p in pieces], [3.0, 8.0, 13.0, 18.0])
    with pytest.raises(ValueError):
        dashes(line, 0.0, 1.0)


def test_box_corners_are_oriented():
    corners = box_corners([[1.0, 2.0]], [np.pi / 2], [4.0], [2.0])[0]
    # heading north: front-left is north-west of the centre
    np.testing.assert_allclose(corners, [[0.0, 4.0], [2.0, 4.0], [2.0, 0.0], [0.0, 0.0]], atol=1e-12)
