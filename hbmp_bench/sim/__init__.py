"""The one room that talks to SUMO: libsumo in-process for the first simulation of a process,
TraCI to a ``sumo`` child process for any further one (see :mod:`hbmp_bench.sim.sumo`)."""

from hbmp_bench.sim.sumo import BACKGROUND_TYPE, EGO_TYPE, Actors, LightAhead, SumoSim, VehicleState, VehicleType

__all__ = ["BACKGROUND_TYPE", "EGO_TYPE", "Actors", "LightAhead", "SumoSim", "VehicleState", "VehicleType"]
