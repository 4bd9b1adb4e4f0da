"""Errors a user meets: each says what is wrong in one line, and the CLI prints it without a traceback."""

from __future__ import annotations

import os
from collections.abc import Iterable


class UserError(ValueError):
    """A mistake in what the user asked for: a bad option, an unreadable file, a plug-in that fails.

    ``hbmp-bench`` prints the message as one line and exits with code 2. It is raised at the
    boundaries where user input enters the package (options, files, ``module:Class`` plug-ins),
    with the original exception as ``__cause__``, so Python callers keep the full traceback. It is
    a ``ValueError`` (bad input), as configuration validation raises.
    """


class ConfigError(UserError):
    """A configuration that cannot hold: a field out of range, two fields that contradict each other.

    Raised by the ``__post_init__`` checks of the package's frozen configuration dataclasses (env,
    reward, training, evaluation configs). The message names the field, the value and what is
    allowed. It is a ``UserError``, so ``hbmp-bench`` prints it as one line, and thereby still a
    ``ValueError`` for callers that catch that.
    """


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, raised after the interrupted work stopped cleanly (children ended, files whole).

    The message says what was kept and how to resume; ``hbmp-bench`` prints it and exits with 130.
    """


def raised_at(exc: BaseException) -> str:
    """``file:line`` of the innermost source frame of ``exc``'s traceback ("" without one): where a
    plug-in's own code failed, for a one-line message."""
    where = ""
    tb = exc.__traceback__
    while tb is not None:
        filename = tb.tb_frame.f_code.co_filename
        if not filename.startswith("<"):  # not <frozen importlib...> nor <string>
            where = f"{os.path.basename(filename)}:{tb.tb_lineno}"
        tb = tb.tb_next
    return where


class UnknownNameError(UserError, KeyError):
    """A name (env id, town, task, suite, agent, map) that no registry knows.

    The message lists the valid names so a typo is fixed in one look. It is both a ``KeyError`` (a
    failed look-up) and a ``UserError`` (bad user input, a ``ValueError``).
    """

    def __init__(self, kind: str, name: object, valid: Iterable[str]):
        self.kind = kind
        self.name = name
        self.valid = tuple(sorted(valid))
        super().__init__(f"unknown {kind} {name!r}; valid: {', '.join(self.valid) or '(none)'}")

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])
