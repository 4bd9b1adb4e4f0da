"""Fixtures of the evaluation tests."""

import os
import shutil
import tempfile
from pathlib import Path

import pytest


@pytest.fixture
def agent_dir(monkeypatch):
    """A folder the agent process can write to whichever user it runs as (``nobody`` when the
    tests run as root), named to agents by ``HBMP_TEST_AGENT_DIR``; agents leave their reports there."""
    folder = tempfile.mkdtemp(prefix="hbmp-agent-")
    os.chmod(folder, 0o777)
    monkeypatch.setenv("HBMP_TEST_AGENT_DIR", folder)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def readable_dir():
    """A folder every user can read (``tmp_path`` of root is not): for agent modules the agent
    process imports as ``nobody`` when the tests run as root."""
    folder = tempfile.mkdtemp(prefix="hbmp-agents-")
    os.chmod(folder, 0o755)
    yield Path(folder)
    shutil.rmtree(folder, ignore_errors=True)
