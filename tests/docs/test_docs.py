"""The docs: the README a newcomer reads first, the mkdocs site built strictly with the API reference
complete, and every ``hbmp-bench`` command of the docs' shell blocks accepted by the CLI (the cheap
ones run, and the report commands rewrite exactly the committed ``docs/report/`` tables)."""

from __future__ import annotations

import contextlib
import html
import importlib
import importlib.util
import inspect
import io
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from hbmp_bench.cli import build_parser, main
from hbmp_bench.site.apidocs import documented_rooms, room_modules

from docs_commands import ROOT, DocCommand, doc_commands, python_blocks

API_PACKAGES = ("envs", "agents", "evaluation", "training")
"""The rooms whose every public class and function the API reference must show with its docstring."""

COMMANDS = doc_commands()


def test_readme_is_short_and_the_tour_is_on_the_first_screen():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) < 200, f"README.md has {len(lines)} lines"
    tour = lines.index("## A short tour")
    assert tour < 40, f"the tour starts at line {tour + 1}"


def _claims_table(text: str) -> str:
    start = text.index("\n| the paper's claim |") + 1
    return text[start:text.index("\n\n", start)]


def test_the_readme_states_the_claims_the_reproduction_page_and_the_site_show():
    """The README's results table is the paper-reproduction page's first table (the site's claims): one table, so
    a verdict changed in one place cannot be left behind in the other."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    page = (ROOT / "docs" / "paper-reproduction.md").read_text(encoding="utf-8")
    assert _claims_table(readme) == _claims_table(page)
    assert _claims_table(readme).count("\n") >= 9


def test_readme_links_resolve():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    assert len(links) >= 11, links  # one per docs page at least
    missing = [link for link in links if "://" not in link and not (ROOT / link).exists()]
    assert not missing, f"README links to missing files: {missing}"
    nav = re.findall(r":\s*([\w-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(encoding="utf-8"), flags=re.M)
    pages = {name for name in nav if (ROOT / "docs" / name).is_file()} - {"index.md"}
    linked = {Path(link).name for link in links if link.startswith("docs/")}
    assert len(pages) >= 12 and pages <= linked, f"docs pages of the nav the README does not link: {sorted(pages - linked)}"


@pytest.fixture(scope="module")
def built_docs(tmp_path_factory) -> tuple[Path, str]:
    """``mkdocs build --strict`` into a temporary folder: (the site, mkdocs' output)."""
    site = tmp_path_factory.mktemp("docs-site")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    if run.returncode != 0:
        pytest.fail(f"mkdocs build --strict failed ({run.returncode}):\n{run.stdout}\n{run.stderr}")
    return site, run.stdout + run.stderr


def test_mkdocs_build_strict_has_no_warning(built_docs):
    site, output = built_docs
    assert not [line for line in output.splitlines() if "WARNING" in line or "ERROR" in line], output
    for page in ("index", "getting-started", "envs", "suites", "agents-training", "evaluation", "untrusted-agents",
                 "maps", "throughput", "multi-agent", "paper-reproduction", "design"):
        assert (site / f"{page}.html").is_file(), page
    for room in documented_rooms():
        assert (site / "api" / f"{room}.html").is_file(), room


def _public_objects() -> list[tuple[str, object]]:
    """``(documented path, object)`` of every public class and function of :data:`API_PACKAGES`: the
    names in each package's and module's ``__all__``, and in a module without one, the classes and
    functions it defines whose names do not start with ``_``."""
    found = {}
    for room in API_PACKAGES:
        for name in room_modules(room):
            module = importlib.import_module(name)
            exported = getattr(module, "__all__", None)
            if exported is None:
                exported = [n for n, v in vars(module).items() if not n.startswith("_")
                            and (inspect.isclass(v) or inspect.isfunction(v)) and v.__module__ == name]
            for attr in exported:
                value = getattr(module, attr)
                if inspect.isclass(value) or inspect.isfunction(value):
                    found[f"{value.__module__}.{value.__qualname__}"] = value
    return sorted(found.items())


def _words(text: str) -> str:
    return re.sub(r"\W+", "", text).lower()


def test_api_reference_has_every_public_class_and_function_with_its_docstring(built_docs):
    site, _ = built_docs
    pages = {room: (site / "api" / f"{room}.html").read_text(encoding="utf-8") for room in documented_rooms()}
    objects = _public_objects()
    assert len(objects) > 100, len(objects)
    missing, undocumented = [], []
    for path, value in objects:
        room = path.split(".")[1]
        page = pages.get(room, "")
        at = page.find(f'id="{path}"')
        if at < 0:
            missing.append(path)
            continue
        doc = inspect.getdoc(value)
        if doc and getattr(value, "__doc__", None):
            summary = _words(doc.split("\n\n", 1)[0])[:60]
            section = _words(html.unescape(re.sub(r"<[^>]+>", " ", page[at:at + 40_000])))
            if summary not in section:
                undocumented.append(path)
    assert not missing, f"public names missing from the API reference: {missing}"
    assert not undocumented, f"public names shown without their docstring: {undocumented}"


@pytest.mark.parametrize("command", COMMANDS, ids=str)
def test_docs_command_parses(command: DocCommand):
    """Each ``hbmp-bench`` command of the docs' shell blocks is accepted by the CLI's own parser."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            build_parser().parse_args(list(command.argv))
    except SystemExit as exc:
        pytest.fail(f"{command}: {err.getvalue().strip() or exc}")


def test_docs_have_commands():
    assert len(COMMANDS) >= 40
    assert {c.argv[0] for c in COMMANDS} >= {"evaluate", "report", "list", "train", "leaderboard", "maps", "site"}


def _report_runs(command: DocCommand) -> bool:
    inputs = [a for a in command.argv[1:] if not a.startswith("-")]
    return command.argv[0] == "report" and "--out" in command.argv and all((ROOT / a).is_dir() for a in inputs[:1])


CHEAP = [c for c in COMMANDS if c.argv[:1] == ("list",) or c.argv[:2] == ("maps", "stats")
         and len(c.argv) == 3 or _report_runs(c)]
"""Docs commands cheap enough to run here: ``list``, ``maps stats`` of the built-in towns, ``report`` of
a committed board (``site`` runs in tests/site)."""


@pytest.mark.parametrize("command", CHEAP, ids=str)
def test_cheap_docs_command_runs(command: DocCommand, tmp_path, monkeypatch, capsys):
    """The command exits 0; a ``report`` into ``docs/report/X`` writes exactly the committed tables."""
    monkeypatch.chdir(ROOT)
    argv = list(command.argv)
    out = None
    if "--out" in argv:
        at = argv.index("--out") + 1
        out, argv[at] = argv[at], str(tmp_path / "out")
    assert main(argv) == 0, command
    assert capsys.readouterr().out.strip()
    if out is not None and out.startswith("docs/report/"):
        committed = sorted(p.name for p in (ROOT / out).glob("*.csv"))
        assert committed, f"{out} holds no tables"
        for name in committed:
            assert (tmp_path / "out" / name).read_text() == (ROOT / out / name).read_text(), (
                f"{out}/{name} is not what `{command}` writes from today's boards: rerun it")


def test_cheap_commands_include_the_reports():
    assert sum(c.argv[0] == "report" for c in CHEAP) >= 6 and any(c.argv == ("list",) for c in CHEAP)


PYTHON_BLOCKS = python_blocks()


@pytest.mark.parametrize("block", PYTHON_BLOCKS, ids=lambda b: f"{b[0].relative_to(ROOT)}:{b[1]}")
def test_docs_python_blocks_compile_and_import_what_exists(block):
    """Each python block of the docs is valid Python, and every name it imports from the package exists."""
    import ast

    path, line, code = block
    tree = ast.parse(code, filename=f"{path.name}:{line}")
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("hbmp_bench"):
            module = importlib.import_module(node.module)
            for alias in node.names:
                if not hasattr(module, alias.name):  # ``from package import submodule``
                    assert importlib.util.find_spec(f"{node.module}.{alias.name}") is not None, (
                        f"{path.name}:{line}: {node.module} has no {alias.name}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("hbmp_bench"):
                    importlib.import_module(alias.name)


def test_docs_have_python_blocks():
    assert len(PYTHON_BLOCKS) >= 4 and any(p.name == "README.md" for p, _, _ in PYTHON_BLOCKS)


def test_repository_paths_named_in_the_docs_exist():
    """A folder or file of the repository the README or a docs page names in backticks is there (a run
    removed from training_runs/ or a moved module shows up here); env ids and placeholders are no paths."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    named, missing = 0, []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        for match in re.finditer(r"`((?:training_runs|leaderboards|hbmp_bench|docs|benchmarks)/[^`\s]*)`", text):
            path = match.group(1).rstrip(".,;:)")
            if re.search(r"[<>*{}|]|[A-Z]{3,}|-v\d+$", path):
                continue
            named += 1
            if not (ROOT / path).exists():
                missing.append(f"{page.relative_to(ROOT)}: {path}")
    assert named > 50, named
    assert not missing, missing
