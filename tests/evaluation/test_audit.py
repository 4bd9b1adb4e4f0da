"""Audit by replay (``hbmp-bench leaderboard audit``): episodes are deterministic given their seed (and
salt), so replaying a sample of an entry's episodes with the named agent gives its records again,
field for field; a forged entry that ``add`` cannot tell from a genuine one fails it.

The committed boards' expert entries are audited here on a small sample of short event-fidelity
episodes (a few seconds), so CI audits every change of the package against them.
"""

import json
from pathlib import Path

import pytest

from hbmp_bench.cli import main
from hbmp_bench.evaluation.audit import audit, compare, draw
from hbmp_bench.evaluation.leaderboard import results_document
from hbmp_bench.metrics.records import EpisodeRecord

pytestmark = pytest.mark.slow

BOARDS = Path(__file__).resolve().parents[2] / "leaderboards"
SHORT_S = 10.0
"""Audit only episodes of at most this many simulated seconds [s] (Town02 Straight ones, about 1 s each)."""


def committed(path: str) -> dict:
    return json.loads((BOARDS / path).read_text(encoding="utf-8"))


def rewritten(doc: dict, rows: list[dict], tmp_path: Path, **changes) -> Path:
    """``doc`` with ``rows`` as its episodes, every figure recomputed (a self-consistent forgery), saved."""
    shared = {"suite": doc["suite"], "agent": doc["agent"], "fidelity": doc["fidelity"], "package_version": "0.1.0"}
    sel = doc["selection"]
    fresh = results_document(doc["suite"], doc["agent"], [EpisodeRecord(**r, **shared) for r in rows],
                             towns=sel["towns"], tasks=sel["tasks"], episodes=sel["episodes"], fidelity=doc["fidelity"],
                             privileged=doc["privileged"], agent_fingerprint=doc["provenance"]["agent_fingerprint"])
    path = tmp_path / "entry.json"
    path.write_text(json.dumps({**fresh, "provenance": doc["provenance"], "salted": False, **changes}))
    return path


@pytest.mark.parametrize("entry", ["hbmp/expert.event.json", "corl2017/expert.event.json"])
def test_the_committed_expert_entries_replay_to_their_records(entry):
    result = audit(BOARDS / entry, "expert", 1, seed=0, max_sim_s=SHORT_S)
    assert len(result.episodes) == 1 and result.ok, "\n".join(result.lines())


def test_an_entry_claimed_by_another_agent_fails_its_audit(tmp_path, capsys):
    """The expert's records under the name of an agent that sees M_t and R_t only (``keep``,
    unprivileged, no checkpoint): consistent, so ``add`` takes it; its replay does not."""
    doc = committed("hbmp/expert.event.json")
    path = rewritten(doc, doc["episodes"], tmp_path, agent="keep", privileged=False)
    assert main(["leaderboard", "audit", str(path), "--agent", "keep", "--sample", "1", "--seed", "0",
                 "--max-sim-s", str(SHORT_S), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    (episode,) = report["episodes"]
    assert not report["ok"] and episode["mismatches"]["success"] == [True, False]
    assert episode["mismatches"]["end_reason"][0] == "goal"


def test_an_edited_record_is_reported_field_by_field(tmp_path):
    doc = committed("corl2017/expert.event.json")
    rows = [{**e, "decisions": e["decisions"] - 1} for e in doc["episodes"]]  # every episode, so any draw finds one
    result = audit(rewritten(doc, rows, tmp_path), "expert", 1, seed=3, max_sim_s=SHORT_S)
    (episode,) = result.episodes
    assert not result.ok and list(episode.mismatches) == ["decisions"]
    recorded, replayed = episode.mismatches["decisions"]
    assert replayed == recorded + 1
    assert any("MISMATCH" in line for line in result.lines())


def test_a_dropped_privileged_flag_fails_the_audit(tmp_path):
    doc = committed("hbmp/expert.event.json")
    result = audit(rewritten(doc, doc["episodes"], tmp_path, privileged=False), "expert", 1, seed=0, max_sim_s=SHORT_S)
    assert result.claims == {"privileged": (False, True)} and not result.ok
    assert all(not e.mismatches for e in result.episodes)  # the records themselves are the expert's


def test_the_draw_is_random_and_repeatable_with_a_seed():
    doc = committed("hbmp/expert.event.json")
    short = [e for e in doc["episodes"] if e["duration_s"] <= SHORT_S]
    assert draw(doc, 3, seed=5, max_sim_s=SHORT_S) == draw(doc, 3, seed=5, max_sim_s=SHORT_S)
    assert all(e in short for e in draw(doc, 3, max_sim_s=SHORT_S))
    assert len({json.dumps(draw(doc, 1)[0]) for _ in range(20)}) > 1
    assert compare(short[0], {**short[0], "distance_m": short[0]["distance_m"] + 0.01}) == \
        {"distance_m": (short[0]["distance_m"], short[0]["distance_m"] + 0.01)}
    with pytest.raises(ValueError, match="sample must be >= 1"):
        draw(doc, 0)
