"""hbmp-val: the training town's validation episodes are not the test suites' episodes."""

import dataclasses

from hbmp_bench.scenarios import get_suite, suite_episodes
from hbmp_bench.scenarios.suites import SUITES, episode_list


def test_validation_episodes_are_held_out_from_every_test_suite():
    val = get_suite("hbmp-val")
    assert val.towns == ("Town03",) and val.end_on_violation
    hbmp = get_suite("hbmp")
    assert (val.timeout_speed_kmh, val.timeout_extra_s) == (hbmp.timeout_speed_kmh, hbmp.timeout_extra_s)
    for task in val.tasks:
        held = {(e.start_lane, round(e.start_pos, 1), e.goal_lane, round(e.goal_pos, 1))
                for e in suite_episodes("hbmp-val", "Town03", task)}
        assert len(held) == val.episodes_per_task
        for suite in ("hbmp", "corl2017", "nocrash-regular"):
            if task not in get_suite(suite).tasks:
                continue
            test = {(e.start_lane, round(e.start_pos, 1), e.goal_lane, round(e.goal_pos, 1))
                    for e in suite_episodes(suite, "Town03", task)}
            assert not held & test, f"hbmp-val {task} shares episodes with {suite}"


def test_the_first_20_validation_episodes_are_those_of_the_20_episode_suite(monkeypatch):
    """hbmp-val grew from 20 to 50 episodes per task; runs validate on the first 20 by default, which must be
    the episodes every earlier validation.csv was measured on (each episode draws from its own generator)."""
    short = dataclasses.replace(get_suite("hbmp-val"), episodes_per_task=20)
    monkeypatch.setitem(SUITES, "hbmp-val", short)
    before = [e for task in short.tasks for e in episode_list("hbmp-val", "Town03", task)]
    monkeypatch.undo()
    now = {task: episode_list("hbmp-val", "Town03", task) for task in short.tasks}
    assert all(len(eps) == 50 for eps in now.values())
    assert before == [e for task in short.tasks for e in now[task][:20]]
