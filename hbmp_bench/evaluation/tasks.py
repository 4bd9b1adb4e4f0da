"""What the evaluation runner runs: one episode per task, and the limits it runs them under."""

from __future__ import annotations

import dataclasses
import inspect
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hbmp_bench.errors import ConfigError, UserError
from hbmp_bench.scenarios import all_tasks, check_task, check_town, get_suite, held_episodes

if TYPE_CHECKING:
    from hbmp_bench.evaluation.channel import AgentDescription


@dataclass(frozen=True)
class EpisodeTask:
    """One episode of a suite for one agent.

    Attributes:
        suite / town / task / episode: which episode (``episode`` indexes the suite's list and is
            also the reset seed, so every agent meets the same traffic).
        agent: registry name, ``module:Class`` or checkpoint spec given to ``load_agent``.
        fidelity: the resolved world fidelity (never None here; see ``default_fidelity``).
        salt: the evaluation's secret salt (hex), mixed into the seed of the episode's traffic,
            pedestrians and light phases (``DrivingWorld.start``); "" for the public episodes.
            Only the env process gets it (never the agent process), it is no part of ``key`` and
            is left out of the task's repr.
    """

    suite: str
    town: str
    task: str
    episode: int
    agent: str
    fidelity: str
    salt: str = dataclasses.field(default="", repr=False)

    @property
    def key(self) -> tuple[str, str, str, int, str, str]:
        """The same tuple as ``EpisodeRecord.key`` of its record."""
        return (self.suite, self.town, self.task, self.episode, self.agent, self.fidelity)

    @property
    def label(self) -> str:
        return f"{self.town}/{self.task}/{self.episode}"

    @property
    def vehicles(self) -> tuple[str, ...]:
        """The vehicles its records name, in order (:func:`scene_vehicles` of its suite)."""
        return scene_vehicles(self.suite)

    @property
    def scene(self) -> bool:
        """Whether the task is a scene: several goal-directed vehicles, one record each (``Suite.agents`` > 1)."""
        return get_suite(self.suite).agents > 1


def scene_vehicles(suite: str) -> tuple[str, ...]:
    """The ``EpisodeRecord.vehicle`` of each record one episode of ``suite`` produces, in order: ``("",)`` for a
    single-ego suite (its one record names no vehicle), ``("ego", "ego1", ..., "ego{N-1}")`` for a suite of
    ``N`` goal-directed vehicles (``Suite.agents``; vehicle ``k`` drives ``Episode.agents[k]``)."""
    agents = get_suite(suite).agents
    return ("",) if agents == 1 else ("ego", *(f"ego{k}" for k in range(1, agents)))


def vehicle_episode(episode, vehicle: str):
    """The suite episode (``scenarios.Episode``) ``vehicle`` drives in ``episode`` ("" or ``ego``: the episode's
    own, ``ego{k}``: ``episode.others[k - 1]``); KeyError for a vehicle the episode has not."""
    drivers = episode.agents
    names = ("ego", *(f"ego{k}" for k in range(1, len(drivers))))
    if vehicle == "" and len(drivers) == 1:
        return drivers[0]
    if vehicle not in names:
        raise KeyError(f"episode {episode.key} has no goal-directed vehicle {vehicle!r} (it has {', '.join(names)})")
    return drivers[names.index(vehicle)]


@dataclass(frozen=True)
class RunnerLimits:
    """Time limits and fault handling of isolated episode runs.

    Attributes:
        decision_timeout_s: longest the agent may take for one ``act`` (or ``reset``) [s]; past
            it the agent process is killed and the episode fails with ``agent_error``.
        agent_start_timeout_s: longest the agent process may take to import and build the agent [s].
        start_timeout_s: longest a fresh env process may take to start and report [s].
        watchdog_s: longest the env process may go without a heartbeat [s]. It beats at least
            every 0.5 s, also while it waits for the agent, so only a hung simulation (a SUMO
            step, reset or start) trips it; the env process is then killed and the episode retried.
        retries: reruns of an episode after a simulation error (crash, exception, watchdog).
        max_decisions: stop every episode after this many decisions (``decision_cap``; smoke
            runs); None runs episodes to their end.
        env_factory: ``module:callable`` building the env from ``(town=, task=, suite=,
            fidelity=, **env_kwargs)``; None is ``BehaviorEnv``. For agents that need another env
            (the flat baseline's control env), wrappers and fault-injection tests.
        env_kwargs: extra env options as ``(name, value)`` pairs (e.g. the observation kind a
            policy was trained with).
        agent_memory_mb: address space the agent process may map (``RLIMIT_AS``) [MiB]; an
            allocation past it fails (``MemoryError``). None: no limit.
        agent_cpu_s: CPU time the agent process may use in one episode, building the agent
            included, all its threads together (``RLIMIT_CPU``) [s]; past it the kernel ends the
            process and the episode is an ``agent_error``. None: no limit.
        agent_file_mb: largest file the agent process may write (``RLIMIT_FSIZE``) [MiB]. None: no limit.
        agent_processes: processes and threads the agent's user may have (``RLIMIT_NPROC``), set
            only when the agent runs as ``agent_user`` (the count is per user). None: no limit.
        agent_user: when the evaluator runs as root, the agent process switches to this
            unprivileged user before it loads the agent (see ``sandbox``); None keeps root, which
            lets the agent forge results: only for trusted agents. Ignored when not root.
        agent_preload: modules the fork server imports once, so that an agent process, started
            for every episode, finds them loaded (e.g. a heavy library the agent imports). They
            run in the evaluator's fork server: name trusted libraries only, never the agent's.
            (Agents in the namespace sandbox start a fresh interpreter and import what they need.)
        trust_agent: run agents that bring their own code (``module:Class``, a checkpoint file)
            without the namespace sandbox (``namespaces``), in a process forked by the fork
            server with only the session, resource limits and ``agent_user`` of ``sandbox``: for
            trusted agents, and hosts that cannot give namespaces. False (the default): such
            agents run in the sandbox, and are refused where the host cannot give one.
        agent_env: names of variables of the evaluator's environment the agent process gets
            besides ``namespaces.AGENT_ENVIRONMENT`` (sandbox only; without the sandbox it gets
            the whole environment).
        agent_readable / agent_writable: folders (or files) the sandbox shows the agent
            read-only / writable, at their own paths, besides what it always shows (its
            Python, this package, its own module's folder or checkpoint file). Never name the
            records or leaderboard folders writable.
        episode_wall_factor / episode_wall_extra_s: every episode must end within
            ``episode_wall_factor`` × its timeout (``Episode.timeout_s``, simulated seconds) +
            ``episode_wall_extra_s`` of wall-clock time [s], counted from the agent's start-up
            on; past it the episode ends as ``agent_error`` naming the budget (an agent that
            takes nearly ``decision_timeout_s`` at every decision cannot stretch it further).

    Every episode starts a fresh agent process, so the agent limits hold per episode.
    """

    decision_timeout_s: float = 10.0
    agent_start_timeout_s: float = 120.0
    start_timeout_s: float = 120.0
    watchdog_s: float = 120.0
    retries: int = 1
    max_decisions: int | None = None
    env_factory: str | None = None
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    agent_memory_mb: int | None = 8192
    agent_cpu_s: int | None = 3600
    agent_file_mb: int | None = 1024
    agent_processes: int | None = 512
    agent_user: str | None = "nobody"
    agent_preload: tuple[str, ...] = ()
    trust_agent: bool = False
    agent_env: tuple[str, ...] = ()
    agent_readable: tuple[str, ...] = ()
    agent_writable: tuple[str, ...] = ()
    episode_wall_factor: float = 4.0
    episode_wall_extra_s: float = 120.0

    def __post_init__(self):
        self._check_agent_resources()
        self._check_agent_files()
        self._check_run()

    def _check_agent_resources(self) -> None:
        """Timeouts, the agent process's resource limits and its user."""
        for name in ("decision_timeout_s", "agent_start_timeout_s", "start_timeout_s", "watchdog_s"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("agent_memory_mb", "agent_cpu_s", "agent_file_mb", "agent_processes"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value <= 0):
                raise ConfigError(f"{name} must be a positive integer or None, got {value!r}")
        if self.agent_user is not None and (not isinstance(self.agent_user, str) or not self.agent_user.strip()):
            raise ConfigError(f"agent_user must be a user name or None, got {self.agent_user!r}")

    def _check_agent_files(self) -> None:
        """What the agent process preloads, whether it is trusted, and its environment variables and paths
        (as tuples)."""
        object.__setattr__(self, "agent_preload", tuple(self.agent_preload))
        if not isinstance(self.trust_agent, bool):
            raise ConfigError(f"trust_agent must be True or False, got {self.trust_agent!r}")
        for name in ("agent_env", "agent_readable", "agent_writable"):
            value = getattr(self, name)
            if isinstance(value, str) or not all(isinstance(v, str) and v for v in value):
                raise ConfigError(f"{name} must be a sequence of non-empty strings, got {value!r}")
            object.__setattr__(self, name, tuple(value))
        for name in ("agent_readable", "agent_writable"):
            relative = [p for p in getattr(self, name) if not os.path.isabs(p)]
            if relative:
                raise ConfigError(f"{name} must name absolute paths, got {relative}")

    def _check_run(self) -> None:
        """The episode's wall limit, the preloaded module names, retries, the decision cap and the env."""
        if not self.episode_wall_factor > 0 or not self.episode_wall_extra_s >= 0:
            raise ConfigError(f"episode_wall_factor must be > 0 and episode_wall_extra_s >= 0, got "
                             f"{self.episode_wall_factor} and {self.episode_wall_extra_s}")
        bad = [m for m in self.agent_preload if not isinstance(m, str) or not m.replace(".", "").replace("_", "").isalnum()]
        if bad:
            raise ConfigError(f"agent_preload must name modules (a.b.c), got {bad}")
        if self.retries < 0:
            raise ConfigError(f"retries must be >= 0, got {self.retries}")
        if self.max_decisions is not None and self.max_decisions <= 0:
            raise ConfigError(f"max_decisions must be > 0 or None, got {self.max_decisions}")
        object.__setattr__(self, "env_kwargs", tuple(sorted(dict(self.env_kwargs).items())))
        if self.env_factory is not None and ":" not in self.env_factory:
            raise ConfigError(f"env_factory must be 'module:callable', got {self.env_factory!r}")


def default_fidelity() -> str:
    """The fidelity ``BehaviorEnv`` uses when none is given (recorded with every episode)."""
    from hbmp_bench.envs.behavior_env import BehaviorEnv
    from hbmp_bench.envs.config import WorldConfig

    default = inspect.signature(BehaviorEnv).parameters["fidelity"].default
    return default if isinstance(default, str) else WorldConfig().fidelity


def agent_slug(agent: str) -> str:
    """A file-name-safe form of an agent spec (``my_pkg.mod:Agent`` → ``my_pkg.mod.Agent``)."""
    slug = re.sub(r"[^A-Za-z0-9._-]+", ".", agent).strip(".")
    if not slug:
        raise UserError(f"agent spec {agent!r} has no usable name")
    return slug


def suite_tasks(
    suite: str,
    agent: str,
    *,
    towns: Sequence[str] | None = None,
    tasks: Sequence[str] | None = None,
    episodes: int | Iterable[int] | None = None,
    fidelity: str | None = None,
    salt: str = "",
) -> list[EpisodeTask]:
    """Every episode of a suite selection, ordered by town, task and index.

    Args:
        towns / tasks: subsets of the suite's (None: all of them).
        episodes: the first N episodes per (town, task), or explicit indices (None: all).
        fidelity: None resolves to ``default_fidelity()``; an unknown one raises ValueError.
        salt: the evaluation's secret salt for every task ("" : the public episodes; see
            ``EpisodeTask.salt``).
    """
    spec = get_suite(suite)
    towns = list(dict.fromkeys(check_town(t) for t in (towns or spec.towns)))
    tasks = list(dict.fromkeys(check_task(t) for t in (tasks or spec.tasks)))
    if episodes is None:
        indices = list(range(spec.episodes_per_task))
    elif isinstance(episodes, int):
        if episodes <= 0:
            raise UserError(f"episodes must be > 0, got {episodes}")
        indices = list(range(min(episodes, spec.episodes_per_task)))
    else:
        indices = sorted(set(int(i) for i in episodes))
        bad = [i for i in indices if not 0 <= i < spec.episodes_per_task]
        if bad or not indices:
            raise UserError(f"episode indices must be in [0, {spec.episodes_per_task}), got {bad or 'none'}")
    fidelity = fidelity or default_fidelity()
    from hbmp_bench.envs.config import WorldConfig

    WorldConfig(fidelity=fidelity)  # a bad fidelity fails here, naming the valid ones, not in every episode
    order = {t: k for k, t in enumerate(all_tasks())}
    tasks = sorted(tasks, key=lambda t: order[t])
    held = {(town, task): held_episodes(spec.name, town, task) for town in towns for task in tasks}
    return [EpisodeTask(spec.name, town, task, i, agent, fidelity, salt) for town in towns for task in tasks
            for i in indices if i < held[town, task]]


def adopt_environment(environ: dict[str, str] | None) -> None:
    """Make ``os.environ`` of a child process equal to its caller's (passed at start)."""
    if environ is not None:
        os.environ.clear()
        os.environ.update(environ)


def watch_lifeline(lifeline) -> None:
    """End this (child) process as soon as ``lifeline`` reaches EOF: the pool holds the only write
    end, so a killed or crashed pool takes its children with it, even an agent hung in ``act``.

    The pool alone ends its children: Ctrl-C in a terminal signals the whole process group, and
    the children ignore it, so they neither print tracebacks nor die before the pool stops them.
    """
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    def wait_for_eof() -> None:
        try:
            lifeline.recv()
        except (EOFError, OSError):
            pass
        os._exit(70)

    threading.Thread(target=wait_for_eof, name="hbmp-lifeline", daemon=True).start()


BEHAVIOR_ENV = "hbmp_bench.envs.behavior_env:BehaviorEnv"
"""The env an episode runs in unless the agent or the evaluator names another (``RunnerLimits.env_factory``)."""
SCENE_ENV = "hbmp_bench.envs.scene_env:SceneEnv"
"""The env a scene runs in (an episode of a suite with ``Suite.agents`` > 1: one env holds every vehicle)."""

AGENT_ENV_FACTORIES = ("hbmp_bench.envs.control_env:ControlEnv",)
"""Envs an agent may ask for besides the behavior env (the flat baseline's control env). Only the
evaluator (``RunnerLimits.env_factory``) may name another: an agent naming its own module would
run its code in the env process."""

SCENE_FORMS: dict[str | None, dict[str, Any]] = {None: {}, "hbmp_bench.envs.control_env:ControlEnv": {"ego_driver": "control"}}
"""How a scene (:data:`SCENE_ENV`) runs the env an agent asks for (None: the behavior env; the control env:
every goal-directed vehicle driven by control vectors)."""


def is_privileged(limits: RunnerLimits) -> bool:
    """Whether envs made with ``limits`` give the agent the privileged scene fields."""
    from hbmp_bench.agents.base import PRIVILEGED_OPTION

    return dict(limits.env_kwargs).get(PRIVILEGED_OPTION) is True


def with_agent_env(limits: RunnerLimits, agent: AgentDescription) -> RunnerLimits:
    """``limits`` with the env the agent asks for: an agent may name an ``env_factory`` from
    ``AGENT_ENV_FACTORIES`` (the flat baseline's control env) and ``env_kwargs`` that change what
    its policy sees (``agents.learned.OBSERVATION_OPTIONS``: the observation kind it was trained
    with) or ``privileged`` (``agents.base.PRIVILEGED_OPTION``: the privileged scene fields, which
    any agent may ask for; its results are then marked privileged, see :func:`is_privileged`).
    Anything else is refused with ValueError: an agent must not pick an easier env or run its own
    code in the env process. Explicit limits win."""
    from hbmp_bench.agents.base import PRIVILEGED_OPTION
    from hbmp_bench.agents.learned import OBSERVATION_OPTIONS

    if agent.env_factory is not None and agent.env_factory not in AGENT_ENV_FACTORIES:
        raise UserError(f"the agent asks for env_factory {agent.env_factory!r}; an agent may only ask for "
                         f"{list(AGENT_ENV_FACTORIES)} (the evaluator can set another with RunnerLimits.env_factory)")
    allowed = (*OBSERVATION_OPTIONS, PRIVILEGED_OPTION)
    unknown = sorted(k for k, _ in agent.env_kwargs if k not in allowed)
    if unknown:
        raise UserError(f"the agent asks for env options {unknown}; an agent may only set {list(allowed)}")
    from hbmp_bench.envs.config import WorldConfig
    from hbmp_bench.envs.observation import ObservationConfig

    asked = dict(agent.env_kwargs)
    if "observation" in asked or "road_profile" in asked:  # checked here: not a sim_error in every episode
        ObservationConfig(kind=asked.get("observation", "deformed"), road=asked.get("road_profile", "paper"))
    if PRIVILEGED_OPTION in asked:
        WorldConfig(privileged=asked[PRIVILEGED_OPTION])
    factory = limits.env_factory or agent.env_factory
    kwargs = {**dict(agent.env_kwargs), **dict(limits.env_kwargs)}
    return dataclasses.replace(limits, env_factory=factory, env_kwargs=tuple(kwargs.items()))
