"""The shell commands of the project's documentation: every ``hbmp-bench`` command in a fenced shell block."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

DOC_FILES = (ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), ROOT / "leaderboards" / "README.md",
             ROOT / "leaderboards" / "carla" / "README.md")
"""The pages whose shell blocks are checked: the README, every docs page, the leaderboards' hand-written READMEs."""

SHELL_LANGUAGES = ("bash", "sh", "shell", "console")

_FENCE = re.compile(r"^```(\w*)\s*$")


@dataclass(frozen=True)
class DocCommand:
    """One ``hbmp-bench`` command of a docs page: ``argv`` without the program name."""

    file: Path
    line: int
    argv: tuple[str, ...]

    def __str__(self) -> str:
        return f"{self.file.relative_to(ROOT)}:{self.line}: hbmp-bench {shlex.join(self.argv)}"


def shell_lines(path: Path) -> list[tuple[int, str]]:
    """``(line number, text)`` of every line inside a fenced shell block of ``path``, continuation
    lines (``\\`` at the end) joined to the line they continue."""
    lines, language, pending, start = [], None, "", 0
    for number, text in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        fence = _FENCE.match(text.strip())
        if fence:
            language = None if language is not None else fence.group(1)
            continue
        if language not in SHELL_LANGUAGES:
            continue
        if not pending:
            start = number
        if text.rstrip().endswith("\\"):
            pending += text.rstrip()[:-1] + " "
            continue
        lines.append((start, pending + text))
        pending = ""
    return lines


def doc_commands(files=DOC_FILES) -> list[DocCommand]:
    """Every ``hbmp-bench`` invocation in the shell blocks of ``files`` (a line's ``&&`` / ``;``
    chains split, comments dropped)."""
    found = []
    for path in files:
        for number, text in shell_lines(path):
            words = shlex.split(text.removeprefix("$ "), comments=True)
            command: list[str] = []
            for word in [*words, ";"]:
                if word in ("&&", ";", "||", "|"):
                    if command[:1] == ["hbmp-bench"]:
                        found.append(DocCommand(path, number, tuple(command[1:])))
                    command = []
                else:
                    command.append(word)
    return found


def python_blocks(files=DOC_FILES) -> list[tuple[Path, int, str]]:
    """``(file, first line, code)`` of every fenced ``python`` block of ``files``."""
    blocks = []
    for path in files:
        language, start, lines = None, 0, []
        for number, text in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            fence = _FENCE.match(text.strip())
            if fence:
                if language is None:
                    language, start, lines = fence.group(1), number + 1, []
                else:
                    if language == "python":
                        blocks.append((path, start, "\n".join(lines)))
                    language = None
                continue
            if language is not None:
                lines.append(text)
    return blocks
