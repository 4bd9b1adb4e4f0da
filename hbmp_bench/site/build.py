"""``hbmp-bench site --out DIR``: the static leaderboard website, from the committed boards only.

Pages (all in ``DIR``, linked by relative paths, so the site opens from the file system):

- ``index.html``: every board, its entries and its best complete entry, and the agents;
- ``board-<board>.html``: a board's entries (sortable, filterable by fidelity, town, task and
  privileged), each entry's per-town × per-task outcomes and infractions per km, the paired McNemar
  comparisons and km between infractions of ``hbmp-bench report``, provenance, and every entry's success
  per task × town;
- ``agent-<agent>.html``: a shipped agent's model card and training curves, its entries, its first
  failed episodes with the ``hbmp-bench record`` command that replays each (and, with ``gifs``, the GIF);
- ``paper.html``: the paper's claims (from ``docs/paper-reproduction.md``), Tab. I and Fig. town15
  against the boards;
- ``raw/<board>/``: the results files and README the pages come from; ``img/``: the curves.
"""

from __future__ import annotations

import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

from hbmp_bench.errors import UserError
from hbmp_bench.site import assets, pages
from hbmp_bench.site.boards import BoardData, agent_card, boards_data, claims_table

MARKER = ".hbmp-bench-site"
"""A file the site writes into its folder: a later build may replace only a folder holding it."""

CLAIMS_PAGE = Path("docs") / "paper-reproduction.md"
"""The docs page (under the repository root) whose first table is the paper page's claims."""


@dataclass(frozen=True)
class SiteBuild:
    """What a build wrote: its folder, the pages (relative paths) and the bytes of every file."""

    out: Path
    pages: tuple[str, ...]
    total_bytes: int


def _prepare(out: Path, boards_root: Path) -> None:
    if out.resolve() == boards_root.resolve() or boards_root.resolve() in (out.resolve(), *out.resolve().parents):
        raise UserError(f"--out {out} lies in the boards' folder {boards_root}; choose another folder")
    if out.exists():
        if not out.is_dir():
            raise UserError(f"--out {out} is a file, not a folder")
        if any(out.iterdir()) and not (out / MARKER).is_file():
            raise UserError(f"--out {out} is not empty and holds no site built by hbmp-bench site; "
                            "choose an empty or new folder")
        shutil.rmtree(out)
    out.mkdir(parents=True)
    (out / MARKER).write_text("built by hbmp-bench site; the next build replaces this folder\n", encoding="utf-8")


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


def build_site(out: str | Path, boards_root: str | Path = "leaderboards", repo_root: str | Path | None = None,
               gifs: int = 0) -> SiteBuild:
    """Build the website into ``out`` from the boards under ``boards_root``.

    ``repo_root`` (default: ``boards_root``'s parent) is where the training runs named by the model
    cards and ``docs/paper-reproduction.md`` are looked up; without them the agent pages show no curves
    and the paper page no claims table. ``gifs`` > 0 records that many failed episodes per agent with
    ``hbmp-bench record``'s code (one SUMO run each) and shows them on the agent pages.
    """
    if gifs < 0:
        raise UserError(f"--gifs must be >= 0, got {gifs}")
    out, boards_root = Path(out), Path(boards_root)
    repo_root = Path(repo_root) if repo_root is not None else boards_root.resolve().parent
    boards = boards_data(boards_root)
    agents = sorted({d["agent"] for b in boards for d in b.entries})
    _prepare(out, boards_root)
    _write(out / "assets" / "site.css", assets.SITE_CSS)
    _write(out / "assets" / "site.js", assets.SITE_JS)
    for data in boards:
        target = out / pages.raw_path(data, "")
        target.mkdir(parents=True, exist_ok=True)
        for doc in data.entries:
            shutil.copyfile(data.board.folder / doc["_file"], target / doc["_file"])
        if data.readme is not None:
            shutil.copyfile(data.readme, target / "README.md")
    written = ["index.html", "paper.html"]
    _write(out / "index.html", pages.index_page(boards, agents))
    claims_file = repo_root / CLAIMS_PAGE
    claims = claims_table(claims_file.read_text(encoding="utf-8")) if claims_file.is_file() else []
    _write(out / "paper.html", pages.paper_page(claims, boards, agents))
    for data in boards:
        name = pages.board_file(data)
        _write(out / name, pages.board_page(data, boards, agents))
        written.append(name)
    for agent in agents:
        card = agent_card(agent, repo_root)
        curves = None
        if card is not None and card.run_dir is not None and (card.run_dir / "curves.png").is_file():
            curves = f"img/{pages.slug(agent)}-curves.png"
            (out / "img").mkdir(exist_ok=True)
            shutil.copyfile(card.run_dir / "curves.png", out / curves)
        recorded = _record_failures(agent, boards, out, gifs) if gifs else {}
        name = pages.agent_file(agent)
        _write(out / name, pages.agent_page(agent, card, curves, boards, agents, recorded))
        written.append(name)
    total = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    return SiteBuild(out=out, pages=tuple(written), total_bytes=total)


GIF_EVERY = 5
"""Frames kept by the failure GIFs: every 5th 0.1 s step (2 per simulated second), played at :data:`GIF_FPS`."""

GIF_FPS = 4.0

GIF_MAX_DECISIONS = 150
"""Decisions recorded at most per GIF (a long timeout's GIF ends there)."""


def _record_failures(agent: str, boards: list[BoardData], out: Path, count: int) -> dict:
    """Record ``agent``'s ``count`` shortest failed episodes on built-in towns (of the failures the agent
    page lists) as small GIFs with ``hbmp-bench record``'s function; returns the page's key ->
    ``(GIF path, the replay's record)``, so the page can say whether the replay ended as the entry's
    episode did."""
    from hbmp_bench.envs.recording import record_episode
    from hbmp_bench.maps import TOWNS

    listed = [(data, doc, e) for data in boards for doc in data.entries if doc["agent"] == agent
              for e in pages._failures(doc)[:pages.FAILURES_PER_ENTRY] if e["town"] in TOWNS]
    listed.sort(key=lambda item: (float(item[2].get("duration_s", 0.0)), item[0].board.slug, item[1]["_file"]))
    recorded = {}
    for data, doc, e in listed[:count]:
        rel = f"img/{pages.slug(agent)}-{data.board.slug}-{doc['fidelity']}-{e['town']}-{e['task']}-{e['episode']}.gif"
        (out / "img").mkdir(exist_ok=True)
        key = (data.board.slug, doc["_file"], int(e["episode"]), e["town"], e["task"])
        try:
            replay = record_episode(f"hbmp_bench/{e['town']}-{e['task']}-v0", agent, str(out / rel),
                                    episode_index=int(e["episode"]), suite=doc["suite"], fidelity=doc["fidelity"],
                                    every=GIF_EVERY, max_decisions=GIF_MAX_DECISIONS, fps=GIF_FPS)
        except Exception as exc:  # the page says so; one agent the recorder cannot drive spoils no other page
            (out / rel).unlink(missing_ok=True)
            error = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            print(f"hbmp-bench site: could not record {agent} {key[1]} {e['town']} {e['task']} {e['episode']}: "
                  f"{error}", file=sys.stderr)
            recorded[key] = (None, {"error": error})
            continue
        recorded[key] = (rel, replay)
    return recorded
