"""Privilege that means something (issue 41, finding 3): the episode's identity is not in the agent's
info, and in a salted evaluation the traffic, pedestrians and light phases take a secret salt, so
an agent cannot rebuild its episode and drive the privileged expert on the replica in lockstep.

The public episodes are unchanged (the golden records hold it), a salted one is deterministic
given its salt (an audit replays it), and the salt is committed to before the run and revealed
after it.
"""

import json

import pytest

from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.evaluation import EpisodePool, RunnerLimits, evaluate, suite_tasks
from hbmp_bench.evaluation.audit import audit
from hbmp_bench.evaluation.leaderboard import add_results, submit
from hbmp_bench.evaluation.results_check import commitment
from hbmp_bench.evaluation.salting import SaltKeeper, new_salt
from hbmp_bench.metrics.records import AGENT_ERROR
from hbmp_bench.rollout import run_episode
from hbmp_bench.agents import load_agent

pytestmark = pytest.mark.slow

LIMITS = RunnerLimits(decision_timeout_s=20.0, agent_start_timeout_s=60.0)
EPISODE = dict(towns=["Town01"], tasks=["NavigationDynamic"], episodes=[0], fidelity="event")
"""One hbmp episode with traffic, pedestrians and lights on its route (about 1 s in event fidelity)."""
COMPARED = ("success", "end_reason", "duration_s", "decisions", "distance_m", "red_light", "collision_vehicle")


def outcomes(agents, salt=""):
    """The hbmp Town01 NavigationDynamic episode 0 of each agent, in one pool: records by agent."""
    tasks = [t for a in agents for t in suite_tasks("hbmp", a, salt=salt, **EPISODE)]
    with EpisodePool(1, LIMITS) as pool:
        return {o.record.agent: o.record for o in pool.imap(tasks)}


def drive(record):
    return {k: getattr(record, k) for k in COMPARED}


def test_the_replica_attack_works_on_the_public_episodes_and_fails_on_salted_ones():
    """Unsalted: the attacker finds its episode by its start pose, rebuilds it with privileged=True
    and drives the expert in lockstep (never a different observation): the expert's record, with
    the agent marked unprivileged. Salted: its replica differs from the real episode within a few
    decisions, and the replica's expert, driving the real episode blind, does not drive it as the
    expert does."""
    public = outcomes(["expert", "replica_agents:ReplicaAttacker"])
    attack = public["replica_agents:ReplicaAttacker"]
    assert attack.error == "" and attack.success, attack.error
    assert drive(attack) == drive(public["expert"])  # the public episode can be replicated exactly

    salt = new_salt()
    salted = outcomes(["expert", "replica_agents:ReplicaAttacker", "replica_agents:BlindReplicaAttacker"], salt)
    strict = salted["replica_agents:ReplicaAttacker"]
    assert strict.end_reason == AGENT_ERROR and "replica desynced at decision" in strict.error, strict.error
    blind = salted["replica_agents:BlindReplicaAttacker"]
    assert drive(blind) != drive(salted["expert"]), (drive(blind), drive(salted["expert"]))
    assert salted["expert"].success  # the salted episode itself is as drivable as the public one


def test_the_agent_never_sees_its_episodes_identity_nor_the_salt():
    salt = new_salt()
    record = outcomes(["replica_agents:SaltHunter"], salt)["replica_agents:SaltHunter"]
    assert record.end_reason == AGENT_ERROR and "hex runs found:" in record.error, record.error
    assert salt not in record.error and commitment(salt) not in record.error
    from hbmp_bench.evaluation.env_process import agent_view

    env = BehaviorEnv(town="Town01", task="Straight", suite="hbmp", fidelity="event")
    try:
        _, info = env.reset(seed=0, options={"episode_index": 0})
    finally:
        env.close()
    assert "episode_key" in info and not {"episode_key", "episode", "seed", "salt"} & set(agent_view(info))


def test_a_salted_episode_is_deterministic_given_its_salt_and_the_public_one_unchanged():
    env = BehaviorEnv(town="Town01", task="NavigationDynamic", suite="hbmp", fidelity="event", privileged=True)
    salt_a, salt_b = new_salt(), new_salt()
    runs = {}
    try:
        for name, salt in (("public", ""), ("none", None), ("a", salt_a), ("a again", salt_a), ("b", salt_b)):
            options = {"episode_index": 0} if salt is None else {"episode_index": 0, "salt": salt}
            run = run_episode(env, load_agent("expert"), seed=0, options=options)
            runs[name] = {k: run.info["hbmp_record"][k] for k in COMPARED}
            runs[name]["lights"] = env.world.sim.light_states() if name != "none" else None
    finally:
        env.close()
    assert runs["public"] == {**runs["none"], "lights": runs["public"]["lights"]}
    assert runs["a"] == runs["a again"]
    assert runs["a"] != runs["public"] and runs["b"] != runs["a"]


def test_salted_lights_keep_their_programs_and_start_elsewhere_in_the_cycle():
    env = BehaviorEnv(town="Town01", task="Straight", suite="hbmp", fidelity="event")

    def states():
        api = env.world.sim._api.trafficlight
        return {tls: api.getRedYellowGreenState(tls) for tls in env.world.sim.light_ids()}

    try:
        env.reset(seed=0, options={"episode_index": 0})
        public = states()
        env.reset(seed=0, options={"episode_index": 0, "salt": new_salt()})
        salted = states()
        api = env.world.sim._api.trafficlight
        assert set(public) == set(salted) and public != salted
        for tls in salted:  # same program: the current state is one of its phases
            program = api.getProgram(tls)
            logic = next(lg for lg in api.getAllProgramLogics(tls) if lg.programID == program)
            assert salted[tls] in {p.state for p in logic.phases}
        with pytest.raises(ValueError, match="a salt is 32 to 64 lowercase hex digits"):
            env.reset(seed=0, options={"episode_index": 0, "salt": "not hex"})
    finally:
        env.close()


def test_a_salted_submission_commits_to_its_salt_reveals_it_and_replays(tmp_path):
    path, doc = submit("hbmp", "expert", board_dir=tmp_path / "board", workers=1, limits=LIMITS, progress=False,
                       salted=True, **EPISODE)
    prov = doc["provenance"]
    assert doc["salted"] and len(prov["salt_commitment"]) == 64 and commitment(prov["salt"]) == prov["salt_commitment"]
    readme = (tmp_path / "board" / "hbmp" / "README.md").read_text()
    assert f"| {prov['salt_commitment'][:10]} |" in readme
    records = next((tmp_path / "board" / "hbmp" / "runs").rglob("*.salted.jsonl"))
    keeper = SaltKeeper(records)
    assert keeper.revealed and keeper.path.stat().st_mode & 0o077 == 0  # the evaluator's user alone reads it
    result = audit(path, "expert", 1, seed=0)
    assert result.ok, "\n".join(result.lines())
    # a revealed salt takes no further episodes; unsalted records are not resumed salted, nor the reverse
    with pytest.raises(ValueError, match="salt of .* is revealed"):
        evaluate("hbmp", "expert", towns=["Town01"], tasks=["NavigationDynamic"], episodes=[1], fidelity="event",
                 path=records, workers=1, limits=LIMITS, progress=False, salted=True)
    with pytest.raises(ValueError, match="holds the records of a salted evaluation"):
        evaluate("hbmp", "expert", path=records, limits=LIMITS, progress=False, **EPISODE)
    # a salt that is not the one committed to is refused by add; one that does not replay fails the audit
    forged = dict(doc, provenance={**prov, "salt": new_salt()})
    (tmp_path / "forged.json").write_text(json.dumps(forged))
    with pytest.raises(ValueError, match="not to its salt_commitment"):
        add_results(tmp_path / "forged.json", tmp_path / "other")
    other = new_salt()
    swapped = dict(doc, provenance={**prov, "salt": other, "salt_commitment": commitment(other)})
    (tmp_path / "swapped.json").write_text(json.dumps(swapped))
    assert not audit(tmp_path / "swapped.json", "expert", 1, seed=0).ok
