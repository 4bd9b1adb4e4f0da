"""A leaderboard results file: its layout, its names and how it is read into episode records.

A results file (``<board>/<suite>/<agent>.<fidelity>.json``) holds an evaluation's per-episode records,
the aggregates derived from them and provenance. Reading one is the metrics' business:
``hbmp-bench report`` reads it like a records file (:func:`results_records`; the aggregates are
:func:`hbmp_bench.metrics.report.scores`), and the leaderboard
(:mod:`hbmp_bench.evaluation.leaderboard`) and its checks (:mod:`hbmp_bench.evaluation.results_check`)
build on what is here, never the other way round.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from hbmp_bench.errors import UnknownNameError, UserError
from hbmp_bench.metrics.records import SIM_ERROR, EpisodeRecord
from hbmp_bench.scenarios import get_suite
from hbmp_bench.vocabulary import FIDELITIES, INFRACTION_KINDS

RESULTS_FORMAT = 3
"""Version of the results file layout (2: the ``privileged`` flag; 3: the ``salted`` flag and the
salt's commitment). A format-1 file reads as privileged: before the flag every agent was handed
the privileged scene fields; format 1 and 2 files read as unsalted (salted mode came with 3)."""

EPISODE_COLUMNS = (
    "town", "task", "episode", "seed", "success", "route_completion", "driving_score", *INFRACTION_KINDS, "timeout",
    "duration_s",
    "distance_m", "route_length_m", "decisions", "end_reason", "error",
)
"""Per-episode fields kept in a results file."""

SCENE_COLUMNS = ("vehicle", "agent_collisions")
"""Per-episode fields a multi-agent suite's results file keeps besides :data:`EPISODE_COLUMNS` (its rows are one
per goal-directed vehicle of each scene, see ``EpisodeRecord``)."""


def episode_columns(suite: str) -> tuple[str, ...]:
    """The per-episode fields of a results file of ``suite``: :data:`EPISODE_COLUMNS`, and :data:`SCENE_COLUMNS`
    for a multi-agent suite (``Suite.agents`` > 1)."""
    return (*EPISODE_COLUMNS, *SCENE_COLUMNS) if get_suite(suite).agents > 1 else EPISODE_COLUMNS


NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.:+-]{0,127}")
"""What a suite, fidelity or agent name of a results file may be: letters, digits and ``_ . : + -``,
not starting with a dot, at most 128 characters, and never holding ``..`` (nor ``/``)."""

class ForgedResultsError(UserError):
    """A results file whose claims do not follow from its episodes and its suite (see the module
    docstring); ``problems`` lists each one."""

    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, list(problems)
        shown = "; ".join(self.problems[:12]) + (f"; and {len(self.problems) - 12} more" if len(self.problems) > 12 else "")
        super().__init__(f"{source} is refused: {shown}")


class StaleResultsError(UserError):
    """A results file made for another definition of its suite."""


def check_name(kind: str, value: object) -> str:
    """``value`` if it is a name that may reach a file path (:data:`NAME_PATTERN`), else ValueError."""
    if not isinstance(value, str) or not NAME_PATTERN.fullmatch(value) or ".." in value:
        raise UserError(f"{kind} {value!r} is not a valid name: letters, digits and _ . : + - only, "
                         f"at most 128, not starting with '.', no '..' or '/'")
    return value


def name_problems(doc: dict) -> list[str]:
    """Problems of the fields that reach a path: ``suite`` (a registered suite), ``fidelity`` (one
    of the world's) and ``agent`` (:data:`NAME_PATTERN`)."""
    from hbmp_bench.scenarios import SUITES

    problems = []
    for kind in ("suite", "fidelity", "agent"):
        try:
            check_name(kind, doc.get(kind))
        except ValueError as exc:
            problems.append(str(exc))
    if isinstance(doc.get("suite"), str) and doc["suite"] not in SUITES:
        problems.append(str(UnknownNameError("suite", doc["suite"], SUITES)))
    if doc.get("fidelity") not in FIDELITIES:
        problems.append(f"fidelity {doc.get('fidelity')!r} is not one of {', '.join(FIDELITIES)}")
    provenance = doc.get("provenance")
    if isinstance(provenance, dict) and provenance.get("fidelity", doc.get("fidelity")) != doc.get("fidelity"):
        problems.append(f"provenance.fidelity {provenance.get('fidelity')!r} is not the entry's {doc.get('fidelity')!r}")
    return problems


def _current_format(doc: object, source: str) -> dict:
    """``doc`` read as a format-:data:`RESULTS_FORMAT` file (an older one upgraded, see there), with the fields
    every results file has; else a ``UserError`` naming what is missing."""
    if isinstance(doc, dict) and doc.get("format") == 1 and "privileged" not in doc:
        doc = {**doc, "format": 2, "privileged": True}
    if isinstance(doc, dict) and doc.get("format") == 2:
        doc = {**doc, "format": RESULTS_FORMAT, "salted": False}
    if not isinstance(doc, dict) or doc.get("format") != RESULTS_FORMAT or not isinstance(doc.get("suite"), str):
        raise UserError(f"{source} is not a leaderboard results file (format {RESULTS_FORMAT})")
    if not isinstance(doc.get("provenance"), dict):
        raise UserError(f"{source} has no provenance")
    if not isinstance(doc.get("privileged"), bool):
        raise UserError(f"{source} has no privileged flag (true or false)")
    episodes = doc.get("episodes")
    if not isinstance(episodes, list) or not all(isinstance(e, dict) for e in episodes):
        raise UserError(f"{source} has no list of episodes")
    return doc


def check_results(doc: dict, source: str = "results") -> dict:
    """``doc`` if it is a results file of the installed suite whose ``complete`` and ``sim_errors``
    agree with its episodes; else a clear error. A format-1 file is read as format 3 with
    ``privileged`` true, a format 1 or 2 file as unsalted (see :data:`RESULTS_FORMAT`). Everything
    else a file claims is checked by ``results_check.verify_results``."""
    doc = _current_format(doc, source)
    episodes = doc["episodes"]
    sim_errors = sum(e.get("end_reason") == SIM_ERROR for e in episodes)
    if doc.get("sim_errors") != sim_errors:
        raise UserError(f"{source} says sim_errors={doc.get('sim_errors')!r} but its episodes hold {sim_errors}")
    if doc.get("complete") and (sim_errors or doc.get("subset") or len(episodes) != doc.get("expected_episodes")):
        raise UserError(f"{source} says complete, but it has {len(episodes)} of {doc.get('expected_episodes')} "
                         f"episodes, {sim_errors} sim errors, subset={doc.get('subset')!r}")
    name_issues = name_problems(doc)
    if name_issues:
        raise ForgedResultsError(source, name_issues)
    current = get_suite(doc["suite"]).definition_hash()
    if doc.get("suite_hash") != current:
        raise StaleResultsError(
            f"{source} was made for suite {doc['suite']!r} with definition hash {doc.get('suite_hash')!r}, but the "
            f"installed {doc['suite']!r} hashes to {current!r}: its episodes are not the current suite's. Rerun the "
            f"submission (hbmp-bench leaderboard submit --suite {doc['suite']} --agent {doc.get('agent')}) or remove the file."
        )
    return doc


def results_records(path: str | os.PathLike | dict) -> list[EpisodeRecord]:
    """The episode records of a results file (checked, see :func:`check_results`; or of a results
    document already read), as the evaluation wrote them: so ``hbmp-bench report`` reads
    leaderboard entries like records files."""
    doc = path if isinstance(path, dict) else check_results(json.loads(Path(path).read_text(encoding="utf-8")),
                                                             str(path))
    shared = {"suite": doc["suite"], "agent": doc["agent"], "fidelity": doc["fidelity"],
              "package_version": doc.get("provenance", {}).get("package_version", "")}
    return [EpisodeRecord(**{**episode, **shared}) for episode in doc["episodes"]]
