"""Speed over distance while a chain of speed_down decisions stops the ego from the speed limit.

One curve per fidelity (continuous: the motion planner; event: SUMO's speed command, 0.1 s
decisions), measured by :func:`hbmp_bench.envs.stopping.measure_stop` on a real episode, and for
comparison the continuous fidelity with the previous speed_down step (20 % / 2 m/s). Distance is
counted from the start of the cruise decision before the first speed_down (the worst-case
decision latency); a dot marks the first speed_down. The black curve is the lawful envelope:
``REACTION_S`` at the limit, then ``LAWFUL_DECEL``; it ends at the lawful stopping distance.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hbmp_bench.errors import UserError
from hbmp_bench.planning import BehaviorConfig
from hbmp_bench.render.planner_figure import FIGURE_SUFFIXES

PREVIOUS_SPEED_DOWN = BehaviorConfig(speed_down_frac=0.2, speed_down_min_step=2.0)
"""The speed_down step before the lawful-stop change (20 % / 2 m/s), drawn for comparison."""


def stopping_figure(path: str | os.PathLike, town: str = "Town01", dpi: int = 150) -> list[dict]:
    """Measure the stops and write the figure (PNG, PDF or SVG by suffix) atomically.

    Args:
        path: output file.
        town: a map whose longest Straight episode leaves room to reach the limit and stop.
        dpi: resolution of raster output.

    Returns:
        One :meth:`~hbmp_bench.envs.stopping.StopTrace.summary` per curve, with its ``label``.
    """
    from matplotlib.figure import Figure  # no pyplot: renders with Agg, never touches the user's backend

    from hbmp_bench.envs.stopping import LAWFUL_DECEL, REACTION_S, lawful_stopping_distance, measure_stop
    from hbmp_bench.envs.config import WorldConfig
    from hbmp_bench.render.video import atomic_write

    path = Path(path)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise UserError(f"figure path must end in one of {', '.join(FIGURE_SUFFIXES)}, got {str(path)!r}")
    current = BehaviorConfig()
    step = f"{current.speed_down_frac * 100:g} % / {current.speed_down_min_step:g} m/s"
    runs = (
        (f"continuous (planner), speed_down {step}", WorldConfig(fidelity="continuous"), "#1f77b4", "-"),
        (f"event (SUMO, 0.1 s decisions), speed_down {step}", WorldConfig(fidelity="event"), "#ff7f0e", "-"),
        ("continuous, previous speed_down 20 % / 2 m/s",
         WorldConfig(fidelity="continuous", behavior=PREVIOUS_SPEED_DOWN), "#7f7f7f", "--"),
    )
    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.subplots()
    summaries = []
    v_limit = None
    for label, config, colour, style in runs:
        trace = measure_stop(config, town=town)
        v_limit = trace.speed_limit if v_limit is None else v_limit
        d = trace.travelled_m[trace.cruise_start:] - trace.travelled_m[trace.cruise_start]
        v = trace.speed[trace.cruise_start:]
        k = trace.brake_start - trace.cruise_start
        ax.plot(d, v, style, color=colour, lw=1.8,
                label=f"{label}: {trace.distance_with_latency_m:.1f} m ({trace.distance_m:.1f} m after speed_down)")
        ax.plot(d[k], v[k], "o", color=colour, ms=5)
        summaries.append({"label": label, **trace.summary()})
    bound = lawful_stopping_distance(v_limit)
    react = v_limit * REACTION_S
    v_env = np.linspace(v_limit, 0.0, 100)
    ax.plot(np.concatenate([[0.0], react + (v_limit ** 2 - v_env ** 2) / (2 * LAWFUL_DECEL)]),
            np.concatenate([[v_limit], v_env]), ":", color="black", lw=1.5,
            label=f"lawful: {REACTION_S:g} s + {LAWFUL_DECEL:g} m/s² = {bound:.1f} m")
    ax.axvline(bound, color="black", lw=0.8, alpha=0.5)
    ax.set_xlim(0.0, max(bound, max(s["distance_with_latency_m"] for s in summaries)) * 1.05)
    ax.set_ylim(0.0, v_limit * 1.4)  # room for the legend above the curves
    ax.set_xlabel("distance from the last decision before braking [m]")
    ax.set_ylabel("ego speed [m/s]")
    ax.set_title(f"Stopping from the speed limit ({v_limit * 3.6:.0f} km/h, {town}); dot = first speed_down",
                 fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.3)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:].lower()))
    return summaries
