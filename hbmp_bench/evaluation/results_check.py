"""Checks of a leaderboard results file: its claims are recomputed from its episode records and its suite.

A results file is data made elsewhere, by anyone; a board ranks only what follows from its
episodes. :func:`verify_results` (``leaderboard add``, and every file a board's README is rendered
from) refuses, with :class:`ForgedResultsError` listing every problem found:

- names that reach a path (``suite``, ``fidelity``, ``agent``) outside a strict pattern
  (:data:`~hbmp_bench.metrics.results_file.NAME_PATTERN`, no ``..``, no ``/``), an unknown suite or fidelity (the valid ones are
  named), or a file name other than the one its fields give (an entry copied over another agent's);
- a ``summary``, ``success_pct_by_task``, ``complete``, ``subset``, ``expected_episodes`` or
  ``sim_errors`` other than the one recomputed from the episodes (:func:`hbmp_bench.metrics.report.scores`): a
  hand-edited success %, "500 of 500" over one episode;
- episodes that are not the selection's: a key missing, repeated, or outside the selection, and,
  when ``against_suite``, a selection that is not the suite's (a "complete" entry with fewer episodes
  than the suite has), a seed or route length other than the suite's episode's, a duration past
  the episode's timeout;
- an episode whose fields contradict each other (:func:`record_problems`): a success that is not
  a goal or with a route completion below 1, a driving score other than the one its completion
  and infractions give, an infraction the suite's rules would have ended the episode at (a success
  with a red light under the paper's protocol, a collision that did not end a NoCrash episode);
- when ``against_suite``: a ``privileged`` flag or ``agent_fingerprint`` that contradicts what the
  package knows of the agent (:func:`agent_problems`: its registered agents, a checkpoint file that
  is here), and a salt that does not match its commitment (:func:`salt_problems`).

What it cannot check: that the episodes were run at all (a file can be made up consistently);
:mod:`hbmp_bench.evaluation.audit` replays a sample of them.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from collections import Counter
from pathlib import Path

from hbmp_bench.errors import UserError
from hbmp_bench.metrics.records import AGENT_ERROR, SIM_ERROR, driving_score
from hbmp_bench.evaluation.tasks import scene_vehicles, vehicle_episode
from hbmp_bench.metrics.results_file import (EPISODE_COLUMNS, SCENE_COLUMNS, ForgedResultsError, episode_columns,
                                             name_problems, results_records)
from hbmp_bench.vocabulary import COLLISION_KINDS, INFRACTION_KINDS, VIOLATION_KINDS

WORLD_END_REASONS = ("goal", "timeout", "collision", "violation", "left_network")
"""How the world ends an episode (``envs.vehicle``)."""
END_REASONS = (*WORLD_END_REASONS, AGENT_ERROR, SIM_ERROR)
"""The end reasons a board entry's episode may have (a capped smoke run is no evaluation)."""
SCORE_TOLERANCE = 0.006
"""Largest gap between a record's driving score and the one recomputed from its rounded route
completion (4 decimals: up to 0.005 points on the 0-100 scale)."""
DURATION_SLACK_S = 0.15
"""How far past its timeout [s] an episode may be recorded (the timeout is checked once per 0.1 s step)."""
HEX16 = re.compile(r"[0-9a-f]{16}")
HEX64 = re.compile(r"[0-9a-f]{64}")
SALT = re.compile(r"[0-9a-f]{32,64}")
"""A revealed salt: 16 to 32 random bytes in lowercase hex (``evaluate.new_salt`` makes 16)."""

_INT_FIELDS = ("episode", "seed", *INFRACTION_KINDS, "decisions")
_FLOAT_FIELDS = ("route_completion", "driving_score", "duration_s", "distance_m", "route_length_m")


def commitment(salt: str) -> str:
    """The SHA-256 (hex) of a salt as its text: what a salted entry publishes before the salt is revealed."""
    return hashlib.sha256(salt.encode("ascii")).hexdigest()


def contained(path: Path, folder: Path) -> Path:
    """``path`` if, resolved, it lies inside ``folder`` (resolved), else ValueError."""
    resolved, root = path.resolve(), folder.resolve()
    if resolved.parent != root and root not in resolved.parents:
        raise UserError(f"{path} resolves to {resolved}, outside the board folder {root}")
    return path


def _label(row: dict) -> str:
    vehicle = row.get("vehicle")
    return f"episode {row.get('town')}/{row.get('task')}/{row.get('episode')}" + (f" vehicle {vehicle}" if vehicle else "")


def record_problems(row: dict, *, end_on_violation: bool, end_on_collision: bool,
                    columns: tuple[str, ...] = EPISODE_COLUMNS) -> list[str]:
    """Contradictions within one episode row of a results file (the suite's rules given by
    ``end_on_violation``, the paper's protocol, and ``end_on_collision``, NoCrash's; ``columns``: the
    suite's, ``results_file.episode_columns``)."""
    where = _label(row)
    shape = _row_shape_problems(row, where, columns)
    if shape:
        return shape
    return [*_outcome_problems(row, where), *_rule_problems(row, where, end_on_violation, end_on_collision)]


def _row_shape_problems(row: dict, where: str, columns: tuple[str, ...]) -> list[str]:
    """A missing column, or a value of the wrong type or sign (then nothing else of the row is judged)."""
    missing = [k for k in columns if k not in row]
    if missing:
        return [f"{where} lacks {missing}"]
    bad = [k for k in _INT_FIELDS if isinstance(row[k], bool) or not isinstance(row[k], int) or row[k] < 0]
    bad += [k for k in _FLOAT_FIELDS if isinstance(row[k], bool) or not isinstance(row[k], (int, float))
            or not math.isfinite(row[k]) or row[k] < 0]
    bad += [k for k in ("success", "timeout") if not isinstance(row[k], bool)]
    bad += [k for k in ("town", "task", "end_reason", "error", *SCENE_COLUMNS) if k in columns
            and not isinstance(row[k], str)]
    if bad:
        return [f"{where} has invalid {sorted(set(bad))} (counts and indices: integers >= 0; measures: finite "
                "numbers >= 0; success, timeout: true or false)"]
    return []


def _outcome_problems(row: dict, where: str) -> list[str]:
    """The end reason, success, timeout, route completion and driving score of a row against each other."""
    problems = []
    reason = row["end_reason"]
    if reason not in END_REASONS:
        problems.append(f"{where} ends with {reason!r}, not one of {', '.join(END_REASONS)}")
    if row["success"] != (reason == "goal"):
        problems.append(f"{where} says success={row['success']} with end_reason {reason!r} (a success is a goal)")
    if row["timeout"] != (reason == "timeout"):
        problems.append(f"{where} says timeout={row['timeout']} with end_reason {reason!r}")
    if not 0.0 <= row["route_completion"] <= 1.0:
        problems.append(f"{where} has route_completion {row['route_completion']} outside [0, 1]")
    elif row["success"] and row["route_completion"] != 1.0:
        problems.append(f"{where} is a success with route_completion {row['route_completion']} (1 at the goal)")
    if reason == AGENT_ERROR:
        if row["driving_score"] != 0.0:
            problems.append(f"{where} is an agent_error with driving score {row['driving_score']} (0)")
    elif reason != SIM_ERROR:
        expected = driving_score(row["route_completion"], row)
        if abs(expected - row["driving_score"]) > SCORE_TOLERANCE:
            problems.append(f"{where} has driving score {row['driving_score']}, but its route completion and "
                            f"infractions give {expected:.3f}")
    return problems


def _rule_problems(row: dict, where: str, end_on_violation: bool, end_on_collision: bool) -> list[str]:
    """The row's infraction counts against its end reason and the suite's rules."""
    problems = []
    reason = row["end_reason"]
    collisions = sum(row[k] for k in COLLISION_KINDS)
    violations = sum(row[k] for k in VIOLATION_KINDS)
    if reason == "collision" and not collisions:
        problems.append(f"{where} ends in a collision but counts none")
    if reason == "violation" and not violations:
        problems.append(f"{where} ends in a violation but counts none")
    if end_on_violation and reason in ("goal", "timeout", "left_network") and (collisions or violations):
        problems.append(f"{where} ends with {reason!r} after {collisions} collisions and {violations} violations: "
                        "the suite's protocol ends an episode at its first violation")
    if end_on_collision and reason in ("goal", "timeout", "left_network", "violation") and collisions:
        problems.append(f"{where} ends with {reason!r} after {collisions} collisions: the suite ends an episode "
                        "at its first collision")
    return problems


def episode_problems(doc: dict, *, against_suite: bool) -> list[str]:
    """Problems of a results file's episodes: each row's own (:func:`record_problems`), keys that
    are not exactly the selection's, and when ``against_suite`` a selection outside the suite's and
    rows that differ from the suite's episode (seed, route length, a duration past its timeout); an imported map
    of this machine counts as one of the suite's towns, its episodes drawn on it."""
    from hbmp_bench.scenarios import get_suite

    spec = get_suite(doc["suite"])
    selection = doc.get("selection")
    if not isinstance(selection, dict) or not all(isinstance(selection.get(k), list) for k in ("towns", "tasks", "episodes")):
        return ["its selection is not {towns: [...], tasks: [...], episodes: [...]}"]
    towns, tasks, indices = selection["towns"], selection["tasks"], selection["episodes"]
    if not (all(isinstance(t, str) for t in towns + tasks) and all(isinstance(i, int) and not isinstance(i, bool)
                                                                   for i in indices)):
        return ["its selection names towns and tasks by strings and episodes by integers"]
    problems = _selection_problems(spec, towns, tasks, indices, against_suite)
    rows = doc["episodes"]
    columns = episode_columns(spec.name)
    for row in rows:
        problems += record_problems(row, end_on_violation=spec.end_on_violation, end_on_collision=spec.end_on_collision,
                                    columns=columns)
    if problems:
        return problems
    problems = _key_problems(rows, towns, tasks, indices, scene_vehicles(spec.name))
    if not problems and spec.agents > 1:
        problems = _scene_problems(rows)
    if problems or not against_suite:
        return problems
    return _reference_problems(spec, rows)


def _selection_problems(spec, towns: list, tasks: list, indices: list, against_suite: bool) -> list[str]:
    """A selection whose towns, tasks or episodes are empty or repeat, or (``against_suite``) lie outside the
    suite's (an imported map of this machine counts as one of its towns)."""
    problems = []
    for kind, values in (("towns", towns), ("tasks", tasks), ("episodes", indices)):
        if len(set(values)) != len(values) or not values:
            problems.append(f"its selection's {kind} {values} are empty or repeat")
    if against_suite:
        from hbmp_bench.maps import user_maps

        imported = set(user_maps())  # a suite runs on an imported map too; its episodes are the map's own
        outside = [t for t in tasks if t not in spec.tasks] + [t for t in towns if t not in spec.towns and t not in imported]
        outside += [i for i in indices if not 0 <= i < spec.episodes_per_task]
        if outside:
            problems.append(f"its selection holds {outside}, not in suite {spec.name!r} (towns {list(spec.towns)}, "
                            f"tasks {list(spec.tasks)}, episodes 0-{spec.episodes_per_task - 1})")
    return problems


def _key_problems(rows: list[dict], towns: list, tasks: list, indices: list, vehicles: tuple[str, ...]) -> list[str]:
    """Episodes that appear more than once or lie outside the selection, and (a multi-agent suite's) episodes
    whose rows are not exactly one per vehicle of the scene (``vehicles``: ``tasks.scene_vehicles``): a vehicle
    missing, twice, or one the scene has not."""
    problems = []
    wanted = {(town, task, i) for town in towns for task in tasks for i in indices}
    keys = Counter((r["town"], r["task"], r["episode"], r.get("vehicle", "")) for r in rows)
    repeated = sorted(k for k, n in keys.items() if n > 1)
    extra = sorted({k[:3] for k in keys} - wanted)
    if repeated:
        problems.append(f"{len(repeated)} episodes appear more than once (e.g. {_key_label(repeated[0])})")
    if extra:
        problems.append(f"{len(extra)} episodes are outside its selection (e.g. {'/'.join(map(str, extra[0]))})")
    held: dict[tuple, set] = {}
    for town, task, index, vehicle in keys:
        held.setdefault((town, task, index), set()).add(vehicle)
    for key in sorted(held):
        if held[key] != set(vehicles):
            missing, foreign = sorted(set(vehicles) - held[key]), sorted(held[key] - set(vehicles))
            problems.append(f"episode {'/'.join(map(str, key))} has rows of vehicles {sorted(held[key])}, its scene's "
                            f"are {list(vehicles)}" + (f" (missing {missing})" if missing else "")
                            + (f" (not of the scene: {foreign})" if foreign else ""))
    return problems


def _key_label(key: tuple) -> str:
    return "/".join(map(str, key[:3])) + (f" vehicle {key[3]}" if key[3] else "")


def _scene_problems(rows: list[dict]) -> list[str]:
    """Collisions between a scene's goal-directed vehicles that its rows do not agree on: a vehicle named
    that is not another vehicle of the scene, a pair in one vehicle's row and not the other's, or more such
    collisions than the row's vehicle collisions (``collision_vehicle`` counts them too)."""
    problems = []
    scenes: dict[tuple, dict[str, list[str]]] = {}
    for r in rows:
        scenes.setdefault((r["town"], r["task"], r["episode"]), {})[r["vehicle"]] = r["agent_collisions"].split()
    for row in rows:
        where, named = _label(row), row["agent_collisions"].split()
        scene = scenes[row["town"], row["task"], row["episode"]]
        if len(set(named)) != len(named) or named != sorted(named):
            problems.append(f"{where} names agent collisions {named} out of order or twice")
        for other in named:
            if other == row["vehicle"] or other not in scene:
                problems.append(f"{where} collided with {other!r}, not another vehicle of its scene")
            elif row["vehicle"] not in scene[other]:
                problems.append(f"{where} collided with {other}, whose row does not name {row['vehicle']}")
        if len(named) > row["collision_vehicle"]:
            problems.append(f"{where} collided with {len(named)} controlled agents but counts "
                            f"{row['collision_vehicle']} vehicle collisions")
    return problems


def _reference_problems(spec, rows: list[dict]) -> list[str]:
    """Rows whose seed, route length or duration differ from the suite's episode."""
    from hbmp_bench.scenarios import suite_episodes

    problems = []
    for row in rows:
        reference = vehicle_episode(suite_episodes(spec.name, row["town"], row["task"])[row["episode"]],
                                    row.get("vehicle", ""))
        where = _label(row)
        if row["seed"] != reference.seed:
            problems.append(f"{where} has seed {row['seed']}, the suite's episode {reference.seed}")
        if abs(row["route_length_m"] - reference.route_length_m) > 0.01:
            problems.append(f"{where} has route length {row['route_length_m']} m, the suite's episode "
                            f"{reference.route_length_m} m")
        if row["duration_s"] > reference.timeout_s + DURATION_SLACK_S:
            problems.append(f"{where} lasted {row['duration_s']} s, past the episode's timeout of {reference.timeout_s} s")
    return problems


def _same(a: object, b: object) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def claim_problems(doc: dict, recomputed: dict) -> list[str]:
    """Where a results file's claims differ from what its episodes give (``recomputed``:
    ``leaderboard.scores``)."""
    problems = []
    for key in ("complete", "subset", "expected_episodes", "sim_errors", "selection"):
        if not _same(doc.get(key), recomputed[key]):
            problems.append(f"it says {key}={doc.get(key)!r}, its episodes give {recomputed[key]!r}")
    summary = doc.get("summary") if isinstance(doc.get("summary"), dict) else {}
    for key, value in recomputed["summary"].items():
        if not _same(summary.get(key), value):
            problems.append(f"it says summary.{key}={summary.get(key)!r}, its episodes give {value!r}")
    extra = sorted(set(summary) - set(recomputed["summary"]))
    if extra:
        problems.append(f"its summary has fields no episode gives: {extra}")
    aggregates = doc.get("aggregates") if isinstance(doc.get("aggregates"), dict) else {}
    for view in ("success_pct_by_task", "multi_by_town"):
        claimed, given = aggregates.get(view), recomputed["aggregates"].get(view)
        if not _same(claimed, given):
            problems.append(f"it says {view}={claimed!r}, its episodes give {given!r}")
    return problems


def agent_problems(doc: dict) -> list[str]:
    """Where a results file's ``privileged`` flag or ``agent_fingerprint`` contradicts what the
    package knows of its agent. Checkable: a registered agent (built here: the package's own code;
    a learned one's fingerprint is its shipped checkpoint's), a ``.pt`` checkpoint file that is
    here (hashed, never loaded: a checkpoint may name code). ``privileged`` true is never refused:
    the evaluator may hand any agent the privileged fields (and did before the flag, format 1).
    A ``module:Class`` agent's are its own claims (``audit`` replays it to check them)."""
    from hbmp_bench.agents import AGENTS, PRIVILEGED_OPTION, load_agent
    from hbmp_bench.agents.learned import TRAIN_COMMANDS, checkpoint_fingerprint, shipped_checkpoint
    from hbmp_bench.evaluation.channel import AgentDescription

    agent = doc["agent"]
    claimed = (doc.get("provenance") or {}).get("agent_fingerprint", "")
    problems = []
    if not isinstance(claimed, str) or claimed and not HEX16.fullmatch(claimed):
        return [f"its agent_fingerprint {claimed!r} is not 16 hex digits or empty"]
    if agent in AGENTS:
        description = AgentDescription.of(load_agent(agent))
        privileged = dict(description.env_kwargs).get(PRIVILEGED_OPTION) is True
        known = checkpoint_fingerprint(shipped_checkpoint(agent)) if agent in TRAIN_COMMANDS else description.fingerprint
        if privileged and not doc["privileged"]:
            problems.append(f"it says privileged=false, but agent {agent!r} reads the privileged scene fields")
        if claimed != known:
            problems.append(f"it says agent_fingerprint={claimed!r}, but agent {agent!r} runs "
                            f"{known!r} ({'its shipped checkpoint' if known else 'no checkpoint'})")
    elif agent.endswith(".pt"):
        if os.path.isfile(agent) and claimed != checkpoint_fingerprint(agent):
            problems.append(f"it says agent_fingerprint={claimed!r}, but {agent} here hashes to "
                            f"{checkpoint_fingerprint(agent)!r}")
    return problems


def salt_problems(doc: dict) -> list[str]:
    """A salted entry must publish its salt's commitment (SHA-256, 64 hex digits) and, once
    complete, the salt itself, which must match it; an unsalted one has neither."""
    provenance = doc.get("provenance") or {}
    salted, salt, promised = doc.get("salted"), provenance.get("salt", ""), provenance.get("salt_commitment", "")
    if not isinstance(salted, bool):
        return [f"salted is {salted!r}, not true or false"]
    if not salted:
        return [f"it is unsalted but names a salt or commitment"] if salt or promised else []
    if not isinstance(promised, str) or not HEX64.fullmatch(promised):
        return [f"it is salted, but its salt_commitment {promised!r} is not a SHA-256 (64 hex digits)"]
    if not salt:
        return ["it is salted and complete, but its salt is not revealed (no replay could check it)"] \
            if doc.get("complete") else []
    if not isinstance(salt, str) or not SALT.fullmatch(salt):
        return [f"its salt {salt!r} is not 32-64 lowercase hex digits"]
    if commitment(salt) != promised:
        return [f"its salt hashes to {commitment(salt)}, not to its salt_commitment {promised}"]
    return []


def verify_results(doc: dict, source: str, *, against_suite: bool = True) -> dict:
    """The scores of a results file (``leaderboard.scores``, with every report view when
    ``against_suite``) if everything in it adds up, else :class:`ForgedResultsError` naming each
    problem. ``doc`` must already be a results file of the installed suite (``check_results``).

    ``against_suite`` False (rendering a board's README) skips what needs the suite's episode list
    or the agent built (seeds, route lengths, timeouts, the selection's bounds, the agent's
    privileged flag and fingerprint, the salt); ``leaderboard add`` checks everything."""
    problems = name_problems(doc)
    if not isinstance(doc.get("episodes"), list):
        problems.append("it has no list of episodes")
    if problems:
        raise ForgedResultsError(source, problems)
    problems = episode_problems(doc, against_suite=against_suite)
    if problems:
        raise ForgedResultsError(source, problems)
    selection = doc["selection"]
    from hbmp_bench.metrics.report import scores  # pandas: loaded where a file is checked, not at import

    recomputed = scores(doc["suite"], results_records(doc), towns=selection["towns"], tasks=selection["tasks"],
                        episodes=selection["episodes"], agent=doc["agent"], aggregates=against_suite)
    problems = claim_problems(doc, recomputed)
    problems += salt_problems(doc)
    if against_suite:
        problems += agent_problems(doc)
    if problems:
        raise ForgedResultsError(source, problems)
    return recomputed
