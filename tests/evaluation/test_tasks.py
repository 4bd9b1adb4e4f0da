import pytest

from hbmp_bench.errors import UnknownNameError
from hbmp_bench.evaluation import RunnerLimits, agent_slug, default_fidelity, suite_tasks
from hbmp_bench.evaluation.agent_process import as_action
from hbmp_bench.scenarios import get_suite


def test_suite_tasks_selection_order_and_keys():
    tasks = suite_tasks("corl2017", "expert", towns=["Town02", "Town01", "Town02"], tasks=["Navigation", "Straight"],
                        episodes=2, fidelity="event")
    assert [(t.town, t.task, t.episode) for t in tasks] == [
        ("Town02", "Straight", 0), ("Town02", "Straight", 1), ("Town02", "Navigation", 0), ("Town02", "Navigation", 1),
        ("Town01", "Straight", 0), ("Town01", "Straight", 1), ("Town01", "Navigation", 0), ("Town01", "Navigation", 1),
    ]
    assert len({t.key for t in tasks}) == len(tasks)
    assert tasks[0].key == ("corl2017", "Town02", "Straight", 0, "expert", "event")


def test_suite_tasks_defaults_cover_the_suite_and_resolve_fidelity():
    suite = get_suite("corl2017")
    tasks = suite_tasks("corl2017", "random")
    assert len(tasks) == len(suite.towns) * len(suite.tasks) * suite.episodes_per_task
    assert {t.fidelity for t in tasks} == {default_fidelity()}
    explicit = suite_tasks("corl2017", "random", towns=["Town01"], tasks=["Straight"], episodes=[3, 1, 3])
    assert [t.episode for t in explicit] == [1, 3]


def test_suite_tasks_rejects_bad_input_naming_valid_choices():
    with pytest.raises(UnknownNameError, match="Town01"):
        suite_tasks("corl2017", "expert", towns=["Town9"])
    with pytest.raises(UnknownNameError, match="Straight"):
        suite_tasks("corl2017", "expert", tasks=["Straigth"])
    with pytest.raises(UnknownNameError, match="corl2017"):
        suite_tasks("corl2016", "expert")
    with pytest.raises(ValueError, match="episode indices"):
        suite_tasks("corl2017", "expert", episodes=[25])
    with pytest.raises(ValueError, match="> 0"):
        suite_tasks("corl2017", "expert", episodes=0)
    with pytest.raises(ValueError, match="event"):
        suite_tasks("corl2017", "expert", fidelity="photorealistic")


def test_agent_slug_and_limits_validation():
    assert agent_slug("my_pkg.agents:MyAgent") == "my_pkg.agents.MyAgent"
    assert agent_slug("checkpoints/hbmp v2.pt") == "checkpoints.hbmp.v2.pt"
    with pytest.raises(ValueError):
        agent_slug(":/:")
    with pytest.raises(ValueError, match="decision_timeout_s"):
        RunnerLimits(decision_timeout_s=0)
    with pytest.raises(ValueError, match="retries"):
        RunnerLimits(retries=-1)
    with pytest.raises(ValueError, match="module:callable"):
        RunnerLimits(env_factory="no_colon")


def test_as_action_accepts_integers_and_control_vectors():
    import numpy as np

    assert as_action(3) == 3 and as_action(np.int64(2)) == 2 and as_action(np.array(4)) == 4
    assert as_action(np.array([0.5, -0.25])) == (0.5, -0.25) and as_action([1, 2]) == (1.0, 2.0)
    for bad in (1.5, "2", True, np.array([[1.0, 2.0]]), np.array([]), None, {"a": 1}):
        with pytest.raises(TypeError, match="integer"):
            as_action(bad)
