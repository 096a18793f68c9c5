"""The planner against many outside vehicles: one adapter for every outside simulator
(docs/method.md §12.7).

An outside simulator (highway-env, Eclipse SUMO, a vehicle stack) has many vehicles that the
planner's two-vehicle method never modelled. The simulator's own adapter projects each one
onto its conflict with the ego's path and hands this module a list of :class:`Conflict`:
both vehicles' positions relative to the conflict (negative before it), the other's speed
and limits, and the occupancy intervals of the conflict (where each footprint can touch the
other's path: outside them no overlap is possible). This module does the rest, the same way
for every simulator (:class:`ExternalPlanner`):

- **one planner per conflicting vehicle**, kept while the vehicle conflicts (each holds its
  own belief about that driver's role and its stored prediction of it; a single planner
  switching between vehicles would mix them up), planning against that vehicle while neither
  has cleared the conflict;
- **the most cautious answer**: the lowest of their accelerations, and an IDM gap to a vehicle
  ahead in the ego's own lane (``config.hv.idm``, the ego's ``v_max`` as desired speed);
  without a conflict, full throttle up to ``v_max``;
- **the shield over all of them** (``persuasion.safety.shield.shield_step_many``): the
  acceleration is admitted only if one fallback (brake or go) stays certified against every
  conflicting vehicle and every vehicle ahead in the lane at once, otherwise that fallback is
  applied. A vehicle ahead in the lane is a *follow* conflict: the ego is already in the
  shared lane, so only a leader matters, and the ego keeps the gap of a follower that brakes
  after the step.

Coordinates of a conflict: the ego's ``s`` along its path and the other's along its own, both
zero at the conflict point; for a shared lane (a merge, or a leader), past zero both measure
the same lane, so their difference is the gap between the centres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Hashable, Sequence

import numpy as np

from ..config import Config
from ..safety import shield as sh

#: Kinds of conflict: the paths cross once; the other joins the ego's lane (a merge); the
#: other is ahead in the ego's lane (follow).
CROSSING, MERGE, FOLLOW = "crossing", "merge", "follow"


@dataclass(frozen=True)
class Limits:
    """A vehicle's size and actuation limits."""

    length_m: float
    width_m: float
    u_min_mps2: float
    u_max_mps2: float
    v_min_mps: float
    v_max_mps: float

    @classmethod
    def of(cls, config: Config, who: str) -> Limits:
        v = config.vehicle_of(who)
        return cls(v.length_m, v.width_m, v.u_min_mps2, v.u_max_mps2, v.v_min_mps, v.v_max_mps)


@dataclass(frozen=True)
class Conflict:
    """One outside vehicle on its conflict with the ego's path (module docstring)."""

    key: Hashable  #: the vehicle's identity in the simulator
    kind: str  #: :data:`CROSSING`, :data:`MERGE` or :data:`FOLLOW`
    ego_s_m: float  #: the ego's position relative to the conflict point, along its path [m]
    other_s_m: float  #: the other's, along its own path [m]
    other_v_mps: float  #: the other's speed [m/s]
    #: where the ego's footprint can touch the other's path [m] (a merge: up to the merge
    #: point, 0; follow: unused)
    ego_occupancy: tuple[float, float] = (-math.inf, math.inf)
    #: where the other's footprint can touch the ego's path [m] (a merge: its side zone)
    other_occupancy: tuple[float, float] = (-math.inf, math.inf)
    other: Limits | None = None  #: its limits (default: the configuration's human vehicle)
    #: extra gap a follower keeps [m] (e.g. for a simulator's coarser integration)
    gap_margin_m: float = 0.0
    extra: dict = field(default_factory=dict, compare=False)  #: the adapter's own data


def conflict_arrays(conflicts: Sequence[Conflict], config: Config, ego: Limits
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The shield's inputs for several conflicts: ``(s_R, s_H, v_H, C)`` with ``C`` of shape
    ``(n, N_CONFLICT)`` (``persuasive.safety.shield.conflict_vector``'s layout)."""
    n = len(conflicts)
    s_R, s_H, v_H = np.empty(n), np.empty(n), np.empty(n)
    C = np.empty((n, sh.N_CONFLICT))
    kind = {"off": 0.0, "worst-case": 1.0, "responsive": 2.0}[config.shield]
    human = Limits.of(config, "hv")
    for j, c in enumerate(conflicts):
        o = c.other if c.other is not None else human
        s_R[j], s_H[j] = c.ego_s_m, c.other_s_m
        v_H[j] = min(max(c.other_v_mps, o.v_min_mps), o.v_max_mps)
        row = C[j]
        if c.kind == FOLLOW:  # the ego is in the lane already: only a leader matters
            row[sh.C_R_LO] = row[sh.C_R_HI] = -math.inf
            row[sh.C_H_LO] = row[sh.C_H_HI] = -math.inf
        else:
            row[sh.C_R_LO], row[sh.C_R_HI] = c.ego_occupancy
            row[sh.C_H_LO], row[sh.C_H_HI] = c.other_occupancy
        row[sh.C_SHARED] = 0.0 if c.kind == CROSSING else 1.0
        row[sh.C_GAP] = 0.5 * (ego.length_m + o.length_m) + c.gap_margin_m
        row[sh.C_KIND], row[sh.C_RHO] = kind, config.av.shield_response_s
        row[sh.C_R_UMIN], row[sh.C_R_UMAX] = ego.u_min_mps2, ego.u_max_mps2
        row[sh.C_R_VMIN], row[sh.C_R_VMAX] = ego.v_min_mps, ego.v_max_mps
        row[sh.C_H_UMIN], row[sh.C_H_UMAX] = o.u_min_mps2, o.u_max_mps2
        row[sh.C_H_VMIN], row[sh.C_H_VMAX] = o.v_min_mps, o.v_max_mps
    return s_R, s_H, v_H, C


@dataclass(frozen=True)
class Decision:
    """One decision of :class:`ExternalPlanner`."""

    accel_mps2: float  #: to apply [m/s^2]
    proposed_mps2: float  #: before the shield [m/s^2]
    verdict: str | None  #: the shield's (None when off)
    targets: int  #: vehicles planned against
    conflicts: int  #: vehicles the shield checked


class ExternalPlanner:
    """The ego's planner against many outside vehicles (module docstring).

    ``config``: the planner's configuration (its AV kind, shield and the vehicles' limits);
    ``seed``: the base seed of the per-vehicle planners (vehicle ``i`` met gets ``seed *
    1000 + i``, as the lfg kind draws).
    """

    def __init__(self, config: Config, seed: int = 0):
        self.config = config
        self.seed = seed
        self.ego = Limits.of(config, "av")
        self._planners: dict[Hashable, Any] = {}
        self._made = 0
        # the per-vehicle planners do not shield: the shield runs once, over all vehicles
        self._planner_config = config.with_overrides({"av.shield": "off"})
        from ..record import static_setup

        self._clear_m = float(static_setup(config)[0].hv.clear_s)

    def planner_for(self, key: Hashable):
        """The planner kept for vehicle ``key`` (made when first needed)."""
        from ..planner import Planner

        planner = self._planners.get(key)
        if planner is None:
            planner = self._planners[key] = Planner(self._planner_config,
                                                    seed=self.seed * 1000 + self._made)
            self._made += 1
        return planner

    def act(self, ego_v_mps: float, conflicts: Sequence[Conflict], dt_s: float) -> Decision:
        """The ego's acceleration at speed ``ego_v_mps`` among ``conflicts``."""
        ego, clear = self.ego, self._clear_m
        v = min(max(float(ego_v_mps), ego.v_min_mps), ego.v_max_mps)
        human = Limits.of(self.config, "hv")
        accels, live = [], set()
        leader = None
        for c in conflicts:
            if c.kind == FOLLOW:
                gap = c.other_s_m - c.ego_s_m - 0.5 * (ego.length_m + (
                    c.other or human).length_m)
                if c.other_s_m > c.ego_s_m and (leader is None or gap < leader[0]):
                    leader = (gap, c.other_v_mps)
                continue
            if not (c.other_s_m < clear and c.ego_s_m < clear):
                continue
            live.add(c.key)
            # the planner's model of the human has the configuration's limits
            plan = self.planner_for(c.key).plan(
                av=(c.ego_s_m, v), hv=(c.other_s_m, min(max(c.other_v_mps, human.v_min_mps),
                                                        human.v_max_mps)))
            accels.append(plan.accel_mps2)
        for key in list(self._planners):
            if key not in live:
                del self._planners[key]
        a = min(accels) if accels else ego.u_max_mps2
        if leader is not None:
            a = min(a, idm_follow(self.config, v, leader))
        a = min(max(a, ego.u_min_mps2), ego.u_max_mps2)
        proposed, verdict = a, None
        if self.config.shield != "off":
            s_R, s_H, v_H, C = conflict_arrays(conflicts, self.config, ego)
            a, code = sh.shield_step_many(v, proposed, dt_s, s_R, s_H, v_H, C)
            verdict = sh.VERDICTS[code]
        return Decision(float(a), float(proposed), verdict, len(accels), len(conflicts))


def idm_follow(config: Config, v: float, leader: tuple[float, float]) -> float:
    """IDM acceleration [m/s^2] behind a leader ``(bumper gap [m], speed [m/s])`` with the
    parameters of ``config.hv.idm`` and the ego's ``v_max`` as desired speed."""
    p = config.hv.idm
    v0 = config.vehicle_of("av").v_max_mps
    gap, v_lead = leader
    s_star = p.jam_gap_m + max(0.0, v * p.time_gap_s + v * (v - v_lead) / (
        2.0 * math.sqrt(p.max_accel_mps2 * p.comfort_decel_mps2)))
    return p.max_accel_mps2 * (1.0 - (v / v0) ** p.delta - (s_star / max(gap, 0.1)) ** 2)


__all__ = ["CROSSING", "FOLLOW", "MERGE", "Conflict", "Decision", "ExternalPlanner", "Limits",
           "conflict_arrays", "idm_follow"]
