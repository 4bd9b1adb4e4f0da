"""Errors shared by every registry of the package."""

from __future__ import annotations

from collections.abc import Iterable


class UnknownNameError(KeyError, ValueError):
    """A name (env id, town, task, suite, agent, map) that no registry knows.

    The message lists the valid names so a typo is fixed in one look. It subclasses both
    ``KeyError`` (a failed look-up) and ``ValueError`` (bad user input).
    """

    def __init__(self, kind: str, name: object, valid: Iterable[str]):
        self.kind = kind
        self.name = name
        self.valid = tuple(sorted(valid))
        super().__init__(f"unknown {kind} {name!r}; valid: {', '.join(self.valid) or '(none)'}")

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])
