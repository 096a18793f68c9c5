"""Scenarios: the geometry of two paths and everything that depends on it (docs/method.md §10).

A scenario fills one template (:class:`persuasive.scenarios.base.Scenario`): each vehicle's
:class:`~persuasive.geometry.Path` with its lines (the yield line its stop trajectory stops
at, the line whose first arrival decides who went first, the position past which it has
cleared the conflict) and its conflict zone, the kind of conflict (which distance the game and
the safety checks use), the safety distance, and the initial-state sampling. The loop, the
agents and the game know nothing else of the geometry.

One module per scenario, each with a ``build(config) -> Scenario`` function, registered in
:data:`SCENARIOS` by the name ``[scenario] kind`` selects:

- ``intersection``: the paper's, two single-lane roads crossing at right angles;
- ``crossing``: two straight roads crossing at ``angle_deg`` (90: the intersection, bit for bit);
- ``left-turn``: the AV turns left on an arc across the lane of an oncoming HV;
- ``merge``: the AV's on-ramp joins the HV's lane at ``angle_deg``; then both share the lane.
"""

from __future__ import annotations

from typing import Callable

from .base import InitialStateError, Scenario, first_arrival
from . import crossing, intersection, left_turn, merge

#: Scenario builders by ``[scenario] kind``.
SCENARIOS: dict[str, Callable] = {
    "intersection": intersection.build,
    "crossing": crossing.build,
    "left-turn": left_turn.build,
    "merge": merge.build,
}


def build_scenario(config) -> Scenario:
    """The :class:`Scenario` that ``config.scenario.kind`` names, built from ``config``; a
    many-vehicle kind (``junction``) is refused in one line: it is no pair of paths but
    ``persuasive.many``'s world."""
    build = SCENARIOS.get(config.scenario.kind)
    if build is None:
        from ..config import ConfigError

        raise ConfigError(f"scenario.kind = {config.scenario.kind} is a world of many vehicles "
                          "(persuasive.many); this needs a two-vehicle scenario: "
                          + " | ".join(SCENARIOS))
    return build(config)


__all__ = ["SCENARIOS", "InitialStateError", "Scenario", "build_scenario", "first_arrival"]
