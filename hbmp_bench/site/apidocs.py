"""The docs site's API reference: one page per package room, one section per public module.

Used as a mkdocs hook (``mkdocs.yml``: ``hooks``): :func:`on_files` adds the pages ``api/<room>.md``
at build time, each a list of mkdocstrings ``:::`` blocks, so a module added to a room is in the
reference without anyone editing a page. The modules are found from the package's files (nothing
is imported here; mkdocstrings reads the sources).
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1]
"""The ``hbmp_bench`` package folder."""

API_ROOMS: dict[str, str] = {
    "envs": "Environments: the PettingZoo traffic env, the gymnasium behavior and control envs, observations.",
    "agents": "The agent protocol and registry, the expert, the simple and the learned agents.",
    "policies": "The networks, their action distributions and checkpoint loading (the package's own classes only).",
    "evaluation": "Suite runs, the sandboxed agent process, leaderboards, audits.",
    "training": "DAgger, PPO on rsl-rl, the networks, the training session.",
    "metrics": "Detectors, episode records, summaries and reports.",
    "scenarios": "Tasks, suites and their deterministic episode lists.",
    "planning": "The behavior-conditioned sampling motion planner (pure numpy).",
    "maps": "The towns, their statistics and the import of OpenDRIVE and SUMO nets.",
    "sim": "The one door to SUMO: start and close, the world snapshot, the ego's pose.",
    "render": "The headless top-down renderer, GIF recording and the planner figure.",
}
"""Rooms documented in the API reference (page ``api/<room>.md``) and the line heading each page; a room
the package does not have (yet) is left out (:func:`documented_rooms`)."""

NAV_TITLE = "API reference"
"""The ``mkdocs.yml`` nav section whose pages :func:`on_config` fills in."""


def documented_rooms() -> list[str]:
    """The rooms of :data:`API_ROOMS` that are packages of this checkout."""
    return [room for room in API_ROOMS if (PACKAGE_DIR / room / "__init__.py").is_file()]


def room_modules(room: str) -> list[str]:
    """Dotted names of ``room``'s public modules: the package itself, then each ``.py`` file and
    sub-package whose name does not start with ``_``, sorted."""
    folder = PACKAGE_DIR / room
    if not (folder / "__init__.py").is_file():
        raise ValueError(f"no package hbmp_bench.{room} in {PACKAGE_DIR}")
    names = [f"hbmp_bench.{room}"]
    for path in sorted(folder.iterdir()):
        if path.name.startswith("_"):
            continue
        if path.suffix == ".py":
            names.append(f"hbmp_bench.{room}.{path.stem}")
        elif path.is_dir() and (path / "__init__.py").is_file():
            names.extend(_sub_package(path))
    return names


def _sub_package(folder: Path) -> list[str]:
    prefix = "hbmp_bench." + ".".join(folder.relative_to(PACKAGE_DIR).parts)
    names = [prefix]
    for path in sorted(folder.iterdir()):
        if path.suffix == ".py" and not path.name.startswith("_"):
            names.append(f"{prefix}.{path.stem}")
    return names


def api_page(room: str) -> str:
    """Markdown of ``api/<room>.md``: the room's line, then one mkdocstrings block per module (the
    package's own block without members: its names are documented where they are defined)."""
    modules = room_modules(room)
    parts = [f"# `hbmp_bench.{room}`\n", f"{API_ROOMS[room]}\n"]
    parts.append(f"::: hbmp_bench.{room}\n    options:\n      members: false\n      show_root_heading: false\n")
    parts += [f"::: {name}\n" for name in modules[1:]]
    return "\n".join(parts)


def api_pages() -> dict[str, str]:
    """``{"api/<room>.md": markdown}`` for every room of :data:`API_ROOMS`, and ``api/index.md``."""
    rooms = documented_rooms()
    pages = {f"api/{room}.md": api_page(room) for room in rooms}
    lines = ["# API reference\n", "Generated from the docstrings of the package's modules, one page per room:\n"]
    lines += [f"- [`hbmp_bench.{room}`]({room}.md): {API_ROOMS[room]}" for room in rooms]
    pages["api/index.md"] = "\n".join(lines) + "\n"
    return pages


def _nav_pages(items) -> set[str]:
    found = set()
    for item in items or []:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        found |= _nav_pages(value) if isinstance(value, list) else {value}
    return found


def _title(page: Path) -> str:
    heading = next((line[2:].strip() for line in page.read_text(encoding="utf-8").splitlines()
                    if line.startswith("# ")), "")
    return heading or page.stem.replace("-", " ").capitalize()


def on_config(config):
    """mkdocs hook: the nav's :data:`NAV_TITLE` section lists the generated pages, one per room, and a
    top-level docs page the nav does not name yet is listed before it (under its first heading), so a
    page added to ``docs/`` is never left out of the site."""
    nav = config["nav"] or []
    at = next((i for i, item in enumerate(nav) if isinstance(item, dict) and NAV_TITLE in item), None)
    if at is None:
        raise ValueError(f"mkdocs.yml's nav has no {NAV_TITLE!r} section for the generated API pages")
    nav[at][NAV_TITLE] = [{"Overview": "api/index.md"},
                          *({f"hbmp_bench.{room}": f"api/{room}.md"} for room in documented_rooms())]
    listed = _nav_pages(nav)
    docs_dir = Path(config["docs_dir"])
    added = [{_title(page): page.name} for page in sorted(docs_dir.glob("*.md")) if page.name not in listed]
    nav[at:at] = added
    return config


def on_files(files, config):
    """mkdocs hook: add the generated API pages to the site's files."""
    from mkdocs.structure.files import File

    for path, text in api_pages().items():
        files.append(File.generated(config, path, content=text))
    return files
