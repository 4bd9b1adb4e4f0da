"""``hbmp-bench record`` (an episode as a GIF), ``hbmp-bench plot-planner`` (the planner figure) and
``hbmp-bench plot-stopping`` (the stopping-distance figure)."""

from __future__ import annotations

import argparse
import json


def _cmd_record(args: argparse.Namespace) -> int:
    from PIL import Image

    from hbmp_bench.envs.recording import record_episode

    town = {} if args.town is None else {"town": args.town}
    record = record_episode(args.env, args.agent, args.out, episode_index=args.episode, suite=args.suite,
                            fidelity=args.fidelity, max_decisions=args.max_decisions, every=args.every,
                            fps=args.fps, progress=not args.json, **town)
    if args.json:
        print(json.dumps(record, indent=2))
        return 0
    with Image.open(args.out) as image:
        n_frames = getattr(image, "n_frames", 1)
    print(f"wrote {args.out} ({n_frames} frames)")
    for key in ("town", "task", "episode", "success", "route_completion", "end_reason", "duration_s", "decisions"):
        print(f"  {key:18s} {record.get(key)}")
    return 0


def _cmd_plot_planner(args: argparse.Namespace) -> int:
    from hbmp_bench.render.planner_figure import planner_figure

    costs = planner_figure(args.out, town=args.town, synthetic=args.synthetic)
    if args.json:
        print(json.dumps(costs, indent=2))
        return 0
    print(f"wrote {args.out}")
    print(f"  {'behavior':14s} {'c_velocity':>11s} {'c_dist':>9s} {'c_obs':>9s} {'c_total':>9s}  collision-free")
    for name, c in costs.items():
        print(f"  {name:14s} {c['c_velocity']:11.4g} {c['c_dist']:9.4g} {c['c_obs']:9.4g} {c['c_total']:9.4g}  "
              f"{c['collision_free']}")
    return 0


def _cmd_plot_stopping(args: argparse.Namespace) -> int:
    from hbmp_bench.render.stopping_figure import stopping_figure

    rows = stopping_figure(args.out, town=args.town)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"wrote {args.out}")
    print(f"  {'curve':62s} {'v0 [m/s]':>8s} {'stop [m]':>8s} {'+latency [m]':>12s} {'bound [m]':>9s}")
    for r in rows:
        print(f"  {r['label']:62s} {r['v_start_mps']:8.2f} {r['distance_m']:8.1f} "
              f"{r['distance_with_latency_m']:12.1f} {r['bound_m']:9.1f}")
    return 0


def add_commands(subparsers) -> None:
    """Add ``record``, ``plot-planner`` and ``plot-stopping`` to the ``hbmp-bench`` sub-commands."""
    p = subparsers.add_parser("record", help="run an agent on one episode and write a top-down GIF")
    p.add_argument("--env", required=True, help="env id, e.g. hbmp_bench/Town01-Straight-v0")
    p.add_argument("--town", default=None, help="built-in or imported map; replaces the env id's town")
    p.add_argument("--agent", default="expert", help="registry name or module:Class")
    p.add_argument("--episode", type=int, default=0, help="episode index in the suite")
    p.add_argument("--suite", default="corl2017", help="episode suite (hbmp-bench list shows them)")
    p.add_argument("--fidelity", default=None, help="default: the env's")
    p.add_argument("--every", type=int, default=1, help="keep every K-th 0.1 s frame")
    p.add_argument("--max-decisions", type=int, default=None, help="stop after N decisions")
    p.add_argument("--fps", type=float, default=None, help="playback rate; default real time")
    p.add_argument("--out", required=True, help="output .gif (.mp4 with imageio-ffmpeg)")
    p.add_argument("--json", action="store_true", help="print the episode record as JSON")
    p.set_defaults(func=_cmd_record)

    p = subparsers.add_parser("plot-planner",
                              help="figure of the motion planner's samples and costs for change_left/keep/change_right")
    p.add_argument("--town", default="Town05", help="map with a multi-lane straight road (Town03/04/05)")
    p.add_argument("--synthetic", action="store_true", help="use a synthetic straight three-lane road")
    p.add_argument("--out", required=True, help="output .png (.pdf, .svg)")
    p.add_argument("--json", action="store_true", help="print the costs as JSON")
    p.set_defaults(func=_cmd_plot_planner)

    p = subparsers.add_parser("plot-stopping",
                              help="figure of speed over distance while speed_down decisions stop the ego from the "
                                   "speed limit, in both fidelities")
    p.add_argument("--town", default="Town01", help="map; its longest Straight episode is driven")
    p.add_argument("--out", required=True, help="output .png (.pdf, .svg)")
    p.add_argument("--json", action="store_true", help="print the measured stops as JSON")
    p.set_defaults(func=_cmd_plot_stopping)
