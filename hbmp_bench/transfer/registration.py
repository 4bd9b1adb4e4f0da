"""Gymnasium ids ``hbmp_bench/HighwayTransfer-<scene>-v0``, one per :data:`SCENES` entry."""

from __future__ import annotations

import gymnasium as gym

from hbmp_bench.transfer.scenes import SCENES

ENTRY_POINT = "hbmp_bench.transfer.env:HighwayTransferEnv"


def transfer_env_ids() -> tuple[str, ...]:
    """Every highway-env transfer id."""
    return tuple(f"hbmp_bench/HighwayTransfer-{name}-v0" for name in SCENES)


def register_transfer_envs() -> None:
    """Register every transfer id (idempotent)."""
    for name, env_id in zip(SCENES, transfer_env_ids()):
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=ENTRY_POINT, kwargs={"scene": name}, disable_env_checker=True)
