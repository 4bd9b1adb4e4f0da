"""Test hygiene shared by every folder."""

import signal
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


@pytest.fixture(autouse=True)
def _ctrl_c_still_interrupts(request):
    """A test that runs a pool child's code in this process (``watch_lifeline`` ignores SIGINT there)
    would leave Ctrl-C ignored here and in every subprocess started later (an ignored signal is
    inherited): restore Python's handler and say which test did it."""
    yield
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        warnings.warn(f"{request.node.nodeid} left SIGINT ignored", stacklevel=1)
