"""The one episode loop: hooks, caps, and how failures come out (on gymnasium's CartPole)."""

import gymnasium as gym
import pytest

from hbmp_bench.rollout import AgentFailed, EnvFailed, EpisodeHooks, run_episode


class Push:
    """Pushes right, or raises at decision ``fail_at``."""

    name = "push"

    def __init__(self, fail_at=None):
        self.fail_at, self.calls, self.resets = fail_at, 0, 0

    def reset(self, info):
        self.resets += 1

    def act(self, obs, info):
        if self.calls == self.fail_at:
            raise RuntimeError("agent broke")
        self.calls += 1
        return 1


def test_runs_to_the_end_and_calls_the_hooks():
    env, agent, seen = gym.make("CartPole-v1"), Push(), []
    hooks = EpisodeHooks(on_reset=lambda obs, info: seen.append("reset"),
                         on_step=lambda obs, r, term, trunc, info: seen.append("step"))
    run = run_episode(env, agent, seed=0, hooks=hooks)
    assert run.ended and agent.resets == 1 and run.decisions == agent.calls == len(seen) - 1
    assert seen[0] == "reset" and len(run.act_s) == len(run.step_s) == run.decisions
    assert run.stepping_s == pytest.approx(sum(run.step_s))


def test_cap_and_stop_leave_the_episode_running():
    env = gym.make("CartPole-v1")
    assert run_episode(env, Push(), seed=0, max_decisions=3).decisions == 3
    run = run_episode(env, Push(), seed=0, hooks=EpisodeHooks(stop=lambda run: run.decisions >= 2))
    assert not run.ended and run.decisions == 2


def test_failures_name_their_side():
    env = gym.make("CartPole-v1")
    with pytest.raises(AgentFailed, match="agent broke") as info:
        run_episode(env, Push(fail_at=2), seed=0)
    assert info.value.decisions == 2 and isinstance(info.value.__cause__, RuntimeError)

    def reject(action, decisions):
        raise ValueError(f"invalid action {action!r} at decision {decisions}")

    with pytest.raises(AgentFailed, match="invalid action 1 at decision 0"):
        run_episode(env, Push(), seed=0, hooks=EpisodeHooks(check_action=lambda a, k: reject(a, k)))
    with pytest.raises(EnvFailed) as info:
        run_episode(env, Push(), seed=0, hooks=EpisodeHooks(check_action=lambda a, k: 7))  # CartPole asserts
    assert info.value.phase == "step" and info.value.decisions == 0
