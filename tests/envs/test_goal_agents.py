"""Goal-directed agents: every controlled vehicle with its own start, goal, route, record and end
(``Episode.others``, ``ScenarioConfig.agents``, the ``multi`` suite), checked against what SUMO reports."""

import dataclasses

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

from hbmp_bench.agents import load_agent
from hbmp_bench.envs import traffic_v0
from hbmp_bench.envs.config import ScenarioConfig
from hbmp_bench.errors import ConfigError
from hbmp_bench.metrics.records import EpisodeRecord, agent_collision_pairs
from hbmp_bench.scenarios import get_suite, suite_episodes, with_agents
from hbmp_bench.scenarios.suites import AGENT_START_SPACING_M

THREE = dict(town="Town02", task="NavigationDynamic", suite="hbmp", episode_index=0, agents=3, density="empty",
             fidelity="event", controlled="none")


def test_the_multi_suite_holds_eight_goal_directed_vehicles_per_episode():
    suite = get_suite("multi")
    assert suite.agents == 8
    for town in suite.towns:
        for episode in suite_episodes("multi", town, "NavigationDynamic"):
            legs = episode.agents
            assert len(legs) == 8 and legs[0].others == () and legs[0].start_lane == episode.start_lane
            assert all(leg.town == town and leg.index == episode.index and leg.traffic == episode.traffic
                       and leg.end_on_violation for leg in legs)
            assert len({(leg.start_lane, leg.goal_lane, leg.route) for leg in legs}) == 8
            for k, a in enumerate(legs):
                for b in legs[k + 1:]:
                    assert a.start_lane != b.start_lane or abs(a.start_pos - b.start_pos) >= AGENT_START_SPACING_M
            assert all(leg.timeout_s > leg.route_length_m / (5 / 3.6) for leg in legs)


def test_other_vehicles_are_a_pure_function_of_the_episode():
    episode = suite_episodes("hbmp", "Town02", "Navigation")[3]
    assert with_agents(episode, 4, get_suite("hbmp")) == with_agents(episode, 4, get_suite("hbmp"))
    assert with_agents(episode, 4, get_suite("hbmp")).others[:2] == with_agents(episode, 3, get_suite("hbmp")).others
    assert with_agents(episode, 1, get_suite("hbmp")) == episode
    assert ScenarioConfig(**{k: v for k, v in THREE.items() if k in ("town", "task", "suite", "agents")}
                          ).episodes[0].others == with_agents(suite_episodes("hbmp", "Town02", "NavigationDynamic")[0],
                                                              3, get_suite("hbmp")).others


def test_agents_is_checked():
    with pytest.raises(ConfigError, match="agents"):
        ScenarioConfig(agents=0)
    with pytest.raises(ConfigError, match="scenario type"):
        ScenarioConfig(task="HardBrake", suite="scenarios", agents=2)


def _drive(env, seed=0, max_steps=5000):
    """Every agent driven by its own expert; returns the records each agent's info carried at its end,
    and the agents SUMO still had after each agent's end."""
    obs, infos = env.reset(seed=seed)
    experts = {a: load_agent("expert") for a in env.agents}
    for a in env.agents:
        experts[a].reset(infos[a])
    records, in_sumo_after, pending = {}, {}, []
    for _ in range(max_steps):
        actions = {a: experts[a].act(obs[a], infos[a]) for a in env.agents if infos[a]["decision_required"]}
        obs, _, terms, truncs, infos = env.step(actions)
        ids = set(env.world.sim.vehicle_ids())
        in_sumo_after.update({a: a in ids for a in pending})  # one step after its end
        pending = [a for a in infos if terms[a] or truncs[a]]
        records.update({a: infos[a]["hbmp_record"] for a in pending})
        if not env.agents:
            in_sumo_after.update({a: a in ids for a in pending})
            break
    return records, in_sumo_after


@pytest.mark.slow
def test_each_vehicle_ends_on_its_own_and_the_scene_when_all_have():
    env = traffic_v0.parallel_env(**THREE, privileged=True)
    assert env.possible_agents == ["ego", "ego1", "ego2"]
    records, in_sumo_after = _drive(env)
    assert sorted(records) == ["ego", "ego1", "ego2"]
    legs = env.scenario.episodes[0].agents
    for (name, record), leg in zip(sorted(records.items()), legs):
        assert record["vehicle"] == name and record["route_length_m"] == leg.route_length_m
        assert record["success"] and record["end_reason"] == "goal"
    durations = sorted(r["duration_s"] for r in records.values())
    assert durations[0] < durations[-1]  # each ended at its own time
    last = max(records, key=lambda a: records[a]["duration_s"])
    assert env.world.sim.time == pytest.approx(records[last]["duration_s"], abs=0.051)
    # a vehicle that ended while the scene went on left SUMO; the last stays where it ended
    assert not any(in_sumo_after[a] for a in records if a != last) and in_sumo_after[last]
    assert [r.to_dict() for r in env.records()] == [records[a] for a in env.possible_agents]
    env.close()


@pytest.mark.slow
def test_a_single_ego_record_names_no_vehicle():
    env = traffic_v0.parallel_env(**{**THREE, "agents": None}, privileged=True)
    assert env.possible_agents == ["ego"]
    records, _ = _drive(env)
    assert records["ego"]["vehicle"] == "" and records["ego"]["agent_collisions"] == ""
    env.close()


def test_pairs_of_vehicles_that_collided_are_counted_once():
    base = dict(suite="multi", town="Town01", task="NavigationDynamic", seed=1, agent="a", package_version="0",
                fidelity="event", success=False, route_completion=0.5, collision_vehicle=1, collision_pedestrian=0,
                collision_other=0, wrong_lane=0, off_road=0, red_light=0, timeout=False, duration_s=10.0,
                distance_m=5.0, route_length_m=100.0, decisions=10, driving_score=30.0, end_reason="collision")
    records = [EpisodeRecord(**base, episode=0, vehicle="ego", agent_collisions="ego2"),
               EpisodeRecord(**base, episode=0, vehicle="ego2", agent_collisions="ego ego5"),
               EpisodeRecord(**base, episode=0, vehicle="ego5", agent_collisions="ego2"),
               EpisodeRecord(**base, episode=1, vehicle="ego", agent_collisions="ego2"),
               EpisodeRecord(**dict(base, collision_vehicle=0), episode=1, vehicle="ego3", agent_collisions="")]
    pairs = agent_collision_pairs(records)
    assert {p[4:] for p in pairs} == {(0, "ego", "ego2"), (0, "ego2", "ego5"), (1, "ego", "ego2")}


@pytest.mark.slow
def test_vehicles_that_collide_name_each_other():
    """The ego speeds up into a goal-directed vehicle standing 16 m ahead on its lane: both records
    name the other, and the pair counts once."""
    from hbmp_bench.envs.config import WorldConfig
    from hbmp_bench.envs.world import DrivingWorld
    from hbmp_bench.scenarios import Traffic

    ego = next(e for e in suite_episodes("hbmp", "Town02", "Straight") if e.start_pos + 30 < e.route_length_m)
    ego = dataclasses.replace(ego, traffic=Traffic(0, 0))
    ahead = dataclasses.replace(ego, start_pos=ego.start_pos + 16.0)
    world = DrivingWorld("Town02", WorldConfig(fidelity="event"))
    world.start(dataclasses.replace(ego, others=(ahead,)), seed=0)
    records = {}
    for _ in range(300):
        actions = {a: (0 if a == "ego" else 1) for a in world.live if world.needs_decision(a)}
        *_, infos = world.step(actions)
        records.update({a: i["hbmp_record"] for a, i in infos.items() if "hbmp_record" in i})
        if "ego" in records:
            break
    world.close()
    assert records["ego"]["end_reason"] == "collision" and records["ego"]["collision_vehicle"] >= 1
    assert records["ego"]["agent_collisions"] == "ego1" and records["ego1"]["agent_collisions"] == "ego"
    assert len(agent_collision_pairs([EpisodeRecord(**r) for r in records.values()])) == 1


@pytest.mark.slow
def test_pettingzoo_api_and_seed_tests_with_goal_directed_agents():
    config = {**THREE, "density": "regular", "controlled": 2}
    env = traffic_v0.parallel_env(**config)
    assert env.possible_agents == ["ego", "ego1", "ego2", "bg0", "bg1"]
    parallel_api_test(env, num_cycles=40)
    env.close()
    aec = traffic_v0.env(**config)
    api_test(aec, num_cycles=15)
    aec.close()
    parallel_seed_test(lambda: traffic_v0.parallel_env(**config), num_cycles=20)


@pytest.mark.slow
def test_batched_and_one_by_one_decisions_agree():
    """A learned policy's one forward pass for every deciding vehicle gives each vehicle the action its own
    call would (``LearnedAgent.act_batch``)."""
    agent = load_agent("il")
    env = traffic_v0.parallel_env(**{**THREE, "agents": 4, "density": "regular"}, **agent.env_kwargs)
    obs, infos = env.reset(seed=0)
    compared = 0
    for _ in range(30):
        deciding = [a for a in env.agents if infos[a]["decision_required"]]
        batched = agent.act_batch({a: obs[a] for a in deciding}, {a: infos[a] for a in deciding})
        assert batched == {a: agent.act(obs[a], infos[a]) for a in deciding}
        compared += len(deciding)
        obs, _, _, _, infos = env.step(batched)
        if not env.agents:
            break
    assert compared >= 60
    env.close()


@pytest.mark.slow
def test_a_respawned_vehicle_starts_a_new_episode_of_its_own():
    """A vehicle whose episode ended, put back at a new start: SUMO inserts it at the next step, it decides
    again, and its new record counts from its new start."""
    env = traffic_v0.parallel_env(**{**THREE, "agents": 2, "density": "regular"})
    obs, infos = env.reset(seed=0)
    world = env.world
    leg = dataclasses.replace(suite_episodes("hbmp", "Town02", "Straight")[5], others=())
    with pytest.raises(ValueError, match="ended"):
        world.respawn("ego1", leg)  # still driving
    for _ in range(3000):  # ego1 drives on speed_up until its episode ends
        obs, _, terms, truncs, infos = env.step({a: 0 for a in env.agents if infos[a]["decision_required"]})
        if "ego1" not in env.agents:
            break
    first = world.record(vehicle="ego1")
    assert first.end_reason and "ego1" not in world.live
    ended_at = world.sim.time
    assert world.start_is_free(leg)
    world.respawn("ego1", leg)
    *_, infos = world.step({a: 0 for a in world.live if world.needs_decision(a)})
    assert "ego1" in world.live and infos["ego1"]["decision_required"]
    assert world.vehicles["ego1"].route.episode == leg
    assert world.vehicles["ego1"].state.lane == leg.start_lane
    assert world.record(vehicle="ego1").end_reason == "running"
    assert world.record(vehicle="ego1").duration_s == pytest.approx(0.0, abs=0.051)
    assert world.sim.time == pytest.approx(ended_at + 0.1, abs=1e-6)
    env.close()


@pytest.mark.slow
def test_a_scene_runs_as_one_episode_with_one_call_per_decision():
    from hbmp_bench.agents.scene import SceneAgent
    from hbmp_bench.envs.scene_env import SceneEnv
    from hbmp_bench.rollout import run_episode

    options = {k: v for k, v in THREE.items() if k != "controlled"}
    expert = SceneAgent("expert")
    env = SceneEnv(**options, **expert.env_kwargs)
    run = run_episode(env, expert, seed=0)
    assert run.ended and not expert.batched
    assert len({id(a) for a in expert._agents.values()}) == 3  # one expert per vehicle (its own state)
    records = run.info["hbmp_record"]
    assert [r["vehicle"] for r in records] == ["ego", "ego1", "ego2"] and all(r["success"] for r in records)
    assert [r.to_dict() for r in env.records()] == records
    env.close()

    il = SceneAgent("il")
    calls = []
    batch = il.prototype.act_batch
    il.prototype.act_batch = lambda obs, infos: calls.append(sorted(obs)) or batch(obs, infos)
    env = SceneEnv(**options, **il.env_kwargs, max_cycles=40)
    run = run_episode(env, il, seed=0)
    assert il.batched and len(calls) == run.decisions == 40 and calls[0] == ["ego", "ego1", "ego2"]
    assert run.ended and run.info["hbmp_record"][0]["end_reason"] == "decision_cap"
    env.close()
    with pytest.raises(TypeError, match="controlled"):
        SceneEnv(**options, controlled=2)
