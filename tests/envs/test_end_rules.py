"""When a vehicle's episode ends and with which reason: a violation the rules end at outranks a goal reached in
the same step, so a success under the paper's protocol has none (the boards' results check refuses one that
has)."""

from types import SimpleNamespace

import pytest

from hbmp_bench.envs.vehicle import ControlledVehicle, EndRules
from hbmp_bench.evaluation.results_check import record_problems
from hbmp_bench.metrics.detectors import StepEvents

PAPER = EndRules(on_collision=True, on_violation=True)
NOCRASH = EndRules(on_collision=True, on_violation=False)
CORL2017 = EndRules(on_collision=False, on_violation=False)


def _end(rules: EndRules, ev: StepEvents) -> str:
    vehicle = SimpleNamespace(rules=rules, end_reason="")
    ControlledVehicle.judge(vehicle, ev)
    return vehicle.end_reason


@pytest.mark.parametrize("rules, ev, reason", [
    (PAPER, StepEvents(goal_reached=True), "goal"),
    (PAPER, StepEvents(goal_reached=True, off_road=1), "violation"),
    (PAPER, StepEvents(goal_reached=True, red_light=1), "violation"),
    (PAPER, StepEvents(goal_reached=True, collision_vehicle=1), "collision"),
    (NOCRASH, StepEvents(goal_reached=True, collision_pedestrian=1), "collision"),
    (NOCRASH, StepEvents(goal_reached=True, wrong_lane=1), "goal"),
    (CORL2017, StepEvents(goal_reached=True, collision_vehicle=1, off_road=1), "goal"),
    (PAPER, StepEvents(timeout=True, wrong_lane=1), "violation"),
    (CORL2017, StepEvents(timeout=True, wrong_lane=1), "timeout"),
])
def test_an_ending_violation_outranks_the_goal_of_the_same_step(rules, ev, reason):
    assert _end(rules, ev) == reason


def test_the_flat_episode_that_crossed_its_goal_leaving_the_road_is_a_violation():
    """The shipped `flat` on the hbmp suite, Town01 Straight episode 8: it leaves the road in the step it
    reaches its goal; the record is a violation, which the results check accepts."""
    from hbmp_bench.evaluation import Job, RunnerLimits, run_jobs

    [record] = run_jobs([Job("hbmp", "Town01", "Straight", "flat", (8,), "continuous")], workers=1,
                        limits=RunnerLimits(trust_agent=True))
    row = record.to_dict()
    assert row["off_road"] >= 1 and row["route_completion"] > 0.9, row
    assert row["end_reason"] == "violation" and not row["success"], row
    assert record_problems(row, end_on_violation=True, end_on_collision=True) == []
