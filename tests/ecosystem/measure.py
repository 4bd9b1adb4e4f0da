"""The figures of docs/recipes.md: time and memory of stepping one env with ``render_mode="rgb_array"``
against ``None``, and the frames per second of SB3's ``SubprocVecEnv`` (2 envs) made by
``make_vec_env`` with its default render mode and with rendering off. Event fidelity, random
actions, reset at every episode end, as a trainer steps it.

    python tests/ecosystem/measure.py [--steps 1500] [--long 5000] [--vec-steps 600]

Prints one JSON line per run. Memory is the process's resident set size growth [MB] over the run.
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import gymnasium as gym
import numpy as np

ENV_ID = "hbmp_bench:hbmp_bench/Town01-NavigationDynamic-v0"  # "module:id": a subprocess imports it
OPTIONS = dict(fidelity="event", episode_index=0)


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def run_one(render_mode: str | None, steps: int) -> dict:
    import hbmp_bench  # noqa: F401  (registers the ids)

    env = gym.make(ENV_ID, render_mode=render_mode, **OPTIONS)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    before, start, episodes = rss_mb(), time.perf_counter(), 0
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(int(rng.integers(5)))
        if term or trunc:
            episodes += 1
            env.reset()
    elapsed = time.perf_counter() - start
    grown = rss_mb() - before
    env.close()
    return {"render_mode": render_mode, "steps": steps, "seconds": round(elapsed, 2), "rss_growth_mb": round(grown, 1),
            "episodes_ended": episodes}


def run_vec(render: bool, steps: int) -> dict:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    kwargs = dict(OPTIONS) if render else dict(OPTIONS, render_mode=None)  # SB3's default: "rgb_array"
    vec = make_vec_env(ENV_ID, n_envs=2, seed=0, vec_env_cls=SubprocVecEnv, env_kwargs=kwargs)
    vec.reset()
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    for _ in range(steps):
        vec.step(rng.integers(5, size=2))
    fps = 2 * steps / (time.perf_counter() - start)
    vec.close()
    return {"render_mode": "rgb_array (make_vec_env's default)" if render else None, "fps": round(fps, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--long", type=int, default=5000, help="steps of the memory run with rgb_array (0: skip)")
    parser.add_argument("--vec-steps", type=int, default=600)
    args = parser.parse_args()
    runs = [lambda: run_one(None, args.steps), lambda: run_one("rgb_array", args.steps)]
    if args.long:
        runs.append(lambda: run_one("rgb_array", args.long))
    if args.vec_steps:
        runs += [lambda: run_vec(False, args.vec_steps), lambda: run_vec(True, args.vec_steps)]
    for run in runs:
        print(json.dumps(run()), flush=True)


if __name__ == "__main__":
    main()
