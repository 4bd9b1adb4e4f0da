"""Audit by replay: run a random sample of a leaderboard entry's episodes again and compare the records.

An episode is deterministic given its suite episode (start, goal, route, seed), the fidelity, the
agent and, for a salted entry, the evaluation's salt (revealed in the entry once its run is over):
the same agent on the same code and platform drives it again to the same record, field for field.
``hbmp-bench leaderboard audit ENTRY --agent A --sample K`` replays K episodes drawn at random
(``seed`` makes the draw repeatable) with agent ``A`` in the evaluator (isolated, as ``evaluate``
runs it), and reports every field of every episode that differs, and whether the replayed agent
reads the privileged fields or runs other weights than the entry says. It exits non-zero on any
mismatch.

A record that differs is no proof of forgery where the entry was made on other code
(``provenance.code_fingerprint``) or another float platform (``provenance.machine.float_platform``:
another SIMD level can round a transcendental differently, see the golden records): the report
names both, so the auditor can tell.
"""

from __future__ import annotations

import json
import os
import random
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from hbmp_bench.errors import UserError
from hbmp_bench.evaluation.results_check import commitment, verify_results
from hbmp_bench.metrics.results_file import EPISODE_COLUMNS, check_results, episode_columns
from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits, is_privileged, with_agent_env
from hbmp_bench.metrics.records import SIM_ERROR

FLOAT_FIELDS = ("route_completion", "driving_score", "duration_s", "distance_m", "route_length_m")
"""Fields compared as numbers: equal when their printed (rounded) values are (records keep 2-4 decimals)."""


@dataclass(frozen=True)
class EpisodeAudit:
    """One replayed episode: ``key`` (town, task, episode), and each field whose replay differs
    from the entry's record as ``field: (recorded, replayed)``."""

    key: tuple[str, str, int] | tuple[str, str, int, str]
    mismatches: dict[str, tuple[object, object]]

    @property
    def label(self) -> str:
        return "/".join(map(str, self.key[:3])) + (f" vehicle {self.key[3]}" if len(self.key) > 3 else "")


@dataclass(frozen=True)
class AuditResult:
    """What an audit found.

    Attributes:
        entry: the results file audited; agent: the agent replayed.
        episodes: one :class:`EpisodeAudit` per replayed episode, in the order drawn.
        claims: entry-level mismatches (``privileged``, ``agent_fingerprint``), as ``field: (entry, replay)``.
        notes: what may explain a mismatch other than forgery (other code, another platform).
    """

    entry: str
    agent: str
    episodes: tuple[EpisodeAudit, ...]
    claims: dict[str, tuple[object, object]] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Every replayed record and every claim matches."""
        return not self.claims and not any(e.mismatches for e in self.episodes)

    def lines(self) -> list[str]:
        """A readable report: one line per episode, one per mismatching field."""
        out = [f"audit of {self.entry} with agent {self.agent!r}: {len(self.episodes)} episodes replayed"]
        for name, (entry, replay) in self.claims.items():
            out.append(f"  {name}: entry says {entry!r}, the replayed agent {replay!r}")
        for episode in self.episodes:
            out.append(f"  {episode.label}: {'match' if not episode.mismatches else 'MISMATCH'}")
            for name, (recorded, replayed) in episode.mismatches.items():
                out.append(f"    {name}: recorded {recorded!r}, replayed {replayed!r}")
        out += [f"  note: {n}" for n in self.notes]
        out.append("verdict: " + ("every replayed record matches" if self.ok else "MISMATCH"))
        return out

    def to_dict(self) -> dict:
        return {"entry": self.entry, "agent": self.agent, "ok": self.ok, "claims": self.claims,
                "notes": list(self.notes),
                "episodes": [{"key": list(e.key), "mismatches": e.mismatches} for e in self.episodes]}


def compare(recorded: dict, replayed: dict, columns: Sequence[str] = EPISODE_COLUMNS) -> dict[str, tuple[object, object]]:
    """The fields of ``columns`` (default :data:`~hbmp_bench.metrics.results_file.EPISODE_COLUMNS`; a
    multi-agent suite's: ``episode_columns``) whose values differ (numbers in :data:`FLOAT_FIELDS` compared as
    the records round them)."""
    out = {}
    for name in columns:
        a, b = recorded.get(name), replayed.get(name)
        same = abs(a - b) < 1e-9 if name in FLOAT_FIELDS and isinstance(a, (int, float)) and isinstance(b, (int, float)) \
            else a == b
        if not same:
            out[name] = (a, b)
    return out


def draw(doc: dict, sample: int, seed: int | None = None, max_sim_s: float | None = None) -> list[dict]:
    """``sample`` episodes of an entry drawn at random (``seed``: repeatable; None: fresh
    randomness), among those that did not end in a ``sim_error`` and, with ``max_sim_s``, that
    lasted at most that many simulated seconds [s] (a cheap audit, e.g. in CI). Of a multi-agent
    entry whole scenes are drawn (a scene counts as one, its rows judged together: every vehicle's);
    the rows of the drawn scenes are returned."""
    if sample < 1:
        raise UserError(f"sample must be >= 1 episodes, got {sample}")
    scenes: dict[tuple, list[dict]] = {}
    for e in doc["episodes"]:
        scenes.setdefault((e["town"], e["task"], e["episode"]), []).append(e)
    pool = [rows for rows in scenes.values() if all(e["end_reason"] != SIM_ERROR for e in rows)
            and (max_sim_s is None or max(e["duration_s"] for e in rows) <= max_sim_s)]
    if not pool:
        raise UserError(f"the entry has no episode to replay{f' of at most {max_sim_s} s' if max_sim_s else ''}")
    rng = random.Random(seed) if seed is not None else random.SystemRandom()
    return [e for rows in rng.sample(pool, min(sample, len(pool))) for e in rows]


def audit(
    entry: str | os.PathLike,
    agent: str,
    sample: int,
    *,
    seed: int | None = None,
    max_sim_s: float | None = None,
    workers: int | None = 1,
    limits: RunnerLimits | None = None,
    progress: bool = False,
) -> AuditResult:
    """Replay ``sample`` random episodes of the results file ``entry`` with ``agent`` and compare.

    Args:
        entry: a leaderboard results file (checked first: ``results_check.verify_results``).
        agent: the agent to replay (registry name, ``module:Class`` or checkpoint), usually the
            entry's own; a renamed entry is audited with the agent it claims to be.
        sample / seed / max_sim_s: which episodes (see :func:`draw`).
        workers / limits: as for ``evaluate`` (the episodes run isolated, in the evaluator).

    Raises ValueError when the entry cannot be replayed: a salted entry whose salt is not revealed
    or does not match its commitment.
    """
    from hbmp_bench.evaluation.evaluate import code_fingerprint, iter_outcomes
    from hbmp_bench.evaluation.pool import describe_agent
    from hbmp_bench.evaluation.provenance import float_platform

    path = Path(entry)
    doc = check_results(json.loads(path.read_text(encoding="utf-8")), str(path))
    verify_results(doc, str(path), against_suite=False)
    provenance = doc["provenance"]
    salt = ""
    if doc["salted"]:
        salt = provenance.get("salt") or ""
        if not salt:
            raise UserError(f"{path} is salted and its salt is not revealed yet: it cannot be replayed")
        if commitment(salt) != provenance.get("salt_commitment"):
            raise UserError(f"{path}: its salt does not match its salt_commitment")
    chosen = draw(doc, sample, seed, max_sim_s)
    limits = limits or RunnerLimits()
    description = describe_agent(agent, limits)
    limits = with_agent_env(limits, description)
    claims = {}
    if is_privileged(limits) and not doc["privileged"]:
        claims["privileged"] = (doc["privileged"], True)
    if description.fingerprint != (provenance.get("agent_fingerprint") or ""):
        claims["agent_fingerprint"] = (provenance.get("agent_fingerprint") or "", description.fingerprint)
    tasks = list(dict.fromkeys(EpisodeTask(doc["suite"], e["town"], e["task"], e["episode"], agent, doc["fidelity"],
                                           salt) for e in chosen))
    replayed = {}
    for outcome in iter_outcomes(tasks, workers=workers, limits=limits, progress=progress,
                                 descriptions={agent: description}):
        for record in outcome.records:
            replayed[_row_key(record.to_dict())] = record.to_dict()
    columns = episode_columns(doc["suite"])
    episodes = tuple(EpisodeAudit(_row_key(e), compare(e, replayed.get(_row_key(e), {}), columns)) for e in chosen)
    notes = []
    if provenance.get("code_fingerprint") != code_fingerprint():
        notes.append(f"the entry ran code {provenance.get('code_fingerprint')}, this is {code_fingerprint()}: "
                     "a mismatch may come from a change of the package")
    made_on = (provenance.get("machine") or {}).get("float_platform")
    if made_on != float_platform():
        notes.append(f"the entry was made on {made_on or 'an unrecorded float platform'}, this is {float_platform()}: "
                     "a mismatch may be float rounding")
    return AuditResult(str(path), agent, episodes, claims, tuple(notes))


def _row_key(row: dict) -> tuple:
    """(town, task, episode), and the vehicle of a multi-agent episode's row."""
    key = (row["town"], row["task"], row["episode"])
    return (*key, row["vehicle"]) if row.get("vehicle") else key


def audit_lines(result: AuditResult, as_json: bool = False) -> Sequence[str]:
    """The CLI's output of an audit: its report lines, or one JSON document."""
    return [json.dumps(result.to_dict(), indent=2, default=list)] if as_json else result.lines()
