"""Regenerate town nets: ``python -m hbmp_bench.maps.generate [Town01 ...] [--out DIR]``.

Without town names every built-in town is rebuilt; without ``--out`` the shipped files
in ``hbmp_bench/maps/data/`` are overwritten. ``--plain`` also keeps the plain XML.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import UnknownNameError
from .builder import build_spec
from .registry import DATA_DIR
from .stats import net_stats
from .towns import TOWNS, town_spec


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("towns", nargs="*", default=list(TOWNS))
    parser.add_argument("--out", type=Path, default=DATA_DIR)
    parser.add_argument("--plain", action="store_true", help="keep the plain XML too")
    args = parser.parse_args(argv)
    for name in args.towns:
        if name not in TOWNS:
            raise UnknownNameError("town", name, TOWNS)
        path = build_spec(town_spec(name), args.out, keep_plain=args.plain)
        print(name, path, json.dumps(net_stats(path)))


if __name__ == "__main__":
    main()
