"""Plain state containers shared by the planner, the vehicle model and the executor.

Positions refer to the CENTRE of the vehicle footprint (x east, y north) [m]; yaw is
counter-clockwise from +x [rad]; speeds [m/s].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hbmp_bench.errors import ConfigError

__all__ = ["VehicleState", "Obstacles"]


@dataclass(frozen=True)
class VehicleState:
    """Ego state.

    Attributes:
        x, y: footprint centre [m].
        yaw: heading [rad].
        v: forward speed [m/s] (>= 0; the models never reverse).
        steer: current front-wheel steering angle [rad] (used by the vehicle model's
            steering-rate limit; ignored by the planner).
    """

    x: float
    y: float
    yaw: float
    v: float
    steer: float = 0.0

    def __post_init__(self):
        vals = (self.x, self.y, self.yaw, self.v, self.steer)
        if not all(np.isfinite(vals)):
            raise ConfigError(f"VehicleState must be finite, got {vals}")
        if self.v < 0:
            raise ConfigError(f"VehicleState.v must be >= 0 [m/s], got {self.v}")

    @property
    def xy(self) -> np.ndarray:
        """(2,) position [m]."""
        return np.array([self.x, self.y])

    def as_array(self) -> np.ndarray:
        """``(4,)`` ``[x, y, yaw, v]``."""
        return np.array([self.x, self.y, self.yaw, self.v])


def _arr(a) -> np.ndarray:
    a = np.array(a, dtype=float).reshape(-1)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Obstacles:
    """K surrounding vehicles, each predicted at constant velocity along its heading.

    Attributes (all (K,) float arrays):
        x, y: footprint centre [m].
        yaw: heading [rad].
        v: speed [m/s] along ``yaw``.
        length, width: footprint size [m] (> 0).
    """

    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray
    length: np.ndarray
    width: np.ndarray
    _k: int = field(init=False, repr=False, default=0)

    def __post_init__(self):
        arrs = {n: _arr(getattr(self, n)) for n in ("x", "y", "yaw", "v", "length", "width")}
        k = len(arrs["x"])
        for n, a in arrs.items():
            if a.shape != (k,):
                raise ConfigError(f"Obstacles.{n} has shape {a.shape}, expected ({k},)")
            object.__setattr__(self, n, a)
        table = np.stack(list(arrs.values()))  # one finiteness check for all six (hot path)
        if not np.isfinite(table).all():
            bad = next(n for n, a in arrs.items() if not np.isfinite(a).all())
            raise ConfigError(f"Obstacles.{bad} must be finite")
        if not (table[4:] > 0).all():
            raise ConfigError("Obstacles.length and width must be > 0 [m]")
        object.__setattr__(self, "_k", k)

    def __len__(self) -> int:
        return self._k

    @classmethod
    def empty(cls) -> Obstacles:
        z = np.zeros(0)
        return cls(z, z, z, z, z, z)

    @classmethod
    def from_rows(cls, rows) -> Obstacles:
        """From an iterable of ``(x, y, yaw, v, length, width)`` rows."""
        a = np.asarray(list(rows), dtype=float).reshape(-1, 6)
        return cls(*a.T)

    def subset(self, mask) -> Obstacles:
        """Obstacles selected by a boolean mask or index array."""
        return Obstacles(self.x[mask], self.y[mask], self.yaw[mask], self.v[mask],
                         self.length[mask], self.width[mask])

    def predict(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Constant-velocity positions at times ``t`` (T,) [s] -> ``(x, y)`` each (K, T) [m]."""
        t = np.asarray(t, dtype=float)[None, :]
        return (self.x[:, None] + (self.v * np.cos(self.yaw))[:, None] * t,
                self.y[:, None] + (self.v * np.sin(self.yaw))[:, None] * t)
