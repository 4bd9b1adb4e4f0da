"""The one rule for an action at the env's door: what an agent may send for a space, and the
canonical value the layers below it receive.

- ``Discrete(n)`` (the behaviors): an int, a numpy integer or a 0-d integer array in
  ``[start, start + n)``; never a bool (Python counts ``True`` as 1, no behavior is a truth value).
  Canonical form: a Python ``int``.
- ``Box`` (the flat baseline's ``[accel, steer]``): finite numbers, as many as the space has,
  in any array-like shape of that size. Canonical form: a ``float32`` array of the space's shape.
  Values outside the bounds are clipped by the driver (what a Gaussian policy samples), unless
  ``strict`` asks for an element of the space (the evaluator: an untrusted agent's action must
  belong to the space it was given).

Every env of the package validates through :func:`check_action` once, in
:meth:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv.check_actions`; the evaluator asks the same
function before it steps the env, so that a bad action counts as the agent's error.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from hbmp_bench.planning.behaviors import BEHAVIORS

CONTROL_FIELDS = ("accel", "steer")
"""The flat baseline's action entries, in order (see :mod:`hbmp_bench.envs.control_env`)."""
CONTROL_SPACE = spaces.Box(-1.0, 1.0, (len(CONTROL_FIELDS),), dtype=np.float32)
"""The flat baseline's action space: fractions of the bicycle model's limits."""
BEHAVIOR_SPACE = spaces.Discrete(len(BEHAVIORS))
"""The behavior layer's action space, in the paper's order (:data:`~hbmp_bench.planning.behaviors.BEHAVIORS`)."""


def check_action(space: spaces.Space, action: Any, what: str = "action", strict: bool = False) -> int | np.ndarray:
    """``action`` in its canonical form for ``space`` (see the module docstring).

    Raises:
        ValueError: ``action`` is no action of ``space``; the message names ``what``, the valid
            values and what was given, on one line.
    """
    if isinstance(space, spaces.Discrete):
        start, n = int(space.start), int(space.n)
        value = action.item() if isinstance(action, np.ndarray) and action.shape == () and \
            np.issubdtype(action.dtype, np.integer) else action
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or \
                not start <= int(value) < start + n:
            names = f" ({', '.join(BEHAVIORS)})" if n == len(BEHAVIORS) and start == 0 else ""
            raise ValueError(f"{what} must be an int in [{start}, {start + n}){names}, "
                             f"got {type(action).__name__} {_short(action)}")
        return int(value)
    if isinstance(space, spaces.Box):
        try:
            array = np.asarray(action, dtype=space.dtype).reshape(-1)
        except (TypeError, ValueError):
            array = None
        if array is None or array.size != int(np.prod(space.shape)) or not np.all(np.isfinite(array)) or \
                strict and not space.contains(array.reshape(space.shape)):
            fields = f" [{', '.join(CONTROL_FIELDS)}]" if space.shape == CONTROL_SPACE.shape else ""
            raise ValueError(f"{what} must be {int(np.prod(space.shape))} finite numbers{fields} in "
                             f"[{float(np.min(space.low)):g}, {float(np.max(space.high)):g}], got {_short(action)}")
        return array.reshape(space.shape)
    if not space.contains(action):
        raise ValueError(f"{what} must be an element of {space}, got {_short(action)}")
    return action


def _short(value: Any) -> str:
    """``repr(value)`` on one line, at most 80 characters."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:77] + "..."
