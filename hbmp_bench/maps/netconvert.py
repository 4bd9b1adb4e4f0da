"""Locate and run the ``netconvert`` binary of the eclipse-sumo wheel."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def netconvert_binary() -> Path:
    """Path of ``netconvert`` shipped with the ``eclipse-sumo`` Python wheel.

    Raises RuntimeError when the wheel is missing. A system SUMO or a hand-set
    ``SUMO_HOME`` is never used.
    """
    try:
        import sumo  # the eclipse-sumo wheel
    except ImportError as exc:  # pragma: no cover - the wheel is a dependency
        raise RuntimeError("the 'eclipse-sumo' package is needed to run netconvert") from exc
    name = "netconvert.exe" if sys.platform == "win32" else "netconvert"
    path = Path(sumo.SUMO_HOME) / "bin" / name
    if not path.exists():  # pragma: no cover
        raise RuntimeError(f"netconvert not found in the eclipse-sumo wheel ({path})")
    return path


def run_netconvert(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run netconvert with ``args`` in ``cwd``; RuntimeError with its stderr on failure."""
    import sumo

    env = dict(os.environ)
    env["SUMO_HOME"] = str(sumo.SUMO_HOME)  # the wheel's own data (xsd, typemaps)
    proc = subprocess.run([str(netconvert_binary()), *args], cwd=cwd, env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        msg = (proc.stderr or proc.stdout).strip()
        raise RuntimeError(f"netconvert failed ({proc.returncode}): {msg}")
    return proc


def netconvert_version() -> str:
    """netconvert's version line (``Eclipse SUMO netconvert Version 1.28.0``... first line of
    ``--version``)."""
    import sumo

    env = dict(os.environ)
    env["SUMO_HOME"] = str(sumo.SUMO_HOME)
    proc = subprocess.run([str(netconvert_binary()), "--version"], env=env, capture_output=True, text=True)
    return (proc.stdout.strip().splitlines() or ["unknown"])[0]
