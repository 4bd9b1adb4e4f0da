"""Shared fixtures of the map tests: parsed nets of the shipped towns (read once)."""

from __future__ import annotations

import pytest
import sumolib

from hbmp_bench.maps import TOWNS, net_path


@pytest.fixture(scope="session")
def nets() -> dict:
    """sumolib nets of every shipped town, keyed by town name."""
    return {t: sumolib.net.readNet(str(net_path(t)), withInternal=True,
                                   withPedestrianConnections=True) for t in TOWNS}


@pytest.fixture(autouse=True)
def _isolated_user_maps(tmp_path, monkeypatch):
    """Never touch the real user data directory in tests."""
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path / "hbmp_data"))
