"""The leaderboard website built once by its own command, and a headless Chromium to open it in."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import pytest

from hbmp_bench.cli import main

ROOT = Path(__file__).resolve().parents[2]
BOARDS = ROOT / "leaderboards"

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
"""Browser binaries tried in order (Debian's ``chromium`` first: CI installs it); ``HBMP_CHROMIUM`` names
another one."""


def chromium_binary() -> str | None:
    named = os.environ.get("HBMP_CHROMIUM")
    if named:
        return named if Path(named).is_file() else None
    return next((found for found in map(shutil.which, CHROMIUM_NAMES) if found), None)


@pytest.fixture(scope="session")
def built_site(tmp_path_factory) -> tuple[Path, float]:
    """``hbmp-bench site --out DIR`` of the committed boards: (DIR, wall seconds)."""
    out = tmp_path_factory.mktemp("site") / "site"
    start = time.perf_counter()
    assert main(["site", "--out", str(out), "--boards", str(BOARDS)]) == 0
    return out, time.perf_counter() - start


@pytest.fixture(scope="session")
def site(built_site) -> Path:
    return built_site[0]


@pytest.fixture(scope="session")
def screenshots(tmp_path_factory) -> Path:
    """Where the browser tests save screenshots of the main pages (``HBMP_SITE_SCREENSHOTS`` to keep them)."""
    named = os.environ.get("HBMP_SITE_SCREENSHOTS")
    folder = Path(named) if named else tmp_path_factory.mktemp("screenshots")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@pytest.fixture(scope="session")
def browser():
    binary = chromium_binary()
    if binary is None:
        pytest.skip(f"no Chromium binary found (tried {', '.join(CHROMIUM_NAMES)} and HBMP_CHROMIUM): "
                    "apt-get install chromium")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=binary, args=["--no-sandbox"])
        yield chromium
        chromium.close()


class Page:
    """A browser page that records console errors, uncaught exceptions and failed requests."""

    def __init__(self, browser):
        self.context = browser.new_context(viewport={"width": 1400, "height": 900})
        self.page = self.context.new_page()
        self.errors: list[str] = []
        self.page.on("console", lambda m: self.errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
        self.page.on("requestfailed", lambda r: self.errors.append(f"failed request: {r.url}"))

    def open(self, file: Path):
        self.page.goto(file.resolve().as_uri(), wait_until="load")
        return self.page

    def close(self):
        self.context.close()


@pytest.fixture
def browser_page(browser):
    page = Page(browser)
    yield page
    page.close()


def results_file(site_dir: Path, href: str) -> dict:
    """A results file the site links to (``raw/<board>/<file>``), read from the site itself."""
    return json.loads((site_dir / href).read_text(encoding="utf-8"))
