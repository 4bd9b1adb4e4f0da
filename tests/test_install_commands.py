"""The README's install-and-test command and CI install the same thing and run the same tests."""

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _pip_installs(text: str) -> list[list[str]]:
    """The arguments of every ``pip install`` in a shell text, options such as ``-q`` left out."""
    installs = []
    for line in text.splitlines():
        if line.lstrip().startswith("#"):
            continue
        for command in re.split(r"&&|;", line):
            words = shlex.split(command)
            if words[:2] == ["pip", "install"] or words[:4] == ["python", "-m", "pip", "install"]:
                args = words[words.index("install") + 1:]
                installs.append([w for w in args if not w.startswith("-") or w == "-e"])
    return installs


def test_readme_test_command_installs_what_ci_installs():
    readme = (ROOT / "README.md").read_text()
    block = readme.split("# 2. install and run the tests", 1)[1].split("```", 1)[0]
    ci = (ROOT / ".ci" / "run").read_text()
    ci_installs = [args for args in _pip_installs(ci) if args != ["pip"]]  # CI also upgrades pip itself
    assert _pip_installs(block) == ci_installs
    assert ["-e", ".[dev,ray]"] in ci_installs  # ray: tests/evaluation/test_ray_backend.py runs, not skips
    assert "python -m pytest -q" in block and "python -m pytest -q" in ci
