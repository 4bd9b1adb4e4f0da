"""The expert's seeded episodes give the records and decision digests stored in ``golden/records.json``
(written by ``golden_records.py --write``): a refactor keeps behaviour, step for step, in both fidelities,
single-ego and multi-agent. They were stored before the envs redesign, which kept them; they are rewritten
only for a deliberate change of behaviour, named in its commit (last: the planner's full brake when no sample is collision-free,
``PlannerConfig.infeasible_fallback="brake"``: the single-ego Town01 case ends 0.1 s later, 0.75 m shorter, and
the multi-agent cases by 2-8 m of route; before it the planner leaves the ego's followers out of
its collision check, ``PlannerConfig.ignore_followers``: the 4-vehicle Town02 case drives 8 decisions further, 0.918
of its route instead of 0.857, before its step cap; before it λ's scale 0.25, rewards only; before it the
towns' smoother junction lanes and 2 m crossings, episode rules 11: route lengths moved by ~0.1 m and a
multi-agent case by a few decisions)."""

import json

import pytest

from golden_records import GOLDEN, case_names, run_case

EXPECTED = json.loads(GOLDEN.read_text())


def test_every_case_has_a_golden_entry():
    assert sorted(EXPECTED) == sorted(case_names())


@pytest.mark.slow
@pytest.mark.parametrize("name", case_names())
def test_expert_episode_is_unchanged(name):
    got = run_case(name)
    assert got["record"] == EXPECTED[name]["record"]
    assert got["digest"] == EXPECTED[name]["digest"]
