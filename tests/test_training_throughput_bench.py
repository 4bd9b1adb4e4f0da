"""The training-throughput benchmark's setups: ``LEARNERSxWORKERS[+overlap][@REV]``, where ``@REV`` runs the code of
an older commit (the baseline a throughput target was set against) from an extracted copy, not this checkout."""

import argparse
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    spec = importlib.util.spec_from_file_location("training_throughput", ROOT / "benchmarks" / "training_throughput.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_setups_name_learners_workers_the_overlap_and_a_revision():
    bench = _bench()
    assert bench.parse_setup("1x2") == (1, 2, False, None)
    assert bench.parse_setup("8x2+overlap") == (8, 2, True, None)
    assert bench.parse_setup("1x2@10727f3") == (1, 2, False, "10727f3")
    assert bench.parse_setup("8x2+overlap@HEAD~1") == (8, 2, True, "HEAD~1")
    for bad in ("8", "8x", "x2", "8x2+", "8x2@", "8x2@-rf", "8x2 @HEAD"):
        with pytest.raises(argparse.ArgumentTypeError, match="LEARNERSxWORKERS"):
            bench.parse_setup(bad)


@pytest.mark.skipif(not (ROOT / ".git").exists(), reason="needs the git history")
def test_a_revision_runs_its_own_code_not_the_checkout(tmp_path):
    bench = _bench()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    source = bench.code_of(head, str(tmp_path))
    assert bench.code_of(head, str(tmp_path)) == source  # extracted once
    env = dict(os.environ, PYTHONPATH=source)
    imported = subprocess.run([sys.executable, "-c", "import hbmp_bench; print(hbmp_bench.__file__)"], env=env,
                              cwd=tmp_path, capture_output=True, text=True, check=True).stdout.strip()
    assert Path(imported).resolve() == (Path(source) / "hbmp_bench" / "__init__.py").resolve()
    with pytest.raises(SystemExit, match="git archive failed"):
        bench.code_of("no-such-revision", str(tmp_path))
