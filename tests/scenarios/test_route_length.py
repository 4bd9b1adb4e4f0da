"""Route lengths are what a car drives: the expert, driving to the goal in SUMO, covers them.

Event fidelity (SUMO drives the ego): its odometer matches continuous fidelity's on these routes
(medians 1.003-1.006 on all 25 Straight episodes of Town01 and Town03, both fidelities); each of
SUMO's instantaneous lane changes adds ~3 m of sideways jump to it, which the median ignores.
"""

import numpy as np
import pytest

from hbmp_bench.agents import agent_env_kwargs, load_agent
from hbmp_bench.envs import make

EPISODES = range(10)
MAX_STEP_M = 1.6
"""Most progress one 0.1 s decision can add: the expert cruises below 15 m/s [m]."""


def _drive(town: str, index: int) -> tuple[dict, np.ndarray]:
    """The expert's record of one Straight episode and its progress [m] after every decision."""
    agent = load_agent("expert")
    env = make(f"hbmp_bench/{town}-Straight-v0", episode_index=index, fidelity="event", **agent_env_kwargs(agent)).unwrapped
    try:
        obs, info = env.reset(seed=0)
        agent.reset(info)
        progress = [info["route_completion"]]
        while True:
            obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
            progress.append(info["route_completion"])
            if terminated or truncated:
                record = info["hbmp_record"]
                return record, np.array(progress) * record["route_length_m"]
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("town", ["Town01", "Town03"])
def test_expert_drives_the_route_length_on_straight_routes(town):
    ratios = []
    for index in EPISODES:
        record, progress = _drive(town, index)
        assert record["end_reason"] == "goal", (town, index, record["end_reason"])
        ratios.append(record["distance_m"] / record["route_length_m"])
        steps = np.diff(progress[:-1])  # the last step is the goal, which completes the route
        assert steps.min() >= 0.0 and steps.max() < MAX_STEP_M, (town, index, steps.max())  # no jump at junctions
        assert progress[-2] > record["route_length_m"] - 3.0  # the goal is 2 m around the route's end
    assert 0.97 <= float(np.median(ratios)) <= 1.05, ratios
