"""``hbmp-bench site``: build the static leaderboard website (:mod:`hbmp_bench.site.build`)."""

from __future__ import annotations

import argparse
import time


def _cmd_site(args: argparse.Namespace) -> int:
    from hbmp_bench.site.build import build_site

    start = time.perf_counter()
    result = build_site(args.out, boards_root=args.boards, gifs=args.gifs)
    print(f"wrote {len(result.pages)} pages to {result.out} ({result.total_bytes / 1e6:.1f} MB with the raw "
          f"results files) in {time.perf_counter() - start:.1f} s; open {result.out / 'index.html'}")
    return 0


def add_commands(subparsers) -> None:
    """Add ``site`` to the ``hbmp-bench`` sub-commands."""
    p = subparsers.add_parser("site", help="build the static leaderboard website from the committed boards "
                              "(opens from the file system: DIR/index.html)")
    p.add_argument("--out", required=True, help="folder to write the site into (replaced if an earlier build)")
    p.add_argument("--boards", default="leaderboards", help="the boards' folder: <suite>/ and <group>/<suite>/ "
                   "folders of results files")
    p.add_argument("--gifs", type=int, default=0, help="record this many failed episodes per agent as GIFs "
                   "(one SUMO run each; 0: list the replay commands only)")
    p.set_defaults(func=_cmd_site)
