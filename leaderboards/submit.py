#!/usr/bin/env python
"""Submit an agent to a leaderboard: ``python leaderboards/submit.py --suite corl2017 --agent NAME [--workers N]``.

The same as ``hbmp-bench leaderboard submit``; run from the repository root so results land in
``leaderboards/<suite>/``. See leaderboards/README.md.
"""

import sys

from hbmp_bench.cli import main

if __name__ == "__main__":
    sys.exit(main(["leaderboard", "submit", *sys.argv[1:]]))
