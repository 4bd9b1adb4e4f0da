"""hbmp_bench: hierarchical behavior and motion planning benchmark on SUMO.

Importing the package registers the gymnasium ids ``hbmp_bench/<Town>-<Task>-v0``; nothing
starts SUMO at import.
"""

__version__ = "0.1.0"

from hbmp_bench.envs.registration import register_envs as _register_envs  # noqa: E402

_register_envs()
