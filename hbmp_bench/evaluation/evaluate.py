"""Resumable suite evaluation: every episode of a selection, records appended as episodes finish.

The records file is append-only JSON lines, one line per finished episode, written (and fsynced)
the moment the episode's outcome arrives. Running the same evaluation again skips every episode
whose record is already there, keyed by (suite, town, task, episode, agent, fidelity), so a
killed run loses at most the episodes in flight and never counts one twice. A torn last line is
cut before appending. Episodes recorded as ``sim_error`` are run again on resume (the last record
of a key wins when reading).

The agent is untrusted: no code of it runs in this process. It is built once in a sandboxed
agent process first (``describe_agent``), which also says which env it needs (only known envs
and observation options are accepted). While the run goes on, the records file must hold
exactly what this run appended to it (``integrity.RecordsLedger``); a file changed behind the
evaluator's back raises ``TamperedError``. The records file, its provenance and the ledger exist
before the agent is first built, and a records or provenance file the evaluator did not seal
(``integrity.RecordsSeal``) is refused rather than resumed. One evaluation at a time writes a records file
(``integrity.records_lock``): a second one on the same file is refused, naming the first.
"""

from __future__ import annotations

import dataclasses
import functools

import os
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hbmp_bench.errors import ConfigError, Interrupted, UnknownNameError, UserError
from hbmp_bench.evaluation.channel import AgentDescription
from hbmp_bench.evaluation.integrity import RecordsLedger, RecordsSeal, TamperedError, quarantine, records_lock
from hbmp_bench.evaluation.pool import AgentBuildError, EpisodeOutcome, EpisodePool, describe_agent
from hbmp_bench.evaluation.salting import SaltKeeper, commitment
from hbmp_bench.evaluation.tasks import (EpisodeTask, RunnerLimits, agent_slug, is_privileged, suite_tasks,
                                         with_agent_env)
from hbmp_bench.metrics.records import AGENT_ERROR, SIM_ERROR, EpisodeRecord, repair_records

BACKENDS = ("process", "ray")
"""``process``: an ``EpisodePool`` on this machine; ``ray``: Ray actors (local or a cluster)."""


@dataclass(frozen=True)
class EvaluationResult:
    """What an evaluation left behind.

    Attributes:
        path: the JSON-lines records file.
        records: the selection's records (the latest of each episode: one, or a scene's one per vehicle in
            vehicle order), in suite order.
        ran / skipped: episodes run by this call / found already finished in the file.
        wall_s: wall time of this call [s].
        missing: selected episodes without their records (the run was interrupted).
        privileged: the env gave the agent the privileged scene fields (it asked for them, or
            the evaluator's limits set them): its scores are not comparable with a learned agent's.
        agent_fingerprint: the agent's weights as its description names them (a learned agent's
            ``checkpoint_fingerprint``; "" for an agent without a checkpoint).
        salt_commitment: SHA-256 (hex) of the evaluation's salt; "" for the public episodes.
        salt: the salt, once every selected episode is recorded ("" before, and when unsalted).
    """

    path: Path
    records: tuple[EpisodeRecord, ...]
    ran: int
    skipped: int
    wall_s: float
    missing: int
    privileged: bool = False
    agent_fingerprint: str = ""
    salt_commitment: str = ""
    salt: str = ""

    @property
    def sim_errors(self) -> int:
        """Episodes the simulation could not finish (not scored; run again on resume)."""
        return sum(r.end_reason == SIM_ERROR for r in self.records)

    @property
    def agent_errors(self) -> int:
        """Episodes the agent failed by raising, hanging, dying or breaking the protocol (scored as failures)."""
        return sum(r.end_reason == AGENT_ERROR for r in self.records)


class EvaluationInterrupted(Interrupted):
    """Ctrl-C during ``evaluate``, after its processes ended: ``path`` keeps ``finished`` of the
    ``selected`` episodes; the same evaluation again runs the rest."""

    def __init__(self, path: Path, finished: int, selected: int):
        self.path, self.finished, self.selected = path, finished, selected
        super().__init__(f"{finished} of {selected} episodes are recorded in {path}; "
                         "run the same evaluation again to resume")


def _check_workers(workers: int | None) -> None:
    if workers is not None and workers < 1:
        raise UserError(f"workers must be >= 1 (parallel episode slots), got {workers}")


def records_path(out_dir: str | os.PathLike, suite: str, agent: str, salted: bool = False) -> Path:
    """``<out_dir>/<suite>__<agent slug>.jsonl`` (``.salted.jsonl`` for a salted evaluation)."""
    return Path(out_dir) / f"{suite}__{agent_slug(agent)}{'.salted' if salted else ''}.jsonl"


def iter_outcomes(
    tasks: Sequence[EpisodeTask],
    *,
    workers: int | None = None,
    backend: str = "process",
    address: str | None = None,
    limits: RunnerLimits | None = None,
    progress: bool = True,
    descriptions: Mapping[str, AgentDescription] | None = None,
) -> Iterator[EpisodeOutcome]:
    """Outcomes of ``tasks`` as they finish, with a progress bar showing the running success rate.
    Each agent's episodes run in the env it asks for (see ``EpisodePool``).

    Args:
        workers: parallel slots (default: one per core for ``process``, the cluster's CPUs for ``ray``).
        backend: one of ``BACKENDS``; ``address`` is the Ray cluster (None: a local instance).
        descriptions: agents already described (``describe_agent``), by name.
    """
    from tqdm import tqdm

    if backend not in BACKENDS:
        raise UnknownNameError("backend", backend, BACKENDS)
    _check_workers(workers)
    limits = limits or RunnerLimits()
    if not tasks:
        return
    successes = 0
    with tqdm(total=len(tasks), unit="ep", disable=not progress) as bar:
        if backend == "ray":
            from hbmp_bench.evaluation.ray_backend import ray_imap

            source = ray_imap(tasks, limits, workers=workers, address=address, descriptions=descriptions)
        else:
            pool = EpisodePool(min(workers or os.cpu_count() or 1, len(tasks)), limits, descriptions=descriptions)
            source = pool_imap(pool, tasks)
        driven = 0
        for outcome in source:
            successes += sum(r.success for r in outcome.records)
            driven += len(outcome.records)
            bar.update(1)
            bar.set_postfix(success=f"{successes / max(driven, 1):.0%}")
            yield outcome


def pool_imap(pool: EpisodePool, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
    """``pool.imap`` that closes the pool when done or abandoned."""
    with pool:
        yield from pool.imap(tasks)


def evaluate(
    suite: str,
    agent: str,
    *,
    towns: Sequence[str] | None = None,
    tasks: Sequence[str] | None = None,
    episodes: int | Iterable[int] | None = None,
    fidelity: str | None = None,
    out_dir: str | os.PathLike = "runs",
    path: str | os.PathLike | None = None,
    workers: int | None = None,
    backend: str = "process",
    address: str | None = None,
    limits: RunnerLimits | None = None,
    progress: bool = True,
    salted: bool = False,
) -> EvaluationResult:
    """Evaluate ``agent`` on a suite selection, resuming from the records file.

    Args:
        suite / towns / tasks / episodes / fidelity: the selection (see ``suite_tasks``).
        out_dir: folder of the records file ``<suite>__<agent>.jsonl``; ``path`` overrides the file.
        workers / backend / address: see ``iter_outcomes``.
        limits: timeouts, watchdog and retries; ``max_decisions`` is refused (capped episodes
            are no evaluation).
        salted: run the episodes with a secret salt (``salting``): their traffic, pedestrians
            and light phases cannot be rebuilt outside the evaluator. The salt is made before
            any agent code runs and kept beside the records (default file
            ``<suite>__<agent>.salted.jsonl``); ``EvaluationResult.salt_commitment`` names it, and
            ``EvaluationResult.salt`` reveals it once every selected episode is recorded, after
            which the records file takes no further episode.

    The agent is built once first (in a sandboxed agent process, see ``describe_agent``), so a
    bad name fails before any episode; its env needs and checkpoint fingerprint come from it.

    Every option is checked before anything is written. Ctrl-C (``KeyboardInterrupt``) ends the
    episodes in flight and their processes, keeps every finished record, and raises
    :class:`EvaluationInterrupted`, which says how many are kept; calling again resumes.
    Raises ``TamperedError`` when the records file changes behind the evaluator's back.
    """
    limits = limits or RunnerLimits()
    if limits.max_decisions is not None:
        raise ConfigError("evaluate runs whole episodes: limits.max_decisions must be None")
    if backend not in BACKENDS:
        raise UnknownNameError("backend", backend, BACKENDS)
    _check_workers(workers)
    selection = suite_tasks(suite, agent, towns=towns, tasks=tasks, episodes=episodes, fidelity=fidelity)
    _check_agent_spec(agent)
    path = Path(path) if path is not None else records_path(out_dir, selection[0].suite, agent, salted)
    path.parent.mkdir(parents=True, exist_ok=True)
    with records_lock(path):
        keeper = SaltKeeper(path)  # before any agent code runs: the salt exists, readable by this user only
        salt = keeper.salt(salted, resuming=path.exists() and path.stat().st_size > 0)
        selection = [dataclasses.replace(t, salt=salt) for t in selection]
        # before any agent code runs: only records this evaluator sealed are resumed, and the
        # records file, its provenance and the ledger exist and are noted
        seal, side, created, ledger = _open_records(path)
        description = _describe_watched(agent, limits, path, created, side, ledger)
        limits = with_agent_env(limits, description)
        fingerprint = description.fingerprint
        check_provenance(path, agent, fingerprint, sorted({t.town for t in selection}))
        seal.write()
        finished = finished_episodes(ledger.records(), selection)
        todo = [t for t in selection if t.key not in finished]
        _check_salt_kept(path, keeper, salt, todo)
        start = time.perf_counter()
        ran = _record_outcomes(todo, ledger, seal, kept_before=len(selection) - len(todo), total=len(selection),
                               workers=workers, backend=backend, address=address, limits=limits, progress=progress,
                               descriptions={agent: description})
        records = ledger.records()
        done = finished_episodes(records, selection)
        revealed = keeper.reveal() if salt and all(t.key in done for t in selection) else ""
    kept = episode_records(records, selection)
    return EvaluationResult(path, tuple(r for t in selection if t.key in kept for r in kept[t.key]), ran,
                            len(selection) - len(todo), time.perf_counter() - start,
                            len(selection) - len(kept), privileged=is_privileged(limits),
                            agent_fingerprint=fingerprint, salt_commitment=commitment(salt) if salt else "",
                            salt=revealed)


def _check_salt_kept(path: Path, keeper: SaltKeeper, salt: str, todo: Sequence[EpisodeTask]) -> None:
    """A salted records file whose salt is revealed takes no further episode: they could be rebuilt."""
    if salt and todo and keeper.revealed:
        raise UserError(f"the salt of {path} is revealed, so its episodes could be rebuilt: a salted evaluation "
                        f"of more episodes goes into another folder (--out)")


def episode_key(record: EpisodeRecord) -> tuple[str, str, str, int, str, str]:
    """The episode a record is of, as ``EpisodeTask.key`` names it (a scene's N records share it)."""
    return (record.suite, record.town, record.task, record.episode, record.agent, record.fidelity)


def episode_records(records: Sequence[EpisodeRecord], selection: Sequence[EpisodeTask]
                    ) -> dict[tuple, tuple[EpisodeRecord, ...]]:
    """Per selected episode (``EpisodeTask.key``) whose every vehicle (``EpisodeTask.vehicles``) has a record:
    the latest record of each, in vehicle order. A later run of an episode (after a ``sim_error``) wins
    vehicle by vehicle; an episode a vehicle of which has no record is left out (it is run again)."""
    vehicles = {t.key: t.vehicles for t in selection}
    latest: dict[tuple, dict[str, EpisodeRecord]] = {}
    for record in records:
        key = episode_key(record)
        if key in vehicles:
            latest.setdefault(key, {})[record.vehicle] = record
    return {key: tuple(latest[key][v] for v in vehicles[key]) for key in vehicles
            if key in latest and set(vehicles[key]) <= set(latest[key])}


def finished_episodes(records: Sequence[EpisodeRecord], selection: Sequence[EpisodeTask]) -> set[tuple]:
    """The selected episodes (``EpisodeTask.key``) whose records are all there and none a ``sim_error``."""
    return {key for key, rows in episode_records(records, selection).items()
            if all(r.end_reason != SIM_ERROR for r in rows)}


def _open_records(path: Path):
    """Before any agent code runs: only records this evaluator sealed are resumed, and the records file, its
    provenance file and the ledger exist and are noted. (seal, provenance path, whether the records file was
    created now, ledger)."""
    side = provenance_path(path)
    seal = RecordsSeal(path, side)
    seal.check_resumable()
    repair_records(path)
    created = not path.exists()
    if created:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
    return seal, side, created, RecordsLedger(path)


def _record_outcomes(todo: list, ledger: RecordsLedger, seal: RecordsSeal, *, kept_before: int, total: int,
                     **run: Any) -> int:
    """Run ``todo`` (``run``: :func:`iter_outcomes`' options), appending each outcome to the ledger and
    resealing; the number run. Ctrl-C raises :class:`EvaluationInterrupted` with the records kept."""
    ran = 0
    try:
        for outcome in iter_outcomes(todo, **run):
            ledger.append(*outcome.records)
            seal.write()
            ran += 1
    except KeyboardInterrupt:  # the pool has ended its processes on the way out
        raise EvaluationInterrupted(ledger.path, kept_before + ran, total) from None
    return ran


def _check_agent_spec(agent: str) -> None:
    """Refuse, before any file is written, an agent that :func:`~hbmp_bench.agents.load_agent` would not
    find: no registry name, plug-in path or checkpoint (a ``.pt`` path must be a file)."""
    from hbmp_bench.agents import AGENTS

    if agent not in AGENTS and not agent.endswith(".pt") and ":" not in agent:  # as load_agent says, before any file
        raise UnknownNameError("agent", agent, [*AGENTS, "<module:Class>", "<path/to/checkpoint.pt>"])
    if agent.endswith(".pt") and agent not in AGENTS and not os.path.isfile(agent):
        raise AgentBuildError(f"agent could not be built: no checkpoint file {agent!r}")


def _describe_watched(agent: str, limits: RunnerLimits, path: Path, created: bool, side: Path,
                      ledger: RecordsLedger):
    """Build the agent once in its sandbox (:func:`describe_agent`) while the records file, its ledger and
    its provenance ``side`` file are watched: a bad agent leaves no records file the evaluator ``created``,
    and a records or provenance file changed meanwhile is refused (``TamperedError``)."""
    noted_side = side.read_bytes() if side.exists() else None
    try:
        description = describe_agent(agent, limits)  # the agent's code runs (in its sandbox) from here on
    except BaseException:
        if created and path.exists() and path.stat().st_size == 0:  # a bad agent leaves no records file
            path.unlink()
        raise
    ledger.verified()
    if (side.read_bytes() if side.exists() else None) != noted_side:
        moved = quarantine(side)
        raise TamperedError(f"{side} changed while the agent was built: something other than the evaluator wrote "
                            f"it{f' (moved to {moved.name})' if moved else ''}; evaluate again")
    return description


def provenance_path(path: Path) -> Path:
    """``<records>.provenance.json``: what produced the records (see ``check_provenance``)."""
    return path.with_name(path.name + ".provenance.json")


@functools.cache  # the package does not change under a running process
def code_fingerprint() -> str:
    """sha256 (first 16 hex digits) of the package's own code and data: every ``.py`` file and
    every built-in net under ``hbmp_bench/``. An episode's outcome depends on the behavior layer,
    the planner, the detectors and the rule-based agents as much as on a checkpoint's weights."""
    import hashlib

    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for f in sorted(p for pattern in ("*.py", "*.net.xml") for p in root.rglob(pattern)):
        digest.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def check_provenance(path: Path, agent: str, fingerprint: str, towns: Sequence[str]) -> None:
    """Refuse to resume ``path`` with anything else than what began it.

    Records are keyed by suite, town, task, episode and agent name, so without this a retrained
    checkpoint under the same name, a map imported again under the same name, or another version
    of this package would be credited with the old episodes. What produced the records is kept in
    ``<records>.provenance.json`` beside them: ``code`` (:func:`code_fingerprint`), ``agent`` (a
    learned agent's checkpoint hash, "" for the others) and ``maps`` (``maps.map_hash`` of every
    imported town, which can change under its name; built-in towns are part of the code).
    """
    import json

    from hbmp_bench.maps import TOWNS, map_hash

    current = {"code": code_fingerprint(), "agent": fingerprint,
               "maps": {town: map_hash(town) for town in towns if town not in TOWNS}}
    side = provenance_path(path)
    known = json.loads(side.read_text()) if side.exists() else None
    if known is None and path.exists() and path.stat().st_size > 0:
        raise UserError(f"{path} holds episodes of unknown provenance (no {side.name}): evaluate into another "
                        f"folder (--out), or delete {path.name} to start over")
    known = known or {"code": current["code"], "agent": current["agent"], "maps": {}}
    changed = [f"{what} {known[what] or '(none)'}, now {current[what] or '(none)'}" for what in ("code", "agent")
               if known[what] != current[what]]
    changed += [f"map {t!r} {known['maps'][t]}, now {h}" for t, h in sorted(current["maps"].items())
                if known["maps"].get(t, h) != h]
    if changed:
        raise UserError(f"{path} holds episodes of another {agent!r} run ({'; '.join(changed)}): evaluate into "
                        f"another folder (--out), or delete {path.name} and {side.name} to start over")
    merged = {**known, "maps": {**known["maps"], **current["maps"]}}
    if merged != known or not side.exists():
        tmp = side.with_name(side.name + ".tmp")
        tmp.write_text(json.dumps(merged, indent=2, sort_keys=True) + "\n")
        os.replace(tmp, side)
