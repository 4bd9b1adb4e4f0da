"""The leaderboard website in a real browser (headless Chromium): every page loads without a console
error, sorting and filtering change the rows as they should, every link and image resolves, and the
numbers on the pages are the committed results files'."""

from __future__ import annotations

import functools
import json
import math
import shlex
from pathlib import Path

import pytest

from hbmp_bench.cli import build_parser
from hbmp_bench.scenarios import SCENARIO_TYPES

ROOT = Path(__file__).resolve().parents[2]
BOARDS = ROOT / "leaderboards"

MAIN_PAGES = ("index.html", "board-hbmp.html", "agent-hbmp.html", "paper.html")

TASK_LABELS = {"Straight": "Straight", "OneTurn": "One turn", "Navigation": "Navigation",
               "NavigationDynamic": "Nav. dynamic", **{name: name for name in SCENARIO_TYPES}}
"""The labels the pages show: the CoRL2017 tasks' (the paper's), a scenario type by its name."""


@functools.cache
def board_folders() -> dict[str, Path]:
    """Page slug -> committed board folder (``carla-hbmp`` -> ``leaderboards/carla/hbmp``)."""
    return {"-".join(p.relative_to(BOARDS).parts): p for p in sorted(BOARDS.rglob("*"))
            if p.is_dir() and "archive" not in p.parts and "runs" not in p.parts and any(p.glob("*.json"))}


@functools.cache
def entries(slug: str) -> dict[str, dict]:
    """The committed results files of a board, by file name (read once per test session)."""
    return {p.name: json.loads(p.read_text(encoding="utf-8")) for p in board_folders()[slug].glob("*.json")}


def covered(doc: dict) -> set[tuple[str, str]]:
    """The (town, task) cells an entry has episodes in (a subset entry covers only some)."""
    return {(e["town"], e["task"]) for e in doc["episodes"]}


def rows(page, table: str, visible_only: bool = True) -> list[dict]:
    """The rows of a table as ``{"attrs": data-*, "cells": {data-field: text}, "texts": [cell texts]}``."""
    return page.evaluate(
        """([id, visible]) => Array.from(document.getElementById(id).tBodies[0].rows)
            .filter(r => !visible || !r.hidden)
            .map(r => ({attrs: Object.assign({}, r.dataset),
                        cells: Object.fromEntries(Array.from(r.cells).filter(c => c.dataset.field)
                                                   .map(c => [c.dataset.field, c.innerText.trim()])),
                        texts: Array.from(r.cells).map(c => c.innerText.trim())}))""", [table, visible_only])


def one(value, digits=1) -> str:
    return f"{value:.{digits}f}"


def test_every_page_loads_without_console_errors(site, browser_page, screenshots):
    pages = sorted(p.name for p in site.glob("*.html"))
    assert set(MAIN_PAGES) <= set(pages) and len(pages) >= 12, pages
    for name in pages:
        page = browser_page.open(site / name)
        assert page.title().endswith("hbmp_bench"), name
        for count in page.locator("[data-count-for]").all():  # the script ran: each filter form counted its rows
            assert " of " in count.inner_text(), name
        if name in MAIN_PAGES:
            page.screenshot(path=str(screenshots / name.replace(".html", ".png")))
    assert not browser_page.errors, browser_page.errors
    assert all((screenshots / n.replace(".html", ".png")).stat().st_size > 10_000 for n in MAIN_PAGES)


def test_every_link_and_image_resolves(site, browser_page):
    checked = 0
    for html_file in sorted(site.glob("*.html")):
        page = browser_page.open(html_file)
        links = page.eval_on_selector_all("a[href]", "els => els.map(a => a.getAttribute('href'))")
        for href in links:
            assert "://" not in href and not href.startswith("/"), f"{html_file.name}: {href} leaves the site"
            target, _, fragment = href.partition("#")
            path = site / target if target else html_file
            assert path.is_file(), f"{html_file.name} links to missing {href}"
            if fragment:
                assert f'id="{fragment}"' in path.read_text(encoding="utf-8"), f"{html_file.name}: no #{fragment}"
            checked += 1
        images = page.eval_on_selector_all(
            "img", "els => els.map(i => [i.getAttribute('src'), i.complete && i.naturalWidth > 0])")
        for src, loaded in images:
            assert loaded, f"{html_file.name}: image {src} did not load"
            checked += 1
    assert checked > 200, checked
    assert not browser_page.errors, browser_page.errors
    folders = board_folders()
    for raw in site.glob("raw/*/*"):  # the raw files are the committed ones, byte for byte
        assert raw.read_bytes() == (folders[raw.parent.name] / raw.name).read_bytes(), raw


def test_sorting_orders_the_rows(site, browser_page):
    page = browser_page.open(site / "board-hbmp.html")
    header = page.locator("#entries thead th", has_text="success %").first
    files = entries("hbmp")
    expected = [one(v) for v in sorted(d["summary"]["success_pct"] for d in files.values())]
    header.click()
    shown = [r["cells"]["summary.success_pct"] for r in rows(page, "entries")]
    assert shown == expected and header.get_attribute("aria-sort") == "ascending"
    header.click()
    shown = [r["cells"]["summary.success_pct"] for r in rows(page, "entries")]
    assert shown == expected[::-1] and header.get_attribute("aria-sort") == "descending"
    page.locator("#entries thead th", has_text="agent").first.click()  # a text column sorts as text
    assert [r["cells"]["agent"] for r in rows(page, "entries")] == sorted(d["agent"] for d in files.values())
    km = page.locator("#breakdown thead th", has_text="km driven").first
    km.click()
    driven = [float(r["cells"]["km_driven"]) for r in rows(page, "breakdown")]
    assert driven == sorted(driven) and len(driven) == sum(len(covered(d)) for d in files.values())
    assert not browser_page.errors, browser_page.errors


def test_filters_keep_the_rows_they_name(site, browser_page):
    page = browser_page.open(site / "board-hbmp.html")
    files = entries("hbmp")
    form = "form[data-for=entries]"
    page.select_option(f"{form} select[name=fidelity]", "event")
    assert {r["attrs"]["file"] for r in rows(page, "entries")} == {n for n, d in files.items() if d["fidelity"] == "event"}
    page.select_option(f"{form} select[name=fidelity]", "")
    page.select_option(f"{form} select[name=privileged]", "no")
    shown = {r["attrs"]["file"] for r in rows(page, "entries")}
    assert shown == {n for n, d in files.items() if not d["privileged"]} and shown
    assert page.inner_text("[data-count-for=entries]") == f"{len(shown)} of {len(files)} rows"
    page.fill(f"{form} input[name=q]", "hbmp-s")
    assert [r["cells"]["agent"] for r in rows(page, "entries")] == ["hbmp-s"]

    breakdown = "form[data-for=breakdown]"
    page.select_option(f"{breakdown} select[name=town]", "Town03")
    page.select_option(f"{breakdown} select[name=task]", "NavigationDynamic")
    shown = rows(page, "breakdown")
    assert len(shown) == sum(("Town03", "NavigationDynamic") in covered(d) for d in files.values())
    assert all(r["cells"]["town"] == "Town03" and r["cells"]["task"] == "Nav. dynamic" for r in shown)
    page.select_option(f"{breakdown} select[name=task]", "")
    assert len(rows(page, "breakdown")) == sum(sum(t == "Town03" for t, _ in covered(d)) for d in files.values())

    page = browser_page.open(site / "board-carla-hbmp.html")  # subsets: a town filter keeps the entries covering it
    page.select_option("form[data-for=entries] select[name=town]", "CARLA_Town02")
    assert len(rows(page, "entries")) == len(entries("carla-hbmp"))
    assert not browser_page.errors, browser_page.errors


def _infractions_per_100km(doc: dict) -> float:
    scored = [e for e in doc["episodes"] if e["end_reason"] not in ("sim_error", "decision_cap")]
    km = sum(e["distance_m"] for e in scored) / 1000.0
    events = sum(e[k] for e in scored for k in ("collision_vehicle", "collision_pedestrian", "collision_other",
                                                  "wrong_lane", "off_road", "red_light"))
    return 100.0 * events / km if km else 0.0


def test_numbers_on_the_board_pages_are_the_results_files(site, browser_page):
    checked = 0
    for slug in board_folders():
        files = entries(slug)
        page = browser_page.open(site / f"board-{slug}.html")
        shown = rows(page, "entries")
        assert {r["attrs"]["file"] for r in shown} == set(files), slug
        for r in shown:
            doc, cells = files[r["attrs"]["file"]], r["cells"]
            s, prov = doc["summary"], doc["provenance"]
            assert cells["agent"] == doc["agent"] and cells["fidelity"] == doc["fidelity"]
            assert cells["summary.success_pct"] == one(s["success_pct"])
            assert cells["summary.mean_driving_score"] == one(s["mean_driving_score"])
            assert cells["summary.mean_route_completion"] == one(100 * s["mean_route_completion"])
            assert cells["summary.km_per_infraction"] == ("" if s["km_per_infraction"] is None
                                                          else one(s["km_per_infraction"], 2))
            assert cells["infractions_per_100km"] == one(_infractions_per_100km(doc), 2)
            assert int(cells["summary.episodes"]) == s["episodes"] == len(doc["episodes"])
            assert int(cells["summary.timeouts"]) == s["timeouts"]
            assert cells["provenance.git_commit"] == prov["git_commit"][:10]
            for task, value in doc["aggregates"]["success_pct_by_task"].items():
                assert cells[f"aggregates.success_pct_by_task.{task}"] == one(value)
            checked += 1
        matrix = {(r["attrs"]["file"], r["cells"]["town"], r["cells"]["task"]): r["cells"] for r in rows(page, "breakdown")}
        for name, doc in files.items():
            for row in doc["aggregates"]["success"]:
                for town, value in row.items():
                    if town != "task" and value is not None:  # None: no episode of the task there (a scenario
                        cells = matrix[(name, town, row["task"])]  # type its town cannot host)
                        assert cells["success_pct"] == one(value), (slug, name, town, row["task"])
                        episodes = [e for e in doc["episodes"] if e["town"] == town
                                    and TASK_LABELS[e["task"]] == row["task"]]
                        assert int(cells["episodes"]) == len(episodes)
                        ends = [e["end_reason"] for e in episodes]  # an outcome is what ended the episode
                        assert int(cells["timeout"]) == ends.count("timeout")
                        assert int(cells["collision"]) == ends.count("collision")
                        assert int(cells["red_light"]) == sum(e["end_reason"] == "violation" and e["red_light"] > 0
                                                              and e["wrong_lane"] + e["off_road"] == 0 for e in episodes)
                        assert cells["km_driven"] == one(sum(e["distance_m"] for e in episodes) / 1000, 2)
        provenance = {r["attrs"]["file"]: r["cells"] for r in rows(page, "provenance")}
        for name, doc in files.items():
            prov = doc["provenance"]
            assert provenance[name]["provenance.code_fingerprint"] == (prov.get("code_fingerprint") or "")
            assert provenance[name]["provenance.agent_fingerprint"] == (prov.get("agent_fingerprint") or "–")
            assert provenance[name]["provenance.machine.cpu"] == prov["machine"]["cpu"]
        assert rows(page, "paired") if len(files) > 1 else True
    assert checked >= 30, checked
    assert not browser_page.errors, browser_page.errors


def test_paired_comparisons_are_the_reports(site, browser_page):
    from hbmp_bench.metrics.report import build_report

    paired = build_report([BOARDS / "hbmp"])["paired"]
    page = browser_page.open(site / "board-hbmp.html")
    shown = {(r["cells"]["first"], r["cells"]["second"]): r["cells"] for r in rows(page, "paired")}
    assert len(shown) == len(paired) >= 15
    for (first, second), r in paired.iterrows():
        cells = shown[(first, second)]
        assert int(cells["only_first"]) == r["only_first"] and int(cells["only_second"]) == r["only_second"]
        assert math.isclose(float(cells["p_mcnemar"]), r["p_mcnemar"], rel_tol=1e-3)
    hbmp_il = shown[("hbmp [continuous]", "il [continuous]")]  # the README's headline: 18 episodes only hbmp finished, 5 only il, p = 0.011
    assert (hbmp_il["only_first"], hbmp_il["only_second"], hbmp_il["p_mcnemar"]) == ("18", "5", "0.0106")


def test_paper_page_sets_the_paper_against_the_boards(site, browser_page):
    page = browser_page.open(site / "paper.html")
    hbmp = entries("hbmp")["hbmp.continuous.json"]
    corl = entries("corl2017")["hbmp.continuous.json"]
    matrix = {row["task"]: row for row in hbmp["aggregates"]["success"]}
    corl_matrix = {row["task"]: row for row in corl["aggregates"]["success"]}
    table_i = rows(page, "table-i")
    assert len(table_i) == 8
    paper = {"Town01": [100, 100, 100, 95], "Town02": [100, 100, 100, 88]}
    for r in table_i:
        town, label = r["cells"]["town"], r["cells"]["task"]
        assert r["cells"]["paper"] == one(paper[town][list(TASK_LABELS.values()).index(label)])
        assert r["cells"]["hbmp"] == one(matrix[label][town])
        assert r["cells"]["corl2017"] == one(corl_matrix[label][town])
    town15 = rows(page, "town15")
    assert len(town15) == 10
    for r in town15:
        value = matrix[r["cells"]["task"]][r["cells"]["town"]]
        assert r["cells"]["hbmp"] == one(value) and r["cells"]["verdict"] == ("met" if value > 85 else "not met")
    text = (ROOT / "docs" / "paper-reproduction.md").read_text(encoding="utf-8")
    first_table = text[text.index("\n|"):].split("\n\n", 1)[0].strip().splitlines()
    claims = rows(page, "claims")
    assert len(claims) == len(first_table) - 2 >= 7  # the header and its rule are the table's head
    assert claims[0]["texts"][0] == first_table[2].split("|")[1].strip()
    assert not browser_page.errors, browser_page.errors


def test_agent_pages_show_curves_entries_and_replayable_failures(site, browser_page):
    parser = build_parser()
    folders = board_folders()
    for agent in ("hbmp", "il", "hbmp-s", "flat"):
        page = browser_page.open(site / f"agent-{agent}.html")
        curves = page.eval_on_selector_all("img[src^='img/']", "els => els.map(i => i.naturalWidth)")
        assert curves and all(w > 300 for w in curves), agent
        shown = rows(page, "agent-entries")
        expected = {(slug, name) for slug in folders for name, doc in entries(slug).items() if doc["agent"] == agent}
        assert {(r["attrs"]["board"], r["attrs"]["file"]) for r in shown} == expected
        for r in shown:
            doc = entries(r["attrs"]["board"])[r["attrs"]["file"]]
            failed = [e for e in doc["episodes"] if not e["success"]]
            assert int(r["cells"]["failures"]) == len(failed)
        for r in rows(page, "failures"):
            command = shlex.split(r["texts"][-1].splitlines()[0])
            args = parser.parse_args(command[1:])
            assert args.command == "record" and args.agent == agent and args.episode == int(r["cells"]["episode"])
            doc = next(d for slug in folders for d in entries(slug).values()
                       if d["agent"] == agent and d["suite"] == args.suite and d["fidelity"] == args.fidelity
                       and r["attrs"]["board"] in (slug,))
            # the episode's row; a scene suite's episode has one per vehicle, and the row is a failed vehicle's
            matching = [e for e in doc["episodes"] if e["town"] == r["cells"]["town"]
                        and e["episode"] == args.episode and TASK_LABELS[e["task"]] == r["cells"]["task"]]
            assert any(not e["success"] and int(r["cells"]["seed"]) == e["seed"] for e in matching)
    assert not browser_page.errors, browser_page.errors


@pytest.mark.parametrize("name", MAIN_PAGES)
def test_page_weight_is_small(site, name):
    """A page and everything it loads (stylesheet, script, images) stays under 20 MB."""
    import re

    text = (site / name).read_text(encoding="utf-8")
    loaded = {m for m in re.findall(r'(?:src|href)="([^"#]+)"', text) if not m.endswith(".html")
              and not m.startswith("raw/")}
    weight = len(text.encode()) + sum((site / m).stat().st_size for m in loaded)
    assert weight < 20e6, (name, weight)


def test_index_names_each_boards_best_entries(site, browser_page):
    page = browser_page.open(site / "index.html")
    shown = {r["attrs"]["board"]: r["cells"] for r in rows(page, "boards")}
    assert set(shown) == set(board_folders())
    for slug, cells in shown.items():
        complete = [d for d in entries(slug).values() if d["complete"]]
        assert int(cells["entries"]) == len(entries(slug)) and int(cells["complete"]) == len(complete)
        fair = [d for d in complete if not d["privileged"]]
        if fair:
            best = max(fair, key=lambda d: (d["summary"]["success_pct"], d["summary"]["mean_driving_score"]))
            assert cells["best_unprivileged"] == f"{best['agent']} ({best['fidelity']})"
            assert cells["best_unprivileged_success_pct"] == one(best["summary"]["success_pct"])
        else:
            assert cells["best_unprivileged"] == "–"
    assert shown["hbmp"]["best_unprivileged"] == "hbmp (continuous)"
