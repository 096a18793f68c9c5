"""The paper's unsignalled intersection (docs/method.md §1): two single-lane roads crossing at
right angles at the origin, the AV along +x, the HV along +y.

The distance is ``sqrt(s_AV^2 + s_HV^2)`` (a conflict along the paths), the crossing line of
each vehicle ``lane_width + length / 2`` (6.5 m) before the conflict point both stops the
library's stop trajectory and decides who went first; the conflict zone of each is
``|s| < min_dist``, and a vehicle has cleared the conflict ``min_dist`` past it.
"""

from __future__ import annotations

from dataclasses import replace

from .. import packing as slot
from ..config import Config
from ..geometry import Path
from .base import (Scenario, crossing_occupancies, pair_min_dist, shape,
                   with_occupancies)


def build(config: Config) -> Scenario:
    """The intersection scenario of ``config``."""
    min_dist = pair_min_dist(config)
    paths = {}
    for who, direction in (("av", (1.0, 0.0)), ("hv", (0.0, 1.0))):
        veh = shape(config, who)
        line = -(config.vehicle.lane_width_m + veh.length_m / 2)
        paths[who] = replace(Path.straight(veh, (0.0, 0.0), direction), yield_s=line,
                             first_s=line, clear_s=min_dist, zone=(-min_dist, min_dist))
    paths = with_occupancies(paths, crossing_occupancies, config)
    scenario = Scenario("intersection", config, paths["av"], paths["hv"],
                        slot.CONFLICT_ALONG_PATHS, min_dist, config.vehicle.lane_width_m)
    scenario.check_starts()
    return scenario
