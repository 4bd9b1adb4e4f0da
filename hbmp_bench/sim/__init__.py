"""The one room that talks to SUMO (libsumo, in-process)."""

from hbmp_bench.sim.sumo import BACKGROUND_TYPE, EGO_TYPE, Actors, LightAhead, SumoSim, VehicleState, VehicleType

__all__ = ["BACKGROUND_TYPE", "EGO_TYPE", "Actors", "LightAhead", "SumoSim", "VehicleState", "VehicleType"]
