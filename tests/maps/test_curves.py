"""Curve speeds: what a lane's bends allow at 4 m/s² over a second of driving, and the measure of it."""

from __future__ import annotations

import numpy as np
import pytest

from hbmp_bench.maps.curves import LATERAL_ACCEL_MAX_MPS2, curve_speed
from hbmp_bench.metrics.episode import LateralAcceleration


def _arc(radius: float, angle: float, n: int = 60) -> np.ndarray:
    t = np.linspace(0.0, angle, n)
    return np.stack([radius * np.sin(t), radius * (1 - np.cos(t))], axis=1)


@pytest.mark.parametrize("radius", [5.0, 8.0, 20.0, 40.0])
def test_a_long_bend_gets_the_speed_of_its_radius(radius):
    v = curve_speed(_arc(radius, np.pi, 600), 13.89)  # finely drawn: a polyline's vertices turn in steps
    # within two of the search's 0.1 m/s steps: the window is measured in 0.25 m of arc
    assert v == pytest.approx(min(np.sqrt(LATERAL_ACCEL_MAX_MPS2 * radius), 13.89), abs=0.2)
    assert v <= np.sqrt(LATERAL_ACCEL_MAX_MPS2 * radius) + 1e-9  # never above what the bend allows


def test_a_straight_keeps_its_limit_and_a_short_kink_costs_little():
    assert curve_speed(np.array([[0.0, 0.0], [100.0, 0.0]]), 13.89) == 13.89
    kink = np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 2.0]])  # 2.3 degrees
    assert curve_speed(kink, 13.89) == 13.89
    assert curve_speed(_arc(8.0, np.pi / 2), 3.0) == 3.0  # below the bend's speed already


def test_the_measure_and_the_limit_agree():
    """A car at a bend's curve speed shows at most the limit in the records' measure (speed x yaw rate, 1 s)."""
    shape = _arc(10.0, np.pi / 2, 200)
    v = curve_speed(shape, 13.89)
    meter = LateralAcceleration()
    seg = np.hypot(*np.diff(shape, axis=0).T)
    heading = np.unwrap(np.arctan2(*np.diff(shape, axis=0).T[::-1]))
    t = np.concatenate([[0.0], np.cumsum(seg / v)])
    for k in range(len(heading)):
        meter.add(t[k + 1], v, heading[k])
    assert LATERAL_ACCEL_MAX_MPS2 - 0.3 < meter.peak_mps2 <= LATERAL_ACCEL_MAX_MPS2 + 0.05
