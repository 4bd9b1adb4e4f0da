"""rsl-rl ``VecEnv`` over workers, one environment (one libsumo simulation) per worker process.

Two transports behind the same ``VecEnv``: :class:`SubprocVecEnv` (local processes over pipes, the
default) and :class:`RayVecEnv` (Ray actors, one per environment, on a local Ray instance or a
cluster: ``hbmp-bench train ... --backend ray --address ray://HEAD:10001``). Both run
:class:`~hbmp_bench.training.worker.EnvRunner` in the worker, so the same seeds give the same
observations; :func:`make_vec_env` picks one by name.

Observations come back as a ``TensorDict`` with batch size ``(num_envs,)`` and one group per key
of the environment's observation dict, plus the action mask:

    occupancy    (N, 1, rows, cols) float32   M_t, a 2-D group (rsl-rl sends it through CNNs)
    road         (N, 10) float32              R_t, a 1-D group
    action_mask  (N, 5) float32               1 = behavior feasible (only if the env reports one)

Actions are ``(N, num_actions)``: for ``Discrete(5)`` ``num_actions`` is 1 and the entry is the
behavior index (as float, rsl-rl's storage is float); for a ``Box`` they are the control values.
Episodes reset automatically: the observation returned for a finished environment is the first
one of its next episode, ``dones`` marks it, and ``extras["time_outs"]`` says which of the ends
were the env's timeout (truncation), which PPO bootstraps.
"""

from __future__ import annotations

import multiprocessing as mp
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from hbmp_bench.errors import ConfigError
from hbmp_bench.training.run import BACKENDS
from hbmp_bench.training.worker import (EnvActor, StepReply, WorkerEnvConfig, asynchronous_scene, make_env,
                                        run_worker)

MAX_EPISODE_DECISIONS = 1_000_000
"""``max_episode_length`` reported to rsl-rl: episodes end by the env's own timeout, not here."""


class WorkerError(RuntimeError):
    """A worker process failed, died or stopped answering."""


class WorkerVecEnv(VecEnv):
    """The ``VecEnv`` shared by every transport: ``num_envs`` environments, each in its own process.

    Args:
        config: how each worker builds its environment (id, options, reward mode, expert labels, learners
            per simulation: ``config.agents``).
        num_envs: number of workers (>= 1); the VecEnv's ``num_envs`` is workers x ``config.agents`` (one slot
            per learner, worker-major: worker ``i``'s learners are slots ``i * agents`` ...).
        seed: base seed; worker ``i`` starts with the seed ``SeedSequence([seed, i])`` gives, later
            episodes follow from the env's own generator, so a run is reproducible.
        device: torch device of the returned tensors.
        reply_timeout_s: a worker that does not answer a step within this time is an error [s].

    Subclasses start the workers (:meth:`_start`), carry one request to every worker and bring
    back the replies in order (:meth:`_request_all`), and stop them (:meth:`close`).

    Attributes (besides rsl-rl's): ``observation_space``, ``action_space`` (of one env),
    ``episodes_done`` (finished episodes so far).
    """

    def __init__(self, config: WorkerEnvConfig, num_envs: int, seed: int = 0, device: str = "cpu",
                 reply_timeout_s: float = 300.0):
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        probe = make_env(config)  # validates the id and options here, before any worker starts
        try:
            self.observation_space = probe.observation_space
            self.action_space = probe.action_space
        finally:
            probe.close()
        if isinstance(self.action_space, spaces.Discrete):
            self.num_actions = 1
        elif isinstance(self.action_space, spaces.Box) and len(self.action_space.shape) == 1:
            self.num_actions = int(self.action_space.shape[0])
        else:
            raise ValueError(f"unsupported action space {self.action_space}; valid: Discrete or a 1-D Box")
        self.config = config
        self.asynchronous = asynchronous_scene(config)
        """The learners of a scene decide at different times: stepped by :meth:`step_slots`, not :meth:`step`."""
        self.num_workers = num_envs
        self.num_envs = num_envs * config.agents
        self.device = device
        self.cfg = {"env_id": config.env_id, **config.kwargs, "reward": config.reward, "agents": config.agents}
        self.max_episode_length = MAX_EPISODE_DECISIONS
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long, device=device)
        self.reply_timeout_s = reply_timeout_s
        self.episodes_done = 0
        self._finished: list[tuple[int, dict[str, Any]]] = []
        self._closed = False
        try:
            self._start()
            seeds = [int(np.random.SeedSequence([seed, i]).generate_state(1)[0]) for i in range(num_envs)]
            self._replies = self._slots(self._request_all("reset", seeds))
        except BaseException:
            self.close()
            raise
        self._obs = self._stack_obs(self._replies)

    # ------------------------------------------------------------ transport
    def _start(self) -> None:
        raise NotImplementedError

    def _request_all(self, command: str, args: list) -> list:
        """Send ``(command, args[i])`` to worker ``i`` for every worker; the replies in worker order (each a
        list of its slots' replies when ``config.agents`` > 1)."""
        raise NotImplementedError

    def _slots(self, replies: list) -> list[StepReply]:
        """The workers' replies, one per slot."""
        return [r for worker in replies for r in worker] if self.config.agents > 1 else list(replies)

    def close(self) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------ protocol
    def _stack_obs(self, replies: list[StepReply]) -> TensorDict:
        groups = {
            key: torch.as_tensor(np.stack([r.obs[key] for r in replies]), dtype=torch.float32, device=self.device)
            for key in replies[0].obs
        }
        masked = [r.action_mask is not None for r in replies]
        if any(masked) and not all(masked):
            raise RuntimeError(f"workers disagree on the action mask (present in {sum(masked)} of {len(masked)} "
                               "replies): an env's reset and step infos must both have it or both lack it")
        if all(masked):
            groups["action_mask"] = torch.as_tensor(np.stack([r.action_mask for r in replies]),
                                                    dtype=torch.float32, device=self.device)
        return TensorDict(groups, batch_size=[self.num_envs], device=self.device)

    def _env_action(self, action: np.ndarray):
        if self.num_actions == 1 and isinstance(self.action_space, spaces.Discrete):
            return int(np.rint(action[0]))
        return action.astype(self.action_space.dtype)

    # --------------------------------------------------------------- VecEnv
    def get_observations(self) -> TensorDict:
        """The current observations, see the module docstring for the groups."""
        return self._obs

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """One decision in every environment.

        Args:
            actions: (num_envs, num_actions).

        Returns:
            obs: TensorDict (num_envs,) of the next observations.
            rewards: (num_envs,) float32 training rewards (see :data:`~hbmp_bench.vocabulary.TRAINING_REWARD_MODES`).
            dones: (num_envs,) long, 1 where the episode ended (the obs is then the next episode's first).
            extras: ``time_outs`` (num_envs,) long: ended by the env's timeout; ``expert_actions``
                (num_envs,) long: the expert's behavior for the returned obs (-1 without labels);
                ``episodes``: ``[(env index, summary)]`` finished this step; ``log``: means of the
                finished episodes' r_T, success and length under ``/episode/...`` (only when some ended);
                ``expert_controls`` (num_envs, 2): the expert's controls for the returned obs (only with them).
        """
        if self._closed:
            raise RuntimeError("the VecEnv is closed")
        if self.asynchronous:
            raise RuntimeError("the learners of an asynchronous scene decide at different times: step_slots steps it")
        acts = actions.detach().cpu().numpy().reshape(self.num_envs, self.num_actions)
        per_slot = [self._env_action(a) for a in acts]
        if self.config.agents > 1:
            k = self.config.agents
            per_worker = [per_slot[i * k:(i + 1) * k] for i in range(self.num_workers)]
        else:
            per_worker = per_slot
        replies = self._slots(self._request_all("step", per_worker))
        self._replies = replies
        self._obs = self._stack_obs(replies)
        rewards = torch.tensor([r.reward for r in replies], dtype=torch.float32, device=self.device)
        dones = torch.tensor([r.terminated or r.truncated for r in replies], dtype=torch.long, device=self.device)
        time_outs = torch.tensor([r.truncated and not r.terminated for r in replies], dtype=torch.long,
                                 device=self.device)
        self.episode_length_buf += 1
        self.episode_length_buf[dones.bool()] = 0
        episodes = [(i, r.episode) for i, r in enumerate(replies) if r.episode is not None]
        self._finished.extend(episodes)
        self.episodes_done += len(episodes)
        extras: dict[str, Any] = {
            "time_outs": time_outs,
            "expert_actions": torch.tensor([r.expert_action for r in replies], dtype=torch.long, device=self.device),
            "episodes": episodes,
        }
        if replies[0].expert_control is not None:
            extras["expert_controls"] = self.expert_controls
        if episodes:
            extras["log"] = {
                f"/episode/{key}": torch.tensor([float(e[key]) for _, e in episodes])
                for key in ("r_T", "r_T_plus_r_t", "success", "infractions", "length")
            }
        return self._obs, rewards, dones, extras

    def step_slots(self, actions: dict[int, np.ndarray]) -> list[tuple[int, StepReply]]:
        """One step of every worker: ``actions`` for the slots that decide (global slot index ->
        (num_actions,) action); returns ``[(slot, reply)]`` of the slots whose transition completed or that
        must decide (``StepReply.completes`` / ``decides``), and counts the finished episodes
        (:meth:`pop_episodes`). In an asynchronous scene (:attr:`asynchronous`) the slots decide when their
        behaviors end; in any other every slot decides at every step, so ``actions`` has every slot and
        every reply completes and decides: the same loop drives both
        (:class:`~hbmp_bench.training.async_rollout.AsyncRollout`)."""
        if self._closed:
            raise RuntimeError("the VecEnv is closed")
        if not self.asynchronous:
            if sorted(actions) != list(range(self.num_envs)):
                raise RuntimeError(f"every slot decides at every step here: actions for the {self.num_envs} "
                                   f"slots, got {len(actions)}")
            acts = np.stack([np.asarray(actions[i]).reshape(self.num_actions) for i in range(self.num_envs)])
            self.step(torch.as_tensor(acts))
            return list(enumerate(self._replies))
        k = self.config.agents
        per_worker = [{} for _ in range(self.num_workers)]
        for slot, action in actions.items():
            per_worker[slot // k][slot % k] = self._env_action(np.asarray(action).reshape(self.num_actions))
        out = []
        for i, replies in enumerate(self._request_all("step", per_worker)):
            out.extend((i * k + slot, reply) for slot, reply in replies)
        episodes = [(slot, r.episode) for slot, r in out if r.episode is not None]
        self._finished.extend(episodes)
        self.episodes_done += len(episodes)
        return out

    def stack(self, replies: list[StepReply]) -> TensorDict:
        """The observations of ``replies`` as one TensorDict (batch: their number), the groups of :meth:`step`."""
        groups = {key: torch.as_tensor(np.stack([r.obs[key] for r in replies]), dtype=torch.float32,
                                       device=self.device) for key in replies[0].obs}
        if replies[0].action_mask is not None:
            groups["action_mask"] = torch.as_tensor(np.stack([r.action_mask for r in replies]), dtype=torch.float32,
                                                    device=self.device)
        return TensorDict(groups, batch_size=[len(replies)], device=self.device)

    @property
    def expert_actions(self) -> torch.Tensor:
        """(num_envs,) long: the expert's behavior for the current observations (-1 without labels)."""
        return torch.tensor([r.expert_action for r in self._replies], dtype=torch.long, device=self.device)

    @property
    def expert_controls(self) -> torch.Tensor:
        """(num_envs, 2) float32: the control ``[a, s]`` the expert's stack applies in the current states
        (``WorkerEnvConfig.expert_controls``)."""
        return torch.as_tensor(np.stack([r.expert_control for r in self._replies]), dtype=torch.float32,
                               device=self.device)

    def pop_episodes(self) -> list[tuple[int, dict[str, Any]]]:
        """Summaries ``[(env index, summary)]`` of the episodes finished since the last call, in order."""
        out, self._finished = self._finished, []
        return out

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SubprocVecEnv(WorkerVecEnv):
    """Workers as local processes over pipes (see :class:`WorkerVecEnv` for the arguments).

    Args:
        start_method: ``spawn`` (default) or ``forkserver``; never ``fork`` (libsumo, torch threads).
    """

    def __init__(self, config: WorkerEnvConfig, num_envs: int, seed: int = 0, device: str = "cpu",
                 start_method: str = "spawn", reply_timeout_s: float = 300.0):
        if start_method not in ("spawn", "forkserver"):
            raise ConfigError(f"start_method must be 'spawn' or 'forkserver', got {start_method!r}")
        self._start_method = start_method
        self._conns, self._procs = [], []
        super().__init__(config, num_envs, seed=seed, device=device, reply_timeout_s=reply_timeout_s)

    def _start(self) -> None:
        context = mp.get_context(self._start_method)
        for i in range(self.num_workers):
            parent, child = context.Pipe()
            proc = context.Process(target=run_worker, args=(child, self.config), name=f"hbmp-env-{i}", daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)

    def _request_all(self, command: str, args: list) -> list[StepReply]:
        for i, conn in enumerate(self._conns):
            try:
                conn.send((command, args[i]))
            except (BrokenPipeError, OSError) as exc:
                raise WorkerError(f"training worker {i} (pid {self._procs[i].pid}) died "
                                  f"(exit code {self._procs[i].exitcode})") from exc
        return [self._receive(i) for i in range(self.num_workers)]

    def _receive(self, i: int) -> StepReply:
        conn, proc = self._conns[i], self._procs[i]
        try:
            if not conn.poll(self.reply_timeout_s):
                raise WorkerError(f"training worker {i} (pid {proc.pid}) did not answer within "
                                  f"{self.reply_timeout_s:.0f} s")
            status, payload = conn.recv()
        except (EOFError, ConnectionResetError, BrokenPipeError) as exc:
            proc.join(timeout=1.0)
            raise WorkerError(f"training worker {i} (pid {proc.pid}) died (exit code {proc.exitcode})") from exc
        if status == "error":
            raise WorkerError(f"training worker {i} failed: {payload}")
        return payload

    # ---------------------------------------------------------------- close
    def close(self) -> None:
        """Close every environment and join the workers (idempotent); stragglers are terminated."""
        if self._closed:
            return
        self._closed = True
        for conn, proc in zip(self._conns, self._procs):
            if proc.is_alive():
                try:
                    conn.send(("close", None))
                    if conn.poll(10.0):
                        conn.recv()
                except (EOFError, BrokenPipeError, ConnectionResetError, OSError):
                    pass
        for conn, proc in zip(self._conns, self._procs):
            proc.join(timeout=10.0)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5.0)
            conn.close()


class RayVecEnv(WorkerVecEnv):
    """Workers as Ray actors, one environment per actor (see :class:`WorkerVecEnv` for the arguments).

    Args:
        address: a running cluster (``ray://HEAD:10001``, ``auto``); None starts a local Ray instance
            unless Ray is already initialised in this process. A local instance started here is shut
            down by :meth:`close`. Every node needs the package installed (``pip install
            "hbmp-bench[ray]"``).
        cpus_per_worker: Ray CPUs each actor reserves.

    An actor that raises, dies or does not answer within ``reply_timeout_s`` is a :class:`WorkerError`.
    """

    def __init__(self, config: WorkerEnvConfig, num_envs: int, seed: int = 0, device: str = "cpu",
                 address: str | None = None, cpus_per_worker: float = 1.0, reply_timeout_s: float = 300.0):
        from hbmp_bench.evaluation.ray_backend import import_ray

        self._ray = import_ray()
        self._address = address
        self._cpus = float(cpus_per_worker)
        self._actors: list = []
        self._started_ray = False
        super().__init__(config, num_envs, seed=seed, device=device, reply_timeout_s=reply_timeout_s)

    def _start(self) -> None:
        ray = self._ray
        if not ray.is_initialized():
            ray.init(address=self._address, include_dashboard=False, log_to_driver=False)
            self._started_ray = True
        actor_cls = ray.remote(num_cpus=self._cpus, max_restarts=0)(EnvActor)
        self._actors = [actor_cls.remote(self.config) for _ in range(self.num_workers)]

    def _request_all(self, command: str, args: list) -> list[StepReply]:
        ray = self._ray
        refs = [actor.request.remote(command, args[i]) for i, actor in enumerate(self._actors)]
        replies = []
        for i, ref in enumerate(refs):
            try:
                replies.append(ray.get(ref, timeout=self.reply_timeout_s))
            except ray.exceptions.GetTimeoutError as exc:
                raise WorkerError(f"training worker {i} (Ray actor) did not answer within "
                                  f"{self.reply_timeout_s:.0f} s") from exc
            except ray.exceptions.RayActorError as exc:
                raise WorkerError(f"training worker {i} (Ray actor) died: {str(exc)[:500]}") from exc
            except ray.exceptions.RayTaskError as exc:
                raise WorkerError(f"training worker {i} failed: {exc}") from exc
        return replies

    def close(self) -> None:
        """Close every environment and end the actors (idempotent); a Ray instance started here is shut down."""
        if self._closed:
            return
        self._closed = True
        ray = self._ray
        try:
            if self._actors:
                closing = [actor.request.remote("close", None) for actor in self._actors]
                ray.wait(closing, num_returns=len(closing), timeout=10.0)
        except ray.exceptions.RayError:
            pass
        finally:
            for actor in self._actors:
                ray.kill(actor)
            if self._started_ray:
                ray.shutdown()


def make_vec_env(config: WorkerEnvConfig, num_envs: int, seed: int = 0, backend: str = "process",
                 address: str | None = None, **kwargs) -> WorkerVecEnv:
    """The ``VecEnv`` of ``backend`` (one of :data:`BACKENDS`); ``address`` only with ``ray``."""
    if backend == "process":
        if address is not None:
            raise ConfigError("address is for the ray backend only")
        return SubprocVecEnv(config, num_envs, seed=seed, **kwargs)
    if backend == "ray":
        return RayVecEnv(config, num_envs, seed=seed, address=address, **kwargs)
    from hbmp_bench.errors import UnknownNameError

    raise UnknownNameError("training backend", backend, BACKENDS)
