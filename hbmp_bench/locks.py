"""One writer per output: an exclusive ``flock`` on a lock file, refused at once when another process holds it.

Two evaluations writing one records file, or two training runs writing one run folder, would interleave their
rows (and the ledger would call the first one's rows tampering). The lock is released when the process ends,
however it ends; the lock file stays (removing it would race with a waiter) and holds the pid of the last
holder, which the refusal names.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from hbmp_bench.errors import UserError


class Busy(UserError):
    """Another process holds the lock of the output this one would write."""


@contextlib.contextmanager
def exclusive_lock(lock_path: str | os.PathLike, refusal: Callable[[str], Busy]) -> Iterator[None]:
    """Hold the exclusive lock on ``lock_path`` (created if missing) for the block.

    Args:
        lock_path: the lock file; its folder must exist.
        refusal: builds the error raised when another process holds the lock, from that process's pid
            (``"unknown"`` if it wrote none).
    """
    fd = os.open(Path(lock_path), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            raise refusal(holder) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        yield
    finally:
        os.close(fd)  # releases the lock
