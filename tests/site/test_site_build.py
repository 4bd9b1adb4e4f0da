"""``hbmp-bench site``: builds fast from the committed boards alone, and refuses bad input with a clear error."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from hbmp_bench.cli import main
from hbmp_bench.errors import UserError
from hbmp_bench.site.build import MARKER, build_site

ROOT = Path(__file__).resolve().parents[2]
BOARDS = ROOT / "leaderboards"


def test_site_builds_in_under_two_minutes_with_every_board_and_agent(built_site):
    site, seconds = built_site
    assert seconds < 120, seconds
    boards = sorted(p for p in BOARDS.rglob("*.json") if "archive" not in p.parts and "runs" not in p.parts)
    agents = {json.loads(p.read_text(encoding="utf-8"))["agent"] for p in boards}
    pages = {p.name for p in site.glob("*.html")}
    assert {f"agent-{a}.html" for a in agents} <= pages
    assert {"board-hbmp.html", "board-corl2017.html", "board-nocrash-dense.html", "board-carla-hbmp.html",
            "index.html", "paper.html"} <= pages
    assert len(list(site.glob("raw/*/*.json"))) == len(boards)
    assert (site / MARKER).is_file()


def test_a_rebuild_replaces_an_earlier_site_but_never_another_folder(tmp_path, capsys):
    small = tmp_path / "boards"
    shutil.copytree(BOARDS / "nocrash-empty", small / "nocrash-empty", ignore=shutil.ignore_patterns("archive"))
    out = tmp_path / "site"
    assert main(["site", "--out", str(out), "--boards", str(small)]) == 0
    assert "wrote" in capsys.readouterr().out
    (out / "stale.html").write_text("left from before")
    build_site(out, small)
    assert not (out / "stale.html").exists() and (out / "board-nocrash-empty.html").is_file()

    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("keep me")
    assert main(["site", "--out", str(other), "--boards", str(small)]) == 2
    assert "is not empty and holds no site built by hbmp-bench site" in capsys.readouterr().err
    assert (other / "mine.txt").read_text() == "keep me"
    assert main(["site", "--out", str(small / "site"), "--boards", str(small)]) == 2
    assert "lies in the boards' folder" in capsys.readouterr().err


def test_bad_boards_are_refused_by_name(tmp_path, capsys):
    assert main(["site", "--out", str(tmp_path / "a"), "--boards", str(tmp_path / "missing")]) == 2
    assert "no leaderboard folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["site", "--out", str(tmp_path / "b"), "--boards", str(tmp_path / "empty")]) == 2
    assert "holds no board" in capsys.readouterr().err
    odd = tmp_path / "odd" / "not-a-suite"
    odd.mkdir(parents=True)
    shutil.copy(BOARDS / "nocrash-empty" / "expert.continuous.json", odd)
    with pytest.raises(UserError, match="'not-a-suite' is no suite; valid: .*corl2017"):
        build_site(tmp_path / "c", tmp_path / "odd")
    assert not (tmp_path / "c").exists()


def test_a_results_file_whose_figures_were_edited_is_never_shown(tmp_path):
    """The site reads boards through the checks ``leaderboard render`` makes: an entry whose success %
    does not follow from its episodes is refused, and nothing is written."""
    boards = tmp_path / "boards"
    shutil.copytree(BOARDS / "nocrash-empty", boards / "nocrash-empty", ignore=shutil.ignore_patterns("archive"))
    path = boards / "nocrash-empty" / "hbmp-s.continuous.json"
    doc = json.loads(path.read_text(encoding="utf-8"))
    doc["summary"]["success_pct"] = 100.0
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ValueError, match="success"):
        build_site(tmp_path / "site", boards)
    assert not (tmp_path / "site").exists()


def test_negative_gifs_are_refused(tmp_path):
    with pytest.raises(UserError, match="--gifs must be >= 0"):
        build_site(tmp_path / "site", BOARDS, gifs=-1)


@pytest.mark.slow
def test_gifs_replay_the_entrys_shortest_failure(tmp_path):
    """``--gifs 1``: the agent page shows a GIF of its shortest failed episode, recorded by ``record``'s
    function from the episode's seed, and says the replay ended as the results file recorded."""
    boards = tmp_path / "boards" / "hbmp"
    boards.mkdir(parents=True)
    shutil.copy(BOARDS / "hbmp" / "hbmp.continuous.json", boards)
    doc = json.loads((boards / "hbmp.continuous.json").read_text(encoding="utf-8"))
    shortest = min((e for e in doc["episodes"] if not e["success"]), key=lambda e: e["duration_s"])
    site = tmp_path / "site"
    assert main(["site", "--out", str(site), "--boards", str(tmp_path / "boards"), "--gifs", "1"]) == 0
    gifs = list((site / "img").glob("*.gif"))
    assert [g.name for g in gifs] == [f"hbmp-hbmp-continuous-{shortest['town']}-{shortest['task']}-"
                                      f"{shortest['episode']}.gif"]
    assert 10_000 < gifs[0].stat().st_size < 2_000_000
    page = (site / "agent-hbmp.html").read_text(encoding="utf-8")
    assert f'src="img/{gifs[0].name}"' in page
    assert f"replayed: {shortest['end_reason']} at {shortest['duration_s']:.1f} s, as the entry recorded" in page
