"""The sandbox's view of files: what it shows is readable by the agent's own uid, wherever it lies."""

import os
import shutil
import subprocess
import sys

import pytest

from hbmp_bench.evaluation.namespaces import UID_BASE, bwrap_argv, sandbox_problem

pytestmark = pytest.mark.skipif(bool(sandbox_problem()), reason=sandbox_problem() or "sandbox available")


def test_an_agent_folder_under_the_hosts_tmp_is_readable_by_the_agents_uid(tmp_path):
    """A clone, virtualenv or agent module under the host's /tmp is shown inside the private /tmp; the
    folders bwrap makes to hold it must be searchable after the agent process leaves root (they were
    not: an evaluation run from a clone in /tmp could start no sandboxed agent)."""
    agent = tmp_path / "deep" / "agent_pkg"
    agent.mkdir(parents=True)
    (agent / "probe_module.py").write_text("ANSWER = 42\n")
    os.chmod(tmp_path, 0o700)  # as pytest makes it: private to the evaluator
    code = f"import sys; sys.path.insert(0, {str(agent)!r}); import probe_module; print(probe_module.ANSWER)"
    command = [sys.executable, "-c", code]
    if os.geteuid() == 0:  # the evaluator is root: the agent process runs as a uid of its own
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("setpriv (util-linux) is needed to switch uid as the agent process does")
        uid = str(UID_BASE + 4242)
        command = [setpriv, "--reuid", uid, "--regid", uid, "--clear-groups", *command]
    done = subprocess.run(bwrap_argv(command, readable=[str(agent)]), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "42"
