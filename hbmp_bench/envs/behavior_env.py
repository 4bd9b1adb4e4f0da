"""Single-ego gymnasium environment: the behavior layer of HBMP on a SUMO town."""

from __future__ import annotations

from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.ego_view import EgoView, keyword_signature
from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv
from hbmp_bench.errors import ConfigError


class BehaviorEnv(EgoView):
    """HBMP behavior environment.

    ## Description
    The ego drives from a start to a goal pose along a global route on a SUMO recreation of a
    CARLA town, among background vehicles and pedestrians driven by SUMO. Each step the agent
    picks one of five behaviors; the behavior is executed until it completes: by default
    (``fidelity="continuous"``) the paper's behavior-conditioned sampling motion planner replans
    at 10 Hz and drives a bicycle model until the ego has converged to the target lane and speed
    (1-8 s, ``info["duration_s"]``); with ``fidelity="event"`` SUMO's speed and lane-change
    commands complete it within one 0.1 s decision (the paper's SUMO stage).

    ## Action space
    ``Discrete(5)``, the paper's order: 0 speed_up, 1 speed_down, 2 change_left, 3 change_right,
    4 keep. A behavior infeasible for R_t (no lane on that side) is executed as keep;
    ``info["action_mask"]`` marks the feasible ones. An action outside 0..4, or a bool, raises ValueError.

    ## Observation space
    ``Dict(occupancy=Box(0, 1, (1, rows, cols), float32), road=Box(0, 2, (10,), float32))``:
    M_t and R_t, see :mod:`hbmp_bench.envs.observation` for every cell and entry.

    ## Rewards
    ``reward="dense"`` (default, HBMP): r_k + r_T. r_k = λ(c̃_total) = −scale · c̃_total
    (``ExecutorConfig.reward_scale``, 0.25), c̃_total the mean cost of
    the planner's chosen trajectories over the behavior (0 in event fidelity); r_T is the paper's
    terminal reward, paid when the event happens: +100 goal, −50 collision or timeout, −10 red
    light, −1 wrong lane / off-road, and −50 more when the episode ends before the goal otherwise
    than by a collision or a timeout (left the network; a violation under the paper's protocol: see
    ``metrics.episode.TERMINAL_REWARD``). ``reward="sparse"`` (HBMP-S): r_T only.
    ``info["reward_components"]`` has both; ``info["planner_costs"]`` the cost terms.

    ## Episode end
    Terminated at the goal (ego centre within the suite's radius, 2 m), when the ego leaves the
    network, and, when the suite says so, at a collision (NoCrash) or any violation (the paper's
    protocol). Truncated at the suite's timeout (CoRL2017: route length at 10 km/h + 10 s and a full red at
    every light on the route).
    ``info["hbmp_record"]`` then holds the episode record (``info["episode"]`` is left to Gymnasium's
    ``RecordEpisodeStatistics`` and SB3's ``Monitor``). ``max_cycles`` truncates at that step
    (the record then says ``end_reason="decision_cap"``); so does Gymnasium's
    ``gym.make(id, max_episode_steps=N)``, without a record.

    ## Arguments
    Keyword-only: ``scenario`` / ``world`` (the frozen configs), or their keyword form, with the
    defaults of :func:`~hbmp_bench.envs.config.env_configs` (the same for every env of the package):
    town, task: which scenario (``Town01``..``Town05`` or an imported map; ``Straight``, ``OneTurn``,
        ``Navigation``, ``NavigationDynamic``).
    suite: episode list and rules (``corl2017`` default, ``hbmp``, ``nocrash-*``).
    episode_index: fix one episode of the list; None draws one per reset from the reset seed.
    random_goals: ignore the suite list and draw a fresh start and goal every reset (training).
    fidelity, reward, decision_period_s: see :class:`WorldConfig` (None: its defaults).
    observation: ``deformed`` or ``vehicle_centric`` M_t; grid options via ``observation_config``.
    road_profile: R_t's entries: ``paper`` (the paper's ten) or ``metric`` (and the stop distance
        and speed in metric units; see :mod:`hbmp_bench.envs.observation`).
    density: override background traffic (``empty``, ``corl``, ``regular``, ``dense``); another
        value raises ValueError here.
    privileged: add the privileged fields to ``info["scene"]`` (the rule-based expert's; see
        :class:`WorldConfig`); default off.
    render_mode: None, ``rgb_array`` (drawn when ``render()`` is called, nothing kept) or
        ``rgb_array_list`` (every SUMO step's frame, returned by ``render()``).
    max_cycles: truncate the episode at this step (None: the suite's rules only).

    ## Implementation
    The parallel env (:class:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv`) with no background
    agent, seen from the ego (:class:`~hbmp_bench.envs.ego_view.EgoView`): one implementation for both.

    ## Version history
    v0: first release.
    """

    def __init__(self, **kwargs):
        scenario, world = kwargs.pop("scenario", None), kwargs.pop("world", None)
        parallel = TrafficParallelEnv(scenario=scenario, world=world, controlled="none",
                                      render_mode=kwargs.pop("render_mode", None), **kwargs)
        if parallel.config.ego_driver != "behavior":
            raise ConfigError(f"BehaviorEnv runs the behavior layer (ego_driver='behavior'), got "
                             f"{parallel.config.ego_driver!r}: the control driver's env is ControlEnv")
        super().__init__(parallel)


BehaviorEnv.__signature__ = keyword_signature(BehaviorEnv)
