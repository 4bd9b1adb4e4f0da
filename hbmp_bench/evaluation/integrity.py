"""Results integrity: what an evaluation wrote is what it reads back.

An agent process that runs as the evaluator's own user can write the records file and the
leaderboard folder (one that runs as ``nobody`` cannot, see ``sandbox``). So the evaluator

- keeps the records file's exact bytes as it left them (``RecordsLedger``): before and after each
  record it appends, and before it reads the results, the file must hold those bytes, else
  ``TamperedError``; the records it returns are parsed from the bytes it checked;
- notes the leaderboard folder's results files before a submission runs (``BoardSnapshot``) and
  refuses to write its entry when one was added, changed or removed meanwhile.

One evaluation at a time writes a records file (``records_lock``): a second one started on the same
file (the same suite, agent and ``--out``) is refused with a message naming the running one,
rather than both appending and the ledger reporting the other's records as tampering.

A file found changed is moved aside to ``<name>.tampered`` (never deleted), so neither
``hbmp-bench report``, a resumed evaluation nor the leaderboard picks up what it holds.

It cannot vouch for records written before the run began (a resumed file): those are as
trustworthy as the runs that wrote them.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from pathlib import Path

from hbmp_bench.locks import Busy, exclusive_lock
from hbmp_bench.metrics.records import EpisodeRecord, append_record, parse_records, record_line


class TamperedError(ValueError):
    """A records file or leaderboard folder changed behind the evaluator's back during a run."""


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def quarantine(path: Path) -> Path | None:
    """Move ``path`` aside to ``<name>.tampered`` (replacing an older one); None when it is gone."""
    target = path.with_name(path.name + ".tampered")
    try:
        os.replace(path, target)
    except FileNotFoundError:
        return None
    return target


class EvaluationRunning(Busy):
    """Another evaluation holds the records file's lock."""


def records_lock(path: str | os.PathLike) -> contextlib.AbstractContextManager[None]:
    """Hold the exclusive lock ``<records>.lock`` for the block; raise :class:`EvaluationRunning` at once
    when another process holds it (:func:`hbmp_bench.locks.exclusive_lock`)."""
    return exclusive_lock(Path(path).with_name(Path(path).name + ".lock"), lambda holder: EvaluationRunning(
        f"another evaluation (pid {holder}) is writing {path}: wait for it to finish, or evaluate into another "
        "--out folder"))


class RecordsLedger:
    """The records file at ``path`` as this evaluator last left it (size and sha256 of its bytes).

    Args:
        path: the JSON-lines records file (need not exist yet).
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        data = self._read()
        self.size, self.digest = len(data), _digest(data)
        self.appended = 0

    def _read(self) -> bytes:
        return self.path.read_bytes() if self.path.exists() else b""

    def _tampered(self, when: str) -> TamperedError:
        moved = quarantine(self.path)
        return TamperedError(
            f"{self.path} changed while the evaluation ran ({when}): something other than the evaluator wrote to it "
            f"— an agent under evaluation can, when it runs as your user. Its records cannot be trusted"
            f"{f' and were moved to {moved.name}' if moved else ''}: evaluate again as root (the agent then runs as "
            f"an unprivileged user) or in a container.")

    def verified(self) -> bytes:
        """The file's bytes, checked to be exactly those this evaluator left; else ``TamperedError``."""
        data = self._read()
        if len(data) != self.size or _digest(data) != self.digest:
            n = self.appended
            raise self._tampered(f"found {len(data)} bytes, expected {self.size} after {n} record(s) appended by this run")
        return data

    def append(self, record: EpisodeRecord) -> None:
        """Append ``record`` (``append_record``), checking the file before and after."""
        before = self.verified()
        append_record(self.path, record)
        expected = before + record_line(record).encode("utf-8")
        if self._read() != expected:
            raise self._tampered("while a record was appended")
        self.size, self.digest = len(expected), _digest(expected)
        self.appended += 1

    def records(self) -> list[EpisodeRecord]:
        """Every record of the file, parsed from its verified bytes."""
        return parse_records(self.verified().decode("utf-8").splitlines(keepends=True))


class BoardSnapshot:
    """The ``*.json`` results files of a leaderboard folder (name → sha256) at one moment."""

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.files = self._scan()

    def _scan(self) -> dict[str, str]:
        if not self.folder.is_dir():
            return {}
        return {p.name: _digest(p.read_bytes()) for p in sorted(self.folder.glob("*.json")) if p.is_file()}

    def check_unchanged(self) -> None:
        """Raise ``TamperedError`` naming the results files added, changed or removed since the snapshot."""
        now = self._scan()
        changed = sorted(set(now) ^ set(self.files) | {n for n in set(now) & set(self.files) if now[n] != self.files[n]})
        if changed:
            moved = [p.name for n in changed if n in now and (p := quarantine(self.folder / n)) is not None]
            raise TamperedError(
                f"leaderboard folder {self.folder} changed while the submission ran ({', '.join(changed)}): "
                f"results files were added, changed or removed by something other than this submission — an agent "
                f"under evaluation can, when it runs as your user (or another submission ran at the same time). "
                f"Nothing was written{'; moved aside: ' + ', '.join(moved) if moved else ''}. Check those files "
                f"(rename one back if it was yours), then submit again (finished episodes are kept).")
