"""Forged results files against ``leaderboard add`` and the board's README (issue 41, finding 4, and
attacks of our own): every claim of a results file is recomputed from its episodes and its suite,
and a file that does not add up is refused with the reason, writing nothing.

The genuine files forged here are committed board entries (real runs), so no episode is simulated.
"""

import copy
import hashlib
import json
import shutil
from pathlib import Path

import pytest

from hbmp_bench.agents.learned import checkpoint_fingerprint, shipped_checkpoint
from hbmp_bench.cli import main
from hbmp_bench.evaluation.leaderboard import (add_results, entry_path, load_entries, render_readme, results_document,
                                               write_json)
from hbmp_bench.evaluation.results_check import ForgedResultsError, verify_results
from hbmp_bench.metrics.records import EpisodeRecord
from hbmp_bench.metrics.results_file import episode_columns

BOARDS = Path(__file__).resolve().parents[2] / "leaderboards"
SUITE = "hbmp"


def genuine(name: str) -> dict:
    """A committed entry of the hbmp board (``expert.event``, ``il.continuous`` ...)."""
    return json.loads((BOARDS / SUITE / f"{name}.json").read_text(encoding="utf-8"))


@pytest.fixture
def board(tmp_path):
    """A board holding two genuine hbmp entries (hbmp and il, continuous fidelity)."""
    root = tmp_path / "board"
    (root / SUITE).mkdir(parents=True)
    for name in ("hbmp.continuous", "il.continuous"):
        shutil.copy(BOARDS / SUITE / f"{name}.json", root / SUITE / f"{name}.json")
    render_readme(root, SUITE)
    return root


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def refused(doc: dict, board: Path, tmp_path: Path, match: str) -> str:
    """Add ``doc`` to ``board``: it must be refused (message matching ``match``), by the function
    and by the CLI (exit 2), and nothing under ``tmp_path`` may change."""
    source = tmp_path / "forged.json"
    source.write_text(json.dumps(doc), encoding="utf-8")
    before = snapshot(tmp_path)
    with pytest.raises(ValueError, match=match) as caught:
        add_results(source, board)
    assert main(["leaderboard", "add", str(source), "--board-dir", str(board)]) == 2
    assert snapshot(tmp_path) == before, "a refused file changed the board"
    return str(caught.value)


def rescored(doc: dict, rows: list[dict]) -> dict:
    """``doc`` with ``rows`` as its episodes and every figure recomputed from them the way
    ``submit`` computes it: a forger who keeps the file self-consistent."""
    shared = {"suite": doc["suite"], "agent": doc["agent"], "fidelity": doc["fidelity"], "package_version": "0.1.0"}
    records = [EpisodeRecord(**row, **shared) for row in rows]
    sel = doc["selection"]
    fresh = results_document(doc["suite"], doc["agent"], records, towns=sel["towns"], tasks=sel["tasks"],
                             episodes=sel["episodes"], fidelity=doc["fidelity"], privileged=doc["privileged"],
                             agent_fingerprint=doc["provenance"]["agent_fingerprint"])
    return {**fresh, "provenance": doc["provenance"]}


def test_a_genuine_entry_is_added_and_its_aggregates_recomputed(board, tmp_path):
    doc = genuine("expert.event")
    doc["aggregates"]["failures"] = [{"forged": 1}]  # a stale or edited report view is replaced, not trusted
    source = tmp_path / "expert.event.json"
    source.write_text(json.dumps(doc))
    target = add_results(source, board)
    installed = json.loads(target.read_text())
    assert installed["aggregates"]["failures"] != [{"forged": 1}]
    assert installed["summary"] == genuine("expert.event")["summary"]
    assert [e["agent"] for e in load_entries(board, SUITE)] == ["expert", "hbmp", "il"]


def test_a_hand_edited_results_file_is_not_ranked(board, tmp_path):
    """Issue 41 #4: the expert's entry renamed, ``privileged`` false and ``success_pct`` 100."""
    doc = genuine("expert.continuous")
    doc.update(agent="champion.agents:Champion", privileged=False)
    doc["summary"]["success_pct"] = 100.0
    refused(doc, board, tmp_path, "summary.success_pct=100.0, its episodes give 99.38")
    only_pct = genuine("hbmp.continuous")
    only_pct["summary"]["success_pct"] = 99.9
    refused(only_pct, board, tmp_path, "success_pct=99.9")


def test_one_episode_claiming_the_whole_suite_is_refused(board, tmp_path):
    """Issue 41 #4: 1 episode with ``expected_episodes: 1`` and ``summary.episodes: 500`` was ranked
    as "500 of 500"."""
    doc = genuine("il.continuous")
    doc["episodes"] = doc["episodes"][:1]
    doc.update(expected_episodes=1, complete=True)
    doc["summary"]["episodes"] = 500
    message = refused(doc, board, tmp_path, "expected_episodes=1, its episodes give 800")
    assert "summary.episodes=500, its episodes give 1" in message
    # kept self-consistent (every figure over the one episode) it is still no complete entry
    single = rescored(genuine("il.continuous"), genuine("il.continuous")["episodes"][:1])
    single.update(expected_episodes=1, complete=True)
    refused(single, board, tmp_path, "complete=True, its episodes give False")


def test_a_fidelity_cannot_overwrite_another_entry_or_leave_the_board(board, tmp_path):
    """Issue 41 #4: ``continuous/../hbmp.continuous`` overwrote hbmp's entry, ``../../..`` wrote
    outside the board."""
    for fidelity in ("continuous/../hbmp.continuous", "../../../escaped", "continuous\n"):
        doc = genuine("expert.continuous")
        doc["fidelity"] = doc["provenance"]["fidelity"] = fidelity
        refused(doc, board, tmp_path, "fidelity .* is not a valid name")
    assert not list(tmp_path.parent.glob("escaped*")) and not list(tmp_path.glob("escaped*"))
    with pytest.raises(ValueError, match="not a valid name"):
        entry_path(board, SUITE, "expert", False, "../x")
    suite = genuine("expert.continuous")
    suite["suite"] = "../hbmp"
    refused(suite, board, tmp_path, "suite '../hbmp' is not a valid name")


def test_a_fake_fingerprint_is_refused_where_it_can_be_checked(board, tmp_path):
    """Issue 41 #3: an entry may claim any ``agent_fingerprint``, and the board printed it as its
    weights. A registered learned agent's must be its shipped checkpoint's, a registered agent
    without one has none, a checkpoint file that is here must hash to it."""
    doc = genuine("il.continuous")
    doc["provenance"]["agent_fingerprint"] = checkpoint_fingerprint(shipped_checkpoint("hbmp"))
    refused(doc, board, tmp_path, "agent 'il' runs '1b8d1ce7c33e3dc5' \\(its shipped checkpoint\\)")
    expert = genuine("expert.event")
    expert["provenance"]["agent_fingerprint"] = "0123456789abcdef"
    refused(expert, board, tmp_path, "agent 'expert' runs '' \\(no checkpoint\\)")
    weights = tmp_path / "mine.pt"
    shutil.copy(shipped_checkpoint("il"), weights)
    as_file = genuine("il.continuous")
    as_file["agent"] = str(weights.relative_to(tmp_path))
    as_file["provenance"]["agent_fingerprint"] = "fedcba9876543210"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(tmp_path)
        refused(as_file, board, tmp_path, "mine.pt here hashes to '1b8d1ce7c33e3dc5'")


def test_a_plugin_agents_fingerprint_is_shown_as_its_own_claim(board, tmp_path):
    doc = genuine("il.continuous")
    doc["agent"] = "my_pkg.agents:Driver"
    source = tmp_path / "driver.json"
    source.write_text(json.dumps(doc))
    add_results(source, board)
    row = next(line for line in (board / SUITE / "README.md").read_text().splitlines() if "`my_pkg.agents:Driver`" in line)
    assert "| 1b8d1ce7c3 (claimed) |" in row


def test_the_expert_cannot_drop_its_privileged_flag(board, tmp_path):
    doc = genuine("expert.event")
    doc["privileged"] = False
    refused(doc, board, tmp_path, "privileged=false, but agent 'expert' reads the privileged scene fields")


# --------------------------------------------------------------------------- attacks of our own
def test_an_agent_name_cannot_inject_rows_into_the_readme(board, tmp_path):
    """The agent name went into the README's table as it was: a name holding ``|`` and a newline
    added a row of the forger's choosing, ranked first."""
    doc = genuine("il.continuous")
    doc["agent"] = "x` | no | 0.0 |\n| 1 | `forged-champion` | no | 100.0 | 100.0 | 100.0 | 100.0 | 100.0 |\n| 9 | `y"
    refused(doc, board, tmp_path, "agent .* is not a valid name")
    assert "forged-champion" not in (board / SUITE / "README.md").read_text()


def test_an_agent_name_cannot_take_another_agents_file(board, tmp_path):
    """``hbmp:`` and ``hbmp/`` have the file name of ``hbmp``'s entry: a forged, unprivileged copy of
    the expert's records would have replaced it."""
    for name, match in (("hbmp:", "would replace .*hbmp.continuous.json, the entry of agent 'hbmp'"),
                        ("hbmp/", "agent 'hbmp/' is not a valid name")):
        doc = genuine("il.continuous")
        doc["agent"] = name
        refused(doc, board, tmp_path, match)


def test_a_suite_filled_with_copies_of_one_good_episode_is_refused(board, tmp_path):
    """800 copies of one successful episode, every figure recomputed from them: the counts add up,
    but the suite's episodes are not there."""
    doc = genuine("hbmp-s.continuous")
    best = next(e for e in doc["episodes"] if e["success"])
    forged = rescored(doc, [dict(best) for _ in doc["episodes"]])
    assert forged["complete"] and forged["summary"]["success_pct"] == 100.0  # what the old check let through
    refused(forged, board, tmp_path, "800 episodes appear more than once|appear more than once")


def test_records_that_contradict_themselves_are_refused(board, tmp_path):
    """Failed episodes turned into goals, each file recomputed so its summary agrees: a goal with a
    red light under the paper's protocol, a timeout marked success, an inflated driving score."""
    doc = genuine("hbmp-s.continuous")
    failures = [k for k, e in enumerate(doc["episodes"]) if not e["success"]]
    red = copy.deepcopy(doc["episodes"])
    red[failures[0]].update(success=True, end_reason="goal", timeout=False, route_completion=1.0, red_light=1,
                            driving_score=70.0)
    refused(rescored(doc, red), board, tmp_path, "ends with 'goal' after 0 collisions and 1 violations")
    late = copy.deepcopy(doc["episodes"])
    timeout = next(k for k in failures if late[k]["end_reason"] == "timeout")
    late[timeout]["success"] = True
    refused(rescored(doc, late), board, tmp_path, "success=True with end_reason 'timeout'")
    score = copy.deepcopy(doc["episodes"])
    score[failures[0]]["driving_score"] = 100.0
    refused(rescored(doc, score), board, tmp_path, "route completion and infractions give")


def test_episodes_that_are_not_the_suites_are_refused(board, tmp_path):
    """Another seed or a shorter route than the suite's episode, a duration past its timeout."""
    doc = genuine("il.continuous")
    rows = copy.deepcopy(doc["episodes"])
    rows[0]["seed"] += 1
    rows[1]["route_length_m"] = round(rows[1]["route_length_m"] / 2, 2)
    rows[2]["duration_s"] = 10_000.0
    message = refused(rescored(doc, rows), board, tmp_path, "has seed")
    assert "route length" in message and "past the episode's timeout" in message


def test_non_finite_numbers_are_refused(board, tmp_path):
    """A NaN success % (JSON allows it when read) sorts anywhere; refused when the file is read."""
    source = tmp_path / "nan.json"
    source.write_text(json.dumps(genuine("il.continuous")).replace('"success_pct": 97.38', '"success_pct": NaN'))
    with pytest.raises(ValueError, match="finite numbers only, not NaN"):
        add_results(source, board)


def test_a_forged_file_dropped_into_the_board_stops_the_readme(board):
    """A file written into the board folder by hand (not through ``add``) is checked when the
    README is rendered: a hand-edited success % is never ranked."""
    path = board / SUITE / "il.continuous.json"
    doc = json.loads(path.read_text())
    doc["summary"]["success_pct"] = 100.0
    write_json(path, doc)
    with pytest.raises(ForgedResultsError, match="summary.success_pct=100.0"):
        render_readme(board, SUITE)
    assert main(["leaderboard", "render", "--suite", SUITE, "--board-dir", str(board)]) == 2
    moved = board / SUITE / "expert.continuous.json"  # a genuine entry under another agent's file name
    shutil.copy(BOARDS / SUITE / "il.continuous.json", moved)
    path.unlink()
    with pytest.raises(ForgedResultsError, match="belong in il.continuous.json, not expert.continuous.json"):
        render_readme(board, SUITE)


@pytest.mark.parametrize("name", sorted(str(p.relative_to(BOARDS)) for p in BOARDS.glob("*/*.json")))
def test_every_committed_entry_passes_the_checks_of_add(name):
    doc = json.loads((BOARDS / name).read_text(encoding="utf-8"))
    assert doc["salted"] is False  # made before salted mode: the public episodes
    verify_results(doc, name, against_suite=True)
    assert all(set(e) == set(episode_columns(doc["suite"])) for e in doc["episodes"])  # a scene suite's: + vehicle
    assert hashlib.sha256(b"").hexdigest() not in json.dumps(doc)  # no empty salt's commitment
