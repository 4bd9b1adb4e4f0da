"""The leaderboard website's pages: plain HTML written from :mod:`hbmp_bench.site.boards`' data.

Every page links ``assets/site.css`` and ``assets/site.js`` (sorting and filtering, no library) by
relative paths, so the site opens from the file system as well as from any static host. Numbers are
written as the results files hold them (one decimal where the boards' tables round), and each cell of
a figure carries ``data-field`` naming the results-file field it shows.
"""

from __future__ import annotations

import html
import math
import re
import shlex
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from hbmp_bench.site.boards import INFRACTION_KINDS, AgentCard, BoardData

PAPER = "Learning hierarchical behavior and motion planning for autonomous driving (Wang et al.)"

PAPER_TABLE_I: dict[str, dict[str, float]] = {
    "Town01": {"Straight": 100.0, "OneTurn": 100.0, "Navigation": 100.0, "NavigationDynamic": 95.0},
    "Town02": {"Straight": 100.0, "OneTurn": 100.0, "Navigation": 100.0, "NavigationDynamic": 88.0},
}
"""The paper's Tab. I: success % of HBMP trained on Town03 only, 40 episodes per task, in Town1 and Town2."""

PAPER_TOWN15_PCT = 85.0
"""The paper's Fig. town15: more than this success % in every town (40 random-goal episodes each)."""

FAILURES_PER_ENTRY = 5
"""Failed episodes listed per entry on an agent's page (the first in town, task, episode order)."""

PAPER_AGENTS = ("hbmp", "il", "hbmp-s", "expert")
"""The agents whose pairs the paper page's paired table shows."""


def esc(value) -> str:
    return html.escape(str(value), quote=True)


def inline(markdown: str) -> str:
    """HTML of one line of markdown: ``code`` and **bold**, everything else escaped."""
    parts = re.split(r"(`[^`]*`)", markdown)
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"<code>{esc(part[1:-1])}</code>")
        else:
            out.append(re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", esc(part)))
    return "".join(out)


def fmt(value, digits: int = 1) -> str:
    """A number as the boards print it: ``digits`` decimals; "" for None/NaN, "no event" for inf."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float) and math.isinf(value):
        return "no event"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}f}"


@dataclass(frozen=True)
class Cell:
    """One table cell: ``html`` shown, ``sort`` key (the number for numeric columns), ``field`` (the
    results-file field shown, for the tests), ``text`` for a left-aligned text column."""

    html: str
    sort: str | None = None
    field: str | None = None
    text: bool = False
    wrap: bool = False

    def render(self) -> str:
        attrs = []
        if self.sort is not None:
            attrs.append(f'data-sort="{esc(self.sort)}"')
        if self.field:
            attrs.append(f'data-field="{esc(self.field)}"')
        if self.text or self.wrap:
            attrs.append(f'class="{"text wrap" if self.wrap else "text"}"')
        return f"<td {' '.join(attrs)}>{self.html}</td>" if attrs else f"<td>{self.html}</td>"


def num(value, field: str | None = None, digits: int = 1) -> Cell:
    """A numeric cell; sorts by its value (None and NaN last, inf first among "no event")."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        key = ""
    elif isinstance(value, float) and math.isinf(value):
        key = "1e308"
    else:
        key = repr(float(value))
    return Cell(esc(fmt(value, digits)), sort=key, field=field)


def txt(value, field: str | None = None, raw_html: str | None = None) -> Cell:
    return Cell(raw_html if raw_html is not None else esc(value), field=field, text=True)


TEXT_CLASS = ' class="text"'


def table(table_id: str, headers: Sequence[str], rows: Iterable[tuple[Sequence[Cell], dict[str, str]]],
          sortable: bool = True) -> str:
    """An HTML table; each row is ``(cells, data attributes)`` (``{"town": "Town01 Town02"}`` becomes
    ``data-town="Town01 Town02"``, what the filter forms match)."""
    rows = list(rows)
    text_columns = [bool(rows) and all(cells[i].text for cells, _ in rows) for i in range(len(headers))]
    head = "".join(f'<th scope="col"{TEXT_CLASS if text_columns[i] else ""}>{esc(h)}</th>'
                   for i, h in enumerate(headers))
    body = []
    for cells, attrs in rows:
        data = "".join(f' data-{k}="{esc(v)}"' for k, v in attrs.items())
        body.append(f"<tr{data}>" + "".join(c.render() for c in cells) + "</tr>")
    cls = ' class="sortable"' if sortable else ""
    return (f'<div class="scroll"><table id="{esc(table_id)}"{cls}>\n<thead><tr>{head}</tr></thead>\n<tbody>\n'
            + "\n".join(body) + "\n</tbody></table></div>\n")


def filters(table_id: str, selects: dict[str, Sequence[tuple[str, str]]], text: bool = True) -> str:
    """A filter form for ``table_id``: one ``<select name=K>`` per key (values with their labels, "all"
    first) and a text box; the row count is shown beside it."""
    parts = [f'<form class="filters" data-for="{esc(table_id)}" aria-label="filter {esc(table_id)}">']
    for name, options in selects.items():
        opts = '<option value="">all</option>' + "".join(
            f'<option value="{esc(v)}">{esc(label)}</option>' for v, label in options)
        parts.append(f'<label>{esc(name)} <select name="{esc(name)}">{opts}</select></label>')
    if text:
        parts.append('<label>text <input name="q" type="search" placeholder="filter rows"></label>')
    parts.append(f'<span class="count" data-count-for="{esc(table_id)}"></span></form>')
    return "".join(parts) + "\n"


def page(title: str, body: str, boards: Sequence[BoardData], agents: Sequence[str]) -> str:
    """A whole page: the header's links to every board and agent page, then ``body``."""
    nav = ['<a href="index.html">Leaderboards</a>', '<a href="paper.html">Paper reproduction</a>']
    nav += [f'<a href="{board_file(b)}">{esc(b.board.title)}</a>' for b in boards]
    nav += [f'<a href="{agent_file(a)}">{esc(a)}</a>' for a in agents]
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
        f"<title>{esc(title)} · hbmp_bench</title>\n"
        "<link rel=\"stylesheet\" href=\"assets/site.css\">\n<script src=\"assets/site.js\" defer></script>\n"
        "</head>\n<body>\n<header><nav>" + " ".join(nav) + "</nav></header>\n<main>\n"
        + body + "</main>\n</body>\n</html>\n"
    )


def slug(name: str) -> str:
    """A file-name-safe form of an agent or board name."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name)


def board_file(data: BoardData) -> str:
    return f"board-{slug(data.board.slug)}.html"


def agent_file(agent: str) -> str:
    return f"agent-{slug(agent)}.html"


def raw_path(data: BoardData, name: str) -> str:
    """Where a board's file (a results file, its README) is copied in the site."""
    return f"raw/{slug(data.board.slug)}/{name}"


def _task_labels() -> dict[str, str]:
    from hbmp_bench.scenarios import TASK_LABELS

    return dict(TASK_LABELS)


def _entry_towns(doc: dict) -> list[str]:
    return list(doc.get("selection", {}).get("towns", []))


def _entry_tasks(doc: dict) -> list[str]:
    return list(doc.get("selection", {}).get("tasks", []))


def _entry_attrs(doc: dict) -> dict[str, str]:
    return {"file": doc["_file"], "agent": doc["agent"], "fidelity": doc["fidelity"],
            "privileged": "yes" if doc["privileged"] else "no", "town": " ".join(_entry_towns(doc)),
            "task": " ".join(_entry_tasks(doc))}


def infractions_per_100km(doc: dict) -> float:
    """Infraction events (:data:`~hbmp_bench.site.boards.INFRACTION_KINDS`) per 100 km driven over an
    entry's scored episodes (0 where nothing was driven)."""
    from hbmp_bench.metrics.report import EXCLUDED

    scored = [e for e in doc["episodes"] if e.get("end_reason") not in EXCLUDED]
    km = sum(float(e.get("distance_m", 0.0)) for e in scored) / 1000.0
    events = sum(int(e.get(k, 0)) for e in scored for k in INFRACTION_KINDS)
    return 100.0 * events / km if km > 0 else 0.0


def _yes_no(flag) -> str:
    """"yes" or "no", as the tables write a flag."""
    return "yes" if flag else "no"


def _agent_link(agent: str) -> Cell:
    """A text cell naming an agent, linked to its page."""
    return txt(agent, "agent", f'<a href="{agent_file(agent)}">{esc(agent)}</a>')


def _file_link(data: BoardData, name: str) -> Cell:
    """A text cell naming a board's results file, linked to its copy in the site."""
    return txt(name, None, f'<a href="{raw_path(data, name)}">{esc(name)}</a>')


def _p_cell(r) -> Cell:
    """The cell of a paired comparison's McNemar p (three significant digits; sorts by the value)."""
    return Cell(esc(f"{float(r['p_mcnemar']):.3g}"), sort=repr(float(r["p_mcnemar"])), field="p_mcnemar")


def _board_selects(entries: Sequence[dict], labels: dict[str, str],
                   tasks: Sequence[str]) -> dict[str, list[tuple[str, str]]]:
    """The options of a board's filter forms: its entries' fidelities, privileged, towns and tasks."""
    fidelities = sorted({d["fidelity"] for d in entries})
    towns = sorted({t for d in entries for t in _entry_towns(d)})
    return {"fidelity": [(f, f) for f in fidelities], "privileged": [("yes", "yes"), ("no", "no")],
            "town": [(t, t) for t in towns], "task": [(t, labels[t]) for t in tasks]}


def _board_intro(data: BoardData) -> list[str]:
    """HTML of a board page's title, description and note (entries, complete ones, suite hash)."""
    entries = data.entries
    readme = (f' The board\'s own table: <a href="{raw_path(data, "README.md")}">README.md</a>.'
              if data.readme else "")
    return [f"<h1>Leaderboard: {esc(data.board.title)}</h1>\n", f"<p>{inline(data.description)}</p>\n",
            f'<p class="note">{len(entries)} entries, {sum(d["complete"] for d in entries)} complete '
            f'(every episode of the suite: ranked in <code>leaderboards/</code>); partial runs cover '
            f'part of the suite and compare only on their own episodes. Suite definition hash '
            f'<code>{esc(entries[0]["suite_hash"])}</code>. Click a column to sort; the forms filter '
            f'rows.{readme}</p>\n']


def _entry_row(data: BoardData, doc: dict, tasks: Sequence[str]) -> tuple[list[Cell], dict[str, str]]:
    """The row of one entry in a board's entries table: its summary, per-task success and provenance."""
    s, prov, by_task = doc["summary"], doc["provenance"], doc["aggregates"].get("success_pct_by_task", {})
    return ([
        _agent_link(doc["agent"]),
        txt(doc["fidelity"], "fidelity"), txt(_yes_no(doc["privileged"]), "privileged"),
        txt(_yes_no(doc["complete"]), "complete"),
        num(s.get("success_pct"), "summary.success_pct"),
        *(num(by_task.get(t), f"aggregates.success_pct_by_task.{t}") for t in tasks),
        num(s.get("mean_driving_score"), "summary.mean_driving_score"),
        num(100.0 * s.get("mean_route_completion", 0.0), "summary.mean_route_completion"),
        num(infractions_per_100km(doc), "infractions_per_100km", digits=2),
        num(s.get("km_per_infraction"), "summary.km_per_infraction", digits=2),
        num(s.get("collisions"), "summary.collisions"), num(s.get("red_light"), "summary.red_light"),
        num(s.get("timeouts"), "summary.timeouts"), num(s.get("episodes"), "summary.episodes"),
        txt(" ".join(_entry_towns(doc))), txt((prov.get("git_commit") or "")[:10], "provenance.git_commit"),
        txt((prov.get("date_utc") or "")[:10]),
        num(prov.get("wall_time_s"), "provenance.wall_time_s", digits=0),
        _file_link(data, doc["_file"]),
    ], _entry_attrs(doc))


def _entries_section(data: BoardData, labels: dict[str, str], tasks: Sequence[str],
                     selects: dict[str, list[tuple[str, str]]]) -> list[str]:
    """HTML of a board page's entries table, its filter form and the note on its columns."""
    head = ["agent", "fidelity", "privileged", "complete", "success %",
            *(labels[t] + " %" for t in tasks), "driving score", "route completion %", "infractions / 100 km",
            "km / infraction", "collisions", "red lights", "timeouts", "episodes", "towns", "commit", "date",
            "wall s", "results file"]
    rows = [_entry_row(data, doc, tasks) for doc in data.entries]
    return ["<h2 id=\"entries-title\">Entries</h2>\n", filters("entries", selects), table("entries", head, rows),
            '<p class="note">success %: episodes that reached the goal; driving score: CARLA Leaderboard '
            '(route completion × infraction penalty), mean over episodes; infractions: collision, wrong-lane, '
            'off-road and red-light events (an episode can have several).</p>\n']


def _breakdown_row(doc: dict, r: dict, labels: dict[str, str]) -> tuple[list[Cell], dict[str, str]]:
    """The row of one entry's town × task in a board's breakdown table."""
    attrs = {**_entry_attrs(doc), "town": r["town"], "task": r["task"]}
    return ([
        _agent_link(doc["agent"]),
        txt(doc["fidelity"]), txt(_yes_no(doc["privileged"])), txt(r["town"], "town"),
        txt(labels[r["task"]], "task"), num(int(r["episodes"]), "episodes"), num(r["success_pct"], "success_pct"),
        *(num(int(r[k]), k) for k in ("collision", "red_light", "timeout", "wrong_lane", "left_network",
                                       "agent_error")),
        num(r["km_driven"], "km_driven", digits=2), num(int(r["infraction_events"]), "infraction_events"),
        num(r["infractions_per_km"], "infractions_per_km", digits=3),
    ], attrs)


def _breakdown_section(data: BoardData, labels: dict[str, str],
                       selects: dict[str, list[tuple[str, str]]]) -> list[str]:
    """HTML of a board page's per town and task table, with its note and filter form."""
    by_file = {d["_file"]: d for d in data.entries}
    rows = [_breakdown_row(by_file[r["source"]], r, labels) for r in data.breakdown.to_dict(orient="records")]
    return ["<h2>Per town and task</h2>\n",
            '<p class="note">Each entry\'s episodes per town × task: episodes per outcome, what ended each '
            '(<code>hbmp-bench report</code>\'s outcome counts), km driven and infraction events per km.</p>\n',
            filters("breakdown", selects),
            table("breakdown", ["agent", "fidelity", "privileged", "town", "task", "episodes", "success %",
                                "collision", "red light", "timeout", "wrong lane / off-road", "left network",
                                "agent error", "km driven", "infraction events", "infractions / km"], rows)]


def _paired_row(first: str, second: str, r) -> tuple[list[Cell], dict[str, str]]:
    """The row of one pair of entries in a board's paired comparisons table."""
    return ([txt(first, "first"), txt(second, "second"), num(int(r["episodes"]), "episodes"),
             num(int(r["both_success"]), "both_success"), num(int(r["only_first"]), "only_first"),
             num(int(r["only_second"]), "only_second"), num(int(r["neither"]), "neither"),
             num(float(r["diff_pp"]), "diff_pp"), _p_cell(r)], {})


def _paired_section(data: BoardData) -> list[str]:
    """HTML of a board page's paired comparisons: its note, filter form and table (empty where no pairs)."""
    rows = [_paired_row(first, second, r)
            for (first, second), r in (data.paired.iterrows() if not data.paired.empty else ())]
    return ["<h2>Paired comparisons</h2>\n",
            '<p class="note">Every pair of entries on the episodes both scored (the <code>paired</code> view of '
            '<code>hbmp-bench report</code>): episodes only one of them finished and the exact two-sided '
            'McNemar p on those. A small p: the gap is more than the luck of these episodes (it says nothing of '
            'training seeds).</p>\n', filters("paired", {}, text=True),
            table("paired", ["first", "second", "episodes", "both reached the goal", "only first",
                             "only second", "neither", "difference (pp)", "p (McNemar)"], rows)]


def _km_between_section(data: BoardData) -> list[str]:
    """HTML of a board page's km between infractions table, one column per infraction kind."""
    columns = data.km_between.columns
    rows = [([txt(label, "result_set"), *(num(float(r[k]), k, digits=2) for k in columns)], {})
            for label, r in data.km_between.iterrows()]
    return ["<h2>km between infractions</h2>\n",
            '<p class="note">km driven per infraction event of each kind (the <code>km_between</code> view of '
            '<code>hbmp-bench report</code>); "no event": none of that kind.</p>\n',
            table("km-between", ["entry", *(c.replace("_", " ") for c in columns)], rows)]


def _provenance_row(data: BoardData, doc: dict) -> tuple[list[Cell], dict[str, str]]:
    """The row of one entry in a board's provenance table: fingerprints, commit, machine and wall time."""
    prov = doc["provenance"]
    machine = prov.get("machine") or {}
    return ([
        txt(data.labels[doc["_file"]], "label"),
        txt(prov.get("code_fingerprint") or "", "provenance.code_fingerprint"),
        txt(prov.get("agent_fingerprint") or "–", "provenance.agent_fingerprint"),
        txt(prov.get("git_commit") or "", "provenance.git_commit"), txt(prov.get("package_version") or ""),
        txt(machine.get("cpu") or "", "provenance.machine.cpu"),
        num(machine.get("cpu_count"), "provenance.machine.cpu_count"),
        txt(machine.get("python") or ""), txt(machine.get("platform") or "", "provenance.machine.platform"),
        txt(prov.get("date_utc") or ""), num(prov.get("wall_time_s"), "provenance.wall_time_s", digits=1),
        num(prov.get("workers"), "provenance.workers"), txt(prov.get("backend") or ""),
        txt(((prov.get("salt_commitment") or "")[:10]) if doc.get("salted") else "no"),
        _file_link(data, doc["_file"]),
    ], _entry_attrs(doc))


def _provenance_section(data: BoardData) -> list[str]:
    """HTML of a board page's provenance table, with its note."""
    rows = [_provenance_row(data, doc) for doc in data.entries]
    return ["<h2>Provenance</h2>\n",
            '<p class="note">What made each entry: the fingerprints of the package\'s code and of the agent\'s '
            'weights as they ran, the commit, the machine and the wall time (with its workers).</p>\n',
            table("provenance", ["entry", "code fingerprint", "weights fingerprint", "commit", "version", "CPU",
                                 "cores", "Python", "platform", "date (UTC)", "wall s", "workers", "backend",
                                 "salted", "results file"], rows)]


def _matrix_details(data: BoardData, doc: dict) -> str:
    """HTML of one entry's success per task and town, a table in a collapsed ``<details>``."""
    matrix = doc["aggregates"].get("success", [])
    columns = [k for k in (matrix[0] if matrix else {}) if k != "task"]
    rows = [([txt(row["task"], "task"), *(num(row.get(c), f"success.{c}") for c in columns)], {})
            for row in matrix]
    return (f'<details id="matrix-{esc(slug(doc["_file"]))}"><summary>{esc(data.labels[doc["_file"]])} '
            f'({esc(doc["fidelity"])}, {esc(doc["_file"])})</summary>\n'
            + table(f"matrix-table-{slug(doc['_file'])}", ["task", *columns], rows, sortable=False)
            + "</details>\n")


def _matrices_section(data: BoardData) -> list[str]:
    """HTML of a board page's success per task and town, one collapsed table per entry."""
    return ["<h2>Success per task and town, each entry</h2>\n", *(_matrix_details(data, doc) for doc in data.entries)]


def board_page(data: BoardData, boards: Sequence[BoardData], agents: Sequence[str]) -> str:
    """A board's page: its entries, per town and task, paired comparisons, km between infractions,
    provenance and each entry's success matrix."""
    labels = _task_labels()
    tasks = [t for t in labels if any(t in _entry_tasks(d) for d in data.entries)]
    selects = _board_selects(data.entries, labels, tasks)
    parts = [*_board_intro(data), *_entries_section(data, labels, tasks, selects),
             *_breakdown_section(data, labels, selects), *_paired_section(data), *_km_between_section(data),
             *_provenance_section(data), *_matrices_section(data)]
    return page(f"Leaderboard {data.board.title}", "".join(parts), boards, agents)


def _failures(doc: dict) -> list[dict]:
    return [e for e in doc["episodes"] if not e.get("success") and e.get("end_reason") != "sim_error"]


def replay_command(doc: dict, episode: dict) -> str:
    """The ``hbmp-bench record`` command that replays an episode of an entry as a GIF."""
    from hbmp_bench.maps import TOWNS

    town = episode["town"]
    env_town = town if town in TOWNS else TOWNS[0]
    argv = ["hbmp-bench", "record", "--env", f"hbmp_bench/{env_town}-{episode['task']}-v0"]
    if town != env_town:
        argv += ["--town", town]
    argv += ["--suite", doc["suite"], "--episode", str(episode["episode"]), "--agent", doc["agent"],
             "--fidelity", doc["fidelity"], "--out", f"{slug(doc['agent'])}-{town}-{episode['task']}-{episode['episode']}.gif"]
    return shlex.join(argv)


def replay_note(replay: dict, episode: dict) -> str:
    """How a GIF's replay ended against the entry's episode (deterministic given the seed: they agree
    unless the GIF stopped at its decision cap, or the code or float platform differ)."""
    said = f"replayed: {replay.get('end_reason')} at {fmt(float(replay.get('duration_s', 0.0)))} s"
    if replay.get("end_reason") == episode.get("end_reason") and math.isclose(
            float(replay.get("duration_s", -1.0)), float(episode.get("duration_s", -2.0))):
        return said + ", as the entry recorded"
    return said + f"; the entry recorded {episode.get('end_reason')} at {fmt(float(episode.get('duration_s', 0.0)))} s"


def _model_card_section(card: AgentCard | None) -> str:
    """HTML of an agent's model card facts, or the note that none ships with it."""
    if card is None:
        return '<p class="note">No model card ships with this agent (a rule-based or a submitted one).</p>\n'
    return ('<h2>Model card</h2>\n<dl class="facts">'
            + "".join(f"<dt>{esc(k)}</dt><dd>{inline(v)}</dd>" for k, v in card.facts) + "</dl>\n")


def _curves_section(agent: str, card: AgentCard | None, curves: str | None) -> list[str]:
    """HTML of an agent's training curves figure and the run it comes from (nothing without curves)."""
    if not curves:
        return []
    parts = [f'<h2>Training curves</h2>\n<img class="figure" src="{esc(curves)}" '
             f'alt="training curves of {esc(agent)}">\n']
    if card is not None and card.run_dir is not None:
        parts.append(f'<p class="note">From the training run <code>{esc(card.run_dir.name)}</code> '
                     f'(<code>hbmp-bench curves</code> redraws it).</p>\n')
    return parts


def _agent_entry_row(data: BoardData, doc: dict) -> tuple[list[Cell], dict[str, str]]:
    """The row of one of an agent's entries on its page: the board, the summary and the results file."""
    s = doc["summary"]
    return ([
        txt(data.board.title, "board", f'<a href="{board_file(data)}">{esc(data.board.title)}</a>'),
        txt(doc["fidelity"], "fidelity"), txt(_yes_no(doc["complete"]), "complete"),
        num(s.get("success_pct"), "summary.success_pct"),
        num(s.get("mean_driving_score"), "summary.mean_driving_score"),
        num(infractions_per_100km(doc), "infractions_per_100km", digits=2),
        num(s.get("episodes"), "summary.episodes"), num(len(_failures(doc)), "failures"),
        _file_link(data, doc["_file"]),
    ], {"board": data.board.slug, "fidelity": doc["fidelity"], "file": doc["_file"]})


def _replay_cell(doc: dict, e: dict, gif: tuple[str, dict] | None) -> str:
    """HTML of a failed episode's replay cell: the replay command, then its GIF and how the replay ended,
    or why it was not recorded (the command alone without a GIF)."""
    cell = f"<code>{esc(replay_command(doc, e))}</code>"
    if gif and gif[0] is None:
        cell += (f'<br><span class="note bad" data-field="replay">not recorded: '
                 f'{esc(gif[1]["error"])}</span>')
    elif gif:
        path, replay = gif
        cell += (f'<br><img class="figure" src="{esc(path)}" alt="replay of {esc(e["town"])} '
                 f'{esc(e["task"])} {e["episode"]}"><br><span class="note" data-field="replay">'
                 f'{esc(replay_note(replay, e))}</span>')
    return cell


def _failure_row(data: BoardData, doc: dict, e: dict, labels: dict[str, str],
                 gifs: dict[tuple, tuple[str, dict]] | None) -> tuple[list[Cell], dict[str, str]]:
    """The row of one failed episode of an entry in an agent's failures table, with its replay cell."""
    key = (data.board.slug, doc["_file"], int(e["episode"]), e["town"], e["task"])
    cell = _replay_cell(doc, e, (gifs or {}).get(key))
    return ([
        txt(data.board.title, "board"), txt(doc["fidelity"]), txt(e["town"], "town"),
        txt(labels.get(e["task"], e["task"]), "task"), num(int(e["episode"]), "episode"),
        num(int(e["seed"]), "seed"), txt(e.get("end_reason") or "", "end_reason"),
        num(100.0 * float(e.get("route_completion", 0.0)), "route_completion"),
        Cell(cell, text=True, wrap=True),
    ], {"board": data.board.slug, "fidelity": doc["fidelity"], "town": e["town"], "task": e["task"]})


def _agent_docs(agent: str, boards: Sequence[BoardData]) -> list[tuple[BoardData, dict]]:
    """An agent's entries on every board, each with its board (boards' order, then entries')."""
    return [(data, doc) for data in boards for doc in data.entries if doc["agent"] == agent]


def _agent_tables(agent: str, boards: Sequence[BoardData],
                  gifs: dict[tuple, tuple[str, dict]] | None) -> list[str]:
    """HTML of an agent page's entries table and its failed episodes table (with their note and filter)."""
    labels = _task_labels()
    docs = _agent_docs(agent, boards)
    rows = [_agent_entry_row(data, doc) for data, doc in docs]
    failure_rows = [_failure_row(data, doc, e, labels, gifs)
                    for data, doc in docs for e in _failures(doc)[:FAILURES_PER_ENTRY]]
    return ["<h2>Entries</h2>\n", table("agent-entries", ["board", "fidelity", "complete", "success %",
                                                        "driving score", "infractions / 100 km", "episodes",
                                                        "failed episodes", "results file"], rows),
            "<h2>Failed episodes</h2>\n",
            f'<p class="note">The first {FAILURES_PER_ENTRY} failed episodes of each entry (town, task, episode '
            'order) and the command that replays one as a top-down GIF: episodes are deterministic given their '
            'seed. An episode on an imported town (CARLA\'s) replays once the map is imported under that name '
            '(<code>hbmp-bench maps import</code>).</p>\n', filters("failures", {}, text=True),
            table("failures", ["board", "fidelity", "town", "task", "episode", "seed", "end", "route completion %",
                               "replay"], failure_rows)]


def agent_page(agent: str, card: AgentCard | None, curves: str | None, boards: Sequence[BoardData],
               agents: Sequence[str], gifs: dict[tuple, tuple[str, dict]] | None = None) -> str:
    """An agent's page: its model card, training curves, entries and failed episodes (with their GIFs)."""
    parts = [f"<h1>Agent: {esc(agent)}</h1>\n", _model_card_section(card), *_curves_section(agent, card, curves),
             *_agent_tables(agent, boards, gifs)]
    return page(f"Agent {agent}", "".join(parts), boards, agents)


def _entry(boards: Sequence[BoardData], slug_: str, agent: str, fidelity: str = "continuous") -> dict | None:
    for data in boards:
        if data.board.slug == slug_:
            for doc in data.entries:
                if doc["agent"] == agent and doc["fidelity"] == fidelity:
                    return doc
    return None


def _matrix_value(doc: dict | None, town: str, task: str) -> float | None:
    if doc is None:
        return None
    label = _task_labels()[task]
    for row in doc["aggregates"].get("success", []):
        if row.get("task") == label:
            return row.get(town)
    return None


def _claims_section(claims: list[list[str]]) -> list[str]:
    """HTML of the paper page's claims table (a header row, then one row per claim; nothing without claims)."""
    if not claims:
        return []
    header, body = claims[0], claims[1:]
    return ["<h2>Claims</h2>\n",
            '<p class="note">From <code>docs/paper-reproduction.md</code>, where each figure has its '
            'command, its paired test and the replays behind each miss.</p>\n',
            table("claims", header, [([Cell(inline(c), text=True, wrap=True) for c in row], {}) for row in body],
                  sortable=False)]


def _table_i_row(town: str, task: str, value: float, labels: dict[str, str], hbmp: dict | None,
                 corl: dict | None, carla: dict | None) -> tuple[list[Cell], dict[str, str]]:
    """The row of one town and task of Tab. I: the paper's value, the three boards' and the difference."""
    here = _matrix_value(hbmp, town, task)
    return ([txt(town, "town"), txt(labels[task], "task"), num(value, "paper"),
             num(here, "hbmp"), num(_matrix_value(corl, town, task), "corl2017"),
             num(_matrix_value(carla, f"CARLA_{town}", task), "carla"),
             num(None if here is None else here - value, "difference")],
            {"town": town, "task": task})


def _table_i_section(boards: Sequence[BoardData], labels: dict[str, str], hbmp: dict | None) -> list[str]:
    """HTML of the paper page's Tab. I against the shipped ``hbmp`` on the hbmp, corl2017 and CARLA boards."""
    corl = _entry(boards, "corl2017", "hbmp")
    carla = _entry(boards, "carla-hbmp", "hbmp")
    rows = [_table_i_row(town, task, value, labels, hbmp, corl, carla)
            for town, paper in PAPER_TABLE_I.items() for task, value in paper.items()]
    return ["<h2>Tab. I: success % in Town1 and Town2</h2>\n",
            '<p class="note">The shipped <code>hbmp</code>, continuous fidelity: the <code>hbmp</code> suite '
            '(the paper\'s protocol, 40 episodes per task), the <code>corl2017</code> suite (25 per task, its '
            'own rules) and the <code>hbmp</code> suite on CARLA\'s own Town01 and Town02 (imported from '
            'CARLA\'s OpenDRIVE files).</p>\n',
            table("table-i", ["town", "task", "paper", "here: hbmp suite", "here: corl2017",
                              "here: CARLA's own town", "hbmp suite − paper (pp)"], rows)]


def _town15_row(town: str, task: str, labels: dict[str, str],
                hbmp: dict | None) -> tuple[list[Cell], dict[str, str]]:
    """The row of one task and town of Fig. town15: the hbmp board's success % and whether it is met."""
    here = _matrix_value(hbmp, town, task)
    met = here is not None and here > PAPER_TOWN15_PCT
    return ([txt(labels[task], "task"), txt(town, "town"), num(here, "hbmp"),
             Cell(f'<span class="{"good" if met else "bad"}">{"met" if met else "not met"}</span>',
                  text=True, field="verdict")], {"town": town, "task": task})


def _town15_section(labels: dict[str, str], hbmp: dict | None) -> list[str]:
    """HTML of the paper page's Fig. town15 verdicts, per task and every town of the ``hbmp`` entry."""
    towns = sorted({k for row in (hbmp or {}).get("aggregates", {}).get("success", []) for k in row if k != "task"})
    rows = [_town15_row(town, task, labels, hbmp) for task in ("Navigation", "NavigationDynamic") for town in towns]
    return [f"<h2>Fig. town15: more than {PAPER_TOWN15_PCT:.0f} % in every town</h2>\n",
            table("town15", ["task", "town", "here: hbmp suite %", "verdict"], rows)]


def _paper_paired_section(boards: Sequence[BoardData]) -> list[str]:
    """HTML of the paper page's paired table: the ``hbmp`` board's pairs of :data:`PAPER_AGENTS` (nothing
    without that board or its pairs)."""
    board = next((b for b in boards if b.board.slug == "hbmp"), None)
    if board is None or board.paired.empty:
        return []
    rows = [([txt(first, "first"), txt(second, "second"), num(int(r["only_first"]), "only_first"),
              num(int(r["only_second"]), "only_second"), _p_cell(r)], {})
            for (first, second), r in board.paired.iterrows()
            if first.split(" ")[0] in PAPER_AGENTS and second.split(" ")[0] in PAPER_AGENTS]
    return ["<h2>Paired: is a gap more than the luck of the episodes?</h2>\n",
            '<p class="note">The <code>hbmp</code> board\'s paired view (<code>hbmp-bench report '
            'leaderboards/hbmp</code>): episodes only the first / only the second finished, exact '
            'McNemar p.</p>\n',
            table("paper-paired", ["first", "second", "only first", "only second", "p (McNemar)"], rows)]


def paper_page(claims: list[list[str]], boards: Sequence[BoardData], agents: Sequence[str]) -> str:
    """The paper reproduction page: the claims, Tab. I and Fig. town15 against the boards, and the paired
    comparisons of the ``hbmp`` board."""
    labels = _task_labels()
    hbmp = _entry(boards, "hbmp", "hbmp")
    parts = ["<h1>Paper reproduction</h1>\n", f"<p>{esc(PAPER)}: the paper's claims against this benchmark's "
             "boards.</p>\n", *_claims_section(claims), *_table_i_section(boards, labels, hbmp),
             *_town15_section(labels, hbmp),
             *_paper_paired_section(boards)]
    return page("Paper reproduction", "".join(parts), boards, agents)


def index_page(boards: Sequence[BoardData], agents: Sequence[str]) -> str:
    parts = ["<h1>hbmp_bench leaderboards</h1>\n",
             "<p>Hierarchical behavior and motion planning on SUMO recreations of CARLA's towns. Every table here is "
             "built by <code>hbmp-bench site</code> from the committed boards' results files; each links to the "
             "raw file it comes from.</p>\n"]
    rows = []
    for data in boards:
        complete = [d for d in data.entries if d["complete"]]
        rank = lambda d: (d["summary"].get("success_pct", 0.0), d["summary"].get("mean_driving_score", 0.0))  # noqa: E731
        best = max(complete, key=rank, default=None)
        fair = max((d for d in complete if not d["privileged"]), key=rank, default=None)
        rows.append(([
            txt(data.board.title, "board", f'<a href="{board_file(data)}">{esc(data.board.title)}</a>'),
            txt(data.board.suite, "suite"), txt(" ".join(data.towns), "towns"), num(len(data.entries), "entries"),
            num(len(complete), "complete"),
            txt(f"{best['agent']} ({best['fidelity']})" if best else "–", "best"),
            num(best["summary"]["success_pct"] if best else None, "best_success_pct"),
            txt(f"{fair['agent']} ({fair['fidelity']})" if fair else "–", "best_unprivileged"),
            num(fair["summary"]["success_pct"] if fair else None, "best_unprivileged_success_pct"),
        ], {"board": data.board.slug}))
    parts += ["<h2>Boards</h2>\n", table("boards", ["board", "suite", "towns", "entries", "complete entries",
                                                   "best complete entry", "success %",
                                                   "best without privileged state", "success %"], rows)]
    parts.append('<p class="note">Privileged entries (the rule-based expert) read the simulator\'s scene: a '
                 'reference, not comparable with agents that see M_t and R_t only. Partial runs (subsets of a '
                 'suite) are not ranked.</p>\n')
    parts.append("<h2>Agents</h2>\n<ul>" + "".join(f'<li><a href="{agent_file(a)}">{esc(a)}</a></li>' for a in agents)
                 + "</ul>\n")
    parts.append('<p><a href="paper.html">Paper reproduction</a>: the paper\'s claims, Tab. I and Fig. town15 '
                 'against the boards.</p>\n')
    return page("Leaderboards", "".join(parts), boards, agents)
