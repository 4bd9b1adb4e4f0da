"""What the privileged scene costs: event-fidelity ``env.step`` time with and without ``privileged=True``.

    python benchmarks/privileged_scene.py [--decisions 600] [--rounds 3] [--json]

The expert drives one episode of Town01 NavigationDynamic (hbmp suite: lights, traffic,
pedestrians) in a privileged env, and its actions are recorded. Both envs then replay those
actions from the same reset, round after round in alternating order, so a loaded machine slows
both alike; each replay has its own env, the only simulation open, so both run on libsumo (a second
open one would run over TraCI, see :mod:`hbmp_bench.sim.sumo`); only ``env.step`` is timed (no agent,
no reset, no warm-up). Both replays see the same M_t and
R_t (``tests/envs/test_privileged.py``).
"""

from __future__ import annotations

import argparse
import json
import platform
import time

from hbmp_bench.agents import agent_env_kwargs, load_agent
from hbmp_bench.envs import BehaviorEnv

SCENARIO = {"town": "Town01", "task": "NavigationDynamic", "suite": "hbmp", "fidelity": "event"}


def expert_actions(decisions: int) -> list[int]:
    """The expert's first ``decisions`` actions on episode 0 (fewer if it ends before)."""
    agent = load_agent("expert")
    env = BehaviorEnv(**SCENARIO, **agent_env_kwargs(agent))
    actions = []
    try:
        obs, info = env.reset(seed=0, options={"episode_index": 0})
        agent.reset(info)
        while len(actions) < decisions:
            actions.append(int(agent.act(obs, info)))
            obs, _, terminated, truncated, info = env.step(actions[-1])
            if terminated or truncated:
                break
    finally:
        env.close()
    return actions


def replay(env: BehaviorEnv, actions: list[int]) -> float:
    """Seconds spent in ``env.step`` replaying ``actions`` from the episode's reset."""
    env.reset(seed=0, options={"episode_index": 0})
    spent = 0.0
    for action in actions:
        start = time.perf_counter()
        env.step(action)
        spent += time.perf_counter() - start
    return spent


def measure(decisions: int, rounds: int) -> dict:
    actions = expert_actions(decisions)
    spent = {True: 0.0, False: 0.0}
    for k in range(rounds):
        for mode in ((True, False) if k % 2 == 0 else (False, True)):
            env = BehaviorEnv(**SCENARIO, privileged=mode)  # one simulation open at a time
            try:
                replay(env, actions[:20])  # warm-up: the first reset loads the network and fills caches
                spent[mode] += replay(env, actions)
            finally:
                env.close()
    steps = len(actions) * rounds
    with_ms, without_ms = 1e3 * spent[True] / steps, 1e3 * spent[False] / steps
    return {"scenario": SCENARIO, "decisions": len(actions), "rounds": rounds,
            "step_ms_privileged": round(with_ms, 3), "step_ms_default": round(without_ms, 3),
            "default_over_privileged": round(without_ms / with_ms, 3),
            "machine": f"{platform.processor() or platform.machine()}, {platform.python_version()}"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--decisions", type=int, default=600)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result = measure(args.decisions, args.rounds)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"event-fidelity env.step over {result['decisions']} decisions x {result['rounds']} rounds: "
              f"privileged {result['step_ms_privileged']:.3f} ms, default {result['step_ms_default']:.3f} ms, "
              f"ratio default/privileged {result['default_over_privileged']:.3f}")


if __name__ == "__main__":
    main()
