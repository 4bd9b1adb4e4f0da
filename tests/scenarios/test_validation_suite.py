"""hbmp-val: the training town's validation episodes are not the test suites' episodes."""

from hbmp_bench.scenarios import get_suite, suite_episodes


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
