"""Leaderboards kept as files: ``<board>/<suite>/<agent>.<fidelity>.json`` results and a generated README.

A submission evaluates an agent on a suite (resumable, see ``evaluate``) and writes a results
file with the per-episode records, the aggregate scores and provenance (package and library
versions, git commit, the fingerprints of the code that ran and of the agent's weights, suite
definition hash, seeds, date, machine, fidelity, wall time). The suite's ``README.md`` is then
regenerated: a ranked table per fidelity.

Rules:
- Only *complete* entries are ranked: every episode of the official suite (all towns, tasks and
  episodes) with no ``sim_error`` left. A run on a subset (``towns``/``tasks``/``episodes``) is
  written as ``<agent>.<fidelity>.subset.json`` and listed under "Partial runs (not ranked)"; it never
  replaces a full entry. An entry with sim errors is listed there too, with their count.
- ``agent_error`` episodes are the agent's failures (success false, driving score 0) and count.
- A submission refuses to write its entry when the board's results files changed while it ran
  (``integrity.BoardSnapshot``), and reads its records only from bytes it checked
  (``integrity.RecordsLedger``): an agent under evaluation cannot slip in a forged entry.
- ``add`` checks that a results file's ``complete`` and ``sim_errors`` agree with its episodes.
- A results file whose suite definition hash differs from the installed suite's is refused
  (``StaleResultsError``) when it is added and when the README is generated: its episodes are not
  the current suite's.
- Complete entries are ranked by success %, then driving score. Partial runs are listed below them,
  unranked and ordered by what they cover, never by their scores: full-suite runs with missing
  episodes or sim errors first, then subsets; the most episodes first (a 2-episode run's 100 %
  is not above a 200-episode run's 90 %). Every row shows its episodes as "scored of the whole
  suite's".
- An entry whose agent read the privileged scene fields (it asked for ``privileged=True``, as the
  rule-based expert does: light schedules, junction foes, the leader; see
  ``hbmp_bench.envs.privileged``) is marked ``privileged`` in its results file and in the
  README's tables: it is a reference, not comparable with an agent that sees M_t and R_t only.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from hbmp_bench import __version__
from hbmp_bench.errors import UserError
from hbmp_bench.evaluation.evaluate import code_fingerprint, evaluate
from hbmp_bench.evaluation.integrity import BoardSnapshot
from hbmp_bench.evaluation.provenance import git_commit, library_versions, machine_description, utc_now
from hbmp_bench.evaluation.results_check import contained, verify_results
from hbmp_bench.evaluation.tasks import RunnerLimits, agent_slug, suite_tasks
from hbmp_bench.metrics.records import DRIVING_SCORE_DEFINITION, EpisodeRecord
from hbmp_bench.metrics.report import scores
from hbmp_bench.metrics.results_file import (  # noqa: F401  (StaleResultsError, results_records: the board's names too)
    EPISODE_COLUMNS, RESULTS_FORMAT, ForgedResultsError, StaleResultsError, check_name, check_results, episode_columns,
    results_records)
from hbmp_bench.scenarios import TASK_LABELS, get_suite

def entry_path(board_dir: str | os.PathLike, suite: str, agent: str, subset: bool, fidelity: str) -> Path:
    """``<board>/<suite>/<agent slug>.<fidelity>.json`` (``.subset.json`` for partial runs): one
    entry per agent and fidelity, ranked in that fidelity's table. ``suite`` and ``fidelity`` must
    be names (``metrics.results_file.NAME_PATTERN``: no ``/``, no ``..``) and the path must resolve inside
    ``<board>/<suite>``; ValueError otherwise."""
    check_name("suite", suite)
    check_name("fidelity", fidelity)
    folder = Path(board_dir) / suite
    return contained(folder / f"{agent_slug(agent)}.{fidelity}{'.subset' if subset else ''}.json", folder)


def runs_dir(board_dir: str | os.PathLike, suite: str) -> Path:
    """Where submissions keep their raw JSON-lines records (ignored by git; resumable):
    ``<board>/<suite>/runs/<suite hash>-<code fingerprint>``, so records of an older suite
    definition or another version of the package never mix in (see ``evaluate.check_provenance``)."""
    return Path(board_dir) / suite / "runs" / f"{get_suite(suite).definition_hash()}-{code_fingerprint()}"


def results_document(
    suite: str,
    agent: str,
    records: Sequence[EpisodeRecord],
    *,
    towns: Sequence[str],
    tasks: Sequence[str],
    episodes: Sequence[int],
    fidelity: str,
    wall_s: float | None = None,
    workers: int | None = None,
    backend: str = "process",
    privileged: bool = False,
    agent_fingerprint: str = "",
    salt_commitment: str = "",
    salt: str = "",
) -> dict:
    """The results file content for ``records`` of a selection of ``suite``; ``privileged``: the
    agent read the privileged scene fields (``EvaluationResult.privileged``); ``agent_fingerprint``:
    its weights (``EvaluationResult.agent_fingerprint``); ``salt_commitment``: the SHA-256 of the
    evaluation's secret salt ("" for the public, unsalted episodes; the entry is then ``salted``)
    and ``salt`` the salt itself once the run is over (``EvaluationResult.salt``), so anyone can
    replay the episodes (``audit``).

    A git commit alone does not say what ran (the tree may have been edited), so the provenance
    also keeps ``code_fingerprint`` (``evaluate.code_fingerprint``: the package's code and nets as
    they were run) and ``agent_fingerprint``: which checkpoint an entry measured can be checked
    against the one that ships (``checkpoint_fingerprint``)."""
    spec = get_suite(suite)
    scored = scores(spec.name, records, towns=towns, tasks=tasks, episodes=episodes, agent=agent)
    return {
        "format": RESULTS_FORMAT,
        "suite": spec.name,
        "suite_hash": spec.definition_hash(),
        "agent": agent,
        "fidelity": fidelity,
        "privileged": bool(privileged),
        "salted": bool(salt_commitment),
        **scored,
        "episodes": [{k: r.to_dict()[k] for k in episode_columns(spec.name)} for r in records],
        "provenance": {
            "package_version": __version__,
            "git_commit": git_commit(),
            "code_fingerprint": code_fingerprint(),
            "agent_fingerprint": agent_fingerprint,
            "suite_definition_hash": spec.definition_hash(),
            "seeds": {"suite_seed": spec.seed, "reset_seed": "episode index",
                      "episode_seeds": "per episode in 'episodes'"},
            "salt_commitment": salt_commitment,
            "salt": salt,
            "date_utc": utc_now(),
            "machine": machine_description(),
            "libraries": library_versions(),
            "fidelity": fidelity,
            "workers": workers,
            "backend": backend,
            "wall_time_s": None if wall_s is None else round(wall_s, 1),
        },
    }


def write_json(path: Path, doc: dict) -> Path:
    """Write a results document to ``path`` (one line per episode, so diffs stay readable) through a
    temporary file and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    head = json.dumps({k: v for k, v in doc.items() if k != "episodes"}, indent=1, allow_nan=False)
    rows = ",\n".join("  " + json.dumps(e, allow_nan=False) for e in doc.get("episodes", []))
    text = head[:-2] + ',\n "episodes": [\n' + rows + "\n ]\n}\n"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


def load_entries(board_dir: str | os.PathLike, suite: str, skip: str | None = None) -> list[dict]:
    """Every results file of a suite's board, checked: a stale one raises ``StaleResultsError``, one
    whose summary, completeness or names do not follow from its episodes, or that lies under
    another entry's file name, ``ForgedResultsError`` (``results_check.verify_results`` without
    the checks against the suite's episode list, which ``add`` makes). ``skip``: a file name left out."""
    folder = Path(board_dir) / get_suite(suite).name
    entries = []
    for path in sorted(p for p in folder.glob("*.json") if p.name != skip):
        doc = check_results(json.loads(path.read_text(encoding="utf-8")), str(path))
        if doc["suite"] != get_suite(suite).name:
            raise UserError(f"{path} holds results of suite {doc['suite']!r}, not {suite!r}")
        verify_results(doc, str(path), against_suite=False)
        own = entry_path(board_dir, doc["suite"], doc["agent"], doc["subset"], doc["fidelity"]).name
        if path.name != own:
            raise ForgedResultsError(str(path), [f"its agent {doc['agent']!r}, fidelity {doc['fidelity']!r} and "
                                                 f"subset={doc['subset']} belong in {own}, not {path.name}"])
        entries.append(doc | {"_file": path.name})
    return entries


def _rank_key(doc: dict) -> tuple:
    """Order of complete entries: success %, then driving score, best first."""
    return (-doc["summary"].get("success_pct", 0.0), -doc["summary"].get("mean_driving_score", 0.0), doc["agent"])


def _partial_key(doc: dict) -> tuple:
    """Order of partial runs, by what they cover: full-suite runs (missing episodes or sim errors)
    before subsets, then the most scored episodes first; scores only break ties."""
    return (bool(doc.get("subset")), -doc["summary"].get("episodes", 0), *_rank_key(doc))


def _suite_episodes(suite: str) -> int:
    """Episodes of the whole suite (every town, task and episode)."""
    from hbmp_bench.scenarios import selection_size

    spec = get_suite(suite)
    return selection_size(spec.name, spec.towns, spec.tasks, range(spec.episodes_per_task))


def _row(doc: dict, rank: str, tasks: Sequence[str]) -> list[str]:
    s, prov = doc["summary"], doc["provenance"]
    by_task = doc["aggregates"].get("success_pct_by_task", {})
    km = s.get("km_per_infraction")
    lb2 = [f"{_mean_driving_score_lb2(doc):.1f}"] if _shows_lb2(tasks) else []
    return [
        rank, f"`{doc['agent']}`", "yes" if doc["privileged"] else "no", f"{s.get('success_pct', 0.0):.1f}",
        *(f"{by_task[t]:.1f}" if t in by_task else "–" for t in tasks),
        f"{s.get('mean_driving_score', 0.0):.1f}", *lb2, f"{100.0 * s.get('mean_route_completion', 0.0):.1f}",
        NO_INFRACTION if km is None else f"{km:.2f}", f"{s.get('episodes', 0)} of {_suite_episodes(doc['suite'])}",
        str(doc.get("sim_errors", 0)),
        prov.get("package_version") or "", (prov.get("git_commit") or "")[:10],
        _weights(doc), (prov.get("date_utc") or "")[:10],
        "" if prov.get("wall_time_s") is None else f"{prov['wall_time_s']:.0f}",
        (prov.get("salt_commitment") or "")[:10] if doc.get("salted") else "no",
    ]


def _weights(doc: dict) -> str:
    """The weights column: the first digits of ``agent_fingerprint`` ("–" without one), marked
    "(claimed)" for a ``module:Class`` agent, whose fingerprint is its own word."""
    from hbmp_bench.agents import AGENTS

    fingerprint = (doc["provenance"].get("agent_fingerprint") or "")[:10]
    if not fingerprint:
        return "–"
    own_claim = doc["agent"] not in AGENTS and not doc["agent"].endswith(".pt")
    return f"{fingerprint} (claimed)" if own_claim else fingerprint


NO_INFRACTION = "no infraction"
"""km / infraction of an entry without any infraction event."""

def _shows_lb2(tasks: Sequence[str]) -> bool:
    """Whether a board of these tasks shows the Leaderboard 2.0 driving score too (the scenario suites')."""
    from hbmp_bench.scenarios import SCENARIO_TYPES

    return any(t in SCENARIO_TYPES for t in tasks)


def _mean_driving_score_lb2(doc: dict) -> float:
    """Mean Leaderboard 2.0 driving score (``metrics.records.driving_score_lb2``) of an entry's scored episodes."""
    from hbmp_bench.metrics.records import record_driving_score_lb2
    from hbmp_bench.metrics.report import EXCLUDED

    scores_ = [record_driving_score_lb2(r) for r in doc["episodes"] if r["end_reason"] not in EXCLUDED]
    return sum(scores_) / len(scores_) if scores_ else 0.0


def _held_sentence(spec) -> str:
    """How many episodes the suite holds where that is fewer than towns × tasks × episodes ("" otherwise)."""
    held = _suite_episodes(spec.name)
    if held == len(spec.towns) * len(spec.tasks) * spec.episodes_per_task:
        return ""
    return f" at most: {held} in all (a scenario type has no episode in a town that cannot host it, fewer where it is rare)"


def _lb2_sentence(tasks: Sequence[str]) -> str:
    from hbmp_bench.metrics.records import DRIVING_SCORE_LB2_DEFINITION

    return f"; and the {DRIVING_SCORE_LB2_DEFINITION}" if _shows_lb2(tasks) else ""


def header(tasks: Sequence[str]) -> list[str]:
    """The columns of a board of these tasks (its suite's): a success column per task, the Leaderboard 1.0
    driving score and, on a scenario suite's board, the Leaderboard 2.0 one."""
    lb2 = ["driving score (LB 2.0)"] if _shows_lb2(tasks) else []
    return ["rank", "agent", "privileged", "success %", *(TASK_LABELS[t] + " %" for t in tasks),
            "driving score (LB 1.0)", *lb2, "route completion %", "km / infraction", "episodes", "sim errors", "version",
            "commit", "weights", "date", "wall s", "salted"]


def _table(rows: Iterable[list[str]], tasks: Sequence[str]) -> str:
    columns = header(tasks)
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


MULTI_COLUMNS = ("agents in agent collision %", "agent pairs collided", "other collisions", "red lights",
                 "wrong lane", "timeouts", "arrived / min")
"""The scene figures of a multi-agent board's rows, after the per-town success columns."""
MULTI_FIGURES = ("agents_in_agent_collision_pct", "agent_collision_pairs", "other_collisions", "red_light",
                 "wrong_lane", "timeouts", "throughput_per_min")
"""The ``summary.scene_summary`` keys of :data:`MULTI_COLUMNS`, in their order."""


def _figure(value) -> str:
    return f"{value:.1f}" if isinstance(value, float) else str(value)


def multi_header(towns: Sequence[str]) -> list[str]:
    """The columns of a multi-agent suite's board: success % of the agents, per town, the scene figures."""
    return ["rank", "agent", "privileged", "success % (agents)", *(f"{t} %" for t in towns), *MULTI_COLUMNS,
            "scenes", "agents", "sim errors", "version", "commit", "weights", "date", "wall s", "salted"]


def _multi_row(doc: dict, rank: str, towns: Sequence[str]) -> list[str]:
    s, prov = doc["summary"], doc["provenance"]
    by_town = doc["aggregates"].get("multi_by_town", {})
    return [
        rank, f"`{doc['agent']}`", "yes" if doc["privileged"] else "no", f"{s.get('agent_success_pct', 0.0):.1f}",
        *(f"{by_town[t]['agent_success_pct']:.1f}" if t in by_town else "–" for t in towns),
        *(_figure(s.get(k, 0)) for k in MULTI_FIGURES),
        f"{s.get('scenes', 0)} of {_suite_episodes(doc['suite'])}", str(s.get("agents", 0)),
        str(doc.get("sim_errors", 0)), prov.get("package_version") or "", (prov.get("git_commit") or "")[:10],
        _weights(doc), (prov.get("date_utc") or "")[:10],
        "" if prov.get("wall_time_s") is None else f"{prov['wall_time_s']:.0f}",
        (prov.get("salt_commitment") or "")[:10] if doc.get("salted") else "no",
    ]


def _markdown(columns: Sequence[str], rows: Iterable[list[str]]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


TOWN_COLUMNS = ("agent", "fidelity", "town", "scenes", "agents", "success %", *MULTI_COLUMNS)
"""The columns of a multi-agent board's per-town table."""


def _town_rows(entries: Sequence[dict], towns: Sequence[str]) -> list[list[str]]:
    rows = []
    for doc in entries:
        by_town = doc["aggregates"].get("multi_by_town", {})
        for town in [t for t in towns if t in by_town]:
            f = by_town[town]
            rows.append([f"`{doc['agent']}`", doc["fidelity"], town, str(f["scenes"]), str(f["agents"]),
                         f"{f['agent_success_pct']:.1f}", *(_figure(f[k]) for k in MULTI_FIGURES)])
    return rows


def _multi_parts(spec, ranked: list[dict], partial: list[dict]) -> list[str]:
    """The README sections of a multi-agent suite's board below its preamble."""
    parts = [
        f"Every scene (episode) holds {spec.agents} goal-directed vehicles, each with its own start, goal and "
        "route, all driven by the evaluated policy; each has its own record. success %: of the agents (vehicles) "
        "that reached their goal; agents in agent collision %: of the agents in a collision with another "
        "goal-directed vehicle; agent pairs collided: such pairs, each pair once; other collisions: collision events "
        "with the other road users (SUMO's traffic, pedestrians); red lights, wrong lane: events; timeouts: agents; "
        "arrived / min: agents that reached their goal per minute of scene time (a scene lasts until its last "
        "vehicle's episode ended); scenes: scored of the suite's. Ranked by success %, then driving score.\n"]
    if not ranked:
        parts.append("No complete entries yet.\n")
    for fidelity in sorted({e["fidelity"] for e in ranked}):
        group = sorted((e for e in ranked if e["fidelity"] == fidelity), key=_rank_key)
        parts.append(f"## Fidelity: {fidelity}\n")
        parts.append(_markdown(multi_header(spec.towns),
                               (_multi_row(e, str(k), spec.towns) for k, e in enumerate(group, start=1))))
    if partial:
        parts.append("## Partial runs (not ranked)\n")
        parts.append("Runs with missing scenes or sim errors, then subsets of the suite, listed by the scenes they "
                     "cover (most first), not by score.\n")
        parts.append(_markdown(multi_header(spec.towns),
                               (_multi_row(e, "–", spec.towns) for e in sorted(partial, key=_partial_key))))
    if ranked or partial:
        ordered = [*sorted(ranked, key=lambda e: (e["fidelity"], _rank_key(e))), *sorted(partial, key=_partial_key)]
        parts.append("## Per town\n")
        parts.append(_markdown(TOWN_COLUMNS, _town_rows(ordered, spec.towns)))
    return parts


def render_readme(board_dir: str | os.PathLike, suite: str) -> Path:
    """Regenerate ``<board>/<suite>/README.md`` from the suite's results files (a multi-agent suite's board
    shows the scene figures, :func:`multi_header`)."""
    spec = get_suite(suite)
    entries = load_entries(board_dir, spec.name)
    ranked = [e for e in entries if e["complete"]]
    partial = [e for e in entries if not e["complete"]]
    parts = [
        f"# Leaderboard: {spec.name}\n",
        f"{spec.description}\n",
        f"Suite definition hash `{spec.definition_hash()}`: {len(spec.towns)} towns × {len(spec.tasks)} tasks × "
        f"{spec.episodes_per_task} episodes{_held_sentence(spec)}. Generated from the `*.json` results files by "
        f"`hbmp-bench leaderboard render --suite {spec.name}`; do not edit by hand. Complete entries are ranked by "
        f"success % (episodes that reached the goal), then driving score: the mean over episodes of the "
        f"{DRIVING_SCORE_DEFINITION}{_lb2_sentence(spec.tasks)}. km / infraction: km driven per infraction event (collisions, wrong lane, "
        "off-road and red lights; an episode can have several); episodes: scored of the whole suite's; wall s is the "
        "submission's wall time with its `workers` (see each results file); weights: the first digits of the sha256 of "
        "the checkpoint a learned agent ran (`provenance.agent_fingerprint`), – for an agent without one. Agent errors "
        "count as failed episodes; sim errors (the simulator failed, not the agent) are not scored, and an "
        "entry with any is not ranked. An agent marked privileged read the simulator's privileged scene (light "
        "schedules, junction foes, the leader; the rule-based expert, a reference): not comparable with an agent "
        "that sees M_t and R_t only. salted: the first digits of the SHA-256 of the secret salt its traffic, "
        "pedestrians and light phases took (an agent could not rebuild its episodes; the salt is in the results "
        "file, for `hbmp-bench leaderboard audit`), no for the public episodes.\n",
    ]
    if spec.agents > 1:
        parts += _multi_parts(spec, ranked, partial)
        partial = []
    elif not ranked:
        parts.append("No complete entries yet.\n")
    for fidelity in sorted({e["fidelity"] for e in ranked} if spec.agents == 1 else ()):
        group = sorted((e for e in ranked if e["fidelity"] == fidelity), key=_rank_key)
        parts.append(f"## Fidelity: {fidelity}\n")
        parts.append(_table((_row(e, str(k), spec.tasks) for k, e in enumerate(group, start=1)), spec.tasks))
    if partial:
        parts.append("## Partial runs (not ranked)\n")
        parts.append("Runs with missing episodes or sim errors, then subsets of the suite, listed by the episodes "
                     "they cover (most first), not by score: their figures are over their own episodes only and do "
                     "not compare with the ranked entries.\n")
        parts.append(_table((_row(e, "–", spec.tasks) for e in sorted(partial, key=_partial_key)), spec.tasks))
    path = Path(board_dir) / spec.name / "README.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(parts), encoding="utf-8")
    os.replace(tmp, path)
    return path


def add_results(path: str | os.PathLike, board_dir: str | os.PathLike) -> Path:
    """Check a results file made elsewhere and install it on its suite's board; returns its new path.

    Everything the file claims is recomputed from its episodes and its suite and must agree
    (``results_check.verify_results``: summary, completeness, the suite's episodes, consistent
    records, names that reach a path, the agent's privileged flag and fingerprint, the salt); the
    installed file holds the recomputed aggregates. It must not replace another agent's entry, and
    the board's other entries must pass the checks too. Raises ``ForgedResultsError`` (or
    ``StaleResultsError``, ``ValueError``) and writes nothing when anything does not add up."""
    source = Path(path)
    try:
        raw = json.loads(source.read_text(encoding="utf-8"), parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise UserError(f"{source} is not JSON: {exc}") from None
    doc = check_results(raw, str(source))
    recomputed = verify_results(doc, str(source), against_suite=True)
    target = entry_path(board_dir, doc["suite"], doc["agent"], doc["subset"], doc["fidelity"])
    load_entries(board_dir, doc["suite"], skip=target.name)  # so rendering the board cannot fail after the write
    if target.exists():
        held = json.loads(target.read_text(encoding="utf-8")).get("agent")
        if held != doc["agent"]:
            raise ForgedResultsError(str(source), [f"its agent {doc['agent']!r} would replace {target}, the entry of "
                                                   f"agent {held!r}"])
    write_json(target, {**{k: v for k, v in doc.items() if not k.startswith("_")}, **recomputed})
    render_readme(board_dir, doc["suite"])
    return target


def _no_constant(name: str):
    raise UserError(f"results files hold finite numbers only, not {name}")


def submit(
    suite: str,
    agent: str,
    *,
    board_dir: str | os.PathLike = "leaderboards",
    towns: Sequence[str] | None = None,
    tasks: Sequence[str] | None = None,
    episodes: int | Iterable[int] | None = None,
    fidelity: str | None = None,
    workers: int | None = None,
    backend: str = "process",
    address: str | None = None,
    limits: RunnerLimits | None = None,
    records_dir: str | os.PathLike | None = None,
    progress: bool = True,
    salted: bool = False,
) -> tuple[Path, dict]:
    """Evaluate ``agent`` on ``suite`` (or a subset), write its results file and regenerate the README.
    ``salted``: on salted episodes (``evaluate``'s ``salted``); the entry then names the salt's
    commitment and, once complete, the salt.

    The raw records go to ``records_dir`` (default ``runs_dir(board_dir, suite)``), so an
    interrupted submission resumes where it stopped. Returns (results path, results document).
    Raises ``TamperedError`` (writing nothing) when the records file or the board's results files
    changed behind its back while it ran.
    """
    spec = get_suite(suite)
    check_name("agent", agent)
    load_entries(board_dir, spec.name)  # refuse before a long run if the board holds stale or forged files
    snapshot = BoardSnapshot(Path(board_dir) / spec.name)
    selection = suite_tasks(spec.name, agent, towns=towns, tasks=tasks, episodes=episodes, fidelity=fidelity)
    result = evaluate(spec.name, agent, towns=towns, tasks=tasks, episodes=episodes, fidelity=fidelity,
                      out_dir=records_dir or runs_dir(board_dir, spec.name), workers=workers, backend=backend,
                      address=address, limits=limits, progress=progress, salted=salted)
    doc = results_document(
        spec.name, agent, result.records,
        towns=list(dict.fromkeys(t.town for t in selection)), tasks=list(dict.fromkeys(t.task for t in selection)),
        episodes=sorted({t.episode for t in selection}), fidelity=selection[0].fidelity,
        wall_s=result.wall_s if result.skipped == 0 else None, workers=workers or os.cpu_count(), backend=backend,
        privileged=result.privileged, agent_fingerprint=result.agent_fingerprint,
        salt_commitment=result.salt_commitment, salt=result.salt,
    )
    snapshot.check_unchanged()
    target = entry_path(board_dir, spec.name, agent, doc["subset"], doc["fidelity"])
    try:  # the checks every later render and submission make: a file they would refuse is never written
        verify_results(doc, str(target), against_suite=False)
    except ForgedResultsError as refused:
        raise ForgedResultsError(str(target), [*refused.problems, f"nothing was written (the records are left in "
                                                                  f"{result.path} for inspection)"]) from None
    path = write_json(target, doc)
    render_readme(board_dir, spec.name)
    return path, doc
