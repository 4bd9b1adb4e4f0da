"""What the leaderboard website shows, read from the committed boards and nothing else.

A *board* is a folder of results files of one suite: ``<root>/<suite>/`` (``leaderboards/hbmp``) or, one
level deeper, ``<root>/<group>/<suite>/`` (``leaderboards/carla/hbmp``: the suite on imported towns). Its
entries are read and checked by ``evaluation.leaderboard.load_entries`` (the checks ``leaderboard render``
makes: a stale or forged file is refused, never shown), and every table the ``report`` command computes
(paired McNemar comparisons, km between infractions, outcome counts) comes from
``metrics.report.build_report`` over the entries' episodes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from hbmp_bench.errors import UserError

SKIPPED_FOLDERS = ("archive", "runs")
"""Folders of a board root that hold no current entries: superseded results and unsubmitted records."""

INFRACTION_KINDS = ("collision_vehicle", "collision_pedestrian", "collision_other", "wrong_lane", "off_road", "red_light")
"""Event counts of an episode record that are infractions (the summary's ``km_per_infraction`` counts them)."""


@dataclass(frozen=True)
class Board:
    """One board: ``folder`` holds the results files of ``suite``; ``slug`` names its page."""

    board_dir: Path
    """The folder ``leaderboard --board-dir`` takes (the suite's folder is ``board_dir / suite``)."""
    suite: str
    group: str = ""
    """The board's group folder ("" for a board directly under the root, e.g. ``carla``)."""

    @property
    def folder(self) -> Path:
        return self.board_dir / self.suite

    @property
    def slug(self) -> str:
        return f"{self.group}-{self.suite}" if self.group else self.suite

    @property
    def title(self) -> str:
        return f"{self.suite} ({self.group})" if self.group else self.suite


def find_boards(root: str | Path) -> list[Board]:
    """Every board under ``root`` (a ``leaderboards/`` folder), sorted by group then suite.

    A folder holding ``*.json`` files must be named after a registered suite, else ``UserError``;
    a folder without any is searched one level deeper (a group of boards).
    """
    from hbmp_bench.scenarios import SUITES

    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"no leaderboard folder {root}")
    boards = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir() and p.name not in SKIPPED_FOLDERS):
        if any(folder.glob("*.json")):
            if folder.name not in SUITES:
                raise UserError(f"{folder} holds results files but {folder.name!r} is no suite; "
                                f"valid: {', '.join(sorted(SUITES))}")
            boards.append(Board(root, folder.name))
            continue
        for sub in sorted(p for p in folder.iterdir() if p.is_dir() and p.name not in SKIPPED_FOLDERS):
            if any(sub.glob("*.json")):
                if sub.name not in SUITES:
                    raise UserError(f"{sub} holds results files but {sub.name!r} is no suite; "
                                    f"valid: {', '.join(sorted(SUITES))}")
                boards.append(Board(folder, sub.name, group=folder.name))
    if not boards:
        raise UserError(f"{root} holds no board (no <suite>/*.json results files)")
    return boards


@dataclass
class BoardData:
    """A board's checked entries and the report views over their episodes."""

    board: Board
    entries: list[dict]
    """Results documents as ``load_entries`` returns them (``_file``: the file's name): complete ones first, then by
    fidelity and success."""
    labels: dict[str, str]
    """Entry file name -> its result-set label in the report views (``hbmp``, ``expert [event]``)."""
    paired: pd.DataFrame
    km_between: pd.DataFrame
    breakdown: pd.DataFrame
    """One row per (entry file, town, task): episodes, outcome episode counts, km driven, infraction
    events and success %; see :func:`breakdown`."""
    description: str = ""
    readme: Path | None = None
    towns: list[str] = field(default_factory=list)


def load_board(board: Board) -> BoardData:
    """Read and check ``board``'s entries and compute the report views over their episodes."""
    from hbmp_bench.evaluation.leaderboard import load_entries, results_records
    from hbmp_bench.metrics import report
    from hbmp_bench.scenarios import get_suite

    entries = load_entries(board.board_dir, board.suite)  # in file-name order, as ``report`` reads a folder
    frames, labels = [], {}
    for doc in entries:
        df = pd.DataFrame([r.to_dict() for r in results_records(doc)])
        df["source"] = doc["_file"]
        frames.append(df)
    df = report.label_result_sets(pd.concat(frames, ignore_index=True))
    for doc in entries:
        labels[doc["_file"]] = str(df.loc[df["source"] == doc["_file"], "result_set"].iloc[0])
    views = report.build_report(df)
    entries.sort(key=lambda d: (not d["complete"], d["fidelity"], -d["summary"].get("success_pct", 0.0),
                                -d["summary"].get("mean_driving_score", 0.0), d["agent"]))
    readme = board.folder / "README.md"
    return BoardData(board=board, entries=entries, labels=labels, paired=views["paired"],
                     km_between=views["km_between"], breakdown=breakdown(df),
                     description=get_suite(board.suite).description, readme=readme if readme.is_file() else None,
                     towns=sorted(df["town"].unique()))


def breakdown(df: pd.DataFrame) -> pd.DataFrame:
    """Per (source file, town, task) of a report frame: the outcome counts of ``report.failure_counts``
    (scored episodes by what ended them), ``km_driven`` and ``infraction_events`` (the events of
    :data:`INFRACTION_KINDS`, as the summary's km per infraction counts them), ``success_pct``
    and ``infractions_per_km`` (0 where nothing was driven)."""
    from hbmp_bench.metrics import report
    from hbmp_bench.scenarios import all_tasks

    rows = []
    for task in [t for t in all_tasks() if t in set(df["task"])]:
        part = df[df["task"] == task]
        counts = report.failure_counts(part).reset_index()
        scored = report.scored(part)
        km = scored.groupby(["result_set", "town"])["distance_m"].sum() / 1000.0
        events = scored.groupby(["result_set", "town"])[list(INFRACTION_KINDS)].sum().sum(axis=1)
        source = part.groupby("result_set")["source"].first()
        for row in counts.to_dict(orient="records"):
            key = (row["result_set"], row["town"])
            driven = float(km.get(key, 0.0))
            n_events = int(events.get(key, 0))
            rows.append({**row, "source": source[row["result_set"]], "task": task, "km_driven": driven,
                         "infraction_events": n_events,
                         "success_pct": 100.0 * row["success"] / row["episodes"] if row["episodes"] else math.nan,
                         "infractions_per_km": n_events / driven if driven > 0 else 0.0})
    return pd.DataFrame(rows)


def boards_data(root: str | Path) -> list[BoardData]:
    """:func:`load_board` of every board of :func:`find_boards`."""
    return [load_board(b) for b in find_boards(root)]


_OUT_OPTION = re.compile(r"--out\s+(\S+)")


@dataclass(frozen=True)
class AgentCard:
    """What a shipped agent's model card says, and where its training run lies."""

    agent: str
    facts: list[tuple[str, str]]
    """The card's first list: ``(key, value)`` (command, seed, episodes, wall time, machine)."""
    run_dir: Path | None
    """The training run's folder (the card's command's ``--out``) when it is in the repository."""
    card: Path


def agent_card(agent: str, repo_root: Path) -> AgentCard | None:
    """The model card of a shipped agent (``hbmp_bench/agents/checkpoints/<agent>.md``), or None."""
    path = Path(__file__).resolve().parents[1] / "agents" / "checkpoints" / f"{agent}.md"
    if not path.is_file():
        return None
    facts = []
    for line in path.read_text(encoding="utf-8").splitlines()[1:]:
        if line.startswith("## "):
            break
        if line.startswith("- ") and ":" in line:
            key, value = line[2:].split(":", 1)
            facts.append((key.strip(), value.strip()))
        elif line.startswith("  ") and facts:
            facts[-1] = (facts[-1][0], facts[-1][1] + " " + line.strip())
    run_dir = None
    command = dict(facts).get("command", "")
    match = _OUT_OPTION.search(command)
    if match and (repo_root / match.group(1).strip("`")).is_dir():
        run_dir = repo_root / match.group(1).strip("`")
    return AgentCard(agent=agent, facts=facts, run_dir=run_dir, card=path)


def claims_table(markdown: str) -> list[list[str]]:
    """The first markdown table of ``markdown`` as rows of cells, the header first ([] without one)."""
    rows = []
    for line in markdown.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if all(set(c) <= set("-: ") for c in cells):
                continue
            rows.append(cells)
        elif rows:
            break
    return rows
