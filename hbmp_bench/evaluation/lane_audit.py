"""The detectors against SUMO's own lane keeping: every route of every suite of a map, driven by SUMO.

A car that SUMO drives keeps its lanes by construction (it moves along lane centrelines, changes lanes
only where the net lets it and follows the junction lanes between). Judged by the benchmark's detectors
(:class:`~hbmp_bench.metrics.InfractionDetector`, the same footprint, lanes and junction surface as the
ego's), such a car must show no wrong-lane and no off-road event; where one does, the detector, not
the driver, is wrong about that place of the map. :func:`audit_lane_keeping` drives the distinct start
(lane, position) and route of every episode of the given suites, a few cars at a time in one SUMO run
(lights as the map has them, no other traffic), and returns each disagreement with its place.

``hbmp-bench maps audit NAME`` runs it on a built-in or imported map.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hbmp_bench.envs.vehicle import NOWHERE
from hbmp_bench.maps import net_path
from hbmp_bench.metrics import EgoFrame, InfractionDetector, LaneLocator
from hbmp_bench.scenarios import SUITES, road_network, suite_episodes
from hbmp_bench.sim.sumo import EGO_TYPE, SumoSim

AUDIT_CARS_AT_ONCE = 12
"""Cars on the road at a time: few enough that they rarely meet (none waits long behind another)."""
AUDIT_SPEED_MPS = 3.0
"""A car not at its route's end after route length / this speed + ``AUDIT_GRACE_S`` is reported stuck."""
AUDIT_GRACE_S = 180.0
"""[s] of lights and insertion waits allowed on top of the drive (see ``AUDIT_SPEED_MPS``)."""

_NONE = np.zeros(0)


@dataclass(frozen=True)
class LaneDisagreement:
    """A wrong-lane or off-road event of a car SUMO drives: which episodes' drive, where, when.

    Attributes:
        kind: ``wrong_lane`` or ``off_road``.
        episodes: keys (``suite:Town/Task/index``) of the episodes that share this drive.
        lane: the lane SUMO reports the car on; pos: its position there [m].
        followed_edge: the edge whose lanes the detector judged the car against.
        xy: (2,) footprint centre [m]; time_s: since the car's insertion [s].
    """

    kind: str
    episodes: tuple[str, ...]
    lane: str
    pos: float
    followed_edge: str
    xy: tuple[float, float]
    time_s: float

    def __str__(self) -> str:
        more = f" (+{len(self.episodes) - 1} more)" if len(self.episodes) > 1 else ""
        return (f"{self.kind} on {self.lane} at {self.pos:.1f} m (xy {self.xy[0]:.1f}, {self.xy[1]:.1f}; judged "
                f"against edge {self.followed_edge!r}) {self.time_s:.1f} s into {self.episodes[0]}{more}")


@dataclass
class LaneAudit:
    """What :func:`audit_lane_keeping` found on one map.

    Attributes:
        town: the map; suites: the suites whose episodes were driven.
        drives: distinct drives (start lane, position and route); episodes: the episodes they stand for.
        distance_km: road driven in all [km].
        disagreements: the detectors' events on SUMO's own driving (none where the detectors are right).
        stuck: episode keys of drives that did not reach their route's end in time (not judged to the end).
    """

    town: str
    suites: tuple[str, ...]
    drives: int = 0
    episodes: int = 0
    distance_km: float = 0.0
    disagreements: list[LaneDisagreement] = field(default_factory=list)
    stuck: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        """JSON-ready counts and every disagreement as a line."""
        kinds = [d.kind for d in self.disagreements]
        return {"town": self.town, "suites": list(self.suites), "drives": self.drives, "episodes": self.episodes,
                "distance_km": round(self.distance_km, 2), "wrong_lane": kinds.count("wrong_lane"),
                "off_road": kinds.count("off_road"), "stuck": len(self.stuck),
                "disagreements": [str(d) for d in self.disagreements], "stuck_episodes": self.stuck}


@dataclass
class _Drive:
    """One car of the audit: its route, the episodes it stands for, its detector and followed lane."""

    episodes: list[str]
    route: tuple[str, ...]
    start_lane: str
    start_pos: float
    length_m: float
    detector: InfractionDetector | None = None
    followed_lane: str = ""
    inserted_s: float = np.nan
    last_xy: np.ndarray | None = None
    driven_m: float = 0.0


def _drives(town: str, suites: tuple[str, ...]) -> list[_Drive]:
    """The distinct (route, start lane, start position) of every episode of ``suites`` on ``town``."""
    by_key: dict[tuple, _Drive] = {}
    for suite in suites:
        for task in SUITES[suite].tasks:
            for ep in suite_episodes(suite, town, task):
                key = (ep.route, ep.start_lane, round(ep.start_pos, 2))
                drive = by_key.get(key)
                if drive is None:
                    drive = by_key[key] = _Drive([], ep.route, ep.start_lane, ep.start_pos, ep.route_length_m)
                drive.episodes.append(f"{suite}:{ep.key}")
    return list(by_key.values())


def audit_lane_keeping(town: str, suites: tuple[str, ...] | list[str] | None = None, seed: int = 0,
                       progress=None) -> LaneAudit:
    """Drive every route of ``suites`` (default: all) on ``town`` with SUMO's own driver and judge each car
    with the benchmark's wrong-lane and off-road detectors (see the module docstring).

    Args:
        town: a built-in or imported map.
        suites: suite names; unknown names raise UnknownNameError listing the valid ones.
        seed: SUMO's seed (its drivers' speed deviation).
        progress: called with the number of drives finished so far and the total, after each.
    """
    from hbmp_bench.errors import UnknownNameError

    names = tuple(suites) if suites else tuple(SUITES)
    for name in names:
        if name not in SUITES:
            raise UnknownNameError("suite", name, tuple(SUITES))
    net = road_network(town)
    locator = LaneLocator(net)
    pending = _drives(town, names)
    audit = LaneAudit(town, names, drives=len(pending), episodes=sum(len(d.episodes) for d in pending))
    total = len(pending)
    pending.reverse()  # pop() takes them in suite order
    active: dict[str, _Drive] = {}
    sim = SumoSim(net_path(town))
    sim.start(seed)
    try:
        count = 0
        while pending or active:
            while pending and len(active) < AUDIT_CARS_AT_ONCE:
                drive = pending.pop()
                vid = f"audit{count}"
                count += 1
                sim.add_vehicle(vid, drive.route, lane_index=net.lanes[drive.start_lane].index, pos=drive.start_pos,
                                vtype=EGO_TYPE)
                drive.detector = InfractionDetector(locator, NOWHERE, 0.0, np.inf)
                drive.inserted_s = sim.time
                active[vid] = drive
            sim.step()
            arrived = set(sim.arrived_ids())
            now = sim.time
            for vid in list(active):
                drive = active[vid]
                done = vid in arrived
                if not done:
                    _judge(sim, net, vid, drive, audit, now)
                    if now - drive.inserted_s > drive.length_m / AUDIT_SPEED_MPS + AUDIT_GRACE_S:
                        audit.stuck.extend(drive.episodes)
                        sim.remove_vehicle(vid)
                        done = True
                if done:
                    audit.distance_km += drive.driven_m / 1000.0
                    del active[vid]
                    if progress is not None:
                        progress(total - len(pending) - len(active), total)
    finally:
        sim.close()
    return audit


def _judge(sim: SumoSim, net, vid: str, drive: _Drive, audit: LaneAudit, now: float) -> None:
    """One step of one car: its followed lane as the ego's (``ControlledVehicle.after_sim_step``), then the detector."""
    state = sim.vehicle_state(vid)
    if state is None or not state.lane:
        return  # not inserted yet
    if state.lane in net.lanes and (not drive.followed_lane or net.within_reach(drive.followed_lane, state.lane)):
        drive.followed_lane = state.lane
    if drive.last_xy is not None:
        drive.driven_m += float(np.hypot(*(state.xy - drive.last_xy)))
    drive.last_xy = state.xy
    edge = net.lanes[drive.followed_lane].edge if drive.followed_lane in net.lanes else ""
    ev = drive.detector.update(EgoFrame(state.xy, state.yaw, EGO_TYPE.length, EGO_TYPE.width, None, edge),
                               (), np.zeros((0, 2)), _NONE, _NONE, _NONE, np.zeros(0, bool), now)
    for kind in ("wrong_lane", "off_road"):
        if getattr(ev, kind):
            audit.disagreements.append(LaneDisagreement(kind, tuple(drive.episodes), state.lane, state.lane_pos, edge,
                                                        (float(state.xy[0]), float(state.xy[1])),
                                                        round(now - drive.inserted_s, 1)))


__all__ = ["LaneAudit", "LaneDisagreement", "audit_lane_keeping"]
