"""GIF writing, episode recording and the ``record`` command."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from hbmp_bench.cli import main
from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.errors import UnknownNameError
from hbmp_bench.envs.recording import record_episode
from hbmp_bench.render.video import write_gif, write_video


def _frames(n: int, h: int = 48, w: int = 64) -> list[np.ndarray]:
    frames = []
    for k in range(n):
        f = np.zeros((h, w, 3), dtype=np.uint8)
        f[:, : (k + 1) * w // n] = (200, 40, 40)
        f[h // 2, :, 1] = 255
        frames.append(f)
    return frames


def test_gif_round_trip(tmp_path):
    frames = _frames(6)
    path = write_gif(frames, tmp_path / "sub" / "clip.gif", fps=5)
    assert sorted(p.name for p in path.parent.iterdir()) == ["clip.gif"]  # no temp file left
    with Image.open(path) as gif:
        assert gif.n_frames == 6
        assert gif.size == (64, 48)
        assert gif.info["duration"] == 200
        for k in range(6):
            gif.seek(k)
            rgb = np.asarray(gif.convert("RGB"))
            np.testing.assert_array_equal(rgb, frames[k])  # 3 colours: exact through the palette


def test_gif_accepts_pillow_images(tmp_path):
    images = [Image.fromarray(f).quantize(16) for f in _frames(3)]
    with Image.open(write_video(images, tmp_path / "clip.gif")) as gif:
        assert gif.n_frames == 3


def test_gif_bad_input(tmp_path):
    with pytest.raises(ValueError, match=".gif"):
        write_gif(_frames(2), tmp_path / "clip.png")
    with pytest.raises(ValueError, match="at least one"):
        write_gif([], tmp_path / "clip.gif")
    with pytest.raises(ValueError, match="one size"):
        write_gif(_frames(1) + _frames(1, h=20), tmp_path / "clip.gif")
    with pytest.raises(ValueError, match="uint8"):
        write_gif([np.zeros((8, 8, 3), dtype=float)], tmp_path / "clip.gif")
    with pytest.raises(ValueError, match="fps"):
        write_gif(_frames(1), tmp_path / "clip.gif", fps=0)
    with pytest.raises(ValueError, match="one of"):
        write_video(_frames(1), tmp_path / "clip.avi")
    assert list(tmp_path.iterdir()) == []


def test_mp4_without_a_writer_says_what_to_install(tmp_path):
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        with pytest.raises(ValueError, match="imageio-ffmpeg"):
            write_video(_frames(2), tmp_path / "clip.mp4")
    else:
        pytest.skip("imageio-ffmpeg is installed")


def test_record_episode_bad_input_fails_before_simulating(tmp_path):
    with pytest.raises(UnknownNameError, match="Town01-Straight-v0"):
        record_episode("hbmp_bench/Town09-Straight-v0", "expert", tmp_path / "a.gif")
    with pytest.raises(UnknownNameError, match="expert"):
        record_episode("hbmp_bench/Town01-Straight-v0", "expret", tmp_path / "a.gif")
    with pytest.raises(ValueError, match=".gif"):
        record_episode("hbmp_bench/Town01-Straight-v0", "expert", tmp_path / "a.avi")
    with pytest.raises(ValueError, match="every"):
        record_episode("hbmp_bench/Town01-Straight-v0", "expert", tmp_path / "a.gif", every=0)
    assert list(tmp_path.iterdir()) == []


def test_record_command_errors_exit_2(tmp_path, capsys):
    assert main(["record", "--env", "hbmp_bench/Town09-Straight-v0", "--out", str(tmp_path / "a.gif")]) == 2
    assert "Town01-Straight-v0" in capsys.readouterr().err
    assert main(["record", "--env", "hbmp_bench/Town01-Straight-v0", "--agent", "expret",
                 "--out", str(tmp_path / "a.gif")]) == 2
    assert "expert" in capsys.readouterr().err
    assert main(["record", "--env", "hbmp_bench/Town01-Straight-v0", "--out", str(tmp_path / "a.avi")]) == 2
    assert ".gif" in capsys.readouterr().err


@pytest.mark.slow
def test_record_episode_end_to_end(tmp_path):
    if "rgb_array" not in BehaviorEnv.metadata.get("render_modes", []):
        pytest.skip("BehaviorEnv has no rgb_array render mode yet")
    path = tmp_path / "episode.gif"
    record = record_episode("hbmp_bench/Town01-Straight-v0", "expert", path, episode_index=0, max_decisions=40,
                            every=4)
    assert record["agent"] == "expert"
    assert record["town"] == "Town01" and record["task"] == "Straight" and record["episode"] == 0
    assert 1 <= record["decisions"] <= 40
    with Image.open(path) as gif:
        # one frame per 0.1 s step, every 4th kept (plus the one after reset)
        steps = round(record["duration_s"] / 0.1)
        assert abs(gif.n_frames - (steps // 4 + 1)) <= 2
        frame = np.asarray(gif.convert("RGB"))
    assert frame.ndim == 3 and frame.std() > 5  # a picture, not a blank
