"""The declarative specs of the built-in towns, one small module per town."""

from __future__ import annotations

from importlib import import_module

from ..spec import TownSpec

#: Built-in town names, in order.
TOWNS: tuple[str, ...] = ("Town01", "Town02", "Town03", "Town04", "Town05")


def town_spec(name: str) -> TownSpec:
    """The :class:`TownSpec` of built-in town ``name`` (KeyError if unknown)."""
    if name not in TOWNS:
        raise KeyError(name)
    return import_module(f".{name.lower()}", __name__).SPEC
