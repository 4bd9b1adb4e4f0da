"""Where maps live: the shipped towns (package data) and user-imported maps.

Imported maps are stored as ``<user_maps_dir()>/<name>.net.xml``; the directory is
``$HBMP_BENCH_DATA/maps`` when ``HBMP_BENCH_DATA`` is set, else
``~/.local/share/hbmp_bench/maps``.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import UnknownNameError
from .towns import TOWNS

#: Directory of the shipped ``<Town>.net.xml`` files.
DATA_DIR = Path(__file__).resolve().parent / "data"
NET_SUFFIX = ".net.xml"


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
