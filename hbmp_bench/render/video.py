"""Frames to files: animated GIFs (Pillow), MP4 when ``imageio-ffmpeg`` is installed, and
:func:`record_episode`, which runs an agent on one episode and writes what it rendered.

Files are written atomically: to a temporary file beside the target, then renamed.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

VIDEO_SUFFIXES = (".gif", ".mp4")


def _mp4_writer():
    """The ``imageio_ffmpeg`` module, or a ValueError saying how to get it."""
    try:
        import imageio_ffmpeg
    except ImportError as exc:
        raise ValueError("writing .mp4 needs the optional package imageio-ffmpeg "
                         "(pip install imageio-ffmpeg); write a .gif instead") from exc
    return imageio_ffmpeg


def check_video_path(path: str | os.PathLike) -> Path:
    """``path`` as a Path if its suffix is a writable video format, else ValueError."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"video path must end in one of {', '.join(VIDEO_SUFFIXES)}, got {str(path)!r}")
    if suffix == ".mp4":
        _mp4_writer()
    if path.is_dir():
        raise ValueError(f"video path {str(path)!r} is a directory")
    return path


def _as_image(frame, shape: tuple[int, ...] | None) -> Image.Image:
    if isinstance(frame, Image.Image):
        image = frame
        size = (image.size[1], image.size[0], 3)
    else:
        arr = np.asarray(frame)
        if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
            raise ValueError(f"frames must be (H, W, 3) uint8 arrays, got {arr.shape} {arr.dtype}")
        image, size = Image.fromarray(arr), arr.shape
    if shape is not None and size != shape:
        raise ValueError(f"all frames must have one size; got {size[:2]} after {shape[:2]}")
    return image


def atomic_write(path: Path, write) -> None:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it onto ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # a fresh name beside the target (not mkstemp: its 0600 mode would survive the rename)
    tmp = str(path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}"))
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_gif(frames: Iterable, path: str | os.PathLike, fps: float = 10.0) -> Path:
    """Write frames as a looping animated GIF.

    Args:
        frames: (H, W, 3) uint8 arrays or Pillow images, all of one size (at least one).
        path: target file, ending in ``.gif``; parent folders are created.
        fps: frames per second (GIF stores delays in 10 ms steps).

    Returns:
        The written path.
    """
    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise ValueError(f"GIF path must end in .gif, got {str(path)!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be finite and > 0, got {fps!r}")
    images: list[Image.Image] = []
    shape = None
    for frame in frames:
        image = _as_image(frame, shape)
        shape = (image.size[1], image.size[0], 3)
        images.append(image)
    if not images:
        raise ValueError("write_gif needs at least one frame")
    duration_ms = max(10, int(round(1000.0 / fps / 10.0)) * 10)

    def write(tmp: str) -> None:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=duration_ms,
                       loop=0)

    atomic_write(path, write)
    return path


def write_mp4(frames: Iterable, path: str | os.PathLike, fps: float = 10.0) -> Path:
    """Write frames as an H.264 MP4 (needs ``imageio-ffmpeg``; frame sides must be even)."""
    path = Path(path)
    if path.suffix.lower() != ".mp4":
        raise ValueError(f"MP4 path must end in .mp4, got {str(path)!r}")
    ffmpeg = _mp4_writer()
    arrays = [np.asarray(_as_image(f, None).convert("RGB")) for f in frames]
    if not arrays:
        raise ValueError("write_mp4 needs at least one frame")
    h, w = arrays[0].shape[:2]
    if h % 2 or w % 2 or any(a.shape != arrays[0].shape for a in arrays):
        raise ValueError("MP4 frames must all have one size with even sides")

    def write(tmp: str) -> None:
        writer = ffmpeg.write_frames(tmp, (w, h), fps=fps, macro_block_size=2)
        writer.send(None)
        for a in arrays:
            writer.send(np.ascontiguousarray(a))
        writer.close()

    atomic_write(path, write)
    return path


def write_video(frames: Iterable, path: str | os.PathLike, fps: float = 10.0) -> Path:
    """:func:`write_gif` or :func:`write_mp4`, chosen by the path's suffix."""
    path = check_video_path(path)
    return write_mp4(frames, path, fps) if path.suffix.lower() == ".mp4" else write_gif(frames, path, fps)


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

    The env is made with ``render_mode="rgb_array"``; the frames it rendered at each
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
        env_kwargs: further ``gymnasium.make`` options of the env.

    Returns:
        The episode record as a dict (``EpisodeRecord`` fields; the record so far when
        ``max_decisions`` stopped the episode early), with ``agent`` filled in.
    """
    from tqdm import tqdm

    from hbmp_bench.agents import load_agent
    from hbmp_bench.envs import TRAINING_ID, make

    path = check_video_path(path)
    if int(every) != every or every < 1:
        raise ValueError(f"every must be an int >= 1, got {every!r}")
    if max_decisions is not None and (int(max_decisions) != max_decisions or max_decisions < 1):
        raise ValueError(f"max_decisions must be an int >= 1 or None, got {max_decisions!r}")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be finite and > 0, got {fps!r}")
    policy = load_agent(agent)
    kwargs = dict(env_kwargs, render_mode="rgb_array", suite=suite)
    if env_id != TRAINING_ID:
        kwargs["episode_index"] = episode_index
    if fidelity is not None:
        kwargs["fidelity"] = fidelity
    env = make(env_id, **kwargs)
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
        obs, info = env.reset(seed=episode_index)
        policy.reset(info)
        collect()
        step_s = float(env.unwrapped.config.step_length_s)
        done, decisions = False, 0
        with tqdm(total=max_decisions, unit="decision", disable=not progress) as bar:
            while not done and (max_decisions is None or decisions < max_decisions):
                obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
                decisions += 1
                bar.update(1)
                collect()
                done = terminated or truncated
        record = dict(info["episode"]) if done else env.unwrapped.world.record().to_dict()
    finally:
        env.close()
    if not frames:
        raise RuntimeError(f"{env_id} rendered no frames; does it support render_mode='rgb_array'?")
    record["agent"] = agent
    write_video(frames, path, fps if fps is not None else 1.0 / (step_s * every))
    return record
