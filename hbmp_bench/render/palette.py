"""Colours of the top-down renderer (RGB 0-255); one place so frames and tests agree."""

from __future__ import annotations

BACKGROUND = (52, 60, 52)
ROAD = (78, 78, 84)
SIDEWALK = (168, 164, 150)
KERB = (120, 118, 110)
MARKING = (232, 232, 232)
CENTRE_LINE = (236, 190, 40)

EGO = (20, 150, 255)
EGO_OUTLINE = (255, 255, 255)
VEHICLE = (226, 226, 232)
VEHICLE_OUTLINE = (30, 30, 34)
PEDESTRIAN = (255, 128, 0)

ROUTE = (70, 150, 255)
ROUTE_ALPHA = 0.35
GOAL = (230, 30, 200)

PLAN_FEASIBLE = (170, 225, 255)
PLAN_INFEASIBLE = (240, 70, 70)
PLAN_CHOSEN = (40, 235, 110)

CAPTION_TEXT = (255, 255, 255)
CAPTION_BACK = (0, 0, 0)
CAPTION_ALPHA = 0.55

SIGNAL = {
    "r": (235, 35, 35), "R": (235, 35, 35),
    "y": (255, 190, 0), "Y": (255, 190, 0), "u": (255, 190, 0), "U": (255, 190, 0),
    "g": (30, 200, 70), "G": (30, 200, 70), "s": (30, 200, 70),
    "o": (150, 150, 150), "O": (150, 150, 150),
}
"""Stop-bar colour per SUMO signal character."""
