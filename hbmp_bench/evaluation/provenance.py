"""Where a result came from: package and library versions, git commit, machine, date."""

from __future__ import annotations

import datetime as _dt
import os
import platform
from importlib import metadata
from pathlib import Path

LIBRARIES = ("hbmp-bench", "eclipse-sumo", "libsumo", "numpy", "torch", "gymnasium")
"""Distributions whose versions are recorded with every result."""


def git_commit(start: str | os.PathLike | None = None) -> str | None:
    """The commit checked out in the git repository holding ``start`` (default: this package's
    source), read from the ``.git`` files; None outside a repository (e.g. a wheel install)."""
    path = Path(start or Path(__file__).resolve().parent)
    for folder in (path, *path.parents):
        git = folder / ".git"
        if git.is_file():  # a worktree: "gitdir: <path>"
            text = git.read_text(encoding="utf-8").strip()
            if not text.startswith("gitdir:"):
                return None
            git = (folder / text.partition(":")[2].strip()).resolve()
        if git.is_dir():
            return _resolve_head(git)
    return None


def _resolve_head(git: Path) -> str | None:
    try:
        head = (git / "HEAD").read_text(encoding="utf-8").strip()
    except OSError:
        return None
    if not head.startswith("ref:"):
        return head or None
    ref = head.partition(":")[2].strip()
    common = git
    if (git / "commondir").is_file():
        common = (git / (git / "commondir").read_text(encoding="utf-8").strip()).resolve()
    for base in (git, common):
        if (base / ref).is_file():
            return (base / ref).read_text(encoding="utf-8").strip() or None
        packed = base / "packed-refs"
        if packed.is_file():
            for line in packed.read_text(encoding="utf-8").splitlines():
                parts = line.split()
                if len(parts) == 2 and parts[1] == ref:
                    return parts[0]
    return None


def library_versions() -> dict[str, str | None]:
    """Installed version of each of ``LIBRARIES`` (None when missing)."""
    out = {}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def float_platform() -> str:
    """The machine as far as float rounding goes: its architecture and the highest SIMD level numpy
    dispatches to (e.g. ``x86_64, numpy SIMD X86_V3``: AVX2 and FMA, no AVX-512). Episodes replay
    bit for bit on the same one (``audit``); another may round a transcendental differently."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_features__ as features

    levels = sorted((k for k, found in features.items() if found and k.startswith("X86_V")), reverse=True)
    return f"{platform.machine()}, numpy SIMD {levels[0] if levels else 'baseline'}"


def machine_description() -> dict[str, object]:
    """OS, CPU model and count, Python: enough to compare wall times between entries; and the
    :func:`float_platform` an audit replays on."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next((line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")), cpu)
    except OSError:
        pass
    return {
        "platform": platform.platform(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "float_platform": float_platform(),
    }


def utc_now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
