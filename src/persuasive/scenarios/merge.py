"""A highway on-ramp merge (docs/method.md §10.4).

The HV drives along the main lane (+x, ``y = 0``); the AV's on-ramp comes in from below at
``angle_deg`` (default 30) and joins the main lane at the merge point, the origin, after
which both share the lane (the AV's path continues along +x). Each path's ``s = 0`` is the
merge point, whose first arrival decides who went first.

The distance is the one between the centres, so after the merge it is the longitudinal gap.
Each vehicle's conflict zone starts where it could come within ``min_dist`` of the other path
(``min_dist / sin(angle)`` before the merge point, computed numerically) and never ends (the
lane is shared); the yield line (where the stop trajectory stops) is the start of the zone, and
a vehicle has cleared the merge ``min_dist`` past the merge point.
"""

from __future__ import annotations

import math
from dataclasses import replace

from .. import packing as slot
from ..config import Config
from ..geometry import Path, occupancy_interval, unit, zone_interval
from .base import Scenario, pair_min_dist, shape, with_occupancies

DEFAULT_ANGLE_DEG = 30.0


def merge_occupancies(paths: dict) -> dict:
    """The AV's side zone up to the merge point and the HV's: where its footprint can touch
    the AV's anywhere on that side zone."""
    av_lo = occupancy_interval(paths["av"], paths["hv"])[0]
    return {"av": (av_lo, 0.0),
            "hv": occupancy_interval(paths["hv"], paths["av"], other_range=(av_lo, 0.0))}


def build(config: Config) -> Scenario:
    """The merge scenario of ``config``."""
    angle = config.scenario.angle_deg if config.scenario.angle_deg is not None else \
        DEFAULT_ANGLE_DEG
    min_dist = pair_min_dist(config)
    main = (1.0, 0.0)
    ramp = unit(angle)
    av = Path.bend(shape(config, "av"), (0.0, 0.0), ramp, main)
    hv = Path.straight(shape(config, "hv"), (0.0, 0.0), main)
    paths = {}
    for who, path, other in (("av", av, hv), ("hv", hv, av)):
        zone = zone_interval(path, other, min_dist)
        paths[who] = replace(path, yield_s=zone[0], first_s=0.0, clear_s=min_dist,
                             zone=(zone[0], math.inf))
    # Occupancy (docs/method.md §12.1): the AV's ramp footprint reaches into the main lane
    # from ``av_lo`` on; up to the merge point that is the side zone, past it both share the
    # lane (a car-following conflict). The HV's side zone: where its footprint can touch the
    # AV's anywhere on the side zone.
    paths = with_occupancies(paths, merge_occupancies, config)
    scenario = Scenario("merge", config, paths["av"], paths["hv"], slot.CONFLICT_EUCLIDEAN,
                        min_dist, config.vehicle.lane_width_m, lane_shared=True)
    scenario.check_starts()
    return scenario
