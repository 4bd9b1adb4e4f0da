"""Reference baselines: uniform random behaviors, and always keep."""

from __future__ import annotations

import numpy as np

from hbmp_bench.agents.base import register_agent


@register_agent("random")
class RandomAgent:
    """Uniformly random behavior among the feasible ones (``info["action_mask"]``)."""

    name = "random"

    def __init__(self, seed: int = 0):
        self.rng = np.random.default_rng(seed)

    def reset(self, info):
        pass

    def act(self, observation, info):
        return int(self.rng.choice(np.flatnonzero(info["action_mask"])))


@register_agent("keep")
class KeepAgent:
    """Always ``keep``: holds the current speed (standing still from the start)."""

    name = "keep"

    def reset(self, info):
        pass

    def act(self, observation, info):
        return 4
