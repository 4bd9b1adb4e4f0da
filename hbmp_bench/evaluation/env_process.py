"""The env process of an episode pool slot: it owns the simulation and asks the agent process for actions.

Protocol with the pool (tuples on one duplex pipe; the pool is trusted):
    pool → env  ``("run", (EpisodeTask, env factory, env options))`` followed by the descriptor of a
                fresh agent channel (``multiprocessing.reduction.send_handle``), or ``("stop", None)``;
    env → pool  ``("beat", None)`` once started, then while an episode makes progress or waits
                for the agent (about every 0.5 s), then ``("done", outcome dict)``.

The agent channel is data only from the agent's side (see ``channel``): nothing the agent
process sends is ever unpickled here.

Every episode ends with exactly one ``done``: a finished episode, an ``agent_error`` or a
``sim_error`` (the env raised). ``agent_error`` covers everything the agent does wrong: it
raised, hung past ``decision_timeout_s``, died, closed its channel, stopped reading it, sent a
reply that is malformed, oversized or unsolicited, or an action outside the action space. Such
an episode is a failure (success false, driving score 0) that counts in every table. After a
``sim_error`` the outcome asks the pool to restart the slot, so a broken SUMO never serves the
next episode.
"""

from __future__ import annotations

import dataclasses
import time
import traceback
from multiprocessing import reduction
from multiprocessing.connection import Connection
from typing import Any


from hbmp_bench import rollout
from hbmp_bench.envs.actions import check_action
from hbmp_bench.envs.registration import RECORD_KEY
from hbmp_bench.plugins import resolve
from hbmp_bench.evaluation import channel
from hbmp_bench.evaluation.sandbox import protect_process
from hbmp_bench.evaluation.tasks import (BEHAVIOR_ENV, SCENE_ENV, SCENE_FORMS, EpisodeTask, RunnerLimits,
                                         adopt_environment, vehicle_episode, watch_lifeline)
from hbmp_bench.metrics.records import AGENT_ERROR, DECISION_CAP, SIM_ERROR, EpisodeRecord

BEAT_PERIOD_S = 0.5
"""Least time between two heartbeats sent to the pool [s]."""

WALL_BUDGET = "wall-clock budget"
"""How the error of an episode ended by its wall-clock budget begins (``RunnerLimits.episode_wall_factor``;
its end reason is ``agent_error``: only the agent's answers can stretch an episode that far)."""

EPISODE_IDENTITY = ("episode_key", RECORD_KEY, "episode", "episode_index", "seed", "salt")
"""Info keys that name the episode (or its record, seed or salt): the env process never sends them
to the agent, so an agent cannot look up its episode in the public suite and rebuild it (with
``privileged=True``) in its own process. (The start pose still matches a public episode: only a
salted evaluation makes a rebuilt one differ from the one it drives, see ``salting``.)"""


def agent_view(info: dict) -> dict:
    """``info`` as the agent may see it: without :data:`EPISODE_IDENTITY`, neither at its top nor, in a scene's
    info (``{"vehicles": {vehicle: info}, "ended": {vehicle: record}}``, ``envs.scene_env``), in any vehicle's;
    of a scene's ended vehicles the agent learns each one's ``end_reason`` only (a record names the episode's
    index and seed)."""
    view = {k: v for k, v in info.items() if k not in EPISODE_IDENTITY}
    if isinstance(view.get("vehicles"), dict):
        view["vehicles"] = {vehicle: agent_view(part) if isinstance(part, dict) else part
                            for vehicle, part in view["vehicles"].items()}
        ended = view.get("ended")
        if isinstance(ended, dict):
            view["ended"] = {vehicle: {"end_reason": record.get("end_reason", "")} if isinstance(record, dict) else {}
                             for vehicle, record in ended.items()}
    return view


class AgentFailure(Exception):
    """The agent process raised, timed out, died or broke the channel's protocol; the message says which."""


def build_env(task: EpisodeTask, factory: str | None, env_kwargs: dict | None = None):
    """The env of a task: ``factory(town=, task=, suite=, fidelity=, **env_kwargs)``; None: ``BehaviorEnv``, or
    for a scene (``EpisodeTask.scene``) :data:`~hbmp_bench.evaluation.tasks.SCENE_ENV`, which is also the scene
    form of an agent's env (``tasks.AGENT_ENV_FACTORIES``: the control env's is ``ego_driver="control"``)."""
    kwargs = dict(env_kwargs or {})
    if task.scene and (factory is None or factory in SCENE_FORMS):
        kwargs.update(SCENE_FORMS.get(factory, {}))
        factory = SCENE_ENV
    make = resolve(factory or BEHAVIOR_ENV, "env factory")
    return make(town=task.town, task=task.task, suite=task.suite, fidelity=task.fidelity, **kwargs)


def blank_records(task: EpisodeTask, end_reason: str, error: str) -> tuple[EpisodeRecord, ...]:
    """Failed records, one per vehicle of the task (``EpisodeTask.vehicles``), for an episode that produced no
    data (it never started); each names its vehicle's seed and route length."""
    from hbmp_bench import __version__
    from hbmp_bench.scenarios import suite_episodes

    records = []
    for vehicle in task.vehicles:
        try:
            episode = vehicle_episode(suite_episodes(task.suite, task.town, task.task)[task.episode], vehicle)
            seed, length = episode.seed, episode.route_length_m
        except Exception:  # noqa: BLE001 - the record must be written whatever broke
            seed, length = -1, 0.0
        records.append(EpisodeRecord(
            suite=task.suite, town=task.town, task=task.task, episode=task.episode, seed=seed, agent=task.agent,
            package_version=__version__, fidelity=task.fidelity, success=False, route_completion=0.0,
            collision_vehicle=0, collision_pedestrian=0, collision_other=0, wrong_lane=0, off_road=0, red_light=0,
            timeout=False, duration_s=0.0, distance_m=0.0, route_length_m=length, decisions=0, driving_score=0.0,
            end_reason=end_reason, error=error, vehicle=vehicle,
        ))
    return tuple(records)


def partial_records(env: Any, task: EpisodeTask, end_reason: str, error: str) -> tuple[EpisodeRecord, ...]:
    """The records of a started episode cut short: what the world measured so far (route completion,
    infractions, distance), never a success; an ``agent_error`` scores 0. In a scene every vehicle's record is
    cut so, those that had reached their goal too: one policy drove them all, and it broke the scene."""
    unwrapped = getattr(env, "unwrapped", env)
    if task.scene:
        found = getattr(unwrapped, "records", lambda: None)()
        records = None if found is None else [r if isinstance(r, EpisodeRecord) else EpisodeRecord(**r) for r in found]
    else:
        record_of = getattr(unwrapped, "record", None)
        records = None if record_of is None else [record_of(task.agent)]
    if not records or any(r is None for r in records):
        return blank_records(task, end_reason, error)
    out = []
    for record in records:
        score = 0.0 if end_reason == AGENT_ERROR else record.driving_score
        out.append(dataclasses.replace(record, agent=task.agent, success=False, timeout=False, driving_score=score,
                                       end_reason=end_reason, error=error))
    return scene_checked(task, out)


def scene_checked(task: EpisodeTask, records: list[EpisodeRecord]) -> tuple[EpisodeRecord, ...]:
    """``records`` in the task's vehicle order, if they are exactly one per vehicle of the task
    (``EpisodeTask.vehicles``), each of its episode; else ``RuntimeError`` (the env broke its contract)."""
    by_vehicle = {r.vehicle: r for r in records}
    if len(by_vehicle) != len(records) or set(by_vehicle) != set(task.vehicles):
        raise RuntimeError(f"the env recorded vehicles {sorted(r.vehicle for r in records)}, the episode has "
                           f"{list(task.vehicles)}")
    wrong = [r.vehicle for r in records
             if (r.suite, r.town, r.task, r.episode, r.fidelity) != (task.suite, task.town, task.task, task.episode,
                                                                     task.fidelity)]
    if wrong:
        raise RuntimeError(f"the env's records of {wrong} are of another episode than {task.label}")
    return tuple(by_vehicle[v] for v in task.vehicles)


def wall_budget_s(task: EpisodeTask, limits: RunnerLimits) -> float:
    """The episode's wall-clock budget [s]: ``limits.episode_wall_factor`` × its timeout
    (``Episode.timeout_s``, simulated seconds) + ``limits.episode_wall_extra_s``."""
    from hbmp_bench.scenarios import suite_episodes

    try:
        timeout_s = max(e.timeout_s for e in suite_episodes(task.suite, task.town, task.task)[task.episode].agents)
    except Exception:  # noqa: BLE001 - the env reports an unknown episode itself
        timeout_s = 300.0
    return limits.episode_wall_factor * timeout_s + limits.episode_wall_extra_s


class _AgentLink:
    """The env side of one episode's agent channel: every answer has a timeout, and ``beat`` is
    called while waiting so the pool's watchdog sees the env process alive.

    ``turn`` (a shared byte, or None) is 1 while the agent has the turn (a request sent, its
    reply not yet read), so the pool can tell an env process killed then from a simulator crash.
    ``budget_s`` [s]: the episode's wall-clock budget from ``start`` on (None: none); no answer is
    waited for past it."""

    def __init__(self, end: channel.EnvEnd, limits: RunnerLimits, turn=None, budget_s: float | None = None,
                 scene: bool = False):
        self.end = end
        self.scene = scene
        self.limits = limits
        self.turn = turn
        self.budget_s = budget_s
        self.ends_at: float | None = None
        self.exchanges = 0

    def _exchange(self, message: tuple | None, expected: str, timeout_s: float, what: str) -> Any:
        now = time.monotonic()
        if self.ends_at is None and self.budget_s is not None:
            self.ends_at = now + self.budget_s
        left = None if self.ends_at is None else self.ends_at - now
        if left is not None and left <= 0:
            raise AgentFailure(self._budget_note(what))
        by_budget = left is not None and left < timeout_s
        allowance = left if by_budget else timeout_s
        deadline = now + allowance  # one allowance for taking the request and answering it
        if self.turn is not None:
            self.turn.value = 1
        try:
            if message is not None:
                self.end.request(message, allowance)
            reply = self.end.reply(max(deadline - time.monotonic(), 1e-3))
        except channel.ChannelTimeout:
            if by_budget:
                raise AgentFailure(self._budget_note(what)) from None
            raise AgentFailure(f"agent did not answer {what} within {timeout_s:g} s (hung, too slow, or not "
                               f"reading its channel); the agent process was stopped") from None
        except channel.ChannelClosed as exc:
            raise AgentFailure(f"agent process exited or closed its channel during {what} ({exc})") from None
        except channel.ProtocolError as exc:
            raise AgentFailure(f"agent broke the channel protocol during {what}: {exc}") from None
        finally:
            if self.turn is not None:
                self.turn.value = 0
        self.exchanges += 1
        if reply.kind == channel.ERROR:
            raise AgentFailure(reply.value)
        if reply.kind != expected:
            raise AgentFailure(f"agent broke the channel protocol during {what}: sent {reply.kind!r}, want {expected!r}")
        return reply.value

    def _budget_note(self, what: str) -> str:
        return (f"{WALL_BUDGET}: the episode's wall-clock budget of {self.budget_s:g} s (episode_wall_factor × its "
                f"timeout + episode_wall_extra_s) was used up, at {what} after {self.exchanges} answers; the agent "
                f"process was stopped")

    def start(self) -> channel.AgentDescription:
        return self._exchange(None, channel.READY, self.limits.agent_start_timeout_s, "its start-up")

    def reset(self, info: dict) -> None:
        self._exchange(("reset", agent_view(info)), channel.OK, self.limits.decision_timeout_s, "reset()")

    def act(self, obs: Any, info: dict, decision: int) -> int | tuple[float, ...]:
        return self._exchange(("act", obs, agent_view(info)), channel.ACTIONS if self.scene else channel.ACTION,
                              self.limits.decision_timeout_s, f"act() at decision {decision}")


class _EnvSlot:
    """One env kept across episodes of the same (suite, town, task, fidelity, env factory and options)."""

    def __init__(self):
        self.env = None
        self.key: tuple | None = None

    def get(self, task: EpisodeTask, factory: str | None, env_kwargs: tuple = ()):
        key = (task.suite, task.town, task.task, task.fidelity, factory, tuple(env_kwargs))
        if key != self.key:
            self.close()
            self.env = build_env(task, factory, dict(env_kwargs))
            self.key = key
        return self.env

    def close(self) -> None:
        if self.env is not None:
            self.env.close()
        self.env, self.key = None, None


class _Numbered:
    """The agent link as an agent of :func:`hbmp_bench.rollout.run_episode`: it numbers the
    decisions for the channel and times each answer [s] into ``times``."""

    def __init__(self, link: _AgentLink, times: list[float]):
        self.link, self.times, self.decisions = link, times, 0

    def reset(self, info: dict) -> None:
        self.link.reset(info)

    def act(self, observation, info: dict):
        start = time.perf_counter()
        action = self.link.act(observation, info, self.decisions)
        self.times.append(time.perf_counter() - start)
        self.decisions += 1
        return action




class _SceneActions:
    """The check of a scene's reply: exactly one action per vehicle that decides now (the observed ones;
    an agent cannot act for a vehicle that does not decide, nor leave one out), each in its action space."""

    def __init__(self, env: Any):
        self.env = env
        self.deciding: tuple[str, ...] = ()

    def observed(self, obs, *rest) -> None:
        self.deciding = tuple(obs) if isinstance(obs, dict) else ()

    def __call__(self, actions, decisions: int) -> dict:
        if not isinstance(actions, dict):
            raise ValueError(f"a scene's actions are a dict vehicle -> action, got {type(actions).__name__} at "
                             f"decision {decisions}")
        extra, missing = sorted(set(actions) - set(self.deciding)), sorted(set(self.deciding) - set(actions))
        if extra or missing:
            raise ValueError(f"at decision {decisions} the agent acted for {sorted(actions)}; the deciding vehicles "
                             f"are {sorted(self.deciding)}" + (f" (not deciding: {extra})" if extra else "")
                             + (f" (left out: {missing})" if missing else ""))
        space = self.env.vehicle_action_space
        return {vehicle: _checked(space, actions[vehicle], decisions, vehicle) for vehicle in self.deciding}


def _checked(space, action, decisions: int, vehicle: str = ""):
    """An action (an int, or a tuple of floats off the channel) by the env door's rule, strictly: an element of
    the action space, or the agent's error."""
    try:
        return check_action(space, action, strict=True)
    except ValueError as exc:
        whose = f" of {vehicle}" if vehicle else ""
        raise ValueError(f"invalid action{whose} {action!r} at decision {decisions}: want an element of {space}") from exc


def final_records(task: EpisodeTask, info: dict) -> tuple[EpisodeRecord, ...]:
    """The records the env gave at the episode's end (``info[RECORD_KEY]``: one record dict, a list of them for
    a scene), named the task's agent and checked to be one per vehicle of the task (:func:`scene_checked`)."""
    found = info[RECORD_KEY]
    rows = found if task.scene else [found]
    return scene_checked(task, [dataclasses.replace(EpisodeRecord(**row), agent=task.agent) for row in rows])


def run_episode(task: EpisodeTask, env_slot: _EnvSlot, agent: _AgentLink, limits: RunnerLimits, beat,
                factory: str | None = None, env_kwargs: tuple = ()) -> dict:
    """Run one episode in the env ``factory(**env_kwargs)`` (None: ``BehaviorEnv``, or the scene env for a
    scene; chosen by the pool, never by the agent process); returns the outcome dict sent to the pool (its
    records, one per vehicle of the task, status, restart, timings)."""
    times: list[float] = []

    def outcome(records: tuple[EpisodeRecord, ...], status: str, restart: bool) -> dict:
        return {
            "records": [r.to_dict() for r in records], "status": status, "restart": restart,
            "max_decision_s": max(times, default=0.0),
            "mean_decision_s": sum(times) / len(times) if times else 0.0,
        }

    def sim_error(where: str, exc: BaseException) -> dict:
        trace = "".join(traceback.format_exception(exc, limit=-8))
        return outcome(blank_records(task, SIM_ERROR, f"{where}:\n{trace}"), SIM_ERROR, True)

    try:
        agent.start()
    except AgentFailure as exc:
        return outcome(blank_records(task, AGENT_ERROR, str(exc)), AGENT_ERROR, False)
    try:
        env = env_slot.get(task, factory, env_kwargs)
    except Exception as exc:  # noqa: BLE001
        return sim_error("env reset raised", exc)
    beat(force=True)
    scene = _SceneActions(env) if task.scene else None

    def observed(obs, force: bool) -> None:
        beat(force=force)
        if scene is not None:
            scene.observed(obs)

    check = scene if scene is not None else (lambda action, decisions: _checked(env.action_space, action, decisions))
    hooks = rollout.EpisodeHooks(on_reset=lambda obs, info: observed(obs, True), check_action=check,
                                 on_step=lambda obs, *step: observed(obs, False))
    try:
        options = {"episode_index": task.episode, **({"salt": task.salt} if task.salt else {})}
        run = rollout.run_episode(env, _Numbered(agent, times), seed=task.episode, options=options,
                                  max_decisions=limits.max_decisions, hooks=hooks)
        if not run.ended:
            return outcome(partial_records(env, task, DECISION_CAP, ""), "ok", False)
        return outcome(final_records(task, run.info), "ok", False)
    except rollout.AgentFailed as exc:
        try:
            return outcome(partial_records(env, task, AGENT_ERROR, str(exc)), AGENT_ERROR, False)
        except Exception as broken:  # noqa: BLE001 - the env's records broke its contract
            return sim_error("the env's records after an agent error", broken)
    except rollout.EnvFailed as exc:
        where = "env reset raised" if exc.phase == "reset" else f"env step raised at decision {exc.decisions}"
        return sim_error(where, exc.__cause__)
    except Exception as exc:  # noqa: BLE001 - the env's records broke its contract
        return sim_error("the env's records", exc)


def _import_factory(factory: str | None) -> None:
    """Import the env factory's module before the task is read: a suite registered there (a test's, a
    plug-in's) is then known to this process (what ``build_env`` cannot import fails the episode there)."""
    if factory is not None:
        try:
            resolve(factory, "env factory")
        except Exception:  # noqa: BLE001 - reported by build_env as the episode's sim_error
            pass


def env_main(pool_conn: Connection, limits: RunnerLimits, lifeline: Connection,
             environ: dict[str, str] | None = None, turn=None) -> None:
    """Entry point of the env process (started by the episode pool with the caller's ``environ``;
    it exits when ``lifeline`` closes). It makes itself non-dumpable first, so an agent process
    of the same user can neither trace it nor read its memory."""
    protect_process()
    watch_lifeline(lifeline)
    adopt_environment(environ)
    import hbmp_bench.envs.behavior_env  # noqa: F401  (imported before the first heartbeat)

    env_slot = _EnvSlot()
    last_beat = [time.monotonic()]

    def beat(force: bool = False) -> None:
        now = time.monotonic()
        if force or now - last_beat[0] >= BEAT_PERIOD_S:
            pool_conn.send(("beat", None))
            last_beat[0] = now

    beat(force=True)
    try:
        while True:
            try:
                kind, payload = pool_conn.recv()
            except (EOFError, OSError):
                return
            if kind != "run":
                return
            task, factory, env_kwargs = payload
            end = channel.EnvEnd(channel.socket_from(reduction.recv_handle(pool_conn)), beat, BEAT_PERIOD_S)
            _import_factory(factory)
            try:
                link = _AgentLink(end, limits, turn, wall_budget_s(task, limits), scene=task.scene)
                done = run_episode(task, env_slot, link, limits, beat, factory, env_kwargs)
            finally:
                end.close()
            pool_conn.send(("done", done))
    except (BrokenPipeError, OSError):
        return
    finally:
        try:
            env_slot.close()
        except Exception:  # noqa: BLE001 - closing a broken SUMO must not mask the exit
            pass
