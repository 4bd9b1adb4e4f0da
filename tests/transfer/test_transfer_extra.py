"""highway-env is an optional extra: without it the transfer envs say which extra to install."""

import subprocess
import sys


def test_missing_highway_env_names_the_extra():
    code = ("import sys; sys.modules['highway_env'] = None\n"  # as if highway-env were not installed
            "import gymnasium as gym, hbmp_bench\n"
            "try:\n"
            "    gym.make('hbmp_bench/HighwayTransfer-highway-v0')\n"
            "except ModuleNotFoundError as exc:\n"
            "    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "pip install 'hbmp-bench[highway-env]'" in out


def test_sumo_envs_import_without_highway_env():
    code = ("import sys; sys.modules['highway_env'] = None\n"
            "import hbmp_bench.cli, hbmp_bench.envs, hbmp_bench.evaluation.commands, hbmp_bench.transfer\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "ok"
