"""Test hygiene shared by every folder."""

import sys
import warnings

import pytest


@pytest.fixture(autouse=True)
def _no_simulation_outlives_its_test(request):
    """A test that leaves a libsumo simulation open would push every later simulation of this
    process onto TraCI (``SumoSim``: the first holds libsumo): close it and say which test leaked."""
    yield
    sumo = sys.modules.get("hbmp_bench.sim.sumo")
    holder = getattr(getattr(sumo, "SumoSim", None), "_libsumo_holder", None)
    if holder is not None:
        holder.close()
        warnings.warn(f"{request.node.nodeid} left a libsumo simulation open", stacklevel=1)
