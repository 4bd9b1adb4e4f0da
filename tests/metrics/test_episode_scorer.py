"""The episode scorer shared by the SUMO envs and the highway-env transfer env."""

import numpy as np
import pytest

from hbmp_bench.metrics.episode import TERMINAL_REWARD, EpisodeId, EpisodeScorer, events_reward, terminal_reward
from hbmp_bench.metrics.detectors import StepEvents


def test_terminal_reward_is_the_papers():
    assert terminal_reward(goal=True) == 100.0
    assert terminal_reward(collisions=2, timed_out=True) == 2 * -50.0 - 50.0
    assert terminal_reward(red_light=1, wrong_lane=1, off_road=1) == -10.0 - 1.0 - 1.0
    assert events_reward(StepEvents(collision_pedestrian=1, red_light=1)) == TERMINAL_REWARD["collision"] - 10.0


def test_progress_is_monotone_capped_and_ignores_readings_past_the_slack():
    score = EpisodeScorer(100.0, np.zeros(2))
    score.progressed_to(40.0)
    score.progressed_to(30.0)  # backwards: kept at 40
    assert score.progress_m == 40.0
    score.progressed_to(106.0)  # past length + 5 m: a mismatch, ignored
    assert score.progress_m == 40.0
    score.progressed_to(103.0)  # within the slack: capped at the length
    assert score.progress_m == 100.0 and score.completion(False) == 1.0
    assert EpisodeScorer(100.0, np.zeros(2)).completion(True) == 1.0


def test_distance_and_record():
    score = EpisodeScorer(50.0, np.array([0.0, 0.0]))
    score.moved_to(np.array([3.0, 4.0]))
    score.moved_to(np.array([3.0, 10.0]))
    score.progressed_to(25.0)
    record = score.record(EpisodeId("corl2017", "Town01", "Straight", 3, 7, "event", 50.0), agent="a",
                          package_version="0", totals={"red_light": 1}, success=False, end_reason="timeout",
                          duration_s=12.345, decisions=9)
    assert record.distance_m == 11.0 and record.route_completion == 0.5 and record.timeout
    assert record.red_light == 1 and record.collision_vehicle == 0 and record.duration_s == 12.35
    assert record.driving_score == pytest.approx(50.0 * 0.7)
