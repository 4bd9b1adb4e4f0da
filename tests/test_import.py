"""``import hbmp_bench`` registers every gymnasium id and loads none of the heavy libraries; the command
line's help and listing neither. Checked in fresh interpreters by what is in ``sys.modules`` (the
import time itself is a benchmark figure: ``hbmp-bench bench`` reports ``import_s``)."""

import json
import subprocess
import sys

import pytest

HEAVY = ("libsumo", "sumolib", "numba", "llvmlite", "pandas", "torch", "tensordict", "rsl_rl", "matplotlib",
         "highway_env", "hbmp_bench.sim.sumo", "hbmp_bench.planning.rollout")
"""Modules the package imports where they are used, never at ``import hbmp_bench``."""


def _fresh(code: str) -> dict:
    """Run ``code`` in a fresh interpreter; what it leaves in ``out`` and which HEAVY modules it loaded."""
    script = (f"import json, sys\nout = {{}}\n{code}\n"
              f"print(json.dumps({{'out': out, 'heavy': [m for m in {HEAVY!r} if m in sys.modules]}}))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_import_registers_every_id_without_heavy_modules():
    got = _fresh("import hbmp_bench\n"
                 "import gymnasium as gym\n"
                 "from hbmp_bench.envs import env_ids\n"
                 "from hbmp_bench.transfer import transfer_env_ids\n"
                 "out['expected'] = [*env_ids(), *transfer_env_ids()]\n"
                 "out['registered'] = {i: gym.spec(i).entry_point for i in gym.registry if i.startswith('hbmp_bench/')}")
    assert got["heavy"] == []
    registered = got["out"]["registered"]
    assert sorted(registered) == sorted(got["out"]["expected"])
    assert {"hbmp_bench/Town05-NavigationDynamic-v0", "hbmp_bench/Training-v0",
            "hbmp_bench/HighwayTransfer-highway-v0"} <= set(registered)
    assert set(registered.values()) == {"hbmp_bench.envs.behavior_env:BehaviorEnv",
                                        "hbmp_bench.transfer.env:HighwayTransferEnv"}


@pytest.mark.parametrize("argv", [["--help"], ["list", "--json"]])
def test_cli_help_and_list_load_no_heavy_modules(argv):
    got = _fresh("import contextlib, io\n"
                 "from hbmp_bench.cli import main\n"
                 "with contextlib.redirect_stdout(io.StringIO()) as text:\n"
                 "    try:\n"
                 f"        out['code'] = main({argv!r})\n"
                 "    except SystemExit as exc:\n"
                 "        out['code'] = exc.code\n"
                 "out['text'] = text.getvalue()")
    assert got["heavy"] == []
    assert got["out"]["code"] == 0
    assert "bench" in got["out"]["text"] if argv == ["--help"] else "expert" in json.loads(got["out"]["text"])["agents"]


def test_lazy_names_resolve_to_their_modules():
    got = _fresh("import hbmp_bench.envs as envs, hbmp_bench.metrics as metrics, hbmp_bench.testing as testing\n"
                 "out['dir'] = sorted(set(envs.__all__) - set(dir(envs)))\n"
                 "out['before'] = [m for m in ('libsumo', 'pandas') if m in sys.modules]\n"
                 "from hbmp_bench.envs import BehaviorEnv, ObservationConfig\n"
                 "from hbmp_bench.envs.behavior_env import BehaviorEnv as defined\n"
                 "from hbmp_bench.metrics import summarize\n"
                 "from hbmp_bench.metrics.summary import summarize as summary_defined\n"
                 "from hbmp_bench.testing import smoke_run\n"
                 "from hbmp_bench.testing.smoke import smoke_run as smoke_defined\n"
                 "out['same'] = [BehaviorEnv is defined, summarize is summary_defined, smoke_run is smoke_defined,\n"
                 "               envs.ObservationConfig is ObservationConfig]\n"
                 "out['after'] = [m for m in ('libsumo', 'pandas') if m in sys.modules]\n"
                 "try:\n"
                 "    envs.NoSuchName\n"
                 "except AttributeError as exc:\n"
                 "    out['missing'] = str(exc)")
    assert got["out"]["dir"] == []
    assert got["out"]["before"] == [] and got["out"]["after"] == ["libsumo", "pandas"]
    assert got["out"]["same"] == [True, True, True, True]
    assert "NoSuchName" in got["out"]["missing"]
