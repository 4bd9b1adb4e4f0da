"""A resumed evaluation never mixes two checkpoints under one agent name."""

import pytest

from hbmp_bench.agents.learned import LearnedAgent, shipped_checkpoint
from hbmp_bench.evaluation.evaluate import check_agent_fingerprint


def test_learned_agents_are_fingerprinted_by_their_weights():
    il, hbmp = LearnedAgent(shipped_checkpoint("il")), LearnedAgent(shipped_checkpoint("hbmp"))
    assert len(il.fingerprint) == 16 and il.fingerprint != hbmp.fingerprint
    assert LearnedAgent(shipped_checkpoint("il")).fingerprint == il.fingerprint


def test_resuming_with_other_weights_is_refused(tmp_path):
    records = tmp_path / "corl2017__hbmp.jsonl"
    check_agent_fingerprint(records, "hbmp", "aaaa")  # a new evaluation: the weights are noted
    records.write_text('{"episode": 0}\n')
    check_agent_fingerprint(records, "hbmp", "aaaa")  # same weights: resume
    with pytest.raises(ValueError, match="another 'hbmp'.*--out"):
        check_agent_fingerprint(records, "hbmp", "bbbb")
    assert (tmp_path / "corl2017__hbmp.jsonl.agent").read_text().strip() == "aaaa"


def test_agents_without_weights_are_not_checked(tmp_path):
    records = tmp_path / "corl2017__expert.jsonl"
    check_agent_fingerprint(records, "expert", "")
    assert not (tmp_path / "corl2017__expert.jsonl.agent").exists()
