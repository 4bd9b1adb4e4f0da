"""The one ``module:Attr`` resolver: what it finds and how it fails."""

import pytest

from hbmp_bench.errors import UserError
from hbmp_bench.plugins import resolve


def test_resolves_an_attribute():
    from hbmp_bench.envs.control_env import ControlEnv

    assert resolve("hbmp_bench.envs.control_env:ControlEnv", "env factory") is ControlEnv


@pytest.mark.parametrize("spec", ["no_colon", ":Attr", "module:"])
def test_malformed_spec(spec):
    with pytest.raises(UserError, match="want 'module:Attr'"):
        resolve(spec, "agent")


def test_missing_module_and_attribute():
    with pytest.raises(UserError, match="cannot load agent 'no_such_module_xyz:A'") as info:
        resolve("no_such_module_xyz:A", "agent")
    assert isinstance(info.value.__cause__, ImportError)
    with pytest.raises(UserError, match="has no attribute 'Nope'") as info:
        resolve("hbmp_bench.errors:Nope", "agent")
    assert isinstance(info.value.__cause__, AttributeError)


def test_a_module_that_raises_names_where(tmp_path, monkeypatch):
    (tmp_path / "broken_plugin_mod.py").write_text("x = 1\nraise RuntimeError('boom')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(UserError, match=r"importing broken_plugin_mod raised RuntimeError: boom \(at broken_plugin_mod.py:2\)"):
        resolve("broken_plugin_mod:A", "env factory")
