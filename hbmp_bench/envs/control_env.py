"""The flat end-to-end baseline's environment: continuous control without a behavior layer.

The paper's baseline "directly maps input to u without hierarchical modeling": the agent sets the
ego's acceleration and steering every 0.1 s. Same scenarios, traffic, detectors and pictures as
:class:`~hbmp_bench.envs.BehaviorEnv` (it is one, with another driver).

## Action space
``Box(-1, 1, (2,), float32)``: ``[a, s]``: ``a > 0`` throttle (fraction of the bicycle model's
``max_accel``), ``a < 0`` brake (fraction of ``max_decel``); ``s`` steering (fraction of
``max_steer``, positive = left). One action lasts one 0.1 s simulation step (10 Hz).

## Observation space
``occupancy`` M_t as the behavior env; ``road`` (12,): R_t (10 entries, see
:mod:`hbmp_bench.envs.observation`) then the ego's lateral error to the followed lane divided by
the lane width and its heading error divided by π/2, both clipped to [-2, 2].

## Rewards
``reward="dense"``: r_T + r_t with r_t = −dt·(c_dist + c_obs) of the ego's state after the step
(:func:`hbmp_bench.planning.instant_costs`), the paper's baseline reward without the velocity term;
``dt`` = 0.1 s keeps Σr_t on HBMP's per-second scale (one r_k per ~1 s behavior).
``reward="sparse"``: r_T only.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from gymnasium import spaces

from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.envs.drivers import KEEP, ContinuousConfig, ModelDriver
from hbmp_bench.envs.observation import ROAD_FEATURES
from hbmp_bench.maps.roadnet import RoadNetwork
from hbmp_bench.planning import Control, instant_costs
from hbmp_bench.sim.sumo import Actors, SumoSim, VehicleState, VehicleType

LANE_WIDTH_M = 3.5


class ControlDriver(ModelDriver):
    """One 0.1 s control step per decision on the bicycle model; SUMO mirrors the pose.

    Same protocol as :mod:`hbmp_bench.envs.drivers`; :meth:`set_control` gives the action before
    the world begins the "behavior" (which the world labels keep).
    """

    def __init__(self, sim: SumoSim, net: RoadNetwork, vehicle_id: str, vtype: VehicleType,
                 config: ContinuousConfig):
        super().__init__(sim, net, vehicle_id, config)
        self.planner = dataclasses.replace(config.planner, length=vtype.length, width=vtype.width)
        self.dt = config.executor.dt
        self.path = None
        self._control = Control(0.0, 0.0, 0.0)
        self._left = 0
        self._costs = (0.0, 0.0)

    def set_control(self, action: np.ndarray) -> None:
        accel, steer = (float(np.clip(a, -1.0, 1.0)) for a in action)
        self._control = Control(steer=steer, throttle=max(accel, 0.0), brake=max(-accel, 0.0))

    def begin(self, behavior: int, state: VehicleState, lane: str, next_edges: tuple[str, ...]) -> int:
        self.path = self.lane_path(lane, next_edges)
        self._left = 1
        return KEEP

    def before_step(self, others: Actors) -> bool:
        if self._left <= 0:
            return False
        self._left -= 1
        self.advance(self._control)
        obstacles = self.nearby(others)
        self._costs = instant_costs(self.path, self.model, obstacles, self.planner)
        return True

    def behavior_reward(self) -> float:
        """r_t = −dt·(c_dist + c_obs) after the step."""
        return -self.dt * (self.planner.w_dist * self._costs[0] + self.planner.w_obs * self._costs[1])

    def behavior_costs(self) -> dict[str, float]:
        return {"c_dist": self._costs[0], "c_obs": self._costs[1]}

    def errors(self) -> tuple[float, float]:
        """Lateral [m] and heading [rad] error of the ego to the followed lane."""
        if self.path is None:
            return 0.0, 0.0
        _, e, th, _ = self.path.project(self.model.xy, self.model.yaw)
        return float(e), float(th)


class ControlEnv(BehaviorEnv):
    """Acceleration and steering at 10 Hz on the behavior env's scenarios (see the module docstring).

    Arguments as :class:`BehaviorEnv`; ``fidelity`` must be None or ``continuous`` (the ego always
    runs the bicycle model).
    """

    def __init__(self, *args, fidelity: str | None = None, **kwargs):
        if fidelity not in (None, "continuous"):
            raise ValueError(f"the control env always runs the bicycle model; fidelity must be 'continuous', got {fidelity!r}")
        super().__init__(*args, fidelity="continuous", **kwargs)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.observation_space = spaces.Dict(
            occupancy=self.observation_space["occupancy"],
            road=spaces.Box(-2.0, 2.0, (len(ROAD_FEATURES) + 2,), dtype=np.float32),
        )

    @property
    def world(self):
        world = super().world
        if not isinstance(world.driver, ControlDriver):
            from hbmp_bench.sim.sumo import EGO_TYPE

            world.driver = ControlDriver(world.sim, world.net, "ego", EGO_TYPE, self.config.continuous)
        return world

    def _extend(self, obs: dict) -> dict:
        e, th = self.world.driver.errors()
        extra = np.clip([e / LANE_WIDTH_M, th / (np.pi / 2)], -2.0, 2.0).astype(np.float32)
        return {"occupancy": obs["occupancy"], "road": np.concatenate([obs["road"].astype(np.float32), extra])}

    def reset(self, *, seed=None, options=None):
        obs, info = super().reset(seed=seed, options=options)
        w = self.world
        w.driver.path = w.driver.lane_path(w.followed_lane, w._next_edges())
        return self._extend(obs), info

    def step(self, action):
        if not self._running:
            raise RuntimeError("call reset() before step() (and again after an episode ends)")
        action = np.asarray(action, dtype=np.float32).reshape(-1)
        if action.shape != (2,) or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be 2 finite numbers [accel, steer] in [-1, 1], got {action!r}")
        self.world.driver.set_control(action)
        obs, reward, terminated, truncated, info = self.world.step(KEEP)
        for key in ("behavior", "behavior_executed"):
            info.pop(key, None)
        info["control"] = action.tolist()
        info.pop("action_mask", None)
        if terminated or truncated:
            self._running = False
        return self._extend(obs), reward, terminated, truncated, info
