"""Cross-simulator transfer: the sharable representation (M_t, R_t) on highway-env scenes.

``import hbmp_bench`` registers ``hbmp_bench/HighwayTransfer-<scene>-v0`` for the scenes in
:data:`SCENES`; highway-env itself is imported only when such an env is made.
"""

from hbmp_bench._lazy import lazy_exports
from hbmp_bench.transfer.registration import register_transfer_envs, transfer_env_ids
from hbmp_bench.transfer.scenes import SCENES, TransferScene, get_scene

__all__ = ["SCENES", "HighwayTransferEnv", "TransferScene", "get_scene", "register_transfer_envs",
           "run_transfer_episodes", "transfer_env_ids", "transfer_table"]

__getattr__, __dir__ = lazy_exports(__name__, {
    ".env": ("HighwayTransferEnv",),
    ".evaluate": ("run_transfer_episodes", "transfer_table"),
})
