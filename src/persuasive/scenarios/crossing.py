"""Two straight single-lane roads crossing at an angle (docs/method.md §10.2).

The AV drives along +x through the origin, the HV along the direction at ``angle_deg`` from
it (90: the paper's intersection, built by ``persuasive.scenarios.intersection`` so that it
equals it bit for bit). The distance is the one between the centres; the crossing line of
each vehicle is where its front enters the other's lane strip, ``lane_width / sin(angle) +
length / 2`` before the conflict point, and decides who went first; the conflict zone is
``|s| < min_dist / sin(angle)`` (widened a little), past which the vehicle has cleared.
"""

from __future__ import annotations

import math
from dataclasses import replace

from .. import packing as slot
from ..config import Config
from ..geometry import Path, unit
from . import intersection
from .base import (Scenario, crossing_occupancies, pair_min_dist, shape,
                   with_occupancies)

DEFAULT_ANGLE_DEG = 90.0


def build(config: Config, perpendicular_at_90: bool = True) -> Scenario:
    """The crossing scenario of ``config`` (the intersection when the angle is 90 deg).

    ``perpendicular_at_90=False`` builds the right angle with the general (euclidean)
    distance instead; the tests use it to check that both give the same runs bit for bit.
    """
    angle = config.scenario.angle_deg if config.scenario.angle_deg is not None else \
        DEFAULT_ANGLE_DEG
    if angle == 90.0 and perpendicular_at_90:
        return replace(intersection.build(config), kind="crossing")
    min_dist = pair_min_dist(config)
    sin = 1.0 if angle == 90.0 else math.sin(math.radians(angle))
    reach = min_dist / sin  # the kernels' window is widened a little (persuasive.packing)
    paths = {}
    for who, direction in (("av", (1.0, 0.0)), ("hv", unit(angle))):
        veh = shape(config, who)
        line = -(config.vehicle.lane_width_m / sin + veh.length_m / 2)
        paths[who] = replace(Path.straight(veh, (0.0, 0.0), direction), yield_s=line,
                             first_s=line, clear_s=reach, zone=(-reach, reach))
    paths = with_occupancies(paths, crossing_occupancies, config)
    scenario = Scenario("crossing", config, paths["av"], paths["hv"], slot.CONFLICT_EUCLIDEAN,
                        min_dist, config.vehicle.lane_width_m)
    scenario.check_starts()
    return scenario
