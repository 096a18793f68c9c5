"""An unprotected left turn (docs/method.md §10.3).

Right-hand traffic on a two-lane road crossing a two-lane road, lanes ``w`` wide, the
junction box ``|x|, |y| <= w``. The AV comes from the south in the northbound lane
(``x = w/2``) and turns left on a quarter circle of radius ``R`` (default ``1.5 w``, from box
edge to box edge) into the westbound lane (``y = w/2``); the HV comes from the north in the
southbound lane (``x = -w/2``) and drives straight on. Their paths cross once, inside the box;
each path's ``s = 0`` is that conflict point.

The distance combines the vehicles' distances along their paths to the conflict point,
``sqrt(s_AV^2 + s_HV^2)``, as at the paper's intersection (a conflict along the paths): the
centres of the two vehicles pass within 4 m of each other on their straight approaches, in
adjacent lanes, which must not count as a conflict. Footprint collisions are tested on the
oriented rectangles. Each vehicle's crossing line is where its front enters the box; it
decides who went first and is where the stop trajectory stops. The conflict zone of each is
``|s| < min_dist``; past it the vehicle has cleared.
"""

from __future__ import annotations

import math
from dataclasses import replace

from .. import packing as slot
from ..config import Config
from ..geometry import Path
from .base import (Scenario, crossing_occupancies, pair_min_dist, shape,
                   with_occupancies)


def build(config: Config) -> Scenario:
    """The left-turn scenario of ``config``."""
    w = config.vehicle.lane_width_m
    r = config.scenario.turn_radius_m if config.scenario.turn_radius_m is not None else 1.5 * w
    min_dist = pair_min_dist(config)
    av_veh, hv_veh = shape(config, "av"), shape(config, "hv")
    # The AV's arc starts heading north at (w/2, y0), centred at (w/2 - r, y0), and ends heading
    # west at y = y0 + r; choose y0 so that it ends in the westbound lane (y = w/2).
    y0 = w / 2 - r
    cx, cy = w / 2 - r, y0
    # where the arc meets the HV's lane centre x = -w/2: the quarter circle spans x from w/2
    # down to w/2 - r, so it crosses that lane only when r > w
    dx = -w / 2 - cx
    if not r > w:
        from ..config import ConfigError

        raise ConfigError(f"scenario.turn_radius_m = {r:g} is out of range; allowed: above "
                          f"{w:g} (one lane width), so that the turn crosses the oncoming lane")
    y_c = cy + math.sqrt(r * r - dx * dx)
    phi_c = math.atan2(y_c - cy, -w / 2 - cx)  # polar angle of the conflict point
    s_arc_start = -r * phi_c  # the arc starts at polar angle 0
    av = Path.turn(av_veh, (w / 2, y0), math.pi / 2, r, math.pi / 2, s_arc_start)
    hv = Path.straight(hv_veh, (-w / 2, y_c), (0.0, -1.0))
    # first-arrival lines: the front enters the box (y = -w for the AV, y = +w for the HV)
    av_first = s_arc_start + (-w - av_veh.length_m / 2 - y0)
    hv_first = -((w + hv_veh.length_m / 2) - y_c)
    paths = {}
    for who, path, first in (("av", av, av_first), ("hv", hv, hv_first)):
        paths[who] = replace(path, yield_s=first, first_s=first, clear_s=min_dist,
                             zone=(-min_dist, min_dist))
    paths = with_occupancies(paths, crossing_occupancies, config)
    scenario = Scenario("left-turn", config, paths["av"], paths["hv"],
                        slot.CONFLICT_ALONG_PATHS, min_dist, w)
    scenario.check_starts()
    return scenario
