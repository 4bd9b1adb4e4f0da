"""The one place that talks to SUMO: a simulation and the world snapshot it yields.

Two ways to the same SUMO (the eclipse-sumo / libsumo wheels, same version, same API):

- **libsumo** (fast): SUMO runs inside this process, every call is a C++ function call. libsumo
  holds one simulation per process, so the first ``SumoSim`` started in a process takes it.
- **TraCI** (slower: each call is a round trip over a local socket): a ``SumoSim`` started while
  another one holds libsumo runs the wheel's ``sumo`` binary in a child process and talks to it
  through the ``traci`` client. This is what lets several environments live in one process
  (gymnasium's ``check_env``, ``make_vec`` sync, PettingZoo's seed test).

Both give identical episodes. ``SumoSim`` starts on ``start()``, never in ``__init__``;
``close()`` is idempotent. Vehicles and pedestrians are read each step through subscriptions (one
batched call per kind, not one call per actor).

Angles: SUMO reports degrees clockwise from north; everything leaving this module is
``yaw`` [rad] counter-clockwise from +x. SUMO's vehicle position is the front bumper; this
module returns footprint centres.
"""

from __future__ import annotations

import itertools
import math
import os
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import libsumo
import sumo
import traci.connection
import traci.exceptions

tc = libsumo.constants
_SUMO_ERRORS = (libsumo.TraCIException, traci.exceptions.TraCIException)
"""What SUMO raises for a refused command, through libsumo or through TraCI."""

_SUBSCRIBED = (tc.VAR_POSITION3D, tc.VAR_ANGLE, tc.VAR_SPEED)
_EGO_SUBSCRIBED = (tc.VAR_POSITION3D, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_LANE_ID, tc.VAR_LANEPOSITION, tc.VAR_ROUTE_INDEX)


@dataclass(frozen=True)
class VehicleType:
    """A SUMO vehicle type: footprint [m] and longitudinal limits [m/s²]."""

    id: str
    length: float = 4.5
    width: float = 1.8
    accel: float = 2.6
    decel: float = 4.5
    emergency_decel: float = 9.0
    min_gap: float = 2.5
    max_speed: float = 30.0


EGO_TYPE = VehicleType("hbmp_ego")
BACKGROUND_TYPE = VehicleType("hbmp_background")
SCENARIO_TYPE = VehicleType("hbmp_scenario", accel=4.0, decel=8.0, emergency_decel=9.0)
"""The scripted actors of a scenario type (``scenarios.scenario_types``): they brake as hard as
a car can (8 m/s²) and accelerate briskly (a cut-in, a red-light runner)."""
PEDESTRIAN_SIZE_M = 0.6
"""Square footprint side of a pedestrian for collision checks [m]."""
LEVEL_CLEARANCE_M = 3.0
"""Actors whose elevations differ by this much or more are on different levels (a bridge over a
road) [m]: they can neither touch nor block each other. A road's grade changes the height of two
cars on it by less (20 % over 10 m: 2 m)."""


@dataclass(frozen=True)
class Actors:
    """Everything that moves, at one instant. K actors.

    Attributes:
        ids: (K,) actor ids.
        xy: (K, 2) footprint centres [m].
        yaw: (K,) headings [rad].
        speed: (K,) [m/s].
        length / width: (K,) footprint [m].
        is_pedestrian: (K,) bool.
        z: (K,) elevation [m] (0 on a flat map).
    """

    ids: tuple[str, ...]
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    is_pedestrian: np.ndarray
    z: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)

    def around(self, actor_id: str, clearance_m: float = LEVEL_CLEARANCE_M) -> "Actors":
        """The actors ``actor_id`` can meet: every other one on its level (elevation within
        ``clearance_m`` [m] of its own; all others when it is absent). Its detectors, M_t and
        motion planner see these: a car on a bridge is no obstacle to one on the road below."""
        try:
            at = self.ids.index(actor_id)
        except ValueError:
            return self
        keep = np.abs(self.z - self.z[at]) < clearance_m
        keep[at] = False
        return Actors(
            ids=tuple(itertools.compress(self.ids, keep.tolist())),
            xy=self.xy[keep],
            yaw=self.yaw[keep],
            speed=self.speed[keep],
            length=self.length[keep],
            width=self.width[keep],
            is_pedestrian=self.is_pedestrian[keep],
            z=self.z[keep],
        )


@dataclass(frozen=True)
class VehicleState:
    """A SUMO vehicle's pose and lane position.

    ``xy`` centre [m], ``yaw`` [rad], ``speed`` [m/s], ``lane`` id (internal lanes start with
    ``:``), ``lane_pos`` [m] of the front bumper along the lane, ``route_index`` into its route.
    """

    xy: np.ndarray
    yaw: float
    speed: float
    lane: str
    lane_pos: float
    route_index: int


@dataclass(frozen=True)
class LightAhead:
    """A traffic light ahead on a vehicle's route: the link (``tls``, ``link_index``), the distance
    from the front bumper to its stop line [m] and its signal char now (``r``, ``y``, ``G`` ...)."""

    tls: str
    link_index: int
    distance: float
    state: str


TRACI_CONNECT_TIMEOUT_S = 60.0
"""How long a TraCI ``sumo`` child may take to load its network and accept the connection [s]."""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("localhost", 0))
        return int(probe.getsockname()[1])


def start_traci(args: list[str]) -> traci.connection.Connection:
    """Run ``args`` (the wheel's ``sumo`` and its options) in a child process and connect to it
    over TraCI on a free local port. Raises RuntimeError with SUMO's own message when the child
    exits before accepting (a port taken meanwhile is retried with another)."""
    deadline = time.monotonic() + TRACI_CONNECT_TIMEOUT_S
    while True:
        port = _free_port()
        with tempfile.TemporaryFile() as log:  # the child writes to its own copy; ours closes here
            proc = subprocess.Popen([*args, "--remote-port", str(port)], stdout=subprocess.DEVNULL, stderr=log)
            while proc.poll() is None and time.monotonic() < deadline:
                try:
                    return traci.connection.Connection("localhost", port, proc, None, True, None)
                except OSError:
                    time.sleep(0.02)
            if proc.poll() is None:
                proc.kill()
                proc.wait()
                raise RuntimeError(f"sumo did not accept a TraCI connection within {TRACI_CONNECT_TIMEOUT_S} s")
            log.seek(0)
            message = log.read().decode(errors="replace").strip()
        if "bind" not in message.lower() or time.monotonic() >= deadline:
            raise RuntimeError(f"sumo exited with {proc.returncode} before accepting TraCI: {message}")


def sumo_binary() -> str:
    """Path of the ``sumo`` binary of the eclipse-sumo wheel (libsumo only parses its options)."""
    return os.path.join(sumo.SUMO_HOME, "bin", "sumo")


def sumo_angle_to_yaw(angle_deg: np.ndarray | float) -> np.ndarray | float:
    """SUMO angle (degrees clockwise from north) → yaw [rad] counter-clockwise from +x."""
    return np.radians(90.0 - np.asarray(angle_deg))


def yaw_to_sumo_angle(yaw: float) -> float:
    """Yaw [rad] → SUMO angle [deg]."""
    return (90.0 - math.degrees(yaw)) % 360.0


class SumoSim:
    """One SUMO simulation: through libsumo when this process's libsumo is free at ``start()``,
    otherwise through TraCI (see the module docstring).

    Args:
        net_path: SUMO network file.
        step_length: simulation step [s].
    """

    _libsumo_holder: "SumoSim | None" = None

    def __init__(self, net_path: str | Path, step_length: float = 0.1):
        if step_length <= 0:
            raise ValueError(f"step_length must be > 0, got {step_length}")
        self.net_path = str(net_path)
        self.step_length = float(step_length)
        self._dims: dict[str, tuple[float, float, bool]] = {}
        self._routes = 0
        self._controlled: dict[str, list[str]] | None = None
        self._programs: dict[str, tuple[tuple[float, str], ...]] = {}
        self._snapshot_dims: tuple | None = None
        self._api = None
        """``libsumo`` or a TraCI connection while running (both offer the same domains), else None."""
        self._move_pending = False

    # --------------------------------------------------------------- lifecycle
    @property
    def running(self) -> bool:
        return self._api is not None

    @property
    def uses_libsumo(self) -> bool:
        """Whether this simulation runs in this process through libsumo (False: TraCI, or not running)."""
        return self._api is libsumo

    def start(self, seed: int) -> None:
        """(Re)start the simulation with SUMO's ``--seed``; closes a previous run of this object.
        Through libsumo when no other simulation of this process holds it, through TraCI otherwise."""
        self.close()
        args = [
            sumo_binary(),
            "-n", self.net_path,
            "--step-length", str(self.step_length),
            "--seed", str(int(seed)),
            "--no-step-log", "true",
            "--no-warnings", "true",
            "--collision.action", "none",
            "--time-to-teleport", "-1",
            "--ignore-route-errors", "true",
            "--pedestrian.model", "striping",
            "--default.speeddev", "0.05",
        ]
        if SumoSim._libsumo_holder is None:
            libsumo.start(args)
            SumoSim._libsumo_holder, self._api = self, libsumo
        else:
            self._api = start_traci(args)
        self._move_pending = False
        self._controlled = None
        self._programs = {}
        self._dims = {}
        self._snapshot_dims = None
        self._routes = 0
        types = self._api.vehicletype
        for vtype in (EGO_TYPE, BACKGROUND_TYPE, SCENARIO_TYPE):
            types.copy("DEFAULT_VEHTYPE", vtype.id)
            types.setLength(vtype.id, vtype.length)
            types.setWidth(vtype.id, vtype.width)
            types.setAccel(vtype.id, vtype.accel)
            types.setDecel(vtype.id, vtype.decel)
            types.setEmergencyDecel(vtype.id, vtype.emergency_decel)
            types.setMinGap(vtype.id, vtype.min_gap)
            types.setMaxSpeed(vtype.id, vtype.max_speed)

    def close(self) -> None:
        """End the simulation; safe to call any number of times.

        A pose pushed with ``moveToXY`` and not stepped yet stays registered in libsumo's
        process-wide state past ``close`` and crashes the next simulation's first step
        (segmentation fault in ``simulationStep``); one last step consumes it first."""
        api, self._api = self._api, None
        if api is None:
            return
        try:
            if api is libsumo and self._move_pending:
                libsumo.simulationStep()
            api.close()
        finally:
            self._move_pending = False
            if SumoSim._libsumo_holder is self:
                SumoSim._libsumo_holder = None

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self._api.simulation.getTime())

    def step(self) -> None:
        """Advance one step of ``step_length``."""
        self._api.simulationStep()
        self._move_pending = False

    def time_raw_steps(self, steps: int) -> float:
        """Wall time [s] of ``steps`` bare ``libsumo.simulationStep()`` calls, after dropping every
        subscription and giving all handed-over vehicles back to SUMO's own driver (throughput
        reference: SUMO alone, no package code per step). The scene is unusable for an episode after."""
        for vehicle_id in self._api.vehicle.getIDList():
            self._api.vehicle.unsubscribe(vehicle_id)
            self._api.vehicle.setSpeed(vehicle_id, -1.0)
            self._api.vehicle.setSpeedMode(vehicle_id, 31)
            self._api.vehicle.setLaneChangeMode(vehicle_id, 1621)
        for person_id in self._api.person.getIDList():
            self._api.person.unsubscribe(person_id)
        simulation_step = self._api.simulationStep
        start = time.perf_counter()
        for _ in range(int(steps)):
            simulation_step()
        return time.perf_counter() - start

    # ------------------------------------------------------------------ actors
    def add_vehicle(
        self,
        vehicle_id: str,
        route: tuple[str, ...] | list[str],
        *,
        lane_index: int | str = "best",
        pos: float | str = "base",
        speed: float | str = 0.0,
        vtype: VehicleType = BACKGROUND_TYPE,
    ) -> None:
        """Insert a vehicle on ``route`` now (SUMO lane index, position [m], speed [m/s])."""
        route_id = f"r{self._routes}"
        self._routes += 1
        self._api.route.add(route_id, list(route))
        self._api.vehicle.add(
            vehicle_id,
            route_id,
            typeID=vtype.id,
            depart="now",
            departLane=str(lane_index),
            departPos=str(pos),
            departSpeed=str(speed),
        )
        self._dims[vehicle_id] = (vtype.length, vtype.width, False)
        self._api.vehicle.subscribe(vehicle_id, _EGO_SUBSCRIBED if vtype is EGO_TYPE else _SUBSCRIBED)

    def add_pedestrian(self, person_id: str, edge: str, pos: float, walks: list[tuple[str, str]]) -> None:
        """Insert a pedestrian at ``pos`` [m] on ``edge`` walking to each (from, to) edge pair in turn."""
        self._api.person.add(person_id, edge, pos, depart=tc.DEPARTFLAG_NOW)
        for from_edge, to_edge in walks:
            for stage in self._api.simulation.findIntermodalRoute(from_edge, to_edge, modes=""):
                self._api.person.appendStage(person_id, stage)
        self._api.person.subscribe(person_id, _SUBSCRIBED)
        self._dims[person_id] = (PEDESTRIAN_SIZE_M, PEDESTRIAN_SIZE_M, True)

    def walk_route_exists(self, from_edge: str, to_edge: str) -> bool:
        """True if a pedestrian can walk from ``from_edge`` to ``to_edge``."""
        stages = self._api.simulation.findIntermodalRoute(from_edge, to_edge, modes="")
        return bool(stages) and bool(stages[0].edges)

    def vehicle_ids(self) -> tuple[str, ...]:
        return tuple(self._api.vehicle.getIDList())

    def arrived_ids(self) -> tuple[str, ...]:
        """Vehicles that reached the end of their route in the last step."""
        return tuple(self._api.simulation.getArrivedIDList())

    def snapshot(self) -> Actors:
        """All inserted vehicles and pedestrians now (footprint centres)."""
        pos_, angle_, speed_ = tc.VAR_POSITION3D, tc.VAR_ANGLE, tc.VAR_SPEED
        # a vehicle still waiting for its insertion has no valid 3D position (an invalid 2D one): not on the
        # road. Vehicles then persons, each sorted by id as libsumo gives them (TraCI keeps insertion order):
        # the same order on both paths, so sums over actors are the same to the last bit
        found: list[str] = []
        values: list[float] = []  # x, y, z, angle, speed of each found actor in turn
        for group in (self._api.vehicle.getAllSubscriptionResults(), self._api.person.getAllSubscriptionResults()):
            for i in sorted(group):
                r = group[i]
                pos = r.get(pos_, ())
                if len(pos) == 3:
                    found.append(i)
                    values += pos
                    values.append(r[angle_])
                    values.append(r[speed_])
        ids = tuple(found)
        k = len(ids)
        rows = np.array(values, dtype=float).reshape(k, 5)
        pos, z, yaw, speed = rows[:, :2], rows[:, 2], sumo_angle_to_yaw(rows[:, 3]), rows[:, 4]
        if self._snapshot_dims is None or self._snapshot_dims[0] != ids:  # actors rarely change: cache
            dims = np.array([self._dims.get(i, (4.5, 1.8, False)) for i in ids], dtype=float).reshape(k, 3)
            cached = (dims[:, 0].copy(), dims[:, 1].copy(), dims[:, 2].astype(bool))
            to_centre = np.where(cached[2], 0.0, cached[0] / 2)[:, None]  # front bumper -> centre [m]
            for a in (*cached, to_centre):
                a.setflags(write=False)  # shared by the snapshots that follow
            self._snapshot_dims = (ids, *cached, to_centre)
        _, length, width, is_ped, to_centre = self._snapshot_dims
        heading = np.empty((k, 2))
        np.cos(yaw, out=heading[:, 0])
        np.sin(yaw, out=heading[:, 1])
        heading *= to_centre
        return Actors(ids, np.subtract(pos, heading, out=heading), yaw, speed, length, width, is_ped, z)

    def vehicle_state(self, vehicle_id: str) -> VehicleState | None:
        """Pose and lane of a subscribed vehicle with lane variables (the ego), None if absent."""
        r = self._api.vehicle.getSubscriptionResults(vehicle_id)
        if not r:
            return None
        length = self._dims[vehicle_id][0]
        yaw = float(sumo_angle_to_yaw(r[tc.VAR_ANGLE]))
        front = np.asarray(r[tc.VAR_POSITION3D][:2], dtype=float)
        return VehicleState(
            xy=front - length / 2 * np.array([math.cos(yaw), math.sin(yaw)]),
            yaw=yaw,
            speed=float(r[tc.VAR_SPEED]),
            lane=r[tc.VAR_LANE_ID],
            lane_pos=float(r[tc.VAR_LANEPOSITION]),
            route_index=int(r[tc.VAR_ROUTE_INDEX]),
        )

    def light_ahead(self, vehicle_id: str) -> LightAhead | None:
        """The next traffic light on the vehicle's route, or None."""
        lights = self._api.vehicle.getNextTLS(vehicle_id)
        if not lights:
            return None
        tls, link_index, distance, state = lights[0]
        return LightAhead(tls, int(link_index), float(distance), state)

    def light_state(self, tls: str, link_index: int) -> str:
        """Current signal char (``r``, ``y``, ``g``, ``G`` ...) of one link of a traffic light."""
        return self._api.trafficlight.getRedYellowGreenState(tls)[link_index]

    def light_ids(self) -> tuple[str, ...]:
        """Every traffic light of the net."""
        return tuple(self._api.trafficlight.getIDList())

    def shift_light_phases(self, fractions: dict[str, float]) -> None:
        """Start each traffic light ``tls`` of ``fractions`` that far into its program's cycle
        (a fraction in [0, 1) of the cycle's length), before the first step: the same fixed-time
        program, another phase offset. The phase and its remaining time are set; every later
        phase runs its own duration."""
        api = self._api.trafficlight
        for tls, fraction in fractions.items():
            if not 0.0 <= fraction < 1.0:
                raise ValueError(f"light phase fraction of {tls} must be in [0, 1), got {fraction}")
            program = api.getProgram(tls)
            logic = next(lg for lg in api.getAllProgramLogics(tls) if lg.programID == program)
            durations = [float(p.duration) for p in logic.phases]
            into = fraction * sum(durations)
            for index, duration in enumerate(durations):
                if into < duration:
                    break
                into -= duration
            api.setPhase(tls, index)
            api.setPhaseDuration(tls, max(duration - into, self.step_length))

    def signal_schedule(self, tls: str, link_index: int, horizon_s: float = 60.0) -> tuple[tuple[float, str], ...]:
        """The signal of one link now and at each change within ``horizon_s`` [s]: ((0, char now),
        (seconds until the next change, new char), ...), read off the traffic light's program
        (fixed-time programs; for others the current phase's planned end and the nominal
        durations after it)."""
        phases = self._programs.get(tls)
        if phases is None:
            program = self._api.trafficlight.getProgram(tls)
            logic = next(lg for lg in self._api.trafficlight.getAllProgramLogics(tls) if lg.programID == program)
            phases = self._programs[tls] = tuple((float(p.duration), p.state) for p in logic.phases)
        phase = self._api.trafficlight.getPhase(tls)
        now = self._api.simulation.getTime()
        char = self._api.trafficlight.getRedYellowGreenState(tls)[link_index]
        out = [(0.0, char)]
        t = max(self._api.trafficlight.getNextSwitch(tls) - now, 1e-3)  # a switch due now: just after now
        for k in range(1, 4 * len(phases) + 1):
            if t > horizon_s:
                break
            duration, state = phases[(phase + k) % len(phases)]
            if state[link_index] != out[-1][1]:
                out.append((round(t, 3), state[link_index]))
            t += duration
        return tuple(out)

    def link_users(self, from_lane: str, junction_lanes: tuple[str, ...], horizon_m: float) -> tuple[tuple[str, float, float], ...]:
        """The vehicles on a link's junction lanes and those within ``horizon_m`` [m] of it on
        ``from_lane`` whose next link it is: (id, distance [m] from the front bumper to the link's
        start, negative inside it, speed [m/s])."""
        out = []
        offset = 0.0
        for lane in junction_lanes:
            for vid in self._api.lane.getLastStepVehicleIDs(lane):
                out.append((vid, -(offset + self._api.vehicle.getLanePosition(vid)), self._api.vehicle.getSpeed(vid)))
            offset += self._api.lane.getLength(lane)
        length = self._api.lane.getLength(from_lane)
        for vid in self._api.lane.getLastStepVehicleIDs(from_lane):
            dist = length - self._api.vehicle.getLanePosition(vid)
            links = self._api.vehicle.getNextLinks(vid) if dist <= horizon_m else ()
            if links and links[0][4] == junction_lanes[0]:
                out.append((vid, dist, self._api.vehicle.getSpeed(vid)))
        return tuple(out)

    def next_junction_lane(self, vehicle_id: str) -> str:
        """The first junction (internal) lane of the link SUMO drives the vehicle over at the next
        junction (its choice where several links lead onto the route's next edge), "" if none."""
        links = self._api.vehicle.getNextLinks(vehicle_id)
        return str(links[0][4]) if links else ""

    def crossing_waiters(self, crossing: str, walkingareas: tuple[str, ...]) -> tuple[str, ...]:
        """The pedestrians on the walking areas at a crossing's ends whose next edge is the crossing."""
        return tuple(pid for area in walkingareas for pid in self._api.edge.getLastStepPersonIDs(area)
                     if self._api.person.getNextEdge(pid) == crossing)

    # ---------------------------------------------------------------- commands
    def track_lane(self, vehicle_id: str) -> None:
        """Subscribe a vehicle to its lane variables too, so :meth:`vehicle_state` works for it
        (done for the ego on insertion; a background vehicle driven by an agent needs it)."""
        self._api.vehicle.subscribe(vehicle_id, _EGO_SUBSCRIBED)

    def remove_vehicle(self, vehicle_id: str) -> None:
        """Take a vehicle out of the simulation (no-op if it is already gone)."""
        try:
            self._api.vehicle.unsubscribe(vehicle_id)  # a subscription of a removed vehicle breaks the next step
            self._api.vehicle.remove(vehicle_id)
        except _SUMO_ERRORS:
            pass

    def clear_junction_blockers(self, kept: Callable[[str], bool], wait_s: float) -> tuple[str, ...]:
        """Take out of the simulation every vehicle SUMO drives (not ``kept(id)``: the agents' and scripts')
        that has stood inside a junction for ``wait_s`` [s] or more; returns their ids.

        SUMO resolves a gridlock by teleporting a vehicle that waited too long (``--time-to-teleport``,
        which is off here: it would move the agents' vehicles too). Inside a junction only a gridlock holds
        a car that long: two or three vehicles each in another's path, which the agents' vehicles, driving
        by their own rules among SUMO's, can close with SUMO's."""
        api, out = self._api.vehicle, []
        for vehicle_id in api.getIDList():
            if not kept(vehicle_id) and api.getWaitingTime(vehicle_id) >= wait_s \
                    and api.getLaneID(vehicle_id).startswith(":"):
                self.remove_vehicle(vehicle_id)
                out.append(vehicle_id)
        return tuple(out)

    def hand_over(self, vehicle_id: str) -> None:
        """Give a vehicle's driving to the caller: no SUMO lane changes, no safe-speed or red-light
        braking (only its acceleration limits), so the agent can and must avoid infractions."""
        self._api.vehicle.setLaneChangeMode(vehicle_id, 0)
        self._api.vehicle.setSpeedMode(vehicle_id, 0b000110)

    def give_back(self, vehicle_id: str) -> None:
        """Undo :meth:`hand_over` and any :meth:`set_speed`: SUMO's own driver again (its lane
        changes, safe speeds and red-light braking)."""
        self._api.vehicle.setSpeed(vehicle_id, -1.0)
        self._api.vehicle.setSpeedMode(vehicle_id, 31)
        self._api.vehicle.setLaneChangeMode(vehicle_id, 1621)

    def run_red_lights(self, vehicle_id: str) -> None:
        """Keep SUMO's car following and its acceleration limits but ignore red lights and the right
        of way at junctions (a scenario's red-light runner); no lane changes of its own."""
        self._api.vehicle.setLaneChangeMode(vehicle_id, 0)
        self._api.vehicle.setSpeedMode(vehicle_id, 0b000111)

    def add_walker(self, person_id: str, edge: str, pos: float) -> None:
        """Insert a pedestrian at ``pos`` [m] on ``edge`` that stands still until moved by
        :meth:`move_person_to_xy` (a scenario's scripted pedestrian)."""
        self._api.person.add(person_id, edge, pos, depart=tc.DEPARTFLAG_NOW)
        self._api.person.appendWaitingStage(person_id, 1e6)
        self._api.person.subscribe(person_id, _SUBSCRIBED)
        self._dims[person_id] = (PEDESTRIAN_SIZE_M, PEDESTRIAN_SIZE_M, True)

    def move_person_to_xy(self, person_id: str, xy: np.ndarray, yaw: float) -> None:
        """Place a pedestrian at ``xy`` [m] facing ``yaw`` [rad] in the next step, on a road lane too."""
        self._api.person.moveToXY(person_id, "", float(xy[0]), float(xy[1]), yaw_to_sumo_angle(yaw), 2)

    def remove_person(self, person_id: str) -> None:
        """Take a pedestrian out of the simulation (no-op if it is already gone)."""
        try:
            self._api.person.unsubscribe(person_id)
            self._api.person.remove(person_id)
        except _SUMO_ERRORS:
            pass

    def set_speed(self, vehicle_id: str, speed: float) -> None:
        """Target speed [m/s], reached within the vehicle type's acceleration limits."""
        self._api.vehicle.setSpeed(vehicle_id, max(0.0, float(speed)))

    def change_lane(self, vehicle_id: str, lane_index: int) -> None:
        """Move to SUMO lane ``lane_index`` of the current edge in the next step."""
        self._api.vehicle.changeLane(vehicle_id, int(lane_index), self.step_length)

    def set_route(self, vehicle_id: str, route: tuple[str, ...] | list[str]) -> bool:
        """Replace a vehicle's route (must start with its current edge); False if SUMO refuses
        (e.g. the vehicle is inside a junction on a connection the route does not take)."""
        try:
            self._api.vehicle.setRoute(vehicle_id, list(route))
        except _SUMO_ERRORS:
            return False
        return True

    def move_to_xy(self, vehicle_id: str, xy: np.ndarray, yaw: float, *, edge: str = "", lane_index: int = -1,
                   on_route: bool = True) -> bool:
        """Place a vehicle's footprint centre at ``xy`` [m] with heading ``yaw`` [rad] in the next step.

        ``on_route`` (SUMO keepRoute=1) maps the pose onto the closest lane of the vehicle's own
        route, so its route, route index and next traffic lights stay valid (what a driven ego
        needs); otherwise the vehicle may go anywhere, even off the road (keepRoute=2), and its
        route shrinks to the edge it lands on. ``edge`` / ``lane_index`` are optional hints.
        Returns False when SUMO cannot map the pose (too far from any lane of the route).
        """
        length = self._dims[vehicle_id][0]
        front = np.asarray(xy, dtype=float) + length / 2 * np.array([math.cos(yaw), math.sin(yaw)])
        try:
            self._api.vehicle.moveToXY(vehicle_id, edge, int(lane_index), float(front[0]), float(front[1]),
                                       yaw_to_sumo_angle(yaw), 1 if on_route else 2)
            self._move_pending = True
        except _SUMO_ERRORS:
            return False
        return True

    def light_states(self) -> dict[str, str]:
        """Signal char of every controlled lane now: incoming lane id -> ``r``/``y``/``g``/``G``...

        A lane with several links (e.g. straight and turn) reports the most permissive one.
        """
        if self._controlled is None:
            self._controlled = {
                tls: [links[0][0] if links else "" for links in self._api.trafficlight.getControlledLinks(tls)]
                for tls in self._api.trafficlight.getIDList()
            }
        out: dict[str, str] = {}
        rank = {"G": 4, "g": 3, "y": 2, "Y": 2, "r": 1, "R": 1}
        for tls, lanes in self._controlled.items():
            state = self._api.trafficlight.getRedYellowGreenState(tls)
            for lane, char in zip(lanes, state):
                if lane and rank.get(char, 0) >= rank.get(out.get(lane, ""), 0):
                    out[lane] = char
        return out
