"""Salted evaluations: episodes an agent cannot rebuild outside the evaluator.

A suite's episodes are public (start, goal, route, seed): anyone can build the same episode with
``BehaviorEnv(..., privileged=True)``, and an agent that did so could drive the privileged expert
on its replica in lockstep and score as the expert while marked unprivileged (issue 41, finding
3). In a salted evaluation every episode's background traffic (where each vehicle and pedestrian
starts and goes, SUMO's own randomness) and the phase of every traffic light take a secret
per-evaluation salt besides the episode's seed (``DrivingWorld.start``), while the start, goal and
route stay the suite's. The salt is 16 random bytes (:func:`new_salt`); the evaluation publishes
its SHA-256 (``results_check.commitment``) from the start and the salt itself once its selection is
complete, so anyone can replay the episodes (``audit``) and check that the salt is the one
committed to. The public, unsalted episodes stay for development and the golden records.

While the run goes on the salt lives in ``<records>.salt.json`` (mode 0600, created by the
evaluator only; see :class:`SaltKeeper`); only the env processes get it, inside their tasks, never
an agent process. Once revealed, the records file takes no further salted episodes.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path

from hbmp_bench.errors import UserError
from hbmp_bench.evaluation.results_check import commitment
from hbmp_bench.scenarios import check_salt

SALT_BYTES = 16
"""Random bytes of a salt (128 bits: no search over salts can rebuild an episode)."""


def new_salt() -> str:
    """A fresh secret salt: :data:`SALT_BYTES` random bytes from the OS, as lowercase hex."""
    return secrets.token_hex(SALT_BYTES)


class SaltKeeper:
    """The salt of a salted records file: ``<records>.salt.json`` holds ``{"salt", "revealed"}``,
    readable by the evaluator's user only.

    Args:
        records: the records file (``evaluate``'s ``path``).
    """

    def __init__(self, records: Path):
        self.path = records.with_name(records.name + ".salt.json")

    def _read(self) -> dict | None:
        if not self.path.exists():
            return None
        try:
            doc = json.loads(self.path.read_text(encoding="ascii"))
            check_salt(doc["salt"])
            if not doc["salt"] or not isinstance(doc["revealed"], bool):
                raise ValueError
        except (ValueError, KeyError, TypeError, UnicodeDecodeError):
            raise UserError(f"{self.path} is not a salt file this evaluator wrote: evaluate into another folder "
                            f"(--out)") from None
        return doc

    def salt(self, salted: bool, resuming: bool) -> str:
        """The evaluation's salt: the one kept beside the records, a new one when ``salted`` and
        nothing is recorded yet (``resuming`` False), "" for an unsalted evaluation. A salted
        evaluation on records made unsalted, or the other way round, is refused (UserError)."""
        doc = self._read()
        if not salted:
            if doc is not None:
                raise UserError(f"{self.path.parent} holds the records of a salted evaluation ({self.path.name}): "
                                "evaluate it salted (--salted) or into another folder (--out)")
            return ""
        if doc is None:
            if resuming:
                raise UserError(f"the records beside {self.path.name} were made unsalted: a salted evaluation goes "
                                "into another folder (--out)")
            doc = {"salt": new_salt(), "revealed": False}
            self._write(doc, exclusive=True)
        return doc["salt"]

    @property
    def revealed(self) -> bool:
        """Whether the salt was revealed (the records file then takes no further salted episodes)."""
        doc = self._read()
        return bool(doc and doc["revealed"])

    def reveal(self) -> str:
        """Mark the salt revealed (the evaluation's selection is complete) and return it."""
        doc = self._read()
        if doc is None:
            raise UserError(f"no salt beside the records ({self.path.name})")
        if not doc["revealed"]:
            self._write({**doc, "revealed": True})
        return doc["salt"]

    def _write(self, doc: dict, exclusive: bool = False) -> None:
        text = json.dumps(doc, sort_keys=True) + "\n"
        target = self.path if exclusive else self.path.with_name(self.path.name + ".tmp")
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL
        if not exclusive and target.exists():
            target.unlink()
        fd = os.open(target, flags, 0o600)
        with os.fdopen(fd, "w", encoding="ascii") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        if not exclusive:
            os.replace(target, self.path)


__all__ = ["SALT_BYTES", "SaltKeeper", "commitment", "new_salt"]
