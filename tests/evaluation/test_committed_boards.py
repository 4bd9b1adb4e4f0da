"""An auditor's checks on the committed leaderboards (``leaderboards/<suite>/*.json``): every entry
names the code that ran and the weights it measured, and each entry of a shipped learned agent
measured the checkpoint that ships (a retrained ``hbmp.pt`` must come with new board entries)."""

import json
from pathlib import Path

import pytest

from hbmp_bench.agents.learned import TRAIN_COMMANDS, checkpoint_fingerprint, shipped_checkpoint

BOARDS = Path(__file__).resolve().parents[2] / "leaderboards"


def _entries(pattern: str = "*.json") -> dict[str, dict]:
    return {str(p.relative_to(BOARDS)): json.loads(p.read_text(encoding="utf-8"))
            for p in sorted(BOARDS.glob(f"*/{pattern}"))}


def test_every_committed_entry_names_its_code_and_weights():
    entries = _entries()
    assert len(entries) >= 25  # 5 boards, the expert and the four learned agents on each
    for name, doc in entries.items():
        prov = doc["provenance"]
        assert len(prov["code_fingerprint"]) == 16 and len(prov["git_commit"]) == 40, name
        learned = doc["agent"] in TRAIN_COMMANDS
        assert (len(prov["agent_fingerprint"]) == 16) == learned, (name, prov["agent_fingerprint"])


@pytest.mark.parametrize("agent", sorted(TRAIN_COMMANDS))
def test_each_board_measured_the_checkpoint_that_ships(agent):
    shipped = checkpoint_fingerprint(shipped_checkpoint(agent))
    measured = {name: doc["provenance"]["agent_fingerprint"] for name, doc in _entries(f"{agent}.*.json").items()}
    assert len(measured) >= 5, measured  # one entry per board at least
    assert set(measured.values()) == {shipped}, (shipped, measured)
