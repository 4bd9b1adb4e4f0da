"""Where maps live: the shipped towns (package data) and user-imported maps.

Imported maps are stored as ``<user_maps_dir()>/<name>.net.xml`` with their provenance in
``<name>.map.json`` (:func:`~hbmp_bench.maps.importer.map_info`); the directory is
``$HBMP_BENCH_DATA/maps`` when ``HBMP_BENCH_DATA`` is set, else
``~/.local/share/hbmp_bench/maps``.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

from ..errors import UnknownNameError
from .towns import TOWNS

#: Directory of the shipped ``<Town>.net.xml`` files.
DATA_DIR = Path(__file__).resolve().parent / "data"
NET_SUFFIX = ".net.xml"
INFO_SUFFIX = ".map.json"


def user_maps_dir() -> Path:
    """Directory of user-imported maps (not created here)."""
    root = os.environ.get("HBMP_BENCH_DATA")
    if root:
        return Path(root).expanduser() / "maps"
    return Path.home() / ".local" / "share" / "hbmp_bench" / "maps"


def user_maps() -> tuple[str, ...]:
    """Names of the imported maps, sorted."""
    d = user_maps_dir()
    if not d.is_dir():
        return ()
    names = (p.name[: -len(NET_SUFFIX)] for p in d.glob(f"*{NET_SUFFIX}") if p.is_file())
    return tuple(sorted(n for n in names if n not in TOWNS))


def available_maps() -> tuple[str, ...]:
    """Built-in towns (in order) followed by the user-imported maps."""
    return TOWNS + user_maps()


def net_path(name: str) -> Path:
    """The ``.net.xml`` of built-in town or imported map ``name``.

    Raises UnknownNameError (kind ``"map"``) for any other name.
    """
    if name in TOWNS:
        return DATA_DIR / f"{name}{NET_SUFFIX}"
    if isinstance(name, str) and name in user_maps():
        return user_maps_dir() / f"{name}{NET_SUFFIX}"
    raise UnknownNameError("map", name, available_maps())


def info_path(name: str) -> Path:
    """Where the provenance of imported map ``name`` is (or would be) stored."""
    return user_maps_dir() / f"{name}{INFO_SUFFIX}"


def map_hash(name: str) -> str:
    """First 16 hex digits of the SHA-256 of map ``name``'s net file: what its episodes and records
    are keyed to. UnknownNameError for an unknown name."""
    path = net_path(name)
    stat = path.stat()
    return _file_hash(str(path), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=64)
def _file_hash(path: str, mtime_ns: int, size: int) -> str:
    return file_sha256(path)[:16]


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()
