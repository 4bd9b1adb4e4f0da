import pytest

from hbmp_bench.agents import AGENTS, Agent, load_agent
from hbmp_bench.errors import UnknownNameError


def test_builtin_agents_implement_the_protocol():
    for name in ("expert", "random", "keep"):
        agent = load_agent(name)
        assert isinstance(agent, Agent) and agent.name == name


def test_plugin_by_module_path():
    agent = load_agent("hbmp_bench.agents.simple:KeepAgent")
    assert agent.act({}, {}) == 4


def test_unknown_agent_lists_valid_names():
    with pytest.raises(UnknownNameError) as err:
        load_agent("expret")
    for name in AGENTS:
        assert name in str(err.value)


def test_bad_plugin_path_is_a_clear_error():
    with pytest.raises(ValueError, match="cannot load agent"):
        load_agent("no_such_module:Agent")


def test_a_plugin_that_raises_while_built_is_a_user_error_keeping_its_cause(tmp_path, monkeypatch):
    from hbmp_bench.errors import UserError

    (tmp_path / "exploding_agent.py").write_text(
        "class Agent:\n    def __init__(self):\n        raise RuntimeError('no weights')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(UserError, match=r"Agent\(\) raised RuntimeError: no weights \(at exploding_agent.py:3\)") as err:
        load_agent("exploding_agent:Agent")
    assert isinstance(err.value.__cause__, RuntimeError)  # Python callers keep the plug-in's traceback
    with pytest.raises(UserError, match="does not implement the Agent protocol"):
        load_agent("builtins:object")
