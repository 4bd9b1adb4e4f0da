"""Golden records: the expert's seeded episodes, the regression check of the envs redesign.

Each case runs the expert on one seeded episode and returns its episode record plus a digest of
every decision (agent, action, reward, R_t bytes, M_t bytes, termination flags), so a change of
behaviour anywhere in an episode shows, not only in its end.

The digest hashes floats bit for bit, and bits differ between CPUs: numpy's and the C library's
transcendental functions round the last bit differently on each instruction set, and a closed loop
of several planned vehicles can turn one such bit into another decision (the 4-vehicle Town02 case:
same episode record, another decision stream on a CPU without AVX-512; a 1-ulp perturbation of
numpy's sin, cos, arctan2, hypot, exp and log changes a background vehicle's 6th decision). So
``golden/records.json`` keeps each case's record and its digest per platform
(:func:`platform_label`); the test wants the record and one of the platforms' digests.

``python tests/envs/golden_records.py --write`` regenerates the file on this machine alone (for a
deliberate change of behaviour; each case runs in its own process); ``--add-platform`` adds this
machine's digests to the file and refuses unless every case's record is the stored one.
"""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

GOLDEN = Path(__file__).parent / "golden" / "records.json"

SINGLE = [  # (town, task, episode_index, fidelity)
    ("Town01", "Straight", 0, "continuous"),
    ("Town01", "Straight", 0, "event"),
    ("Town01", "NavigationDynamic", 0, "continuous"),
    ("Town01", "NavigationDynamic", 1, "event"),
    ("Town02", "OneTurn", 1, "continuous"),
    ("Town02", "OneTurn", 1, "event"),
]
MULTI = [  # (town, task, episode_index, controlled, ego_fidelity, background_fidelity, max_steps)
    ("Town01", "NavigationDynamic", 0, 3, "continuous", "event", 400),
    ("Town01", "NavigationDynamic", 0, 2, "event", "continuous", 400),
    ("Town02", "NavigationDynamic", 2, 4, "continuous", "continuous", 300),
]


def platform_label() -> str:
    """The machine as far as float rounding goes: its architecture and the highest SIMD level numpy
    dispatches to (e.g. ``x86_64, numpy SIMD X86_V3``: AVX2 and FMA, no AVX-512)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_features__ as features

    levels = sorted((k for k, found in features.items() if found and k.startswith("X86_V")), reverse=True)
    return f"{platform.machine()}, numpy SIMD {levels[0] if levels else 'baseline'}"


def case_names() -> list[str]:
    return [f"single:{t}:{k}:{i}:{f}" for t, k, i, f in SINGLE] + \
           [f"multi:{t}:{k}:{i}:{c}:{ef}:{bf}:{n}" for t, k, i, c, ef, bf, n in MULTI]


def _feed(h, agent: str, action: int, reward: float, obs: dict, term: bool, trunc: bool) -> None:
    h.update(f"{agent}|{action}|{reward:.9g}|{int(term)}{int(trunc)}|".encode())
    h.update(np.ascontiguousarray(obs["road"]).tobytes())
    h.update(np.ascontiguousarray(obs["occupancy"]).tobytes())


def run_single(town: str, task: str, index: int, fidelity: str) -> dict:
    from hbmp_bench.agents import agent_env_kwargs, load_agent
    from hbmp_bench.envs import BehaviorEnv

    agent = load_agent("expert")
    env = BehaviorEnv(town=town, task=task, fidelity=fidelity, **agent_env_kwargs(agent))
    h = hashlib.sha256()
    try:
        obs, info = env.reset(seed=index, options={"episode_index": index})
        agent.reset(info)
        _feed(h, "ego", -1, 0.0, obs, False, False)
        while True:
            action = int(agent.act(obs, info))
            obs, reward, term, trunc, info = env.step(action)
            _feed(h, "ego", action, reward, obs, term, trunc)
            if term or trunc:
                break
    finally:
        env.close()
    record = dict(info["hbmp_record"])
    record.pop("package_version", None)
    return {"record": record, "digest": h.hexdigest()}


def run_multi(town: str, task: str, index: int, controlled: int, ego_fidelity: str, background_fidelity: str,
              max_steps: int) -> dict:
    from hbmp_bench.agents import agent_env_kwargs, load_agent
    from hbmp_bench.envs import traffic_v0

    env = traffic_v0.parallel_env(town=town, task=task, episode_index=index, controlled=controlled,
                                  ego_fidelity=ego_fidelity, background_fidelity=background_fidelity,
                                  **agent_env_kwargs(load_agent("expert")))
    h = hashlib.sha256()
    try:
        obs, infos = env.reset(seed=index)
        agents = {a: load_agent("expert") for a in env.possible_agents}
        for a in env.agents:
            agents[a].reset(infos[a])
            _feed(h, a, -1, 0.0, obs[a], False, False)
        steps = 0
        while env.agents and steps < max_steps:
            actions = {a: int(agents[a].act(obs[a], infos[a])) for a in env.agents if infos[a]["decision_required"]}
            obs, rewards, terms, truncs, infos = env.step(actions)
            for a in sorted(obs):
                _feed(h, a, actions.get(a, -1), rewards[a], obs[a], terms[a], truncs[a])
            steps += 1
        ego_info = infos.get("ego", {})
        record = ego_info.get("hbmp_record") or _ego_record_so_far(env)
    finally:
        env.close()
    record = dict(record)
    record.pop("package_version", None)
    return {"record": record, "digest": h.hexdigest(), "steps": steps}


def _ego_record_so_far(env) -> dict:
    """The ego's record of an episode cut at ``max_steps``."""
    return env.record().to_dict()


def run_case(name: str) -> dict:
    kind, *args = name.split(":")
    if kind == "single":
        town, task, index, fidelity = args
        return run_single(town, task, int(index), fidelity)
    town, task, index, controlled, ef, bf, steps = args
    return run_multi(town, task, int(index), int(controlled), ef, bf, int(steps))


def _run_each_case() -> dict[str, dict]:
    """Every case, each in a fresh process (a case must not inherit another's simulation)."""
    out = {}
    for name in case_names():
        text = subprocess.run([sys.executable, __file__, name], check=True, capture_output=True, text=True).stdout
        out[name] = json.loads(text.strip().splitlines()[-1])
        print(name, out[name]["record"].get("end_reason"), out[name]["digest"][:12], file=sys.stderr)
    return out


def main() -> None:
    if sys.argv[1:] in (["--write"], ["--add-platform"]):
        label, runs = platform_label(), _run_each_case()
        stored = json.loads(GOLDEN.read_text()) if sys.argv[1] == "--add-platform" else {}
        changed = sorted(n for n in runs if stored and stored.get(n, {}).get("record") != runs[n]["record"])
        if changed:
            sys.exit(f"records differ from the stored ones, so this is no other platform of the same behaviour: {changed}")
        out = {n: {**{k: v for k, v in r.items() if k != "digest"},
                   "digests": {**stored.get(n, {}).get("digests", {}), label: r["digest"]}} for n, r in runs.items()}
        GOLDEN.parent.mkdir(exist_ok=True)
        GOLDEN.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
        return
    print(json.dumps(run_case(sys.argv[1]), sort_keys=True))


if __name__ == "__main__":
    main()
