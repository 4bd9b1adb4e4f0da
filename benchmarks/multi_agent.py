"""The multi-agent traffic env driven by the expert: per-agent outcomes and agent-decisions per second.

    python benchmarks/multi_agent.py [--steps 300] [--counts 1 8 32] [--town Town03] [--gif docs/img/traffic.gif]

1. Report: the expert drives the ego and every controlled background agent (``controlled="all"``,
   Town01 NavigationDynamic, one episode); a pandas table of each agent's success (ego: reached the
   goal; background: never crashed), collisions, red lights and decisions.
2. Throughput: ``--steps`` env steps with 1, 8 and 32 controlled agents (``--town``, dense traffic
   so that 32 vehicles exist; event fidelity for ego and background so every step is one decision
   of every live agent). Agent-decisions/s counts each agent's decision (expert time included,
   reset excluded). Writes ``benchmarks/results/multi_agent.json`` with the machine described.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import pandas as pd

from hbmp_bench.agents import agent_env_kwargs, load_agent
from hbmp_bench.envs import traffic_v0
from hbmp_bench.envs.registration import RECORD_KEY

RESULTS = Path(__file__).parent / "results" / "multi_agent.json"
EXPERT_ENV = agent_env_kwargs(load_agent("expert"))
"""The env options the expert asks for (``privileged=True``: the ego's privileged scene)."""


def run(env, seed: int, max_steps: int, frames: list | None = None) -> tuple[pd.DataFrame, int, float]:
    """Drive every agent with its own expert; returns (per-agent table, decisions, seconds).
    ``frames``: a list to append the rendered view of every step to (env made with ``rgb_array``)."""
    obs, infos = env.reset(seed=seed)
    experts = {a: load_agent("expert") for a in env.possible_agents}
    for a in env.agents:
        experts[a].reset(infos[a])
    rows = {a: {"agent": a, "decisions": 0, "end": "running"} for a in env.possible_agents}
    last_info = dict(infos)
    decisions, start = 0, time.perf_counter()
    for _ in range(max_steps):
        actions = {a: experts[a].act(obs[a], infos[a]) for a in env.agents if infos[a]["decision_required"]}
        for a in actions:
            rows[a]["decisions"] += 1
        decisions += len(actions)
        obs, rewards, term, trunc, infos = env.step(actions)
        last_info.update(infos)
        if frames is not None and env.agents:
            frames.append(env.render())
        for a in term:
            if term[a] or trunc[a]:
                rows[a]["end"] = "terminated" if term[a] else "truncated"
        if not env.agents:
            break
    seconds = time.perf_counter() - start
    for a, row in rows.items():
        totals = last_info[a]["infractions"]
        row["collisions"] = totals["collision_vehicle"] + totals["collision_pedestrian"]
        row["red_light"] = totals["red_light"]
        row["wrong_lane"] = totals["wrong_lane"]
        if a == "ego":
            row["success"] = bool(last_info[a].get(RECORD_KEY, {}).get("success", False))
        else:
            row["success"] = row["collisions"] == 0
    return pd.DataFrame(list(rows.values())), decisions, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=300, help="env steps per throughput run")
    parser.add_argument("--report-steps", type=int, default=3000, help="env steps cap of the report episode")
    parser.add_argument("--counts", type=int, nargs="+", default=[1, 8, 32])
    parser.add_argument("--town", default="Town03")
    parser.add_argument("--gif", default=None, help="also write the first --gif-steps steps of the report episode")
    parser.add_argument("--gif-steps", type=int, default=300)
    args = parser.parse_args()

    if args.gif:
        from hbmp_bench.render import write_gif

        env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", episode_index=0, controlled="all",
                                      render_mode="rgb_array", **EXPERT_ENV)
        frames: list = []
        run(env, seed=0, max_steps=args.gif_steps, frames=frames)
        env.close()
        write_gif(frames[::2], args.gif, fps=5)
        print(f"wrote {args.gif} ({len(frames[::2])} frames)")

    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", episode_index=0, controlled="all", **EXPERT_ENV)
    table, decisions, seconds = run(env, seed=0, max_steps=args.report_steps)
    env.close()
    pd.set_option("display.width", 160)
    print(table.to_string(index=False))
    print(f"report episode: {decisions} agent-decisions in {seconds:.1f} s")

    scaling = []
    for n in args.counts:
        env = traffic_v0.parallel_env(town=args.town, task="NavigationDynamic", episode_index=0, controlled=n,
                                      density="dense", ego_fidelity="event", **EXPERT_ENV)
        _, decisions, seconds = run(env, seed=0, max_steps=args.steps)
        env.close()
        scaling.append({"controlled": n, "agents": n + 1, "env_steps": args.steps, "agent_decisions": decisions,
                        "seconds": round(seconds, 3), "agent_decisions_per_s": round(decisions / seconds, 1),
                        "env_steps_per_s": round(args.steps / seconds, 1)})
        print(scaling[-1])
    result = {
        "machine": {"platform": platform.platform(), "processor": platform.processor(), "cpu_count": os.cpu_count(),
                    "python": platform.python_version()},
        "report": {"town": "Town01", "task": "NavigationDynamic", "controlled": "all", "agents": table.to_dict("records")},
        "scaling": {"town": args.town, "task": "NavigationDynamic", "density": "dense", "runs": scaling},
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    tmp = RESULTS.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(result, indent=2, default=str))
    tmp.replace(RESULTS)
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
