"""SUMO road networks of the benchmark: CARLA Town01-Town05 recreated, plus user maps.

* :data:`TOWNS`, :func:`available_maps`, :func:`net_path`, :func:`user_maps_dir`:
  where the ``.net.xml`` files are.
* :func:`build_town`: rebuild a town from its declarative spec (``towns/``) with the one
  general builder (``builder.py``) and netconvert; ``python -m hbmp_bench.maps.generate``
  rebuilds every shipped net.
* :func:`map_stats`: lengths (m), lane counts, junction counts, extent (m).
* :func:`import_map`: add an OpenDRIVE ``.xodr`` or SUMO ``.net.xml`` under a new name;
  :func:`map_info` (its provenance), :func:`remove_map`, :func:`map_hash` (what records are keyed to).
"""

from __future__ import annotations

from .builder import build_town
from .importer import LIGHTS, import_map, map_info, remove_map
from .registry import available_maps, map_hash, net_path, user_maps, user_maps_dir
from .stats import net_stats
from .towns import TOWNS


def map_stats(name: str) -> dict:
    """Statistics of map ``name`` (built-in or imported); see :func:`net_stats`. An imported map's
    add ``import``: its provenance (:func:`map_info`: source, hashes, netconvert options, ``lights``
    ``source`` or ``lawful``, the source's light count ``source_tls``, guesses, closed lanes).

    Raises UnknownNameError for an unknown name.
    """
    stats = net_stats(net_path(name))
    if name not in TOWNS:
        stats["import"] = map_info(name)
    return stats


__all__ = ["LIGHTS", "TOWNS", "available_maps", "build_town", "import_map", "map_hash", "map_info", "map_stats",
           "net_path", "net_stats", "remove_map", "user_maps", "user_maps_dir"]
