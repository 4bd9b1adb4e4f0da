"""Pictures: a headless top-down renderer, episode GIFs and the planner figure.

* :class:`SceneView` -- what to draw at one instant (world coordinates).
* :class:`TopDownRenderer`, :class:`RenderConfig` -- ``SceneView`` -> RGB frame (H, W, 3) uint8.
* :func:`write_gif`, :func:`write_video` -- frames to an animated GIF (MP4 with imageio-ffmpeg);
  an agent's episode is recorded by :func:`hbmp_bench.envs.recording.record_episode` (render never
  imports envs).
* :func:`planner_figure` -- the motion planner's samples and costs per behavior (PNG).
* :func:`~.stopping_figure.stopping_figure` -- speed over distance of a speed_down chain that
  stops the ego from the speed limit, both fidelities (runs SUMO).

Commands: ``hbmp-bench record``, ``hbmp-bench plot-planner`` and ``hbmp-bench plot-stopping``
(:mod:`.commands`).
"""

from hbmp_bench.render.planner_figure import planner_figure
from hbmp_bench.render.scene import SIGNAL_STATES, SceneView
from hbmp_bench.render.topdown import VIEWS, RenderConfig, TopDownRenderer, ViewTransform
from hbmp_bench.render.video import write_gif, write_video

__all__ = ["SIGNAL_STATES", "VIEWS", "RenderConfig", "SceneView", "TopDownRenderer", "ViewTransform",
           "planner_figure", "write_gif", "write_video"]
