"""Cross-simulator transfer: the sharable representation (M_t, R_t) on highway-env scenes.

``import hbmp_bench`` registers ``hbmp_bench/HighwayTransfer-<scene>-v0`` for the scenes in
:data:`SCENES`; highway-env itself is imported only when such an env is made.
"""

from hbmp_bench.transfer.registration import register_transfer_envs, transfer_env_ids
from hbmp_bench.transfer.scenes import SCENES, TransferScene, get_scene

__all__ = ["SCENES", "HighwayTransferEnv", "TransferScene", "get_scene", "register_transfer_envs",
           "run_transfer_episodes", "transfer_env_ids", "transfer_table"]


def __getattr__(name: str):
    """Heavy parts (highway-env) load on first use."""
    if name == "HighwayTransferEnv":
        from hbmp_bench.transfer.env import HighwayTransferEnv

        return HighwayTransferEnv
    if name in ("run_transfer_episodes", "transfer_table"):
        from hbmp_bench.transfer import evaluate

        return getattr(evaluate, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
