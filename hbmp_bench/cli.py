"""``hbmp-bench``: list what exists, run agents, inspect and import maps."""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path

from hbmp_bench.errors import Interrupted, UnknownNameError, UserError
from hbmp_bench.vocabulary import FIDELITIES

COMMAND_MODULES: tuple[str, ...] = ("hbmp_bench.render.commands", "hbmp_bench.transfer.commands",
                                    "hbmp_bench.evaluation.commands", "hbmp_bench.training.commands", "hbmp_bench.bench",
                                    "hbmp_bench.site.commands")
"""Modules that add their own sub-commands: each has ``add_commands(subparsers)``, whose parsers
set ``func`` (``args -> exit code``). Keeps each room's commands beside its code."""


def _cmd_list(args: argparse.Namespace) -> int:
    from hbmp_bench.agents import AGENTS
    from hbmp_bench.envs import env_ids
    from hbmp_bench.maps import TOWNS, available_maps
    from hbmp_bench.scenarios import SCENARIO_TYPES, SUITES, TASKS

    listing = {
        "env_ids": list(env_ids()),
        "towns": list(TOWNS),
        "maps": list(available_maps()),
        "tasks": list(TASKS),
        "scenario_types": {name: f"[{k.ability}] {k.description}" for name, k in SCENARIO_TYPES.items()},
        "suites": {name: s.description for name, s in SUITES.items()},
        "agents": sorted(AGENTS),
    }
    if args.json:
        print(json.dumps(listing, indent=2))
        return 0
    for key in ("env_ids", "towns", "maps", "tasks", "agents"):
        print(f"{key}:")
        for item in listing[key]:
            print(f"  {item}")
    for key in ("scenario_types", "suites"):
        print(f"{key}:")
        for name, text in listing[key].items():
            print(f"  {name:18s} {text}")
    return 0


def _parse_env_id(env_id: str) -> tuple[str, str]:
    from hbmp_bench.envs import TRAINING_ID, env_ids

    if env_id not in env_ids() or env_id == TRAINING_ID:
        raise UnknownNameError("env id", env_id, [i for i in env_ids() if i != TRAINING_ID])
    town, task = env_id.split("/", 1)[1].rsplit("-", 1)[0].split("-", 1)
    return town, task


def _cmd_run(args: argparse.Namespace) -> int:
    from hbmp_bench.agents import load_agent
    from hbmp_bench.evaluation import Job, run_jobs
    from hbmp_bench.metrics import success_table, summarize
    from hbmp_bench.metrics.summary import SUCCESS_TABLE_TITLE, summary_lines
    from hbmp_bench.scenarios import get_suite

    town, task = _parse_env_id(args.env)
    if args.town is not None:
        from hbmp_bench.scenarios import check_town

        town = check_town(args.town)
    load_agent(args.agent)  # fail fast on a bad name, before any simulation starts
    suite = get_suite(args.suite)
    n = min(args.episodes, suite.episodes_per_task)
    if args.episodes <= 0:
        raise UserError(f"--episodes must be > 0, got {args.episodes}")
    records = run_jobs([Job(suite.name, town, task, args.agent, tuple(range(n)), args.fidelity)],
                       workers=1, progress=not args.json)
    summary = {"env": args.env, "town": town, "agent": args.agent, "suite": suite.name, **summarize(records)}
    if args.json:
        summary["records"] = [r.to_dict() for r in records]
        print(json.dumps(summary, indent=2))
    else:
        print(SUCCESS_TABLE_TITLE)
        print(success_table(records).to_string())
        print()
        print("\n".join(summary_lines(summary)))
    return 0


def _net_file(path: str) -> Path:
    """A ``.net.xml`` file given to ``maps stats`` (a SUMO net as it is, not imported)."""
    file = Path(path).expanduser()
    if not file.is_file():
        raise FileNotFoundError(f"net file not found: {path}")
    return file


def _cmd_maps(args: argparse.Namespace) -> int:
    from hbmp_bench.maps import available_maps, import_map, map_stats, net_stats, remove_map

    if args.maps_cmd == "stats":
        from hbmp_bench.maps.stats import format_stats

        names = args.names or list(available_maps())
        stats = {name: net_stats(_net_file(name)) if name.endswith(".net.xml") else map_stats(name)
                 for name in names}
        print(json.dumps(stats, indent=2) if args.json else format_stats(stats))
        return 0
    if args.maps_cmd == "import":
        path = import_map(args.file, args.name, like=args.like, sidewalks=not args.no_sidewalks,
                          guess_lights=args.guess_lights, lights=args.lights, force=args.force)
        print(f"imported {args.name}: {path}")
        return 0
    if args.maps_cmd == "remove":
        remove_map(args.name)
        print(f"removed {args.name}")
        return 0
    if args.maps_cmd == "audit":
        return _audit_maps(args)
    raise AssertionError(args.maps_cmd)


def _audit_maps(args: argparse.Namespace) -> int:
    """``maps audit``: exit 1 where the detectors flag SUMO's own driving (the disagreements are printed)."""
    from tqdm import tqdm

    from hbmp_bench.evaluation.lane_audit import audit_lane_keeping

    summaries = []
    for name in args.names:
        with tqdm(desc=f"audit {name}", unit="drive", disable=args.json, file=sys.stderr) as bar:
            def progress(done: int, total: int, bar=bar) -> None:
                bar.total = total
                bar.update(done - bar.n)

            summaries.append(audit_lane_keeping(name, args.suites, progress=progress).summary())
    if args.json:
        print(json.dumps(summaries, indent=2))
    for s in summaries if not args.json else ():
        print(f"{s['town']}: {s['drives']} drives ({s['episodes']} episodes of {', '.join(s['suites'])}), "
              f"{s['distance_km']} km: {s['wrong_lane']} wrong lane, {s['off_road']} off-road, {s['stuck']} stuck")
        for line in s["disagreements"]:
            print(f"  {line}")
        if s["stuck"]:
            print(f"  did not reach their route's end: {', '.join(s['stuck_episodes'])}")
    return 1 if any(s["wrong_lane"] or s["off_road"] for s in summaries) else 0


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Every option's help ends with its default, ``(default: X)``, unless the help already says
    it, the default is None (the option is simply absent) or the option is a switch."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        shown = action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE)
        if (shown and "default" not in text and action.default not in (None, False, argparse.SUPPRESS)
                and action.nargs != 0):
            text += " (default: %(default)s)"
        return text


def parsers(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    """``(command, parser)`` for ``parser`` and every sub-command's parser, nested ones included."""
    found = [(parser.prog, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # aliases share a parser
                found += parsers(sub)
    return found


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hbmp-bench", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="env ids, towns, tasks, suites and agents")
    p.add_argument("--json", action="store_true", help="print JSON instead of lists")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("run", help="run an agent for N episodes of one env id and print a summary")
    p.add_argument("--env", default="hbmp_bench/Town01-Navigation-v0",
                   help="env id hbmp_bench/<Town>-<Task>-v0 (hbmp-bench list shows them)")
    p.add_argument("--town", default=None, help="built-in or imported map; replaces the env id's town")
    p.add_argument("--agent", default="expert", help="registry name or module:Class")
    p.add_argument("--episodes", type=int, default=5, help="first N episodes of the suite for this town and task")
    p.add_argument("--suite", default="corl2017", help="episode suite (hbmp-bench list shows them)")
    p.add_argument("--fidelity", default=None, choices=FIDELITIES,
                   help="default: the env's (continuous, the motion planner)")
    p.add_argument("--json", action="store_true", help="print a JSON summary with every episode record")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("maps", help="map statistics, import, removal and the detectors' audit")
    msub = p.add_subparsers(dest="maps_cmd", required=True)
    q = msub.add_parser("stats", help="statistics of built-in and imported maps")
    q.add_argument("names", nargs="*", help="maps to describe side by side, or SUMO .net.xml files as they are "
                   "(e.g. CARLA's own net beside its import; default: every built-in and imported map)")
    q.add_argument("--json", action="store_true", help="print JSON")
    q = msub.add_parser("import", help="import an OpenDRIVE .xodr or SUMO .net.xml under a name (into "
                        "$HBMP_BENCH_DATA/maps, or ~/.local/share/hbmp_bench/maps when it is unset)")
    q.add_argument("file", help="OpenDRIVE .xodr or SUMO .net.xml file")
    q.add_argument("--name", required=True, help="name to use it under (--town NAME)")
    q.add_argument("--like", default=None, help="built-in town whose task parameters (CoRL2017 traffic counts, "
                   "route lengths) the map takes; default: from the map's own size")
    q.add_argument("--lights", default="source", choices=("source", "lawful"),
                   help="traffic light programs: the map's own (source) or the benchmark's lawful timing (lawful)")
    q.add_argument("--guess-lights", action="store_true", help="add lights at junctions without any")
    q.add_argument("--no-sidewalks", action="store_true",
                   help="keep a map without walkable edges so (default: guess sidewalks and crossings)")
    q.add_argument("--force", action="store_true", help="replace an imported map of the same name")
    q = msub.add_parser("remove", help="delete an imported map")
    q.add_argument("name", help="an imported map's name")
    q = msub.add_parser("audit", help="drive every route of the suites with SUMO's own driver and list where the "
                        "wrong-lane and off-road detectors disagree with it (exit 1 if anywhere)")
    q.add_argument("names", nargs="+", help="built-in or imported maps")
    q.add_argument("--suites", nargs="*", default=None, help="suites whose routes to drive; default: every suite")
    q.add_argument("--json", action="store_true", help="print JSON (no progress bar)")
    p.set_defaults(func=_cmd_maps)

    for module_name in COMMAND_MODULES:
        importlib.import_module(module_name).add_commands(sub)
    for _, each in parsers(parser):
        each.formatter_class = HelpFormatter
    return parser


EXIT_USER_ERROR = 2
"""Exit code of a user error (as argparse's own)."""
EXIT_INTERRUPTED = 130
"""Exit code after Ctrl-C (128 + SIGINT, as a shell reports it)."""

USER_ERRORS: tuple[type[BaseException], ...] = (UserError, FileNotFoundError, json.JSONDecodeError)
"""What a user's mistake raises: ``UserError`` (and so ``ConfigError``, ``UnknownNameError``,
``CheckpointError``), a file that is not there, and a user's JSON file that does not parse."""


def is_user_error(exc: BaseException) -> bool:
    """Whether ``exc`` is a mistake in the user's input (one line, no traceback) rather than a bug.

    Decided by type alone (:data:`USER_ERRORS`): the package raises ``UserError`` or one of its
    subclasses where user input enters it (options, files, plug-ins) and ``ConfigError`` from the
    configuration checks; any other exception, a plain ``ValueError`` included, is a bug and keeps
    its traceback.
    """
    return isinstance(exc, USER_ERRORS)


def _one_line(text: str) -> str:
    return " ".join(text.split()) or "(no message)"


def main(argv: list[str] | None = None) -> int:
    """Run ``hbmp-bench``; returns its exit code.

    A user error prints ``hbmp-bench: error: <what is wrong>`` on one line (exit 2). Ctrl-C stops
    the command cleanly and prints ``hbmp-bench: interrupted`` with how to resume (exit 130).
    Anything else is a bug and shows its traceback.
    """
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except KeyboardInterrupt as exc:
        detail = _one_line(str(exc)) if isinstance(exc, Interrupted) else ""
        print(f"hbmp-bench: interrupted{': ' + detail if detail else ''}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:
        if not is_user_error(exc):
            raise
        print(f"hbmp-bench: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_USER_ERROR


def console() -> None:
    """The ``hbmp-bench`` program: :func:`main` with SIGTERM (a scheduler's stop, ``kill``) and SIGINT
    handled like Ctrl-C, also where the shell started the program with SIGINT ignored (``cmd &``):
    runs close their workers and keep what is written, and print how to resume."""
    import signal

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.exit(main())


if __name__ == "__main__":
    console()
