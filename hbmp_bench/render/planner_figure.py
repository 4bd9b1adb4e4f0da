"""The motion planner at work in one situation: its samples for change_left, keep and
change_right and the costs of each behavior's chosen sample (after the paper's figure of
sampled trajectories and its bar chart of cost per behavior).

The default situation is on a real network: the ego in the middle lane of the longest
straight edge with the most same-direction lanes of a shipped town (Town05: three lanes),
a slower car ahead in its lane and another one further ahead in the lane to its right.
``synthetic=True`` uses a straight three-lane road along +x instead.

Each behavior is planned exactly as :class:`~hbmp_bench.planning.BehaviorExecutor` plans
its first step: target lane by :func:`~hbmp_bench.planning.target_path`, ``v_ref`` by
:func:`~hbmp_bench.planning.reference_speed`, then :func:`~hbmp_bench.planning.plan`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hbmp_bench.errors import UserError
from hbmp_bench.maps.roadnet import RoadNetwork, point_along
from hbmp_bench.planning import (Behavior, BehaviorConfig, Obstacles, Path as LanePath, PlannerConfig,
                                 PlanningProblem, PlanResult, ReferencePaths, VehicleState, plan,
                                 reference_speed, target_path)
from hbmp_bench.render.geometry import box_corners, dashes, offset_polyline
from hbmp_bench.render.static import edge_markings, read_walkways

FIGURE_BEHAVIORS = (Behavior.CHANGE_LEFT, Behavior.KEEP, Behavior.CHANGE_RIGHT)
BEHAVIOR_COLOURS = {Behavior.CHANGE_LEFT: "#1f77b4", Behavior.KEEP: "#2ca02c", Behavior.CHANGE_RIGHT: "#ff7f0e"}
COST_LABELS = ("c_velocity", "c_dist", "c_obs", "c_total")
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")
LATERAL_EXAGGERATION = 1.6
"""The scene panel stretches the lateral axis by this factor so the fan of samples shows."""
LOG_FLOOR = 1e-3
"""Lower end of the bar chart's log axis (smaller costs show as empty bars with their value)."""
LANE_WIDTH_M = 3.5
"""Lane width of the synthetic road [m]."""


@dataclass(frozen=True, eq=False)
class PlannerSituation:
    """One planning situation and what to draw around it.

    Attributes:
        name: a short description (town and lane, or ``synthetic``).
        ego: ego state.
        refs: centerlines of the left, current and right lanes (left / right may be None).
        speed_limit: [m/s].
        obstacles: the other vehicles.
        surfaces: (polyline (N, 2), width [m]) road bands to draw as asphalt.
        walkways: (polyline (N, 2), width [m]) sidewalks to draw.
        junctions: polygons (N, 2) drawn as asphalt.
        markings: (polyline (N, 2), kind) with kind ``dashed``, ``centre`` or ``edge``.
    """

    name: str
    ego: VehicleState
    refs: ReferencePaths
    speed_limit: float
    obstacles: Obstacles
    surfaces: tuple[tuple[np.ndarray, float], ...]
    walkways: tuple[tuple[np.ndarray, float], ...]
    junctions: tuple[np.ndarray, ...]
    markings: tuple[tuple[np.ndarray, str], ...]


@dataclass(frozen=True, eq=False)
class BehaviorPlan:
    """The plan of one behavior: requested and effective behavior (a lane change without a
    lane becomes ``KEEP``), its ``v_ref`` [m/s] and the planner's result."""

    requested: Behavior
    effective: Behavior
    v_ref: float
    result: PlanResult

    def costs(self) -> dict[str, float]:
        """``c_velocity``, ``c_dist``, ``c_obs`` and ``c_total`` of the chosen sample."""
        terms = self.result.chosen_costs
        return {"c_velocity": float(terms[0]), "c_dist": float(terms[1]), "c_obs": float(terms[2]),
                "c_total": self.result.c_total}


def _obstacle_on(shape: np.ndarray, s: float, v: float) -> tuple[float, float, float, float, float, float]:
    p, q = point_along(shape, s), point_along(shape, s + 1.0)
    return (float(p[0]), float(p[1]), math.atan2(q[1] - p[1], q[0] - p[0]), v, 4.5, 1.8)


def _straightness(shape: np.ndarray) -> float:
    """Largest distance [m] of a polyline's vertices from its end-to-end chord."""
    a, b = shape[0], shape[-1]
    d = b - a
    n = np.hypot(*d)
    if n < 1e-9:
        return math.inf
    return float(np.max(np.abs((shape[:, 0] - a[0]) * d[1] - (shape[:, 1] - a[1]) * d[0]) / n))


def pick_multilane_edge(net: RoadNetwork, min_length_m: float = 50.0) -> str:
    """The straight edge (vertices within 0.3 m of the chord) of at least ``min_length_m`` with
    the most same-direction lanes (>= 2), longest first, then by id. ValueError if none."""
    candidates = [
        (len(lanes), net.edge_length[e], e) for e, lanes in net.edge_lanes.items()
        if len(lanes) >= 2 and net.edge_length[e] >= min_length_m
        and all(_straightness(net.lanes[i].shape) < 0.3 for i in lanes)
    ]
    if not candidates:
        raise UserError(f"{net.path.name} has no straight edge of >= {min_length_m} m with two or more "
                         "same-direction lanes; use Town03, Town04 or Town05, or the synthetic road")
    return sorted(candidates, key=lambda c: (-c[0], -c[1], c[2]))[0][2]


def network_situation(net: RoadNetwork, name: str = "", ego_speed: float = 8.0, gap_m: float = 16.0,
                      lead_speed: float = 3.0) -> PlannerSituation:
    """The default situation on a real network (see the module docstring).

    Args:
        net: a network with a multi-lane edge (:func:`pick_multilane_edge`).
        name: label of the network in the figure (default: its file name).
        ego_speed: ego speed [m/s].
        gap_m: centre distance to the car ahead in the ego lane [m].
        lead_speed: speed of the car ahead [m/s].
    """
    edge = pick_multilane_edge(net)
    lane_ids = net.edge_lanes[edge]
    ego_lane = lane_ids[len(lane_ids) // 2] if len(lane_ids) >= 3 else lane_ids[0]
    shape = net.lanes[ego_lane].shape
    s_ego = 8.0
    p, q = point_along(shape, s_ego), point_along(shape, s_ego + 1.0)
    ego = VehicleState(float(p[0]), float(p[1]), math.atan2(q[1] - p[1], q[0] - p[0]), ego_speed)

    def ref(side: int) -> LanePath | None:
        lane = net.neighbour_lane(ego_lane, side)
        return None if lane is None else LanePath(net.lanes[lane].shape)

    rows = [_obstacle_on(shape, s_ego + gap_m, lead_speed)]
    right = net.neighbour_lane(ego_lane, -1)
    if right is not None:
        rows.append(_obstacle_on(net.lanes[right].shape, s_ego + 1.9 * gap_m, lead_speed + 2.0))
    edges = [edge] + ([net.opposite[edge]] if net.opposite.get(edge) else [])
    surfaces = tuple((net.lanes[i].shape, net.lanes[i].width) for e in edges for i in net.edge_lanes[e])
    markings = tuple(m for e in edges for m in edge_markings(net, e))
    nodes = set(net.edge_from_to[edge])
    junctions = tuple(net.junction_shapes[n] for n in sorted(nodes) if n in net.junction_shapes)
    near = [(s, w) for s, w in read_walkways(str(net.path)).sidewalks
            if np.min(np.hypot(s[:, 0] - ego.x, s[:, 1] - ego.y)) < 60.0]
    return PlannerSituation(
        name=f"{name or net.path.name.split('.')[0]}, lane {ego_lane}", ego=ego,
        refs=ReferencePaths(ref(+1), LanePath(shape), ref(-1)), speed_limit=net.lanes[ego_lane].speed,
        obstacles=Obstacles.from_rows(rows), surfaces=surfaces, walkways=tuple(near), junctions=junctions,
        markings=markings)


def synthetic_situation(ego_speed: float = 8.0, gap_m: float = 16.0, lead_speed: float = 3.0,
                        speed_limit: float = 13.89) -> PlannerSituation:
    """A straight three-lane one-way road along +x (lane centres y = 0, 3.5, 7 m; the ego in
    the middle one at x = 0), the same traffic as :func:`network_situation`."""
    x = np.array([-40.0, 120.0])
    centres = [np.stack([x, np.full(2, k * LANE_WIDTH_M)], axis=1) for k in range(3)]
    ego = VehicleState(0.0, LANE_WIDTH_M, 0.0, ego_speed)
    rows = [(gap_m, LANE_WIDTH_M, 0.0, lead_speed, 4.5, 1.8), (1.9 * gap_m, 0.0, 0.0, lead_speed + 2.0, 4.5, 1.8)]
    half = LANE_WIDTH_M / 2
    markings = [(c + [0.0, half], "dashed") for c in centres[:2]]
    markings += [(centres[0] - [0.0, half], "edge"), (centres[2] + [0.0, half], "edge")]
    return PlannerSituation(
        name="synthetic three-lane road", ego=ego,
        refs=ReferencePaths(LanePath(centres[2]), LanePath(centres[1]), LanePath(centres[0])),
        speed_limit=speed_limit, obstacles=Obstacles.from_rows(rows),
        surfaces=tuple((c, LANE_WIDTH_M) for c in centres),
        walkways=((centres[0] - [0.0, half + 1.0], 2.0), (centres[2] + [0.0, half + 1.0], 2.0)),
        junctions=(), markings=tuple(markings))


def plan_behaviors(situation: PlannerSituation, planner: PlannerConfig = PlannerConfig(),
                   behavior_cfg: BehaviorConfig = BehaviorConfig(),
                   behaviors: tuple[Behavior, ...] = FIGURE_BEHAVIORS) -> dict[Behavior, BehaviorPlan]:
    """Plan every behavior of ``behaviors`` from the situation's ego state."""
    out = {}
    for requested in behaviors:
        effective, path = target_path(requested, situation.refs)
        v_ref = reference_speed(effective, situation.ego.v, situation.speed_limit, behavior_cfg)
        result = plan(PlanningProblem(situation.ego, path, v_ref, situation.speed_limit, situation.obstacles), planner)
        out[requested] = BehaviorPlan(requested, effective, v_ref, result)
    return out


# ---------------------------------------------------------------------------- drawing
def _to_ego(xy: np.ndarray, ego: VehicleState) -> np.ndarray:
    """World points (..., 2) -> ego frame (..., 2): x ahead, y to the left [m]."""
    c, s = math.cos(ego.yaw), math.sin(ego.yaw)
    d = np.asarray(xy, dtype=float) - [ego.x, ego.y]
    return np.stack([d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c], axis=-1)


def _band(shape: np.ndarray, width: float) -> np.ndarray:
    return np.concatenate([offset_polyline(shape, width / 2), offset_polyline(shape, -width / 2)[::-1]])


def _draw_road(ax, situation: PlannerSituation) -> None:
    """Walkways, junctions, road surfaces and lane markings, in the ego's frame."""
    from matplotlib.patches import Polygon

    ego = situation.ego
    for shape, width in situation.walkways:
        ax.add_patch(Polygon(_to_ego(_band(shape, width), ego), closed=True, fc="#d8d4c8", ec="none", zorder=0))
    for poly in situation.junctions:
        ax.add_patch(Polygon(_to_ego(poly, ego), closed=True, fc="#8a8a90", ec="none", zorder=1))
    for shape, width in situation.surfaces:
        ax.add_patch(Polygon(_to_ego(_band(shape, width), ego), closed=True, fc="#8a8a90", ec="none", zorder=1))
    for line, kind in situation.markings:
        pieces = dashes(line, 3.0, 4.5) if kind == "dashed" else [line]
        for piece in pieces:
            xy = _to_ego(piece, ego)
            ax.plot(xy[:, 0], xy[:, 1], color="#f0c020" if kind == "centre" else "white",
                    lw=1.6 if kind == "centre" else 1.0, zorder=2, solid_capstyle="butt")


def _draw_obstacles(ax, situation: PlannerSituation, horizon: float) -> None:
    """Every obstacle now (filled) and at the planner's horizon at its speed (dashed), with its speed."""
    from matplotlib.patches import Polygon

    ego, obs = situation.ego, situation.obstacles
    for k in range(len(obs)):
        for t, alpha, ls in ((0.0, 1.0, "-"), (horizon, 0.35, "--")):
            x = obs.x[k] + obs.v[k] * math.cos(obs.yaw[k]) * t
            y = obs.y[k] + obs.v[k] * math.sin(obs.yaw[k]) * t
            box = box_corners([[x, y]], [obs.yaw[k]], [obs.length[k]], [obs.width[k]])[0]
            ax.add_patch(Polygon(_to_ego(box, ego), closed=True, fc="#505058" if t == 0 else "none",
                                 ec="#202024", ls=ls, alpha=alpha, lw=1.0, zorder=6))
        ax.annotate(f"{obs.v[k]:.0f} m/s", _to_ego(np.array([obs.x[k], obs.y[k]]), ego), xytext=(0, 12),
                    textcoords="offset points", ha="center", fontsize=7, color="white", zorder=7)


def _draw_plans(ax, situation: PlannerSituation, plans: dict[Behavior, BehaviorPlan]) -> None:
    """Each behavior's samples (light; dotted where they collide), then its chosen trajectory."""
    from matplotlib.colors import to_rgb
    import matplotlib.patheffects as pe

    ego = situation.ego
    for behavior, bp in plans.items():
        tint = 0.45 * np.asarray(to_rgb(BEHAVIOR_COLOURS[behavior])) + 0.55  # lighter than the chosen line
        traj = _to_ego(bp.result.trajectories[:, :, :2], ego)
        for i in range(len(traj)):
            if i == bp.result.chosen:
                continue
            feasible = bool(bp.result.feasible[i])
            ax.plot(traj[i, :, 0], traj[i, :, 1], color=tint, lw=0.8, alpha=0.9 if feasible else 0.8,
                    ls="-" if feasible else (0, (1.0, 2.0)), zorder=4)
    for behavior, bp in plans.items():
        best = _to_ego(bp.result.trajectory[:, :2], ego)
        ax.plot(best[:, 0], best[:, 1], color=BEHAVIOR_COLOURS[behavior], lw=3.2, zorder=3,
                solid_capstyle="round", path_effects=[pe.Stroke(linewidth=4.8, foreground="black"), pe.Normal()])


def _draw_scene(ax, situation: PlannerSituation, plans: dict[Behavior, BehaviorPlan], planner: PlannerConfig,
                x_range: tuple[float, float]) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Polygon

    ego = situation.ego
    _draw_road(ax, situation)
    horizon = float(planner.horizon)
    _draw_obstacles(ax, situation, horizon)
    _draw_plans(ax, situation, plans)
    box = box_corners([[ego.x, ego.y]], [ego.yaw], [planner.length], [planner.width])[0]
    ax.add_patch(Polygon(_to_ego(box, ego), closed=True, fc="#1496ff", ec="white", lw=1.2, zorder=8))
    ax.annotate(f"ego {ego.v:.0f} m/s", (0.0, 0.0), xytext=(0, -16), textcoords="offset points", ha="center",
                va="top", fontsize=7, color="white", zorder=9)
    handles = [Line2D([], [], color=BEHAVIOR_COLOURS[b], lw=3, label=_label(bp)) for b, bp in plans.items()]
    handles.append(Line2D([], [], color="#b0b0b0", lw=0.8, label="feasible sample (light)"))
    handles.append(Line2D([], [], color="#b0b0b0", lw=0.8, ls=(0, (1.0, 2.0)), label="colliding sample"))
    handles.append(Line2D([], [], color="#202024", lw=1.0, ls="--", label=f"obstacle at t = {horizon:g} s"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, fontsize=7.5,
              frameon=False)
    ax.set_xlim(*x_range)
    lat = [0.0] + [float(_to_ego(p.xy, ego)[:, 1].min()) for p in situation.refs.paths if p is not None]
    lat += [float(_to_ego(p.xy, ego)[:, 1].max()) for p in situation.refs.paths if p is not None]
    ax.set_ylim(min(lat) - 4.5, max(lat) + 4.5)
    ax.set_aspect(LATERAL_EXAGGERATION)
    ax.set_facecolor("#55634f")
    ax.set_xlabel("ahead of the ego [m]")
    ax.set_ylabel(f"left of the ego [m] (scale x{LATERAL_EXAGGERATION:g})")


def _label(bp: BehaviorPlan) -> str:
    name = bp.requested.name.lower()
    if bp.effective != bp.requested:
        name += f" (no lane: {bp.effective.name.lower()})"
    n_ok = int(bp.result.feasible.sum())
    return f"{name}: v_ref {bp.v_ref:.1f} m/s, {n_ok}/{bp.result.n_samples} feasible"


def _draw_costs(ax, plans: dict[Behavior, BehaviorPlan]) -> None:
    behaviors = list(plans)
    costs = [plans[b].costs() for b in behaviors]
    n_terms = len(COST_LABELS)
    width = 0.8 / n_terms
    term_colours = ("#8c564b", "#9467bd", "#d62728", "#404040")
    x = np.arange(len(behaviors))
    for j, term in enumerate(COST_LABELS):
        values = [c[term] for c in costs]
        bars = ax.bar(x + (j - (n_terms - 1) / 2) * width, values, width, color=term_colours[j], label=term,
                      hatch="//" if term == "c_total" else None, edgecolor="white" if term == "c_total" else None)
        for bar, value in zip(bars, values):
            ax.annotate(f"{value:.2g}", (bar.get_x() + bar.get_width() / 2, max(value, LOG_FLOOR)), xytext=(0, 2),
                        textcoords="offset points", ha="center", va="bottom", fontsize=6.5, rotation=90)
    ax.set_xticks(x)
    ax.set_xticklabels([b.name.lower() for b in behaviors])
    for tick, b in zip(ax.get_xticklabels(), behaviors):
        tick.set_color(BEHAVIOR_COLOURS[b])
        tick.set_fontweight("bold")
    top = max(max(c.values()) for c in costs)
    ax.set_yscale("log")
    ax.set_ylim(LOG_FLOOR, max(top, 1.0) * 30.0)
    ax.set_ylabel("cost of the chosen sample (log scale)")
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    ax.grid(axis="y", alpha=0.3)


def planner_figure(path: str | os.PathLike, town: str = "Town05", synthetic: bool = False,
                   planner: PlannerConfig = PlannerConfig(), behavior_cfg: BehaviorConfig = BehaviorConfig(),
                   dpi: int = 150) -> dict[str, dict[str, float | bool | str]]:
    """Draw the planner figure and write it (PNG, PDF or SVG by suffix) atomically.

    Args:
        path: output file.
        town: map of the default situation (a shipped town or an imported map).
        synthetic: use the synthetic three-lane road instead of ``town``.
        planner, behavior_cfg: planner parameters and the ``v_ref`` rule.
        dpi: resolution of raster output.

    Returns:
        Per requested behavior name: ``c_velocity``, ``c_dist``, ``c_obs``, ``c_total`` of the
        chosen sample, ``collision_free``, ``effective`` (behavior executed) and ``v_ref``.
    """
    from matplotlib.figure import Figure  # no pyplot: renders with Agg, never touches the user's backend

    from hbmp_bench.render.video import atomic_write

    path = Path(path)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise UserError(f"figure path must end in one of {', '.join(FIGURE_SUFFIXES)}, got {str(path)!r}")
    if synthetic:
        situation = synthetic_situation()
    else:
        from hbmp_bench.maps import net_path
        from hbmp_bench.maps.roadnet import load_road_network

        situation = network_situation(load_road_network(str(net_path(town))), name=town)
    plans = plan_behaviors(situation, planner, behavior_cfg)

    fig = Figure(figsize=(13.0, 4.8), layout="constrained")
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": (2.8, 1.0)})
    reach = max(float(np.max(_to_ego(bp.result.trajectories[:, :, :2], situation.ego)[..., 0]))
                for bp in plans.values())
    _draw_scene(left, situation, plans, planner, (-12.0, max(40.0, reach + 6.0)))
    _draw_costs(right, plans)
    left.set_title(f"Sampled trajectories per behavior ({situation.name}); chosen = thick", fontsize=9)
    right.set_title(f"Costs of the chosen sample (horizon {planner.horizon:g} s)", fontsize=9)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:].lower()))
    return {
        b.name.lower(): {**bp.costs(), "collision_free": bp.result.collision_free,
                         "effective": bp.effective.name.lower(), "v_ref": bp.v_ref}
        for b, bp in plans.items()
    }
