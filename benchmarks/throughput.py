"""Throughput of hbmp_bench against raw SUMO and highway-env, in one run (a few minutes).

    python benchmarks/throughput.py [--quick] [--json] [--out FILE]

Prints a table and writes ``benchmarks/results/throughput.json`` (machine described inside).
The same as ``hbmp-bench bench --out benchmarks/results/throughput.json``; the method is documented
in :mod:`hbmp_bench.bench`.
"""

from __future__ import annotations

import sys
from pathlib import Path

from hbmp_bench.cli import main

RESULT = Path(__file__).resolve().parent / "results" / "throughput.json"

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv and "--profile" not in argv:
        argv += ["--out", str(RESULT)]
    sys.exit(main(["bench", *argv]))
