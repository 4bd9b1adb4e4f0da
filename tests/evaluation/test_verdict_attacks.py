"""Attacks on the verdict (issue 41, part A): hostile checkpoints, records forged before the run,
processes that outlive their episode, the fork server's socket, secrets and network, silent
retries, poisoned bytecode and stretched episodes.

The tests run the evaluator as it runs here (root in CI: sandboxed agents then get a uid of their
own; trusted ones run as ``nobody``) and, where it matters, as an ordinary user
(``test_as_an_ordinary_user``: the same attacks with the evaluator run as ``nobody``).
"""

import dataclasses
import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hostile_agents import for_tests
from hbmp_bench.errors import UserError
from hbmp_bench.evaluation import EpisodePool, RunnerLimits, describe_agent, evaluate, suite_tasks
from hbmp_bench.evaluation import namespaces
from hbmp_bench.evaluation.integrity import RecordsSeal, TamperedError, UnsealedRecordsError
from hbmp_bench.evaluation.namespaces import UID_BASE, UID_COUNT, SandboxUnavailable, sandbox_problem
from hbmp_bench.metrics.records import AGENT_ERROR, DECISION_CAP, read_records

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(bool(sandbox_problem()), reason=f"no namespace sandbox here: {sandbox_problem()}")]

ROOT = os.geteuid() == 0
QUICK = RunnerLimits(decision_timeout_s=3.0, agent_start_timeout_s=30.0, max_decisions=4)


def run(agent, limits=QUICK, episodes=1):
    from hbmp_bench.agents import AGENTS

    plain = ":" in agent or agent.endswith(".pt") or agent in AGENTS
    tasks = suite_tasks("corl2017", agent if plain else f"hostile_agents:{agent}",
                        towns=["Town01"], tasks=["Straight"], episodes=episodes, fidelity="event")
    with EpisodePool(1, for_tests(limits)) as pool:
        return [o.record for o in pool.imap(tasks)]


def found(agent_dir, name):
    path = Path(agent_dir) / f"{name}.json"
    assert path.exists(), f"{name} never reported: its attack did not run"
    return json.loads(path.read_text())


# ------------------------------------------------------------------------------------------ finding 1


def _hostile_checkpoint(folder: Path, actor=None, distribution=None) -> Path:
    """The shipped il policy with its network (or its output distribution) named as another class."""
    import torch

    from hbmp_bench.agents.learned import shipped_checkpoint

    ckpt = torch.load(shipped_checkpoint("il"), map_location="cpu", weights_only=True)
    if actor:
        ckpt["model"]["actor"]["class_name"] = actor
    if distribution:
        ckpt["model"]["actor"]["distribution_cfg"]["class_name"] = distribution
    path = folder / "evil.pt"
    torch.save(ckpt, path)
    path.chmod(0o644)
    return path


@pytest.mark.parametrize("where", ["actor", "distribution"])
def test_a_checkpoint_cannot_name_its_own_classes(readable_dir, where):
    from hbmp_bench.policies.checkpoints import NETWORK_CLASSES, CheckpointError, load_checkpoint

    path = _hostile_checkpoint(readable_dir, **{where: "checkpoint_payload:Evil"})
    with pytest.raises(CheckpointError, match="checkpoint_payload:Evil") as refused:
        load_checkpoint(str(path))
    assert all(name in str(refused.value) for name in NETWORK_CLASSES)  # names the allowed ones


@pytest.mark.parametrize("trust", [False, True], ids=["sandboxed", "trusted"])
def test_a_hostile_checkpoint_runs_no_code_in_the_evaluation(agent_dir, readable_dir, trust):
    """The reported attack: built before the user switch as the package's own code, the
    checkpoint imported the module it named, as root. Now it is refused where it is read."""
    path = _hostile_checkpoint(readable_dir, actor="checkpoint_payload:Evil")
    (record,) = run(str(path), dataclasses.replace(QUICK, trust_agent=trust))
    assert record.end_reason == AGENT_ERROR and "may only build the package's own networks" in record.error
    assert not (Path(agent_dir) / "pwned-checkpoint").exists()


# ------------------------------------------------------------------------------------------ finding 2


SELECTION = dict(towns=["Town01"], tasks=["Straight"], episodes=2, workers=1, progress=False, fidelity="event")


def _preforge(monkeypatch, folder, **limits):
    records = folder / "corl2017__hostile_agents.PreForgingAgent.jsonl"
    monkeypatch.setenv("HBMP_TEST_RECORDS", str(records))
    return records, lambda: evaluate("corl2017", "hostile_agents:PreForgingAgent", out_dir=folder,
                                     limits=for_tests(**limits), **SELECTION)


def test_records_forged_while_the_agent_is_built_are_caught(agent_dir, monkeypatch, readable_dir):
    """Trusted as the evaluator's user (or as nobody with a world-writable --out), the agent
    writes a complete records file and its provenance while it is built: the evaluator made and
    noted both before, so the change is tampering, not a resume."""
    folder = readable_dir / "runs"
    folder.mkdir()
    os.chmod(folder, 0o777)
    records, go = _preforge(monkeypatch, folder, trust_agent=True, agent_user=None)
    with pytest.raises(TamperedError, match="changed"):
        go()
    assert found(agent_dir, "PreForgingAgent")["records"] == "written"  # the attack did write
    assert not records.exists() or not any(r.success for r in read_records(records))


def test_records_the_evaluator_did_not_seal_are_refused(agent_dir, monkeypatch, readable_dir):
    """Records and provenance left before the run (by an earlier agent, another user, by hand)
    are not resumed, and nothing runs."""
    folder = readable_dir / "runs"
    folder.mkdir()
    records, go = _preforge(monkeypatch, folder, trust_agent=True, agent_user=None)
    from hostile_agents import PreForgingAgent

    PreForgingAgent()  # the forged files, written here before the evaluation
    with pytest.raises(UnsealedRecordsError, match="not records this evaluator wrote"):
        go()
    seal = RecordsSeal(records, records.with_name(records.name + ".provenance.json"), key=b"k" * 32)
    seal.write()  # sealed with a key that is not the evaluator's: refused as well
    with pytest.raises(UnsealedRecordsError, match="does not match"):
        go()


def test_a_sandboxed_agent_cannot_reach_the_records_at_construction(agent_dir, monkeypatch, readable_dir):
    folder = readable_dir / "runs"
    folder.mkdir()
    os.chmod(folder, 0o777)
    records, go = _preforge(monkeypatch, folder)
    result = go()
    assert found(agent_dir, "PreForgingAgent")["records"].startswith("write denied")
    assert result.ran == 2 and not any(r.success for r in result.records)


def test_a_killed_run_resumes_from_its_seal(tmp_path):
    """What the seals allow: a run resumed from its own records; a record past the seal (in
    flight at the kill) is cut and run again."""
    first = evaluate("corl2017", "expert", out_dir=tmp_path, **{**SELECTION, "episodes": 1})
    with open(first.path, "a") as fh:
        fh.write(first.path.read_text().replace('"episode": 0', '"episode": 1'))  # appended, never sealed
    again = evaluate("corl2017", "expert", out_dir=tmp_path, **SELECTION)
    assert again.skipped == 1 and again.ran == 1


# ------------------------------------------------------------------------------------------ findings 5, 9


def test_a_fork_chain_dies_with_its_episode(agent_dir):
    run("ForkChainAgent")
    assert found(agent_dir, "ForkChainAgent")["chains"] == 5
    time.sleep(3.0)  # a surviving chain leaves its marker after about 2 s
    assert not list(Path(agent_dir).glob("chain-*"))


def test_the_fork_servers_socket_is_out_of_reach(agent_dir):
    run("ForkServerAgent")
    outcome = found(agent_dir, "ForkServerAgent")
    assert outcome["sockets"] == []  # the sandbox's /tmp is its own


@pytest.mark.skipif(not ROOT, reason="a uid per evaluation needs root")
def test_each_evaluation_gets_a_uid_of_its_own(agent_dir):
    """Two evaluations at once: their agents share no uid (so neither can signal the other's),
    and neither is nobody's or root's."""
    import threading

    def evaluation():
        tasks = suite_tasks("corl2017", "hostile_agents:UidAgent", towns=["Town01"], tasks=["Straight"], episodes=1,
                            fidelity="event")
        with EpisodePool(1, for_tests(QUICK)) as pool:
            list(pool.imap(tasks))

    first = threading.Thread(target=evaluation)
    first.start()
    evaluation()
    first.join()
    uids = [json.loads(p.read_text())["uid"] for p in Path(agent_dir).glob("UidAgent-*.json")]
    assert len(uids) == 2 and uids[0] != uids[1]
    assert all(UID_BASE <= u < UID_BASE + UID_COUNT for u in uids)


def test_no_secrets_no_network_no_evaluator_processes(agent_dir, monkeypatch):
    monkeypatch.setenv("HBMP_FAKE_API_TOKEN", "sk-secret")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "cloud-secret")
    listener = socket.create_server(("127.0.0.1", 0))
    abstract = socket.socket(socket.AF_UNIX)
    abstract.bind(f"\0hbmp-test-{os.getpid()}")
    abstract.listen()
    monkeypatch.setenv("HBMP_TEST_PORT", str(listener.getsockname()[1]))
    monkeypatch.setenv("HBMP_TEST_ABSTRACT", f"hbmp-test-{os.getpid()}")
    try:
        run("SnoopingAgent", dataclasses.replace(QUICK, agent_env=("HBMP_TEST_PORT", "HBMP_TEST_ABSTRACT")))
    finally:
        listener.close()
        abstract.close()
    outcome = found(agent_dir, "SnoopingAgent")
    assert outcome["secret"] == "" and "AWS_SECRET_ACCESS_KEY" not in outcome["environ"]
    allowed = {*namespaces.AGENT_ENVIRONMENT, "PATH", "HOME", "TMPDIR", "USER", "LOGNAME", "HBMP_TEST_PORT",
               "HBMP_TEST_ABSTRACT", *__import__("hostile_agents").TEST_VARIABLES,
               "PWD", "PYTHONDONTWRITEBYTECODE", "PYGAME_HIDE_SUPPORT_PROMPT"}  # set in the sandbox (chdir, an import)
    leaked = {k for k in set(outcome["environ"]) & set(os.environ) if k not in allowed and not k.startswith("LC_")}
    assert not leaked  # of the evaluator's variables, only the allow-listed ones
    for target in ("loopback", "internet", "abstract"):
        assert outcome[target].startswith("failed"), (target, outcome[target])
    assert max(outcome["processes"]) < 20  # its own namespace: a handful of pids, none of the evaluator's


def test_the_evaluators_home_and_key_are_not_in_view(agent_dir, monkeypatch):
    """Attack of our own: the records key (what seals the records) and the evaluator's home."""
    from hbmp_bench.evaluation.integrity import records_key

    records_key()
    monkeypatch.setenv("HBMP_TEST_EVALUATOR_HOME", str(Path.home()))
    run("HomeReaderAgent", dataclasses.replace(QUICK, agent_env=("HBMP_TEST_EVALUATOR_HOME",)))
    outcome = found(agent_dir, "HomeReaderAgent")
    home, key = str(Path.home()), str(Path.home() / ".config" / "hbmp-bench" / "records.key")
    assert outcome[key].startswith("denied") and outcome["/etc/shadow"].startswith("denied")
    # the home is not shown: at most a folder the sandbox made to hold a Python installed there
    assert outcome[home].startswith("denied") or outcome[home] in ("listed 0", "listed 1"), outcome


def test_without_a_sandbox_untrusted_agents_are_refused(monkeypatch, agent_dir):
    monkeypatch.setattr(namespaces, "BWRAP", "hbmp-no-such-bwrap")
    with pytest.raises(SandboxUnavailable, match="--trust-agent"):
        describe_agent("hostile_agents:SandboxProbeAgent", for_tests(QUICK))
    (record,) = run("expert")  # the package's own agents still run, forked and confined
    assert record.end_reason == DECISION_CAP and record.error == ""
    (record,) = run("SandboxProbeAgent", dataclasses.replace(QUICK, trust_agent=True))  # told to trust it
    assert record.end_reason == DECISION_CAP


# ------------------------------------------------------------------------------------------ finding 7


def test_a_sandboxed_agent_cannot_write_bytecode_for_the_package(agent_dir):
    import hbmp_bench.metrics.episode as target

    before = sorted(Path(target.__file__).parent.rglob("*.hbmp-test"))
    run("PycPoisonerAgent")
    outcome = found(agent_dir, "PycPoisonerAgent")
    written = sorted(Path(target.__file__).parent.rglob("*.hbmp-test"))
    for path in set(written) - set(before):
        path.unlink()  # a regression must not leave files in the package
    assert set(outcome) == {"pycache", "beside"}
    assert all(value.startswith("denied") for value in outcome.values()), outcome


# ------------------------------------------------------------------------------------------ finding 8


def test_an_episode_has_a_wall_clock_budget(agent_dir, monkeypatch):
    """Decisions just under the decision timeout no longer stretch an episode without end: the
    budget (here 0.01 × the episode's timeout + 3 s) ends it, and the record says so."""
    from hbmp_bench.scenarios import suite_episodes

    monkeypatch.setenv("HBMP_TEST_SLOW_S", "1.5")
    timeout_s = suite_episodes("corl2017", "Town01", "Straight")[0].timeout_s
    limits = RunnerLimits(decision_timeout_s=2.0, agent_start_timeout_s=30.0, max_decisions=8,
                          episode_wall_factor=0.01, episode_wall_extra_s=3.0,
                          agent_env=("HBMP_TEST_SLOW_S",))
    start = time.monotonic()
    (record,) = run("SlowAgent", limits)
    assert record.end_reason == AGENT_ERROR and not record.success
    assert "wall-clock budget" in record.error and f"{0.01 * timeout_s + 3.0:g} s" in record.error
    assert record.decisions < 8 and time.monotonic() - start < 10.0


# ------------------------------------------------------------------------------------------ the other mode


def _python_for(user: str) -> list[str] | None:
    """A command prefix running this Python as ``user`` (setpriv), or None where that user cannot."""
    setpriv = shutil.which("setpriv")
    if not ROOT or setpriv is None:
        return None
    import pwd

    account = pwd.getpwnam(user)
    prefix = [setpriv, f"--reuid={account.pw_uid}", f"--regid={account.pw_gid}", "--clear-groups", "--"]
    probe = [sys.executable, "-c", "import sys, hbmp_bench, pytest; print(sys.version, sys.base_prefix)"]
    same = f"{sys.version} {sys.base_prefix}"  # the same Python (a loader may fall back on the system's libpython)

    def works(command):
        done = subprocess.run([*command, *probe], capture_output=True, text=True)
        return done.returncode == 0 and done.stdout.strip() == same

    if works(prefix):
        return prefix
    # a Python under a folder only its owner may enter (root's home): shown to the user through a
    # mount namespace that puts an empty folder there, holding only the installation
    python = os.path.realpath(sys.base_prefix)
    closed = next((str(p) for p in reversed(Path(python).parents) if not os.stat(p).st_mode & 0o001), None)
    tool = shutil.which("bwrap")
    if closed is None or tool is None:
        return None
    made = [str(p) for p in Path(python).parents if str(p).startswith(closed)]
    prefix = [tool, "--dev-bind", "/", "/", "--tmpfs", closed, "--ro-bind", python, python,
              *[arg for folder in sorted(made) for arg in ("--chmod", "0755", folder)], *prefix]
    return prefix if works(prefix) else None


def test_as_an_ordinary_user(readable_dir):
    """The evaluator run by an ordinary user (``nobody``): the agent keeps that uid in a user
    namespace of its own, and still can neither forge the records at construction, nor reach the
    fork server, the network or the evaluator's environment."""
    prefix = _python_for("nobody")
    if prefix is None:
        pytest.skip("needs root, setpriv and a Python that nobody may run (this one lives in a folder only its "
                    "owner may enter)")
    work = readable_dir / "work"
    work.mkdir()
    os.chmod(work, 0o777)
    (work / "reports").mkdir()
    os.chmod(work / "reports", 0o777)
    script = work / "ordinary.py"
    script.write_text(textwrap.dedent(f"""
        import json, os, sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        os.environ.update(HBMP_TEST_AGENT_DIR={str(work / "reports")!r}, HBMP_FAKE_API_TOKEN="sk-secret",
                          XDG_CONFIG_HOME={str(work / "config")!r}, HOME={str(work)!r})
        from hostile_agents import for_tests
        from hbmp_bench.evaluation import EpisodePool, RunnerLimits, evaluate, suite_tasks
        if __name__ == "__main__":
            os.environ["HBMP_TEST_RECORDS"] = {str(work / "runs" / "corl2017__hostile_agents.PreForgingAgent.jsonl")!r}
            result = evaluate("corl2017", "hostile_agents:PreForgingAgent", out_dir={str(work / "runs")!r},
                              towns=["Town01"], tasks=["Straight"], episodes=2, workers=1, progress=False,
                              fidelity="event", limits=for_tests())
            out = {{"ran": result.ran, "success": [r.success for r in result.records]}}
            limits = for_tests(RunnerLimits(decision_timeout_s=3.0, agent_start_timeout_s=30.0, max_decisions=4))
            for agent in ("SnoopingAgent", "ForkServerAgent", "SandboxProbeAgent"):
                tasks = suite_tasks("corl2017", "hostile_agents:" + agent, towns=["Town01"], tasks=["Straight"],
                                    episodes=1, fidelity="event")
                with EpisodePool(1, limits) as pool:
                    out[agent] = [(o.record.end_reason, o.record.error[-300:]) for o in pool.imap(tasks)]
            print(json.dumps(out))
    """))
    done = subprocess.run([*prefix, sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                          cwd=work)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["ran"] == 2 and out["success"] == [False, False]
    assert found(work / "reports", "PreForgingAgent")["records"].startswith("write denied")
    snoop = found(work / "reports", "SnoopingAgent")
    assert snoop["secret"] == "" and all(snoop[t].startswith("failed") for t in ("loopback", "internet"))
    assert found(work / "reports", "ForkServerAgent")["sockets"] == []
    probe = found(work / "reports", "SandboxProbeAgent")
    assert probe["uid"] == 65534 and probe["pid"] == 2
