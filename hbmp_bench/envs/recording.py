"""Recording one episode of an agent as an animated GIF (or MP4): the env renders, the pictures
go to :func:`hbmp_bench.render.video.write_video`. Lives with the envs (envs use render; render
never imports envs)."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
from PIL import Image

from hbmp_bench.render.video import check_video_path, write_video
from hbmp_bench.rollout import AgentFailed, EnvFailed, EpisodeHooks, run_episode


def record_episode(
    env_id: str,
    agent: str,
    path: str | os.PathLike,
    episode_index: int = 0,
    suite: str = "corl2017",
    fidelity: str | None = None,
    max_decisions: int | None = None,
    every: int = 1,
    fps: float | None = None,
    progress: bool = False,
    **env_kwargs: Any,
) -> dict:
    """Run ``agent`` on one episode of ``env_id`` and write every ``every``-th rendered frame.

    The env is made with ``render_mode="rgb_array_list"``; the frames it rendered at each
    simulation step (``env.unwrapped.drain_frames()``) are collected after ``reset`` and
    after every decision. The episode is reset with ``seed=episode_index``, like the
    evaluation runner, so the record matches ``hbmp-bench run``.

    Args:
        env_id: a registered id (``hbmp_bench/Town01-Straight-v0``).
        agent: agent registry name or ``module:Class``.
        path: ``.gif`` (or ``.mp4`` with imageio-ffmpeg) to write.
        episode_index: episode of the suite's list (for the training id: the reset seed).
        suite, fidelity: env options (``fidelity=None``: the env's default).
        max_decisions: stop after this many decisions (None: until the episode ends).
        every: keep every ``every``-th frame (>= 1) to keep files small.
        fps: playback rate; default real time (``1 / (step length * every)``).
        progress: show a progress bar of decisions.
        env_kwargs: further ``gymnasium.make`` options of the env; the agent's own
            (``agents.agent_env_kwargs``, e.g. the expert's ``privileged=True``) are added.

    Returns:
        The episode record as a dict (``EpisodeRecord`` fields; the record so far when
        ``max_decisions`` stopped the episode early), with ``agent`` filled in.
    """
    from tqdm import tqdm

    from hbmp_bench.agents import agent_env_kwargs, load_agent
    from hbmp_bench.envs.registration import TRAINING_ID, make

    path = check_video_path(path)
    if int(every) != every or every < 1:
        raise ValueError(f"every must be an int >= 1, got {every!r}")
    if max_decisions is not None and (int(max_decisions) != max_decisions or max_decisions < 1):
        raise ValueError(f"max_decisions must be an int >= 1 or None, got {max_decisions!r}")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be finite and > 0, got {fps!r}")
    policy = load_agent(agent)
    kwargs = dict(agent_env_kwargs(policy), **env_kwargs, render_mode="rgb_array_list", suite=suite)
    if env_id != TRAINING_ID:
        kwargs["episode_index"] = episode_index
    if fidelity is not None:
        kwargs["fidelity"] = fidelity
    factory = getattr(policy, "env_factory", None)  # the env an agent needs besides the behavior env (flat's)
    if factory is None:
        env = make(env_id, **kwargs)
    else:
        from hbmp_bench.evaluation.tasks import AGENT_ENV_FACTORIES
        from hbmp_bench.plugins import resolve

        if factory not in AGENT_ENV_FACTORIES:
            raise ValueError(f"the agent asks for env_factory {factory!r}; an agent may only ask for "
                             f"{list(AGENT_ENV_FACTORIES)}")
        from hbmp_bench.envs.registration import env_ids
        from hbmp_bench.errors import UnknownNameError

        if env_id not in env_ids():
            raise UnknownNameError("env id", env_id, env_ids())
        env = resolve(factory, "env factory")(**{**gym.spec(env_id).kwargs, **kwargs})
    frames: list[Image.Image] = []
    seen = 0

    def collect() -> None:
        nonlocal seen
        for frame in env.unwrapped.drain_frames():
            if seen % every == 0:
                # palette images: a third of the memory of RGB; the GIF writer needs them anyway
                image = Image.fromarray(np.asarray(frame, dtype=np.uint8))
                frames.append(image.quantize(256, method=Image.Quantize.FASTOCTREE))
            seen += 1

    try:
        step_s = float(env.unwrapped.config.step_length_s)
        with tqdm(total=max_decisions, unit="decision", disable=not progress) as bar:
            hooks = EpisodeHooks(on_reset=lambda obs, info: collect(),
                                 on_step=lambda *step: (bar.update(1), collect()))
            try:
                run = run_episode(env, policy, seed=episode_index, max_decisions=max_decisions, hooks=hooks)
            except (AgentFailed, EnvFailed) as exc:
                raise exc.__cause__ from None
        record = run.record(env)
    finally:
        env.close()
    if not frames:
        raise RuntimeError(f"{env_id} rendered no frames; does it support render_mode='rgb_array_list'?")
    record["agent"] = agent
    write_video(frames, path, fps if fps is not None else 1.0 / (step_s * every))
    return record
