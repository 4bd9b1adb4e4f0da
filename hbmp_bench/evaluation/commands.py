"""Sub-commands ``evaluate``, ``report`` and ``leaderboard {submit,add,audit,render}`` of ``hbmp-bench``."""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path

from hbmp_bench.errors import UserError


def _missing_extra_is_user_error(func):
    """A missing optional dependency (the ray extra) becomes a ValueError: exit code 2 with its message."""

    @functools.wraps(func)
    def wrapper(args: argparse.Namespace) -> int:
        try:
            return func(args)
        except ImportError as exc:
            if "hbmp-bench[" not in str(exc):
                raise
            raise UserError(str(exc)) from exc

    return wrapper


def _limits(args: argparse.Namespace):
    from hbmp_bench.evaluation.tasks import RunnerLimits

    def unless_0(value):
        return None if value == 0 else value

    return RunnerLimits(decision_timeout_s=args.decision_timeout, watchdog_s=args.watchdog,
                        agent_memory_mb=unless_0(args.agent_memory_mb), agent_cpu_s=unless_0(args.agent_cpu_s),
                        agent_user=args.agent_user or None, trust_agent=args.trust_agent)


def _add_selection(p: argparse.ArgumentParser, agent_default: str | None) -> None:
    p.add_argument("--suite", default="corl2017", help="episode suite (hbmp-bench list shows them)")
    if agent_default is None:
        p.add_argument("--agent", required=True, help="registry name, module:Class or checkpoint")
    else:
        p.add_argument("--agent", default=agent_default, help="registry name, module:Class or checkpoint")
    p.add_argument("--towns", "--town", nargs="*", help="built-in or imported maps; default: the suite's")
    p.add_argument("--tasks", nargs="*", help="Straight, OneTurn, Navigation, NavigationDynamic; default: the suite's")
    p.add_argument("--episodes", type=int, default=None, help="first N episodes per (town, task); default: all")
    p.add_argument("--fidelity", default=None, help="world fidelity; default: the env's default (recorded)")
    p.add_argument("--workers", type=int, default=None, help="parallel slots; default: one per core")
    p.add_argument("--backend", default="process", help="process (default) or ray")
    p.add_argument("--address", default=None, help="Ray cluster address; default: a local Ray instance")
    p.add_argument("--decision-timeout", type=float, default=10.0, help="seconds per agent decision [s]")
    p.add_argument("--watchdog", type=float, default=120.0, help="seconds without simulation progress [s]")
    from hbmp_bench.evaluation.tasks import RunnerLimits

    default = RunnerLimits()
    p.add_argument("--agent-memory-mb", type=int, default=default.agent_memory_mb,
                   help=f"address space of the agent process [MiB] (default {default.agent_memory_mb}; 0: no limit)")
    p.add_argument("--agent-cpu-s", type=int, default=default.agent_cpu_s,
                   help=f"CPU time of the agent process per episode [s] (default {default.agent_cpu_s}; 0: no limit)")
    p.add_argument("--agent-user", default=default.agent_user,
                   help=f"when run as root, the unprivileged user the agent process runs as (default "
                        f"{default.agent_user}); '' keeps root: only for trusted agents")
    p.add_argument("--trust-agent", action="store_true",
                   help="run an agent that brings its own code or checkpoint without the namespace sandbox (forked, "
                        "with only its session, limits and --agent-user): only for an agent you trust, or a host "
                        "without bubblewrap or namespaces, where untrusted agents are otherwise refused (see README)")
    p.add_argument("--salted", action="store_true",
                   help="salted episodes: traffic, pedestrians and light phases take a secret salt, revealed "
                        "when the run is complete (an agent cannot rebuild its episodes; see README)")
    p.add_argument("--json", action="store_true", help="print a JSON summary (no progress bar)")


@_missing_extra_is_user_error
def _cmd_evaluate(args: argparse.Namespace) -> int:
    from hbmp_bench.evaluation.evaluate import evaluate
    from hbmp_bench.metrics.report import VIEW_LEGENDS, records_frame, success_table
    from hbmp_bench.metrics.summary import SUCCESS_TABLE_TITLE, summarize, summary_lines

    result = evaluate(args.suite, args.agent, towns=args.towns, tasks=args.tasks, episodes=args.episodes,
                      fidelity=args.fidelity, out_dir=args.out, workers=args.workers, backend=args.backend,
                      address=args.address, limits=_limits(args), progress=not args.json, salted=args.salted)
    from hbmp_bench.metrics.report import EXCLUDED, multi_table
    from hbmp_bench.metrics.summary import scene_summary
    from hbmp_bench.scenarios import get_suite

    scene = get_suite(args.suite).agents > 1
    summary = {"records": str(result.path), "ran": result.ran, "skipped": result.skipped,
               "missing": result.missing, "wall_s": round(result.wall_s, 2), "sim_errors": result.sim_errors,
               "agent_errors": result.agent_errors, **summarize(result.records)}
    if scene:
        summary.update(scene_summary([r for r in result.records if r.end_reason not in EXCLUDED]))
    if args.salted:
        summary.update(salt_commitment=result.salt_commitment, salt=result.salt or "(revealed once every episode is recorded)")
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    if result.records:
        print(SUCCESS_TABLE_TITLE)
        print(success_table(records_frame(result.records)).to_string())
        print()
    if result.records and scene:
        print(VIEW_LEGENDS["multi"])
        print(multi_table(records_frame(result.records)).to_string())
        print()
    print("\n".join(summary_lines(summary)))
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from hbmp_bench.metrics.report import VIEW_LEGENDS, build_report, load_results, readable, view_rows, write_report
    from hbmp_bench.scenarios import check_task

    results = load_results(args.paths)
    if args.tasks:
        results = results[results["task"].isin([check_task(t) for t in args.tasks])]
        if results.empty:
            raise UserError(f"the results hold no episode of the tasks {args.tasks}")
    rep = build_report(results)
    first = Path(args.paths[0])
    out = Path(args.out) if args.out else (first if first.is_dir() else first.parent) / "report"
    written = write_report(rep, out)
    if args.json:
        print(json.dumps({"written": [str(p) for p in written],
                          **{name: view_rows(view) for name, view in rep.views.items()}}, indent=2))
        return 0
    for name, view in rep.views.items():
        print(f"== {name}: {VIEW_LEGENDS[name]}")
        print(readable(view).to_string() if not view.empty else "(no episodes)")
        print()
    print(f"written to {out}/ (CSV, markdown, failures.png, report.md)")
    return 0


@_missing_extra_is_user_error
def _cmd_leaderboard(args: argparse.Namespace) -> int:
    from hbmp_bench.evaluation import leaderboard

    if args.leaderboard_cmd == "submit":
        path, doc = leaderboard.submit(
            args.suite, args.agent, board_dir=args.board_dir, towns=args.towns, tasks=args.tasks,
            episodes=args.episodes, fidelity=args.fidelity, workers=args.workers, backend=args.backend,
            address=args.address, limits=_limits(args), records_dir=args.records_dir, progress=not args.json,
            salted=args.salted)
        info = {"results": str(path), "complete": doc["complete"], "subset": doc["subset"], **doc["summary"]}
        print(json.dumps(info, indent=2) if args.json else "\n".join(f"{k:24s} {v}" for k, v in info.items()))
        return 0
    if args.leaderboard_cmd == "add":
        print(f"added {leaderboard.add_results(args.file, args.board_dir)}")
        return 0
    if args.leaderboard_cmd == "render":
        print(f"wrote {leaderboard.render_readme(args.board_dir, args.suite)}")
        return 0
    if args.leaderboard_cmd == "audit":
        from hbmp_bench.evaluation.audit import audit, audit_lines
        from hbmp_bench.evaluation.tasks import RunnerLimits

        result = audit(args.entry, args.agent, args.sample, seed=args.seed, max_sim_s=args.max_sim_s,
                       workers=args.workers, limits=RunnerLimits(decision_timeout_s=args.decision_timeout),
                       progress=not args.json)
        print("\n".join(audit_lines(result, args.json)))
        return 0 if result.ok else 1
    raise AssertionError(args.leaderboard_cmd)


def _cmd_agreement(args: argparse.Namespace) -> int:
    import json

    from hbmp_bench.evaluation.agreement import agreement
    from hbmp_bench.scenarios import check_town, get_suite

    suite = get_suite(args.suite)
    town = check_town(args.town) if args.town else suite.towns[0]
    task = args.task or ("NavigationDynamic" if "NavigationDynamic" in suite.tasks else suite.tasks[0])
    if task not in suite.tasks:
        raise UserError(f"suite {suite.name} has no task {task!r}; its tasks: {', '.join(suite.tasks)}")
    results = agreement(args.agent, args.others, suite.name, town, task, args.episodes, fidelity=args.fidelity,
                        progress=not args.json)
    if args.json:
        print(json.dumps([r.to_dict() for r in results], indent=2))
        return 0
    print(f"{args.agent} drove {args.episodes} {suite.name} {town} {task} episodes; in its states the others chose:")
    for r in results:
        print(f"\n{r.agent}: {r.differ} of {r.decisions} decisions differ ({r.differ_pct:.1f} %)")
        for (mine, theirs, where), n in r.pairs.most_common(args.top):
            print(f"  {n:6d}  {mine} -> {theirs}  ({where})")
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``evaluate``, ``report`` and ``leaderboard`` to the ``hbmp-bench`` parser."""
    p = sub.add_parser("evaluate", help="run an agent on a suite (towns x tasks), isolated and resumable")
    _add_selection(p, agent_default="expert")
    p.add_argument("--out", default="runs", help="folder of the records file <suite>__<agent>.jsonl (default: runs)")
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("agreement", help="how far other policies' choices differ from one driver's, state by state")
    p.add_argument("--agent", default="il", help="the driver: registry name or checkpoint (default: il)")
    p.add_argument("--with", dest="others", nargs="+", required=True, metavar="AGENT",
                   help="agents asked in the driver's states (registry names or checkpoints)")
    p.add_argument("--suite", default="hbmp-val", help="episode suite (default: hbmp-val, no test episodes)")
    p.add_argument("--town", default=None, help="map (default: the suite's first town)")
    p.add_argument("--task", default=None, help="task (default: NavigationDynamic where the suite has it)")
    p.add_argument("--episodes", type=int, default=8, help="first N episodes (default: 8)")
    p.add_argument("--fidelity", default=None, help="world fidelity (default: the env's)")
    p.add_argument("--top", type=int, default=8, help="differing pairs shown per agent (default: 8)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_cmd_agreement)

    p = sub.add_parser("report", help="tables (CSV, markdown) and a failure bar chart from records")
    p.add_argument("paths", nargs="+", metavar="DIR", help="records (.jsonl) or leaderboard results (.json) "
                   "files, or folders of them (e.g. leaderboards/hbmp: every entry of that board)")
    p.add_argument("--tasks", nargs="+", default=None, metavar="TASK",
                   help="only these tasks (e.g. NavigationDynamic: the paper's figure of outcomes per town)")
    p.add_argument("--out", default=None, help="output folder (default: <first DIR>/report)")
    p.add_argument("--json", action="store_true", help="print every view as JSON rows (inf as null)")
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser("leaderboard", help="submit an agent to a suite's leaderboard, add or render results")
    lsub = p.add_subparsers(dest="leaderboard_cmd", required=True)
    q = lsub.add_parser("submit", help="evaluate an agent and write leaderboards/<suite>/<agent>.<fidelity>.json")
    _add_selection(q, agent_default=None)
    q.add_argument("--board-dir", default="leaderboards", help="leaderboard folder (default: leaderboards)")
    q.add_argument("--records-dir", default=None, help="raw records (default: <board>/<suite>/runs/<hash>)")
    q = lsub.add_parser("add", help="check a results file made elsewhere and add it to its board")
    q.add_argument("file", help="results JSON written by leaderboard submit")
    q.add_argument("--board-dir", default="leaderboards", help="leaderboard folder")
    q = lsub.add_parser("audit", help="replay random episodes of an entry with an agent; exit 1 unless every "
                        "record matches field by field")
    q.add_argument("entry", help="a results file (leaderboards/<suite>/<agent>.<fidelity>.json)")
    q.add_argument("--agent", required=True, help="the agent to replay: registry name, module:Class or checkpoint")
    q.add_argument("--sample", type=int, default=5, help="episodes to replay, drawn at random (default 5)")
    q.add_argument("--seed", type=int, default=None, help="seed of the draw (default: fresh randomness)")
    q.add_argument("--max-sim-s", type=float, default=None,
                   help="draw only episodes that lasted at most this many simulated seconds [s] (a quick audit)")
    q.add_argument("--workers", type=int, default=1, help="parallel slots (default 1)")
    q.add_argument("--decision-timeout", type=float, default=10.0, help="seconds per agent decision [s]")
    q.add_argument("--json", action="store_true", help="print the audit as JSON (no progress bar)")
    q = lsub.add_parser("render", help="regenerate <board>/<suite>/README.md")
    q.add_argument("--suite", default="corl2017", help="the suite whose board to render")
    q.add_argument("--board-dir", default="leaderboards", help="leaderboard folder")
    p.set_defaults(func=_cmd_leaderboard)
