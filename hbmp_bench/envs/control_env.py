"""The flat end-to-end baseline's environment: continuous control without a behavior layer.

The paper's baseline "directly maps input to u without hierarchical modeling": the agent sets the
ego's acceleration and steering every 0.1 s. Same scenarios, traffic, detectors and pictures as
:class:`~hbmp_bench.envs.BehaviorEnv`: the same parallel env with the ego's driver configured as
:class:`~hbmp_bench.envs.drivers.ControlDriver` (``ego_driver="control"``).

## Action space
``Box(-1, 1, (2,), float32)``: ``[a, s]``: ``a > 0`` throttle (fraction of the bicycle model's
``max_accel``), ``a < 0`` brake (fraction of ``max_decel``); ``s`` steering (fraction of
``max_steer``, positive = left). One action lasts one 0.1 s simulation step (10 Hz).

## Observation space
``occupancy`` M_t as the behavior env; ``road`` (12,): R_t (10 entries, see
:mod:`hbmp_bench.envs.observation`) then the ego's lateral error to the followed lane divided by
the lane width and its heading error divided by π/2, both clipped to [-2, 2].

## Rewards
``reward="dense"``: r_T + r_t with r_t = λ(dt·(c_dist + c_obs)) of the ego's state after the step
(:func:`hbmp_bench.planning.instant_costs`), the paper's baseline reward without the velocity term;
``dt`` = 0.1 s keeps Σr_t on HBMP's per-second scale (one r_k per ~1 s behavior).
``reward="sparse"``: r_T only.
``reward="carla"``: CARLA's reinforcement-learning baseline reward (the A3C row of the paper's Tab. I), paid every
step: 1 per metre of route progress, 0.05 per km/h of speed gained, −2 per collision, off-road or wrong-lane event
(:data:`~hbmp_bench.metrics.episode.CARLA_RL_REWARD`); no r_T (``info["reward_components"]`` logs it).
"""

from __future__ import annotations

from hbmp_bench.envs.ego_view import EgoView, keyword_signature
from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv
from hbmp_bench.errors import ConfigError


class ControlEnv(EgoView):
    """Acceleration and steering at 10 Hz on the behavior env's scenarios (see the module docstring).

    Arguments as :class:`~hbmp_bench.envs.BehaviorEnv`; ``fidelity`` must be None or ``continuous``
    (the ego always runs the bicycle model). The parallel env with ``ego_driver="control"``: its
    door validates ``[a, s]`` (:func:`~hbmp_bench.envs.actions.check_action`), the driver takes it
    (:class:`~hbmp_bench.envs.drivers.ControlDriver`), R_t's two error entries are the driver's
    (``road_extra``), and ``info`` has ``control`` (the action) and no behavior keys.
    """

    def __init__(self, **kwargs):
        scenario, world = kwargs.pop("scenario", None), kwargs.pop("world", None)
        if world is not None and world.ego_driver != "control":
            raise ConfigError(f"ControlEnv drives with ego_driver='control', got world.ego_driver={world.ego_driver!r}")
        if world is None:
            kwargs["ego_driver"] = kwargs.get("ego_driver", "control")
            if kwargs["ego_driver"] != "control":
                raise ConfigError(f"ControlEnv drives with ego_driver='control', got {kwargs['ego_driver']!r}")
        super().__init__(TrafficParallelEnv(scenario=scenario, world=world, controlled="none",
                                            render_mode=kwargs.pop("render_mode", None), **kwargs))


ControlEnv.__signature__ = keyword_signature(ControlEnv)
