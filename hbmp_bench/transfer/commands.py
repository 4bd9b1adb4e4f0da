"""``hbmp-bench transfer``: zero-shot evaluation of agents on highway-env scenes, and its table.

    hbmp-bench transfer scenes
    hbmp-bench transfer evaluate --agent expert random keep --episodes 50 --out results/transfer
    hbmp-bench transfer report results/transfer --markdown docs/transfer.md
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hbmp_bench.errors import UserError

TABLE_BEGIN = "<!-- transfer-table:begin -->"
TABLE_END = "<!-- transfer-table:end -->"


def add_commands(subparsers) -> None:
    p = subparsers.add_parser("transfer", help="zero-shot transfer of agents to highway-env scenes")
    sub = p.add_subparsers(dest="transfer_cmd", required=True)

    q = sub.add_parser("scenes", help="the highway-env scenes, their success rules, and the ones left out")
    q.set_defaults(func=_cmd_scenes)

    q = sub.add_parser("evaluate", help="run agents on highway-env scenes (deformed and vehicle-centric M_t)")
    q.add_argument("--agent", nargs="+", required=True, help="registry names or module:Class (several allowed)")
    q.add_argument("--scenes", nargs="*", default=None, help="default: every scene")
    q.add_argument("--episodes", type=int, default=50, help="episodes per (agent, scene, observation); seeds 0..N-1")
    q.add_argument("--observation", nargs="+", default=["deformed", "vehicle_centric"],
                   help="M_t kind(s): deformed, vehicle_centric")
    q.add_argument("--out", default=None, help="directory for the records (<stem>.jsonl) and timings")
    q.add_argument("--workers", type=int, default=1, help="worker processes (one run per process)")
    q.add_argument("--markdown", default=None, help="write the tables to this markdown file (see report)")
    q.set_defaults(func=_cmd_evaluate)

    q = sub.add_parser("report", help="the transfer tables of the records in a directory")
    q.add_argument("directory", help="folder of transfer evaluate's records")
    q.add_argument("--markdown", default=None,
                   help=f"write the tables here; an existing file keeps everything outside {TABLE_BEGIN} ... {TABLE_END}")
    q.set_defaults(func=_cmd_report)


def _cmd_scenes(args: argparse.Namespace) -> int:
    from hbmp_bench.transfer import scenes
    from hbmp_bench.transfer.registration import transfer_env_ids

    for (name, scene), env_id in zip(scenes.SCENES.items(), transfer_env_ids()):
        print(f"{env_id}")
        print(f"  {scene.description}")
        print(f"  success: {scene.success_rule}; speed limit {scene.speed_limit_mps:g} m/s")
    print("not registered: parking, racetrack, lane-keeping, two-way, exit, u-turn "
          "(reasons: hbmp_bench.transfer.scenes module docstring)")
    return 0


def _check_load(agents: list[str]) -> tuple[list[str], dict[str, str]]:
    """Agents that load, and a reason for each one that does not (unknown, missing checkpoint)."""
    from hbmp_bench.agents import load_agent

    ok, missing = [], {}
    for name in agents:
        try:
            load_agent(name)
        except Exception as exc:  # noqa: BLE001  (any plug-in failure: report it, run the others)
            missing[name] = f"{type(exc).__name__}: {exc}"
        else:
            ok.append(name)
    return ok, missing


def _cmd_evaluate(args: argparse.Namespace) -> int:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    import pandas as pd
    from tqdm import tqdm

    from hbmp_bench.envs.observation import ObservationConfig
    from hbmp_bench.transfer.evaluate import save_run, timed_run
    from hbmp_bench.transfer.scenes import SCENES, get_scene

    if args.episodes <= 0:
        raise UserError(f"--episodes must be > 0, got {args.episodes}")
    if args.workers <= 0:
        raise UserError(f"--workers must be > 0, got {args.workers}")
    scenes = [get_scene(s).name for s in (args.scenes or SCENES)]
    for kind in args.observation:
        ObservationConfig(kind=kind)
    agents, missing = _check_load(args.agent)
    for name, reason in missing.items():
        print(f"hbmp-bench transfer: agent {name!r} skipped: {reason}", file=sys.stderr)
    if not agents:
        print("hbmp-bench transfer: error: no agent could be loaded", file=sys.stderr)
        return 2
    jobs = [(a, s, args.episodes, k) for a in agents for s in scenes for k in args.observation]
    records, timing = [], []
    bar = tqdm(total=len(jobs) * args.episodes, unit="ep")

    def collect(job, result):
        recs, wall_s = result
        records.extend(recs)
        decisions = sum(r.decisions for r in recs)
        timing.append({"agent": job[0], "scene": job[1], "observation": job[3], "decisions_per_s": decisions / wall_s})
        if args.out:
            save_run(args.out, job[0], job[1], job[3], recs, wall_s)
        bar.update(len(recs))
        bar.set_postfix(success=f"{sum(r.success for r in records) / len(records):.0%}")

    try:
        if args.workers == 1:
            for job in jobs:
                collect(job, timed_run(*job))
        else:
            # spawn: the parent may have imported torch (learned agents), which is not fork-safe
            with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
                futures = [(job, pool.submit(timed_run, *job)) for job in jobs]
                for job, fut in futures:
                    collect(job, fut.result())
    finally:
        bar.close()
    if args.out:
        print(f"records: {args.out}")
    _print_tables(records, pd.DataFrame(timing), missing, args.markdown)
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from hbmp_bench.transfer.evaluate import load_runs

    records, timing = load_runs(args.directory)
    _print_tables(records, timing, {}, args.markdown)
    return 0


def _print_tables(records, timing, missing: dict[str, str], markdown: str | None) -> None:
    from hbmp_bench.metrics.report import to_markdown
    from hbmp_bench.transfer.evaluate import throughput_table, transfer_table

    rates = transfer_table(records)
    speed = throughput_table(records, timing)
    print(rates.to_string())
    print()
    print(speed.to_string())
    if markdown:
        text = "Success and collision rates [% of episodes]:\n\n" + to_markdown(rates)
        text += "\nEpisodes run and decisions per wall-clock second (one process):\n\n" + to_markdown(speed)
        if missing:
            text += "\nNot run: " + "; ".join(f"{k} ({v})" for k, v in missing.items()) + "\n"
        path = write_table_section(markdown, text)
        print(f"markdown: {path}")


def write_table_section(path: str, table_markdown: str) -> Path:
    """Put ``table_markdown`` between the table markers of ``path`` (the rest of an existing file is
    kept; a file without markers gets them appended), written to a temp file and renamed."""
    from hbmp_bench.transfer.evaluate import write_atomic

    target = Path(path)
    block = f"{TABLE_BEGIN}\n{table_markdown.rstrip()}\n{TABLE_END}"
    if target.exists():
        text = target.read_text(encoding="utf-8")
        if TABLE_BEGIN in text and TABLE_END in text and text.index(TABLE_BEGIN) < text.index(TABLE_END):
            head, _, rest = text.partition(TABLE_BEGIN)
            _, _, tail = rest.partition(TABLE_END)
            text = head + block + tail
        else:
            text = text.rstrip("\n") + "\n\n" + block + "\n"
    else:
        text = block + "\n"
    target.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(target, text)
    return target
