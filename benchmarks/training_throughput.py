"""PPO's training throughput: learners per simulation and the overlapped update, measured in one run.

    python benchmarks/training_throughput.py [--kind hbmp|flat] [--episodes 120] [--setups 1x2 8x2 8x2+overlap]
        [--json FILE]

Each setup (``LEARNERSxWORKERS``, ``+overlap`` for ``--ppo overlap_update=true``, ``@REV`` for the code of git
revision ``REV`` instead of this checkout's: its ``hbmp_bench/`` is extracted with ``git archive`` into the
benchmark's temporary folder and put first on ``PYTHONPATH``, so a setup can be the recipe as an older commit
ran it, e.g. ``1x2@10727f3``, the single-ego run when the training-throughput target was set) trains a recipe (``--kind
hbmp``: the shipped ``hbmp``'s, PPO from ``il`` in continuous fidelity; ``flat``: ``training_runs/flat-ilrl``'s,
PPO on controls from ``flat-il``; both on ``Training-v0``, seed 0, no critic warm-up, no validation)
for ``--episodes`` episodes with ``hbmp-bench train``, one setup after the other in fresh folders, so they
meet the same machine; the ratios to the first setup are the figures to read. From each run's
``iterations.csv``: seconds per iteration after the first (the start, the first roll-out and, overlapped, the
first update are left out) and decisions per second over those iterations; the whole command's wall time
gives episodes per minute with the start included, and episodes per hour over the iterations after the first
(the steady rate a long run keeps; the first iteration holds the start and, on a fresh machine, compiling the
kernels).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time

COMMON = ["--scenario", "hbmp_bench/Training-v0", "--seed", "0", "--density", "regular", "--ppo", "anchor_kl=reverse",
          "--ppo", "anchor_coef=0.1", "--critic-warmup", "0", "--validate-every", "0", "--no-progress"]
RECIPES = {
    "hbmp": ["--fidelity", "continuous", "--road-profile", "metric", "--init", "il", *COMMON],
    "flat": ["--init", "flat-il", "--ppo", "init_std=0.1", "--ppo", "gamma=0.999", "--ppo", "lam=0.995",
             "--ppo", "mini_batch_size=256", *COMMON],
}
"""The ``hbmp-bench train`` options of each ``--kind`` (the run's own, less its validation and warm-up)."""
SETUP = re.compile(r"^(\d+)x(\d+)(\+overlap)?(?:@([0-9A-Za-z][0-9A-Za-z._/~^-]*))?$")
REPOSITORY = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def parse_setup(text: str) -> tuple[int, int, bool, str | None]:
    """``"8x2+overlap"`` -> (learners per simulation, workers, overlapped update, None); ``"1x2@10727f3"`` -> (1, 2,
    False, "10727f3")."""
    match = SETUP.match(text)
    if not match:
        raise argparse.ArgumentTypeError(
            f"a setup is LEARNERSxWORKERS, optionally followed by +overlap and @REV (a git revision), got {text!r}")
    return int(match.group(1)), int(match.group(2)), bool(match.group(3)), match.group(4)


def code_of(revision: str, folder: str) -> str:
    """The folder holding revision ``revision``'s ``hbmp_bench/`` (extracted once into ``folder``)."""
    source = os.path.join(folder, "code-" + revision.replace("/", "_"))
    if not os.path.isdir(source):
        archive = subprocess.run(["git", "-C", REPOSITORY, "archive", revision, "hbmp_bench"], capture_output=True)
        if archive.returncode != 0:
            raise SystemExit(f"@{revision}: git archive failed: {archive.stderr.decode().strip()}")
        os.makedirs(source)
        subprocess.run(["tar", "-x", "-C", source], input=archive.stdout, check=True)
    return source


def measure(setup: str, episodes: int, folder: str, kind: str = "hbmp") -> dict:
    """Train one setup of ``kind`` in ``folder``; its throughput figures."""
    from hbmp_bench.training.runlog import read_csv

    agents, workers, overlap, revision = parse_setup(setup)
    out = os.path.join(folder, re.sub(r"[^0-9A-Za-z._-]", "-", setup))
    command = [sys.executable, "-m", "hbmp_bench.cli", "train", kind, *RECIPES[kind], "--episodes", str(episodes),
               "--workers", str(workers), "--out", out]
    if agents != 1 or revision is None:  # commits before many learners per simulation have no --agents
        command += ["--agents", str(agents)]
    if overlap:
        command += ["--ppo", "overlap_update=true"]
    env = dict(os.environ)
    if revision is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [code_of(revision, folder), env.get("PYTHONPATH")]))
    start = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env, cwd=folder)
    if done.returncode != 0:
        raise SystemExit(f"{setup}: hbmp-bench train failed: {done.stderr.strip().splitlines()[-1:]}")
    wall = time.perf_counter() - start
    rows = read_csv(os.path.join(out, "iterations.csv"))
    wall_s, decisions, finished = rows["wall_s"], rows["decisions"], rows["episode"]
    if len(wall_s) < 3:
        raise SystemExit(f"{setup}: {len(wall_s)} iterations in {episodes} episodes; give more --episodes")
    per_iteration = float((wall_s[-1] - wall_s[0]) / (len(wall_s) - 1))
    return {"setup": setup, "agents": agents, "workers": workers, "overlap_update": overlap,
            "iterations": int(len(wall_s)), "s_per_iteration": round(per_iteration, 2),
            "decisions_per_s": round(float(decisions[-1] - decisions[0]) / float(wall_s[-1] - wall_s[0]), 1),
            "episodes_per_min": round(60.0 * episodes / wall, 1),
            "episodes_per_h": round(3600.0 * float(finished[-1] - finished[0]) / float(wall_s[-1] - wall_s[0])),
            "wall_s": round(wall, 1)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kind", choices=sorted(RECIPES), default="hbmp", help="the recipe trained (default hbmp)")
    parser.add_argument("--episodes", type=int, default=120, help="episodes per setup (default 120)")
    parser.add_argument("--setups", nargs="+", default=["1x2", "8x2", "8x2+overlap"], type=str,
                        help="LEARNERSxWORKERS[+overlap] each (default: 1x2 8x2 8x2+overlap); ratios to the first")
    parser.add_argument("--json", default=None, metavar="FILE", help="also write the results to FILE")
    args = parser.parse_args(argv)
    for setup in args.setups:
        parse_setup(setup)  # every setup checked before the first one trains
    with tempfile.TemporaryDirectory(prefix="hbmp-train-bench-") as folder:
        rows = [measure(setup, args.episodes, folder, args.kind) for setup in args.setups]
    base = rows[0]
    for row in rows:
        row["decisions_per_s_ratio"] = round(row["decisions_per_s"] / base["decisions_per_s"], 2)
        row["episodes_per_min_ratio"] = round(row["episodes_per_min"] / base["episodes_per_min"], 2)
        row["episodes_per_h_ratio"] = round(row["episodes_per_h"] / base["episodes_per_h"], 2)
    print(f"{'setup':<20}{'s/iteration':>12}{'decisions/s':>13}{'x':>6}{'episodes/min':>14}{'x':>6}"
          f"{'episodes/h':>12}{'x':>6}")
    for r in rows:
        print(f"{r['setup']:<20}{r['s_per_iteration']:>12}{r['decisions_per_s']:>13}{r['decisions_per_s_ratio']:>6}"
              f"{r['episodes_per_min']:>14}{r['episodes_per_min_ratio']:>6}{r['episodes_per_h']:>12}"
              f"{r['episodes_per_h_ratio']:>6}")
    if args.json:
        result = {"kind": args.kind, "episodes": args.episodes, "machine": f"{platform.system()} {platform.machine()}, "
                  f"{os.cpu_count()} cores, Python {platform.python_version()}", "setups": rows}
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
