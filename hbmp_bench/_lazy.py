"""Lazy public names of a package (PEP 562): a name's module is imported on first access.

Keeps ``import hbmp_bench`` (and the ``hbmp-bench`` command line) from importing libsumo, numba,
pandas or torch while ``from hbmp_bench.envs import BehaviorEnv`` keeps working::

    __getattr__, __dir__ = lazy_exports(__name__, {".behavior_env": ("BehaviorEnv",)})

A lazy name must not also be the name of a submodule of the package: importing that submodule
would bind the module over the name.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping


def lazy_exports(package: str, exports: Mapping[str, tuple[str, ...]]) -> tuple[Callable[[str], object],
                                                                             Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``.

    Args:
        package: the package's ``__name__``.
        exports: module (absolute, or relative to ``package`` like ``".world"``) -> the names it
            defines that the package exports. A value, once resolved, is stored in the package's
            namespace, so ``__getattr__`` runs once per name.
    """
    where = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> object:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name], package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return __getattr__, __dir__
