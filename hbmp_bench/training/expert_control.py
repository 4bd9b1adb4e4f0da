"""The label of ``flat-il``: the control the expert's stack applies in the ego's state now (see
:mod:`hbmp_bench.training.control_dagger`). Apart from the trainer so that a training worker, which computes
it, imports no training loop."""

from __future__ import annotations

from typing import Any

import numpy as np

from hbmp_bench.errors import ConfigError


class ExpertControl:
    """The expert's control in the ego's current state: the label of ``flat-il`` (see the module docstring).

    Args:
        expert: the rule-based expert (default: a new :class:`~hbmp_bench.agents.expert.ExpertAgent`); its
            env must be made with the options it asks for (``privileged=True``).

    The env is a :class:`~hbmp_bench.envs.control_env.ControlEnv` (or any view whose world's ego runs the
    control driver); :meth:`label` reads its world after a reset or a step.
    """

    def __init__(self, expert=None):
        if expert is None:
            from hbmp_bench.agents.expert import ExpertAgent

            expert = ExpertAgent()
        self.expert = expert
        self._shadow = None
        self._sim = None

    def reset(self, info: dict[str, Any]) -> None:
        """A new episode (the expert's own reset)."""
        self.expert.reset(info)

    def behavior(self, env, observation: dict, info: dict) -> int:
        """The expert's behavior for ``observation`` (the control env's info lacks the behavior mask: the
        ego's feasible behaviors, as the behavior env reports them)."""
        ego = env.world.ego
        return int(self.expert.act(observation, {**info, "action_mask": ego.action_mask()}))

    def shadow_driver(self, world):
        """The continuous fidelity's driver for the world's ego, built once per simulation: the planner,
        tracker and vehicle model the behavior env would drive the ego with."""
        if world.config.ego_driver != "control":
            raise ConfigError(f"expert controls label the control driver's ego, not ego_driver="
                              f"{world.config.ego_driver!r}")
        if self._shadow is None or self._sim is not world.sim:
            from hbmp_bench.envs.world import EGO_ID
            from hbmp_bench.sim.sumo import EGO_TYPE

            self._shadow = world.make_driver(EGO_ID, EGO_TYPE, "continuous")
            self._sim = world.sim
        return self._shadow

    def control(self, world, behavior: int) -> np.ndarray:
        """(2,) float32 ``[a, s]``: the first control period of ``behavior`` begun from the ego's state now
        (an infeasible lane change as keep, as :meth:`ControlledVehicle.begin` runs it), planned among the
        actors the ego's driver sees; the vehicle is not moved."""
        from hbmp_bench.envs.drivers import feasible_behaviors
        from hbmp_bench.planning.behaviors import Behavior

        ego = world.ego
        shadow = self.shadow_driver(world)
        shadow.model = ego.driver.model
        if not feasible_behaviors(world.net, ego.state.lane, ego.state.lane_pos)[behavior]:
            behavior = Behavior.KEEP
        shadow.begin(behavior, ego.state, ego.route.begin_lane(), ego.next_edges(), ego.next_lanes())
        control, _ = shadow.executor.step(shadow.model, shadow.nearby(ego.actors))
        return np.array([control.throttle - control.brake, control.steer], dtype=np.float32)

    def label(self, env, observation: dict, info: dict) -> tuple[int, np.ndarray]:
        """(the expert's behavior, its control ``[a, s]``) in the state of ``observation``."""
        behavior = self.behavior(env, observation, info)
        return behavior, self.control(env.world, behavior)
