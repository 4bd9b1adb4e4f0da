"""SUMO road networks of the benchmark: CARLA Town01-Town05 recreated, plus user maps.

* :data:`TOWNS`, :func:`available_maps`, :func:`net_path`, :func:`user_maps_dir`:
  where the ``.net.xml`` files are.
* :func:`build_town`: rebuild a town from its declarative spec (``towns/``) with the one
  general builder (``builder.py``) and netconvert; ``python -m hbmp_bench.maps.generate``
  rebuilds every shipped net.
* :func:`map_stats`: lengths (m), lane counts, junction counts, extent (m).
* :func:`import_map`: add an OpenDRIVE ``.xodr`` or SUMO ``.net.xml`` under a new name.
"""

from __future__ import annotations

from .builder import build_town
from .importer import import_map
from .registry import available_maps, net_path, user_maps_dir
from .stats import net_stats
from .towns import TOWNS


def map_stats(name: str) -> dict:
    """Statistics of map ``name`` (built-in or imported); see :func:`net_stats`.

    Raises UnknownNameError for an unknown name.
    """
    return net_stats(net_path(name))


__all__ = ["TOWNS", "available_maps", "build_town", "import_map", "map_stats", "net_path",
           "net_stats", "user_maps_dir"]
