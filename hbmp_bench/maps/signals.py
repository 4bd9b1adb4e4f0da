"""Signal timing of the generated towns: the rules, the yellow re-timing, and a summary of a net's programs.

netconvert builds every junction's fixed-time program from the builder's options: which movements
move together, the town's vehicle green per main phase (:attr:`~hbmp_bench.maps.spec.TownSpec.green_s`;
the phase's pedestrian crossings turn red :data:`CROSSING_CLEARANCE_S` before its vehicle links), no
protected left-turn phases (left turns yield on the shared green, as in the real CARLA towns'
programs), a yellow, and an all-red clearance of :data:`ALL_RED_TIME_S` after every yellow. netconvert
gives every junction one yellow (3 s up to 70 km/h), shorter than the kinematic rule; the generator
then sets each yellow phase from the fastest approach of its junction (:func:`retime_yellows`):

    yellow(v) = REACTION_TIME_S + v / (2 * YELLOW_DECEL)        [s], rounded up to YELLOW_STEP_S

(the traffic-engineering rule; 3.4 s at 50 km/h, 3.8 s at 60 km/h, 5.2 s at 90 km/h). A driver at
the limit ``v`` who sees the yellow begin is either within its lawful stopping distance
(``v * 1 s + v^2 / (2 * 3 m/s^2)``, 46 m from 50 km/h) and stops, or reaches the stop line before the
yellow ends: no dilemma zone.

Greens: a main phase's vehicle green ``g`` clears a standing queue of :func:`queue_cleared` ``(g)``
vehicles (``START_UP_LOST_S`` then one per ``SATURATION_HEADWAY_S``): 20 s clear 9 cars, a 63 m
queue; 12 s clear 5. Towns with short blocks get the shorter green so that a lawful driver meets the
CoRL2017 timeouts (:mod:`hbmp_bench.scenarios.lawful`). The lights of a town all start their
programs at time 0 (offset 0), with the episode.

Units: seconds and m/s.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

REACTION_TIME_S = 1.0
"""Perception-reaction time of the yellow rule [s]."""
YELLOW_DECEL = 3.0
"""Comfortable deceleration of the yellow rule [m/s²]."""
YELLOW_STEP_S = 0.1
"""Yellows are rounded up to a multiple of this [s] (the simulation step)."""
ALL_RED_TIME_S = 2
"""All-red clearance after every yellow [s]: at 50 km/h a car that entered at the yellow's last
instant drives 28 m in it, across the small towns' junctions (19 m links) and its own length."""
START_UP_LOST_S = 2.0
"""Start-up lost time of a queue at the start of green [s]."""
SATURATION_HEADWAY_S = 2.0
"""Headway of a discharging queue [s] (1800 vehicles/h/lane)."""
CROSSING_CLEARANCE_S = 5
"""The pedestrian crossings of a phase turn red this long before its vehicle links [s] (netconvert's
default)."""

GREEN_CHARS = frozenset("Gg")
"""Signal chars of a link that may go (``g``: green, but yield)."""


def queue_cleared(green_s: float) -> int:
    """Standing vehicles of one lane that a green of ``green_s`` [s] lets through."""
    return max(0, math.floor((green_s - START_UP_LOST_S) / SATURATION_HEADWAY_S + 1e-9))


def yellow_time(speed: float) -> float:
    """Yellow [s] for an approach speed limit ``speed`` [m/s]: ``REACTION_TIME_S + speed / (2
    YELLOW_DECEL)``, rounded up to a multiple of :data:`YELLOW_STEP_S`."""
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be finite and > 0 [m/s], got {speed!r}")
    steps = (REACTION_TIME_S + speed / (2.0 * YELLOW_DECEL)) / YELLOW_STEP_S
    return round(math.ceil(steps - 1e-9) * YELLOW_STEP_S, 3)


@dataclass(frozen=True)
class Program:
    """One traffic light's fixed-time program, as the net states it.

    Attributes:
        id: the traffic light (its junction's) id.
        offset: SUMO's ``offset`` [s].
        durations: (P,) phase durations [s].
        states: (P,) phase states, one char per link index.
        vehicle_links: link indices of the vehicle connections it controls (not crossings).
        approach_speed: fastest speed limit among the lanes those links leave [m/s].
    """

    id: str
    offset: float
    durations: tuple[float, ...]
    states: tuple[str, ...]
    vehicle_links: tuple[int, ...]
    approach_speed: float

    @property
    def cycle(self) -> float:
        """Cycle length [s]."""
        return float(sum(self.durations))

    def yellow_phases(self) -> tuple[int, ...]:
        """Indices of the phases in which some link shows yellow."""
        return tuple(i for i, s in enumerate(self.states) if "y" in s)

    def all_red_phases(self) -> tuple[int, ...]:
        """Indices of the phases in which every vehicle link shows red."""
        return tuple(i for i, s in enumerate(self.states) if all(s[k] == "r" for k in self.vehicle_links))

    def green(self, link: int) -> float:
        """Time per cycle in which ``link`` may go (``G`` or ``g``) [s]."""
        return float(sum(d for d, s in zip(self.durations, self.states) if s[link] in GREEN_CHARS))

    def red_windows(self, link: int) -> tuple[tuple[float, float], ...]:
        """The stretches of one cycle in which ``link`` may not go: (start, end) [s] from the start
        of the program's first phase, a stretch that wraps past the cycle's end ending after it."""
        windows: list[list[float]] = []
        t = 0.0
        for d, s in zip(self.durations, self.states):
            if s[link] not in GREEN_CHARS:
                if windows and windows[-1][1] == t:
                    windows[-1][1] = t + d
                else:
                    windows.append([t, t + d])
            t += d
        if len(windows) > 1 and windows[0][0] == 0.0 and windows[-1][1] == t:
            windows[0] = [windows[-1][0], windows[0][1] + t]
            windows.pop()
        return tuple((a, b) for a, b in windows)

    def longest_red(self, link: int) -> float:
        """The longest stretch in which ``link`` may not go [s]: the longest wait at its stop line."""
        return max((b - a for a, b in self.red_windows(link)), default=0.0)

    def wait(self, link: int, time: float) -> float:
        """Wait [s] of a car that reaches ``link``'s stop line at simulation time ``time`` [s] until
        the link may go (0 when it may go at once)."""
        x = (time - self.offset) % self.cycle
        for a, b in self.red_windows(link):
            for shift in (0.0, self.cycle):
                if a <= x + shift < b:
                    return b - (x + shift)
        return 0.0


def _lane_speeds(root: ET.Element) -> dict[str, float]:
    return {ln.get("id"): float(ln.get("speed")) for ln in root.iter("lane")}


def read_programs(path: str | Path) -> dict[str, Program]:
    """The fixed-time programs of the net at ``path``, by traffic light id."""
    root = ET.parse(path).getroot()
    speeds = _lane_speeds(root)
    links: dict[str, set[int]] = {}
    approach: dict[str, float] = {}
    for c in root.iter("connection"):
        tls, frm = c.get("tl"), c.get("from")
        if tls is None or frm.startswith(":"):
            continue  # uncontrolled, or a pedestrian crossing's link
        links.setdefault(tls, set()).add(int(c.get("linkIndex")))
        approach[tls] = max(approach.get(tls, 0.0), speeds[f"{frm}_{c.get('fromLane')}"])
    programs = {}
    for tl in root.iter("tlLogic"):
        tls = tl.get("id")
        phases = tl.findall("phase")
        programs[tls] = Program(
            id=tls,
            offset=float(tl.get("offset", "0")),
            durations=tuple(float(p.get("duration")) for p in phases),
            states=tuple(p.get("state") for p in phases),
            vehicle_links=tuple(sorted(links.get(tls, ()))),
            approach_speed=approach.get(tls, 0.0),
        )
    return programs


_TL_LOGIC = re.compile(r'(<tlLogic id="(?P<id>[^"]+)"[^>]*>)(?P<body>.*?)(</tlLogic>)', re.S)
_PHASE = re.compile(r'(<phase duration=")([^"]+)"\s+(state="(?P<state>[^"]+)")')


def _fmt_time(t: float) -> str:
    return f"{t:.1f}".rstrip("0").rstrip(".")


def retime_yellows(path: str | Path) -> None:
    """Set every yellow phase of the net at ``path`` to :func:`yellow_time` of its junction's fastest
    approach, in place. Only the ``duration`` attributes of those phases change; the rest of the file
    is left byte for byte as netconvert wrote it. A light that controls no vehicle link keeps its
    program. RuntimeError if a yellow phase is left with another duration (a phase written in a form
    this does not read)."""
    path = Path(path)
    programs = read_programs(path)
    text = path.read_text(encoding="utf-8")

    def logic(m: re.Match) -> str:
        program = programs[m.group("id")]
        if not program.vehicle_links:
            return m.group(0)
        yellow = _fmt_time(yellow_time(program.approach_speed))

        def phase(p: re.Match) -> str:
            if "y" not in p.group("state"):
                return p.group(0)
            return f'{p.group(1)}{yellow}"{" " * max(1, 3 - len(yellow))}{p.group(3)}'

        return m.group(1) + _PHASE.sub(phase, m.group("body")) + m.group(4)

    path.write_text(_TL_LOGIC.sub(logic, text), encoding="utf-8")
    for program in read_programs(path).values():
        if program.vehicle_links:
            want = yellow_time(program.approach_speed)
            wrong = [program.durations[i] for i in program.yellow_phases() if abs(program.durations[i] - want) > 1e-6]
            if wrong:
                raise RuntimeError(f"{path.name}: yellow phases of {program.id!r} not re-timed to {want} s: {wrong}")


def _span(values: list[float]) -> list[float]:
    return [round(min(values), 2), round(max(values), 2)] if values else []


def signal_stats(path: str | Path) -> dict:
    """Timing summary of the net's traffic lights, each as [min, max] over the lights (empty
    without any) [s]: ``yellow_s`` and ``all_red_s`` (phase durations), ``green_s`` (a vehicle
    link's green per cycle), ``red_s`` (a vehicle link's longest wait) and ``cycle_s``."""
    programs = list(read_programs(path).values())
    yellow = [p.durations[i] for p in programs for i in p.yellow_phases()]
    all_red = [p.durations[i] for p in programs for i in p.all_red_phases()
               if "y" in p.states[i - 1]]
    green = [p.green(k) for p in programs for k in p.vehicle_links]
    red = [p.longest_red(k) for p in programs for k in p.vehicle_links]
    return {
        "yellow_s": _span(yellow),
        "all_red_s": _span(all_red),
        "green_s": _span(green),
        "red_s": _span(red),
        "cycle_s": _span([p.cycle for p in programs]),
    }
