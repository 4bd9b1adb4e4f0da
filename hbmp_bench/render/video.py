"""Frames to files: animated GIFs (Pillow), MP4 when ``imageio-ffmpeg`` is installed (an agent's
episode is recorded by :func:`hbmp_bench.envs.recording.record_episode`).

Files are written atomically: to a temporary file beside the target, then renamed.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image

from hbmp_bench.errors import UserError

VIDEO_SUFFIXES = (".gif", ".mp4")


def _mp4_writer():
    """The ``imageio_ffmpeg`` module, or a ValueError saying how to get it."""
    try:
        import imageio_ffmpeg
    except ImportError as exc:
        raise UserError("writing .mp4 needs the optional package imageio-ffmpeg "
                         "(pip install imageio-ffmpeg); write a .gif instead") from exc
    return imageio_ffmpeg


def check_video_path(path: str | os.PathLike) -> Path:
    """``path`` as a Path if its suffix is a writable video format, else ValueError."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise UserError(f"video path must end in one of {', '.join(VIDEO_SUFFIXES)}, got {str(path)!r}")
    if suffix == ".mp4":
        _mp4_writer()
    if path.is_dir():
        raise UserError(f"video path {str(path)!r} is a directory")
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
        raise UserError(f"GIF path must end in .gif, got {str(path)!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise UserError(f"fps must be finite and > 0, got {fps!r}")
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
        raise UserError(f"MP4 path must end in .mp4, got {str(path)!r}")
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
