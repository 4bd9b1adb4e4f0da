"""The shared names agree with the classes that carry them."""

import dataclasses

from hbmp_bench import vocabulary
from hbmp_bench.metrics.detectors import StepEvents
from hbmp_bench.metrics.records import EpisodeRecord
from hbmp_bench.planning.behaviors import Behavior


def test_behaviors_are_the_enums_in_its_order():
    assert tuple(b.name.lower() for b in Behavior) == vocabulary.BEHAVIORS
    assert vocabulary.NUM_BEHAVIORS == len(Behavior) == 5


def test_every_infraction_kind_is_a_record_count_and_every_detected_kind_a_step_event():
    record = [f.name for f in dataclasses.fields(EpisodeRecord)]
    assert [k for k in record if k in vocabulary.INFRACTION_KINDS] == list(vocabulary.INFRACTION_KINDS)
    assert set(vocabulary.DETECTED_KINDS) <= {f.name for f in dataclasses.fields(StepEvents)}
    assert set(vocabulary.INFRACTION_KINDS) == set(vocabulary.COLLISION_KINDS) | set(vocabulary.VIOLATION_KINDS)


def test_modes():
    assert vocabulary.DEFAULT_FIDELITY in vocabulary.FIDELITIES
    assert set(vocabulary.REWARD_MODES) < set(vocabulary.TRAINING_REWARD_MODES)
