"""The evaluation of multi-agent suites: one task is one scene (every goal-directed vehicle of an episode,
driven by one policy), its records one per vehicle; the channel carries every deciding vehicle's action
in one reply; resume, results checks, reports and the board count each vehicle of each scene exactly once.

The end-to-end tests run ``tiny_scene`` (three vehicles on short Town01 routes, event fidelity) through SUMO.
"""

import copy
import dataclasses
import json
import struct

import pytest
from gymnasium import spaces

import tiny_scene
from hbmp_bench.evaluation import EpisodePool, RunnerLimits, evaluate, suite_tasks
from hbmp_bench.evaluation import channel
from hbmp_bench.evaluation.env_process import _SceneActions, agent_view
from hbmp_bench.evaluation.evaluate import episode_records, finished_episodes
from hbmp_bench.evaluation.leaderboard import add_results, render_readme, results_document, write_json
from hbmp_bench.evaluation.results_check import verify_results
from hbmp_bench.evaluation.tasks import scene_vehicles, vehicle_episode
from hbmp_bench.metrics.records import AGENT_ERROR, SIM_ERROR
from hbmp_bench.metrics.report import build_report, records_frame
from hbmp_bench.metrics.results_file import ForgedResultsError
from hbmp_bench.scenarios import get_suite, suite_episodes

SCENE = RunnerLimits(env_factory=tiny_scene.FACTORY, trust_agent=True)


# ------------------------------------------------------------------------------------------ no simulation


def test_a_suite_names_the_vehicles_of_its_records():
    assert scene_vehicles("corl2017") == ("",)
    assert scene_vehicles("multi") == ("ego", *(f"ego{k}" for k in range(1, 8)))
    episode = suite_episodes("multi", "Town02", "NavigationDynamic")[3]
    assert vehicle_episode(episode, "ego").start_lane == episode.start_lane
    assert vehicle_episode(episode, "ego5") == episode.others[4]
    with pytest.raises(KeyError, match="ego8"):
        vehicle_episode(episode, "ego8")
    assert all(t.scene and t.vehicles == scene_vehicles("multi") for t in suite_tasks("multi", "expert"))
    assert len(suite_tasks("multi", "expert")) == 25  # one task per scene, not per vehicle


def test_a_scene_reply_is_data_that_names_each_vehicle_once():
    frame = channel.encode_actions({"ego": 4, "ego1": 0, "ego3": (0.5, -0.25)}, 7)
    reply = channel.decode_reply(frame)
    assert (reply.kind, reply.request) == (channel.ACTIONS, 7)
    assert reply.value == {"ego": 4, "ego1": 0, "ego3": (0.5, -0.25)}

    def crafted(body: bytes) -> bytes:
        return b"M" + struct.pack("<I", 1) + body

    for body in (b'{"ego": 4, "ego": 2}', b'{"ego": true}', b'{"../x": 1}', b'[4]', b'{}', b'{"ego": NaN}',
                 b'{"ego": [1e400]}', b'{"ego": 99999999999999999999999}', b'{"ego": "4"}', b'\xff'):
        with pytest.raises(channel.ProtocolError):
            channel.decode_reply(crafted(body))
    for bad in ({"ego": True}, {f"v{k}": 1 for k in range(channel.MAX_VEHICLES + 1)}, {"a b": 1}, {}, [4]):
        with pytest.raises(ValueError):
            channel.encode_actions(bad, 1)


class _Scene:
    vehicle_action_space = spaces.Discrete(5)


def test_the_env_takes_exactly_one_action_per_deciding_vehicle():
    check = _SceneActions(_Scene())
    check.observed({"ego": None, "ego2": None})
    assert check({"ego2": 1, "ego": 4}, 3) == {"ego": 4, "ego2": 1}
    with pytest.raises(ValueError, match="not deciding: \\['ego1'\\]"):
        check({"ego": 4, "ego2": 1, "ego1": 4}, 3)  # acting for a vehicle that does not decide now
    with pytest.raises(ValueError, match="left out: \\['ego2'\\]"):
        check({"ego": 4}, 3)
    with pytest.raises(ValueError, match="invalid action of ego2"):
        check({"ego": 4, "ego2": 7}, 3)
    with pytest.raises(ValueError, match="a dict"):
        check(4, 3)


def test_a_scene_info_reaches_the_agent_without_the_episode_identity():
    record = {"end_reason": "goal", "episode": 3, "seed": 12345, "route_length_m": 200.0}
    info = {"vehicles": {"ego": {"episode_index": 3, "seed": 12345, "action_mask": [1] * 5},
                         "ego1": {"salt": "ab", "hbmp_record": record}},
            "ended": {"ego2": record}, "seed": 12345}
    view = agent_view(info)
    assert view == {"vehicles": {"ego": {"action_mask": [1] * 5}, "ego1": {}}, "ended": {"ego2": {"end_reason": "goal"}}}
    assert info["ended"]["ego2"]["seed"] == 12345  # the env's own info is left as it was


# ------------------------------------------------------------------------------------------ through SUMO


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Both tiny-scene episodes driven by the expert (event fidelity, two workers)."""
    out = tmp_path_factory.mktemp("scenes")
    result = evaluate(tiny_scene.NAME, "expert", fidelity="event", out_dir=out, workers=2, limits=SCENE,
                      progress=False)
    return out, result


@pytest.mark.slow
def test_a_scene_gives_one_record_per_vehicle_of_its_own_route(scenes):
    out, result = scenes
    assert (result.ran, result.skipped, result.missing, result.sim_errors) == (2, 0, 0, 0)
    assert [(r.episode, r.vehicle) for r in result.records] == [(e, v) for e in (0, 1) for v in ("ego", "ego1", "ego2")]
    for record in result.records:
        reference = vehicle_episode(suite_episodes(tiny_scene.NAME, "Town01", "Straight")[record.episode], record.vehicle)
        assert record.route_length_m == pytest.approx(reference.route_length_m, abs=0.01)
        assert record.agent == "expert" and record.end_reason in ("goal", "collision", "violation", "timeout")
    assert len({r.route_length_m for r in result.records}) == 6  # six vehicles, six routes
    again = evaluate(tiny_scene.NAME, "expert", fidelity="event", out_dir=out, workers=2, limits=SCENE, progress=False)
    assert (again.ran, again.skipped, again.records) == (0, 2, result.records)


@pytest.mark.slow
def test_a_scene_is_resumed_unless_every_vehicle_has_its_record(scenes):
    _, result = scenes
    selection = suite_tasks(tiny_scene.NAME, "expert", fidelity="event")
    records = list(result.records)
    assert finished_episodes(records, selection) == {t.key for t in selection}
    assert finished_episodes(records[:-1], selection) == {selection[0].key}  # episode 1 lost ego2's record
    failed = dataclasses.replace(records[4], end_reason=SIM_ERROR)
    assert finished_episodes([*records, failed], selection) == {selection[0].key}  # a rerun's record wins
    assert finished_episodes([*records, failed, records[4]], selection) == {t.key for t in selection}
    assert [r.vehicle for r in episode_records(records, selection)[selection[1].key]] == ["ego", "ego1", "ego2"]


def _document(result):
    return results_document(tiny_scene.NAME, "expert", result.records, towns=["Town01"], tasks=["Straight"],
                            episodes=[0, 1], fidelity="event", privileged=result.privileged,
                            agent_fingerprint=result.agent_fingerprint)


@pytest.mark.slow
def test_a_results_file_with_a_vehicle_missing_twice_or_claimed_is_refused(scenes):
    _, result = scenes
    doc = _document(result)
    assert doc["complete"] and doc["expected_episodes"] == 6 and doc["summary"]["scenes"] == 2
    verify_results(doc, "scenes", against_suite=True)

    def refused(change, match):
        forged = copy.deepcopy(doc)
        change(forged["episodes"])
        with pytest.raises(ForgedResultsError, match=match):
            verify_results(forged, "forged", against_suite=True)

    refused(lambda rows: rows.pop(2), "missing \\['ego2'\\]")
    refused(lambda rows: rows.append(dict(rows[0])), "more than once")
    refused(lambda rows: rows[1].update(vehicle="ego7"), "not of the scene: \\['ego7'\\]")
    refused(lambda rows: rows[1].update(vehicle=""), "missing \\['ego1'\\]")

    def swap_routes(rows):  # ego1 claims ego2's drive (its record, under its own name)
        rows[1], rows[2] = {**rows[2], "vehicle": "ego1"}, {**rows[1], "vehicle": "ego2"}

    refused(swap_routes, "route length")

    def one_sided(rows):  # ego says it hit ego1, ego1's row does not
        rows[0].update(agent_collisions="ego1", collision_vehicle=1, success=False, end_reason="collision",
                       route_completion=0.5, driving_score=30.0)

    refused(one_sided, "whose row does not name ego")
    refused(lambda rows: rows[0].update(agent_collisions="ego"), "not another vehicle of its scene")


@pytest.mark.slow
def test_a_scene_board_and_report_count_agents_pairs_and_throughput(scenes, tmp_path):
    _, result = scenes
    doc = _document(result)
    for row in doc["episodes"][:2]:  # ego and ego1 of scene 0 collided with each other (both rows say so)
        other = "ego1" if row["vehicle"] == "ego" else "ego"
        row.update(agent_collisions=other, collision_vehicle=1, success=False, end_reason="collision",
                   route_completion=0.5, driving_score=30.0)
    doc = {**doc, **results_document(tiny_scene.NAME, "expert", _records(doc), towns=["Town01"], tasks=["Straight"],
                                     episodes=[0, 1], fidelity="event", privileged=True)}
    summary = doc["summary"]
    assert summary["agent_collision_pairs"] == 1  # one pair, in two rows
    assert summary["agents_in_agent_collision_pct"] == pytest.approx(100 * 2 / 6, abs=0.01)
    arrived = sum(r["success"] for r in doc["episodes"])
    minutes = sum(max(r["duration_s"] for r in doc["episodes"] if r["episode"] == e) for e in (0, 1)) / 60
    assert summary["throughput_per_min"] == pytest.approx(arrived / minutes, abs=1e-3)
    assert summary["agent_success_pct"] == pytest.approx(100 * arrived / 6, abs=0.01)
    assert summary["other_collisions"] == sum(r["collision_vehicle"] + r["collision_pedestrian"] + r["collision_other"]
                                              for r in doc["episodes"]) - 2
    source = tmp_path / "entry.json"
    write_json(source, doc)
    installed = add_results(source, tmp_path / "board")
    readme = render_readme(tmp_path / "board", tiny_scene.NAME).read_text()
    assert "agents in agent collision %" in readme and "arrived / min" in readme and "## Per town" in readme
    assert json.loads(installed.read_text())["aggregates"]["multi_by_town"]["Town01"]["agent_collision_pairs"] == 1
    view = build_report(records_frame(_records(doc))).views["multi"]
    assert view.loc[("expert", "all"), "agent_collision_pairs"] == 1
    assert view.loc[("expert", "Town01"), "agents"] == 6
    per_scene = build_report(records_frame(_records(doc))).views["multi_scenes"]
    assert list(per_scene["agents"]) == [3, 3]
    forged = json.loads(installed.read_text())
    forged["aggregates"]["multi_by_town"]["Town01"]["agent_success_pct"] = 100.0
    write_json(source, forged)
    with pytest.raises(ForgedResultsError, match="multi_by_town"):
        add_results(source, tmp_path / "board")


def _records(doc):
    from hbmp_bench.metrics.results_file import results_records

    return results_records(doc)


@pytest.mark.slow
@pytest.mark.parametrize("agent, message", [("ActsForAnotherAgent", "not deciding"),
                                            ("LeavesOneOutAgent", "left out")])
def test_an_agent_cannot_act_for_a_vehicle_it_was_not_asked_for(agent, message):
    tasks = suite_tasks(tiny_scene.NAME, f"scene_agents:{agent}", episodes=[0], fidelity="event")
    with EpisodePool(1, SCENE) as pool:
        (outcome,) = list(pool.imap(tasks))
    assert [r.vehicle for r in outcome.records] == ["ego", "ego1", "ego2"]
    for record in outcome.records:  # the whole scene is the agent's failure
        assert record.end_reason == AGENT_ERROR and not record.success and record.driving_score == 0.0
        assert message in record.error


@pytest.mark.slow
def test_a_batching_agent_drives_a_salted_scene(tmp_path):
    result = evaluate(tiny_scene.NAME, "scene_agents:HonestBatchedAgent", episodes=[0], fidelity="event",
                      out_dir=tmp_path, workers=1, limits=SCENE, progress=False, salted=True)
    assert [r.vehicle for r in result.records] == ["ego", "ego1", "ego2"]
    assert all(r.end_reason != AGENT_ERROR for r in result.records), [r.error for r in result.records]
    assert result.salt and result.salt_commitment
    doc = results_document(tiny_scene.NAME, "scene_agents:HonestBatchedAgent", result.records, towns=["Town01"],
                           tasks=["Straight"], episodes=[0], fidelity="event", privileged=result.privileged,
                           salt_commitment=result.salt_commitment, salt=result.salt)
    verify_results(doc, "salted", against_suite=True)


def test_the_multi_suite_holds_eight_vehicles_per_scene():
    spec = get_suite("multi")
    assert spec.agents == 8 and spec.tasks == ("NavigationDynamic",)
    assert all(len(e.agents) == 8 for town in spec.towns for e in suite_episodes("multi", town, "NavigationDynamic"))


@pytest.mark.slow
def test_an_audit_replays_a_whole_scene_and_finds_a_changed_vehicle(scenes, tmp_path):
    from hbmp_bench.evaluation.audit import audit

    _, result = scenes
    doc = _document(result)
    path = write_json(tmp_path / "expert.event.json", doc)
    honest = audit(path, "expert", 1, seed=1, limits=SCENE)
    assert honest.ok, honest.lines()
    assert sorted(e.key[3] for e in honest.episodes) == ["ego", "ego1", "ego2"]  # one scene, every vehicle
    scene = honest.episodes[0].key[2]
    for row in doc["episodes"]:
        if row["episode"] == scene and row["vehicle"] == "ego2":
            row["decisions"] += 1  # a claim the replay contradicts (no other check sees it)
    doc = {**doc, **results_document(tiny_scene.NAME, "expert", _records(doc), towns=["Town01"], tasks=["Straight"],
                                     episodes=[0, 1], fidelity="event", privileged=True)}
    changed = audit(write_json(tmp_path / "expert.event.json", doc), "expert", 1, seed=1, limits=SCENE)
    assert not changed.ok
    assert [e.key[3] for e in changed.episodes if e.mismatches] == ["ego2"]
