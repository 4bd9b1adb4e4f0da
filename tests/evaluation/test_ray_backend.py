"""The Ray backend (a local Ray instance here) gives the same records as the process pool."""

import json

import pytest

from hbmp_bench.cli import main
from hbmp_bench.evaluation import evaluate, records_path
from hbmp_bench.metrics.records import read_records

pytestmark = pytest.mark.slow

ray = pytest.importorskip("ray", reason="the ray extra is not installed (pip install 'hbmp-bench[ray]')")


def test_ray_backend_matches_the_process_pool(tmp_path, capsys):
    args = ["evaluate", "--suite", "corl2017", "--agent", "expert", "--towns", "Town01", "--tasks", "Straight",
            "--episodes", "2", "--fidelity", "event", "--json"]
    assert main([*args, "--backend", "ray", "--workers", "2", "--out", str(tmp_path / "ray")]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["ran"] == 2 and summary["episodes"] == 2
    assert not ray.is_initialized()  # the local instance it started is shut down
    pool = evaluate("corl2017", "expert", towns=["Town01"], tasks=["Straight"], episodes=2, fidelity="event",
                    workers=2, out_dir=tmp_path / "pool", progress=False)
    by_ray = sorted((r.to_dict() for r in read_records(records_path(tmp_path / "ray", "corl2017", "expert"))),
                    key=lambda d: d["episode"])
    assert by_ray == [r.to_dict() for r in pool.records]
    assert all(r.success for r in pool.records)

