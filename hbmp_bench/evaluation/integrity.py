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

Records the evaluator resumes from must be its own (``RecordsSeal``): after creating the records
file and after every record it appends, it writes ``<records>.seal``, an HMAC (with a key of the
evaluating user's, ``records_key``, that no agent sandbox shows) of the records' bytes and of the
provenance side file. A records or provenance file without a valid seal — written by an agent
while it was built, by another user, or by hand — is refused rather than resumed; bytes past the
sealed length (a record in flight when a run was killed) are cut. The records file, its
provenance and its ledger exist before any agent code runs (``evaluate``). A seal vouches for
what this user's evaluator wrote: an agent trusted to run as that same user (``--trust-agent``,
not root) can read the key, so it proves nothing against such an agent.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import os
import secrets
from pathlib import Path

from hbmp_bench.errors import UserError
from hbmp_bench.locks import Busy, exclusive_lock
from hbmp_bench.metrics.records import EpisodeRecord, parse_records, record_line


class TamperedError(UserError):
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

    def append(self, *records: EpisodeRecord) -> None:
        """Append an episode's ``records`` (one, or a scene's one per vehicle) in one write, flushed and
        fsynced, checking the file before and after."""
        before = self.verified()
        data = "".join(record_line(r) for r in records).encode("utf-8")
        with open(self.path, "ab") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        expected = before + data
        if self._read() != expected:
            raise self._tampered("while a record was appended")
        self.size, self.digest = len(expected), _digest(expected)
        self.appended += len(records)

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


SEAL_FORMAT = "hbmp_bench.records-seal.v1"


class UnsealedRecordsError(UserError):
    """A records or provenance file the evaluator did not seal: it is refused, not resumed."""


def records_key() -> bytes:
    """The evaluating user's secret key for records seals (32 random bytes), created on first use
    in ``$XDG_CONFIG_HOME/hbmp-bench/records.key`` (default ``~/.config``), readable by that user
    only. The agent sandbox does not show it."""
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    folder = base / "hbmp-bench"
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    path = folder / "records.key"
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    except FileExistsError:
        data = path.read_bytes()
        if len(data) != 32:
            raise UserError(f"{path} is not a records key (32 bytes): delete it to make a new one "
                            "(records sealed with it can then no longer be resumed)") from None
        return data
    with os.fdopen(fd, "wb") as fh:
        fh.write(secrets.token_bytes(32))
    return path.read_bytes()


class RecordsSeal:
    """The seal ``<records>.seal`` of a records file and its provenance side file.

    Args:
        path: the records file.
        side: its provenance side file (``<records>.provenance.json``).
        key: the HMAC key (default ``records_key()``).
    """

    def __init__(self, path: str | os.PathLike, side: str | os.PathLike, key: bytes | None = None):
        self.path, self.side = Path(path), Path(side)
        self.seal_path = self.path.with_name(self.path.name + ".seal")
        self.key = records_key() if key is None else key

    def _mac(self, records: bytes, provenance: bytes | None) -> str:
        message = b"\0".join([SEAL_FORMAT.encode(), hashlib.sha256(records).hexdigest().encode(),
                               b"-" if provenance is None else hashlib.sha256(provenance).hexdigest().encode()])
        return hmac.new(self.key, message, hashlib.sha256).hexdigest()

    def write(self) -> None:
        """Seal the records file's and the side file's current bytes (atomic replace)."""
        records = self.path.read_bytes() if self.path.exists() else b""
        provenance = self.side.read_bytes() if self.side.exists() else None
        doc = {"format": SEAL_FORMAT, "size": len(records), "mac": self._mac(records, provenance)}
        tmp = self.seal_path.with_name(self.seal_path.name + ".tmp")
        tmp.write_text(json.dumps(doc) + "\n")
        os.replace(tmp, self.seal_path)

    def check_resumable(self) -> int:
        """Before any agent code runs: refuse records this evaluator did not seal.

        Nothing there (or an empty records file alone): fine. Else the seal must hold: the
        provenance's bytes and the records' first ``size`` bytes are what was sealed; bytes past
        them (a record appended when the run was killed) are cut. Returns the bytes cut; raises
        ``UnsealedRecordsError`` naming the files otherwise.
        """
        records = self.path.read_bytes() if self.path.exists() else b""
        provenance = self.side.read_bytes() if self.side.exists() else None
        if not records and provenance is None and not self.seal_path.exists():
            return 0
        why = self._unsealed(records, provenance)
        if why:
            names = ", ".join(p.name for p in (self.path, self.side, self.seal_path) if p.exists())
            raise UnsealedRecordsError(
                f"{self.path} is not records this evaluator wrote ({why}): it may have been written by an agent "
                f"while it was built, by another user or by hand, and is not resumed. Evaluate into another folder "
                f"(--out), or delete {names} to start over")
        size = json.loads(self.seal_path.read_text())["size"]
        if len(records) > size:
            with open(self.path, "rb+") as fh:
                fh.truncate(size)
                fh.flush()
                os.fsync(fh.fileno())
        return len(records) - size

    def _unsealed(self, records: bytes, provenance: bytes | None) -> str:
        try:
            doc = json.loads(self.seal_path.read_text())
        except FileNotFoundError:
            return f"no {self.seal_path.name}"
        except (OSError, ValueError) as exc:
            return f"{self.seal_path.name} unreadable: {exc}"
        if not isinstance(doc, dict) or doc.get("format") != SEAL_FORMAT or not isinstance(doc.get("size"), int) \
                or not isinstance(doc.get("mac"), str):
            return f"{self.seal_path.name} is not a seal"
        size = doc["size"]
        if size > len(records) or not hmac.compare_digest(doc["mac"], self._mac(records[:size], provenance)):
            return f"its seal does not match the records and provenance (sealed with another key, or changed since)"
        return ""
