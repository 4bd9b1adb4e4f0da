"""hbmp_bench: hierarchical behavior and motion planning benchmark on SUMO.

Importing the package registers the gymnasium ids ``hbmp_bench/<Town>-<Task>-v0`` (and the
highway-env transfer ids ``hbmp_bench/HighwayTransfer-<scene>-v0``) with ``module:Class`` entry
points; nothing starts SUMO at import, and libsumo, sumolib, numba, pandas, torch and highway-env
are imported where they are used, so the import stays cheap (``hbmp-bench bench`` reports ``import_s``).
"""

__version__ = "0.1.0"

from hbmp_bench.envs.registration import register_envs as _register_envs  # noqa: E402
from hbmp_bench.transfer.registration import register_transfer_envs as _register_transfer_envs  # noqa: E402

_register_envs()
_register_transfer_envs()
