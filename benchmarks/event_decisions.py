"""Decisions per second of the event-fidelity env with the expert (Town01 Navigation dynamic).

    python benchmarks/event_decisions.py [--episodes 5] [--json]

Counts env.step calls (one decision = one 0.1 s SUMO step in event fidelity) over whole episodes,
agent time included, reset time excluded.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

from hbmp_bench.agents import agent_env_kwargs, load_agent
from hbmp_bench.envs import BehaviorEnv


def measure(town: str, task: str, episodes: int) -> dict:
    agent = load_agent("expert")
    env = BehaviorEnv(town=town, task=task, **agent_env_kwargs(agent))
    decisions, seconds = 0, 0.0
    for index in range(episodes):
        obs, info = env.reset(seed=index, options={"episode_index": index})
        agent.reset(info)
        start = time.perf_counter()
        while True:
            obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
            decisions += 1
            if terminated or truncated:
                break
        seconds += time.perf_counter() - start
    env.close()
    return {"town": town, "task": task, "episodes": episodes, "decisions": decisions,
            "seconds": round(seconds, 3), "decisions_per_s": round(decisions / seconds, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [measure("Town01", task, args.episodes) for task in ("Navigation", "NavigationDynamic")]
    result = {"machine": f"{platform.processor() or platform.machine()}, {platform.python_version()}", "rows": rows}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for r in rows:
            print(f"{r['town']} {r['task']:18s} {r['decisions_per_s']:8.1f} decisions/s ({r['decisions']} in {r['seconds']} s)")


if __name__ == "__main__":
    main()
