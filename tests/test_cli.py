import json

from hbmp_bench.cli import main


def test_list_json(capsys):
    assert main(["list", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "hbmp_bench/Town01-Navigation-v0" in out["env_ids"]
    assert out["towns"] == ["Town01", "Town02", "Town03", "Town04", "Town05"]
    assert {"expert", "random", "keep"} <= set(out["agents"])
    assert {"corl2017", "hbmp", "nocrash-regular"} <= set(out["suites"])
    assert out["tasks"] == ["Straight", "OneTurn", "Navigation", "NavigationDynamic"]


def test_run_json(capsys):
    assert main(["run", "--env", "hbmp_bench/Town02-Straight-v0", "--agent", "expert", "--episodes", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("episodes", "success_rate", "collisions", "wrong_lane", "red_light", "timeouts"):
        assert key in out
    assert out["episodes"] == 2 and out["success_rate"] == 1.0


def test_bad_names_exit_2_with_valid_names(capsys):
    assert main(["run", "--env", "hbmp_bench/Town09-Straight-v0"]) == 2
    assert "Town01-Straight-v0" in capsys.readouterr().err
    assert main(["run", "--agent", "expret"]) == 2
    assert "expert" in capsys.readouterr().err
    assert main(["evaluate", "--suite", "corl2016"]) == 2
    assert "corl2017" in capsys.readouterr().err
    assert main(["evaluate", "--towns", "Town9"]) == 2
    assert "Town01" in capsys.readouterr().err


def test_maps_stats_json(capsys):
    assert main(["maps", "stats", "Town02", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["Town02"]
    for key in ("directed_road_length_m", "lanes_per_edge", "lanes_per_edge_mean", "tls_junctions",
                "priority_junctions", "roundabouts", "extent_m", "has_sidewalks"):
        assert key in out


def test_maps_stats_compares_maps_and_net_files(tmp_path, capsys):
    from hbmp_bench.maps import map_stats, net_path

    net = str(net_path("Town02"))
    assert main(["maps", "stats", "Town02", net, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out[net] == map_stats("Town02")
    assert main(["maps", "stats", "Town02", net]) == 0
    header, *rows = capsys.readouterr().out.splitlines()
    assert header.split() == ["Town02", net] and any(r.split()[0] == "lanes_per_edge_mean" for r in rows)
    assert main(["maps", "stats", str(tmp_path / "nowhere.net.xml")]) == 2
    assert "nowhere.net.xml" in capsys.readouterr().err


# ---------------------------------------------------------------- errors a user meets: one line, no traceback

import datetime  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import textwrap  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

from hbmp_bench import cli  # noqa: E402


def _one_line_error(capsys, argv, code=2, prefix="hbmp-bench: error: "):
    """Run the CLI; it must exit with ``code`` and print exactly one stderr line; returns that line."""
    assert main(argv) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(prefix), err
    return lines[0]


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    """Write a module into an importable folder: ``plugins("name", source)``."""
    monkeypatch.syspath_prepend(str(tmp_path))

    def write(name, source):
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(source))
        monkeypatch.delitem(sys.modules, name, raising=False)
        return name

    return write


def _run(agent):
    return ["run", "--env", "hbmp_bench/Town02-Straight-v0", "--agent", agent, "--episodes", "1"]


def test_refused_checkpoint_is_one_line_and_never_suggests_unsafe_loading(tmp_path, capsys):
    path = tmp_path / "pickled.pt"
    torch.save({"format": "hbmp_bench.checkpoint.v1", "saved": datetime.date(2026, 1, 1)}, path)
    line = _one_line_error(capsys, _run(str(path)))
    assert "refused" in line and "datetime.date" in line and str(path) in line
    assert "weights_only=False" not in line and "trust" not in line


@pytest.mark.parametrize("content", [b"this is not a checkpoint\n", b"", b"\x80\x02}q\x00", "half"])
def test_unreadable_checkpoint_is_one_line(tmp_path, capsys, content):
    path = tmp_path / "policy.pt"
    if content == "half":  # a real checkpoint cut in the middle, as an interrupted copy leaves it
        torch.save({"weights": torch.zeros(1000)}, path)
        data = path.read_bytes()
        content = data[: len(data) // 2]
    path.write_bytes(content)
    line = _one_line_error(capsys, _run(str(path)))
    assert f"cannot read checkpoint {str(path)!r}: the file is truncated, damaged or not a torch checkpoint" in line


def test_missing_checkpoint_is_one_line(tmp_path, capsys):
    line = _one_line_error(capsys, _run(str(tmp_path / "nowhere.pt")))
    assert "no checkpoint file" in line and "nowhere.pt" in line


def test_plugin_agent_failures_are_one_line(plugins, capsys):
    plugins("raising_agent", """
        class Agent:
            name = "raising"

            def __init__(self):
                raise RuntimeError("cuda device 3 not found")
    """)
    line = _one_line_error(capsys, _run("raising_agent:Agent"))
    assert "cannot load agent 'raising_agent:Agent'" in line
    assert "RuntimeError: cuda device 3 not found" in line and "raising_agent.py:6" in line

    plugins("failing_import", "import numpy\nraise OSError('models folder is missing')\n")
    line = _one_line_error(capsys, _run("failing_import:Agent"))
    assert "importing failing_import raised OSError: models folder is missing" in line
    assert "failing_import.py:2" in line

    plugins("bad_syntax", "def act(:\n")
    assert "SyntaxError" in _one_line_error(capsys, _run("bad_syntax:Agent"))

    plugins("needs_a_package", "import package_that_is_not_installed\n")
    assert "No module named 'package_that_is_not_installed'" in _one_line_error(capsys, _run("needs_a_package:A"))

    plugins("no_class", "X = 1\n")
    assert "has no attribute 'Agent'" in _one_line_error(capsys, _run("no_class:Agent"))

    plugins("not_an_agent", "class Agent:\n    pass\n")
    assert "does not implement the Agent protocol" in _one_line_error(capsys, _run("not_an_agent:Agent"))


def test_plugin_error_from_the_installed_command_has_no_traceback(plugins, tmp_path):
    """The console script itself, in a fresh process: one line on stderr, exit 2."""
    plugins("raising_agent_cli", """
        class Agent:
            def __init__(self):
                raise KeyError("weights")
    """)
    env = {**__import__("os").environ, "PYTHONPATH": str(tmp_path)}
    done = subprocess.run([sys.executable, "-m", "hbmp_bench.cli", *_run("raising_agent_cli:Agent")], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        "hbmp-bench: error: cannot load agent 'raising_agent_cli:Agent': Agent() raised KeyError: 'weights' "
        "(at raising_agent_cli.py:4)"]
    assert done.stdout == ""


def test_workers_0_creates_nothing(tmp_path, capsys):
    out = tmp_path / "runs"
    line = _one_line_error(capsys, ["evaluate", "--agent", "expert", "--workers", "0", "--out", str(out)])
    assert "workers must be >= 1" in line and "got 0" in line
    assert not out.exists()
    line = _one_line_error(capsys, ["train", "il", "--workers", "0", "--out", str(out)])
    assert "workers must be >= 1, got 0" in line
    assert not out.exists()


def test_unknown_density_is_one_line_before_any_worker_starts(tmp_path, capsys):
    line = _one_line_error(capsys, ["train", "il", "--scenario", "hbmp_bench/Town02-Straight-v0", "--density", "x",
                                    "--episodes", "1", "--workers", "1", "--out", str(tmp_path / "il")])
    assert line == "hbmp-bench: error: unknown density 'x'; valid: corl, dense, empty, regular"


def test_ctrl_c_exits_130_with_one_line(monkeypatch, capsys):
    import hbmp_bench.evaluation as evaluation

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(evaluation, "run_jobs", interrupted)
    assert _one_line_error(capsys, _run("expert"), code=130, prefix="") == "hbmp-bench: interrupted"


def test_bugs_keep_their_traceback(monkeypatch):
    """Only user errors become one line: an exception from a bug propagates (its traceback is printed)."""
    monkeypatch.setattr(cli, "_cmd_list", lambda args: np.stack([np.zeros(2), np.zeros(3)]))
    with pytest.raises(ValueError, match="same shape"):  # raised inside numpy: a bug here, not the user's input
        main(["list"])
    monkeypatch.setattr(cli, "_cmd_list", lambda args: {}["missing"])
    with pytest.raises(KeyError):
        main(["list"])


def test_is_user_error():
    from hbmp_bench.errors import ConfigError, UnknownNameError, UserError

    def raised(fn):
        try:
            fn()
        except Exception as exc:  # noqa: BLE001
            return exc
        raise AssertionError("did not raise")

    assert cli.is_user_error(UserError("bad option"))
    assert cli.is_user_error(UnknownNameError("town", "Town9", ["Town01"]))
    assert cli.is_user_error(raised(lambda: cli._parse_env_id("hbmp_bench/Town9-Straight-v0")))
    assert cli.is_user_error(raised(lambda: json.loads("{not json")))  # a user's file, parsed by the standard library
    assert cli.is_user_error(raised(lambda: open("/nonexistent/records.jsonl")))
    assert not cli.is_user_error(raised(lambda: np.zeros(2).reshape(3)))  # a failing call, not a raise statement
    assert not cli.is_user_error(raised(lambda: np.stack([np.zeros(2), np.zeros(3)])))  # raised inside numpy
    assert not cli.is_user_error(RuntimeError("bug"))

    def validate():
        raise ConfigError("speed must be >= 0")

    assert cli.is_user_error(raised(validate))  # a configuration check
    assert not cli.is_user_error(ValueError("speed must be >= 0"))  # untyped: a bug, whoever raised it


def test_train_resume_hint_follows_what_the_interrupt_left(tmp_path):
    from hbmp_bench.policies.checkpoints import save_checkpoint
    from hbmp_bench.training.commands import _resume_hint

    args = cli.build_parser().parse_args(["train", "il", "--episodes", "10", "--save-every", "5", "--out",
                                          str(tmp_path)])
    assert _resume_hint(args) == f"no checkpoint was written yet (one every 5 episodes); start over with another " \
                                 f"--out than {tmp_path}"
    checkpoint = tmp_path / "checkpoint.pt"
    for done in (5, 10):
        save_checkpoint(str(checkpoint), {"kind": "il", "progress": {"episodes": done}})
        hint = _resume_hint(args)
        if done == 5:
            assert hint.startswith(f"the last checkpoint is {checkpoint} (5 of 10 episodes); resume with: hbmp-bench "
                                   "train il ")
            assert hint.endswith(f"--out {tmp_path} --resume {checkpoint} --save-every 5")  # the run's cadence
        else:  # interrupted after the last checkpoint, while writing the outputs: nothing to resume
            assert hint == f"all 10 episodes are trained ({checkpoint}); {tmp_path / 'policy.pt'}, the curves or the " \
                           "model card may be missing"


def test_missing_checkpoint_through_evaluate_is_one_line(tmp_path, capsys):
    """The agent is built in its sandboxed process before any episode: its one-line error crosses
    the channel as one line, and nothing is written."""
    out = tmp_path / "runs"
    line = _one_line_error(capsys, ["evaluate", "--suite", "corl2017", "--agent", str(tmp_path / "nowhere.pt"),
                                    "--towns", "Town01", "--tasks", "Straight", "--episodes", "1", "--workers", "1",
                                    "--out", str(out)])
    assert line == f"hbmp-bench: error: agent could not be built: no checkpoint file '{tmp_path / 'nowhere.pt'}'"
    assert not out.exists()


def test_maps_import_force_remove_and_town_options(tmp_path, monkeypatch, capsys):
    import shutil as _shutil

    from hbmp_bench.maps import net_path

    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path / "data"))
    src = tmp_path / "copy.net.xml"
    _shutil.copyfile(net_path("Town02"), src)
    assert main(["maps", "import", str(src), "--name", "mine", "--like", "Town02"]) == 0
    assert main(["maps", "import", str(src), "--name", "mine"]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["maps", "import", str(src), "--name", "mine", "--force", "--like", "Town02"]) == 0
    capsys.readouterr()
    assert main(["maps", "stats", "mine", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)["mine"]["import"]
    assert info["source"] == "copy.net.xml" and info["like"] == "Town02"
    for command in (["run", "--town", "nowhere"], ["record", "--env", "hbmp_bench/Town01-Straight-v0", "--town",
                                                   "nowhere", "--out", str(tmp_path / "x.gif")],
                    ["evaluate", "--town", "nowhere"]):
        assert main(command) == 2
        assert "mine" in capsys.readouterr().err  # the valid maps are listed, the import among them
    assert main(["run", "--env", "hbmp_bench/Town01-Straight-v0", "--town", "mine", "--episodes", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["town"] == "mine" and out["records"][0]["town"] == "mine" and out["success_rate"] == 1.0
    assert main(["maps", "remove", "mine"]) == 0
    assert main(["maps", "remove", "mine"]) == 2
    assert main(["maps", "remove", "Town01"]) == 2
