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
- **the shield over all of them** (``persuasive.safety.shield.shield_filter``, the filter
  every world applies, through :class:`persuasive.safety.filter.ShieldFilter`): the
  acceleration is admitted only if one fallback (brake or go) stays certified against every
  conflicting vehicle and every vehicle ahead in the lane at once, otherwise that fallback is
  applied. A vehicle ahead in the lane is a *follow* conflict: the ego is already in the
  shared lane, so only a leader matters, and the ego keeps the gap of a follower that brakes
  after the step.

Coordinates of a conflict: the ego's ``s`` along its path and the other's along its own, both
zero at the conflict point; for a shared lane (a merge, or a leader), past zero both measure
the same lane, so their difference is the gap between the centres.

For simulators that give each vehicle's route as a centre line (SUMO's lane shapes),
:func:`route_conflict` builds the conflict of two routes once (kind, conflict point,
conservative occupancy intervals; :class:`Polyline`, :class:`RouteConflict`), and
:meth:`RouteConflict.conflict` turns the two vehicles' arc lengths into a :class:`Conflict`
each step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Hashable, Sequence

import numpy as np

from ..config import Config, ConfigError
from ..packing import RIGHT_OF_WAY_IDS, SHIELD_KIND_IDS
from ..safety import shield as sh
from ..safety.filter import ShieldFilter
from ..safety.responsibility import POS_TOL_M, DutyWatch
# the conflict's data, shared with the closed loops' tables (persuasive.tables)
from ..tables import CROSSING, FOLLOW, MERGE, Conflict, Limits, RouteConflict


#: How far before a yield line the world gives (``Conflict.ego_line_m``) the shield's rows
#: put it [m]: an outside world's positions are absolute (a junction's route some 200 m long,
#: a SUMO lane), the rows' relative to each conflict, so the world's next position and the
#: shield's prediction of it may round to different floats. An AV creeping to a stop at its
#: line (its speed halving towards 0, the brake fallback's stop always just before the line)
#: could so be put exactly on the line, which counts as past it, with no certified fallback
#: left (seen at the junction, 60-s runs at the stop line: results §16.5). A nanometre is a
#: million of those roundings. A line given at the interval's start so becomes one that binds
#: (the shield stops the AV at it); the default line (``av.yield_line_m`` before the
#: interval) is left as it was.
LINE_TOL_M = 1e-9


def conflict_arrays(conflicts: Sequence[Conflict], config: Config, ego: Limits
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The shield's inputs for several conflicts: ``(s_R, s_H, v_H, C)`` with ``C`` of shape
    ``(n, N_CONFLICT)`` (``persuasive.safety.shield.conflict_vector``'s layout)."""
    human = Limits.of(config, "hv")
    # the slots every conflict shares: the shield's kind and the ego's limits
    base = [0.0] * sh.N_CONFLICT
    base[sh.C_KIND] = SHIELD_KIND_IDS[config.shield]
    base[sh.C_RHO] = config.av.shield_response_s
    base[sh.C_R_UMIN], base[sh.C_R_UMAX] = ego.u_min_mps2, ego.u_max_mps2
    base[sh.C_R_VMIN], base[sh.C_R_VMAX] = ego.v_min_mps, ego.v_max_mps
    before = config.av.yield_line_m or 0.0
    # the clearance: in the follower's gap; the occupancy intervals are the simulator's own
    # projection's, which keeps its own margins (SUMO: 0.5 m laterally, 1.6 m along the
    # path; highway-env: 0.25 m laterally and the Euler step's), not counted twice
    margin = config.shield_margin_m
    s_R, s_H, v_H, rows = [], [], [], []
    for c in conflicts:
        o = c.other if c.other is not None else human
        s_R.append(c.ego_s_m)
        s_H.append(c.other_s_m)
        v_H.append(min(max(c.other_v_mps, o.v_min_mps), o.v_max_mps))
        row = base[:]
        if c.kind == FOLLOW:  # the ego is in the lane already: only a leader matters
            row[sh.C_R_LO] = row[sh.C_R_HI] = -math.inf
            row[sh.C_H_LO] = row[sh.C_H_HI] = -math.inf
        else:
            row[sh.C_R_LO], row[sh.C_R_HI] = c.ego_occupancy
            row[sh.C_H_LO], row[sh.C_H_HI] = c.other_occupancy
        lo = row[sh.C_R_LO]
        line = lo - before if c.ego_line_m is None else float(c.ego_line_m) - LINE_TOL_M
        row[sh.C_R_LINE] = min(line, lo) if math.isfinite(lo) else lo
        row[sh.C_SHARED] = 0.0 if c.kind == CROSSING else 1.0
        row[sh.C_GAP] = 0.5 * (ego.length_m + o.length_m) + margin
        row[sh.C_H_UMIN], row[sh.C_H_UMAX] = o.u_min_mps2, o.u_max_mps2
        row[sh.C_H_VMIN], row[sh.C_H_VMAX] = o.v_min_mps, o.v_max_mps
        # the cut-in rule with this vehicle as the follower (docs/method.md §12.10): in a merge
        # the ego's braking command is held to the rule's in-lane limit
        rule = config.responsibility.resolved(o, ego)
        row[sh.C_RESP_RHO], row[sh.C_RESP_ACCEL], row[sh.C_RESP_BRAKE], row[sh.C_RESP_FRONT] = rule
        row[sh.C_R_ULANE] = (sh.lane_braking(ego.u_min_mps2, rule[3], 0.0) if c.kind == MERGE
                             else ego.u_min_mps2)
        row[sh.C_PRIORITY] = (RIGHT_OF_WAY_IDS[config.responsibility.right_of_way]
                              if c.right_of_way is None else float(c.right_of_way))
        row[sh.C_RESP_OWED] = 1.0  # until the filter's state says otherwise
        rows.append(row)
    C = np.array(rows, float).reshape(len(rows), sh.N_CONFLICT)
    return (np.array(s_R, float), np.array(s_H, float), np.array(v_H, float), C)


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
    1000 + i``, as the lfg kind draws). ``plan_horizon_s`` (optional): a vehicle gets a game
    only while it could reach its occupancy interval within this time at full throttle (the
    planner's prediction horizon, ``library.n_samples * library.sample_dt_s``, is the natural
    value: a vehicle further away cannot be told from no vehicle by the game); the shield
    still checks every vehicle. ``None`` (the default): every conflicting vehicle gets one.
    """

    def __init__(self, config: Config, seed: int = 0, plan_horizon_s: float | None = None):
        if config.av.yield_line_choices_m:
            raise ConfigError("av.yield_line_choices_m (foresight) predicts a run of our own "
                              "simulator; an outside simulator's traffic is not our model: "
                              "set av.yield_line_m instead")
        if config.yield_line_choices is not None:  # corrected mode's default: not here
            config = config.with_overrides({"av.yield_line_choices_m": []})
        self.config = config
        self.seed = seed
        self.plan_horizon_s = plan_horizon_s
        self.ego = Limits.of(config, "av")
        self._human = Limits.of(config, "hv")
        self._planners: dict[Hashable, Any] = {}
        self._made = 0
        # the per-vehicle planners are the closed loop's planner (the same configuration,
        # features that anticipate the shield included); they only propose (Planner.accel):
        # the one shield filters once, over all vehicles
        self._shield = ShieldFilter(SHIELD_KIND_IDS[config.shield], 0.0, self.ego.u_min_mps2)
        #: the responsibility rule's duties and response clocks per vehicle
        #: (docs/method.md §12.13; None for the other shield kinds)
        self.duties: DutyWatch | None = None
        #: how far past the responsible envelope's stop the duties forgive a vehicle's
        #: position [m] (``DutyWatch.slack_m``: a simulator whose integration rolls a braking
        #: vehicle further than the exact step sets its own)
        self.duty_slack_m = POS_TOL_M
        from ..record import static_setup

        self._clear_m = float(static_setup(config)[0].hv.clear_s)

    def planner_for(self, key: Hashable):
        """The planner kept for vehicle ``key`` (made when first needed)."""
        planner = self._planners.get(key)
        if planner is None:
            from ..planner import Planner

            planner = self._planners[key] = Planner(self.config,
                                                    seed=self.seed * 1000 + self._made)
            self._made += 1
        return planner

    def act(self, ego_v_mps: float, conflicts: Sequence[Conflict], dt_s: float,
            shield_lead_m: float | Callable[[float], float] = 0.0) -> Decision:
        """The ego's acceleration at speed ``ego_v_mps`` among ``conflicts``.

        ``shield_lead_m``: the shield takes the ego this much further along its path than the
        conflicts say [m], or a function of the first step's acceleration giving it (a
        simulator whose integration lets a braking vehicle roll further than the exact step:
        highway-env's Euler step, :func:`persuasive.envs.highway.euler_shift`).
        """
        ego = self.ego
        v = min(max(float(ego_v_mps), ego.v_min_mps), ego.v_max_mps)
        planned, leader = self._planned(v, conflicts)
        a = self._propose(v, planned)
        if a is None:
            a = ego.u_max_mps2
        if leader is not None:
            a = min(a, idm_follow(self.config, v, leader))
        a = min(max(a, ego.u_min_mps2), ego.u_max_mps2)
        proposed = a
        a, verdict = self.shield(v, proposed, conflicts, dt_s, shield_lead_m)
        return Decision(float(a), float(proposed), verdict, len(planned), len(conflicts))

    def _planned(self, v: float, conflicts: Sequence[Conflict]
                 ) -> tuple[list[tuple[Hashable, tuple[float, float], tuple[float, float]]],
                            tuple[float, float] | None]:
        """The conflicts :meth:`act` plans against, each ``(key, ego's pair state, the
        other's)`` (the other's speed within the human's limits, the planner's model), in
        their order, and the leader in the ego's lane (``(bumper gap, speed)`` or None). The
        planners of vehicles no longer planned against are dropped."""
        ego, clear, human, horizon = self.ego, self._clear_m, self._human, self.plan_horizon_s
        planned, live = [], set()
        leader = None
        for c in conflicts:
            if c.extra.get("stand_in"):  # a vehicle not in the simulator yet: the shield's
                continue
            if c.kind == FOLLOW:
                gap = c.other_s_m - c.ego_s_m - 0.5 * (ego.length_m + (
                    c.other or human).length_m)
                if c.other_s_m > c.ego_s_m and (leader is None or gap < leader[0]):
                    leader = (gap, c.other_v_mps)
                continue
            if not (c.other_s_m < clear and c.ego_s_m < clear):
                continue
            o = c.other if c.other is not None else human
            if horizon is not None and sh.reach_time(
                    c.other_s_m, min(max(c.other_v_mps, o.v_min_mps), o.v_max_mps),
                    o.u_max_mps2, c.other_occupancy[0], o.v_min_mps, o.v_max_mps) > horizon:
                continue
            live.add(c.key)
            # the planner's model of the human has the configuration's limits (the states
            # are finite and the speeds clamped: Planner.accel, without the Plan)
            planned.append((c.key, (c.ego_s_m, v), (c.other_s_m, min(max(
                c.other_v_mps, human.v_min_mps), human.v_max_mps))))
        if len(live) != len(self._planners):
            for key in [k for k in self._planners if k not in live]:
                del self._planners[key]
        return planned, leader

    def _propose(self, v: float, planned: list) -> float | None:
        """The proposal against the ``planned`` conflicts (:meth:`_planned`; None: none): the
        lowest of one planner's acceleration per vehicle."""
        accels = [self.planner_for(key).accel(ego, other) for key, ego, other in planned]
        return min(accels) if accels else None

    def shield(self, ego_v_mps: float, proposed_mps2: float, conflicts: Sequence[Conflict],
               dt_s: float, shield_lead_m: float | Callable[[float], float] = 0.0,
               driven: bool = False) -> tuple[float, str | None]:
        """The shield alone (no planning): ``(acceleration to apply [m/s^2], verdict)`` for
        the proposal ``proposed_mps2`` at speed ``ego_v_mps`` among ``conflicts``, as
        :meth:`act` applies it (``shield_lead_m``: as there; verdict None: no shield,
        ``config.shield = "off"``). With the ``responsibility`` kind each vehicle's response
        clock is kept from one call to the next and the duties are watched
        (:attr:`duties`); ``driven``: the proposal is what a driver the shield only judges
        drove (its step is certified only if admitted as it was)."""
        a = float(proposed_mps2)
        if not self._shield.on:
            return ShieldFilter.unfiltered(a)[0], None  # refuses a NaN
        ego = self.ego
        v = min(max(float(ego_v_mps), ego.v_min_mps), ego.v_max_mps)
        s_R, s_H, v_H, C = conflict_arrays(conflicts, self.config, ego)
        watch = None
        if self._shield.kind == SHIELD_KIND_IDS["responsibility"]:
            if self.duties is None:
                self.duties = DutyWatch(dt_s, self.duty_slack_m)
            watch = self.duties
            keys = [c.key for c in conflicts]
            watch.restore(keys, C)
        lead = shield_lead_m if callable(shield_lead_m) else (lambda _: float(shield_lead_m))
        self._shield.dt_s = float(dt_s)
        a, code = self._shield.among(a, v, s_R, s_H, v_H, C,
                                     (lead(a), lead(ego.u_min_mps2), lead(ego.u_max_mps2)))
        verdict = ShieldFilter.name(code)
        if watch is not None:
            watch.step(keys, s_H, v_H, C, verdict == "admitted" if driven
                       else verdict != "uncertified",
                       [not (c.extra.get("stand_in") or c.extra.get("placeholder")
                             or c.extra.get("wreck")) for c in conflicts])
        return a, verdict


def idm_follow(config: Config, v: float, leader: tuple[float, float] | None,
               desired_mps: float | None = None) -> float:
    """IDM acceleration [m/s^2] behind a leader ``(bumper gap [m], speed [m/s])`` (None: the
    free road) with the parameters of ``config.hv.idm`` and the ego's ``v_max`` as desired
    speed (``desired_mps``: another)."""
    p = config.hv.idm
    v0 = config.vehicle_of("av").v_max_mps if desired_mps is None else desired_mps
    if leader is None:
        return p.max_accel_mps2 * (1.0 - (v / v0) ** p.delta)
    gap, v_lead = leader
    s_star = p.jam_gap_m + max(0.0, v * p.time_gap_s + v * (v - v_lead) / (
        2.0 * math.sqrt(p.max_accel_mps2 * p.comfort_decel_mps2)))
    return p.max_accel_mps2 * (1.0 - (v / v0) ** p.delta - (s_star / max(gap, 0.1)) ** 2)


# -- projecting a route onto the ego's: conflicts from centre lines ---------------------------


@dataclass(frozen=True)
class Polyline:
    """A route's centre line: vertices ``xy`` (n, 2) [m] and their arc length ``arc`` (n,)
    [m] from the first vertex."""

    xy: np.ndarray
    arc: np.ndarray

    @classmethod
    def of(cls, points) -> Polyline:
        """From vertices; repeated consecutive vertices are dropped."""
        pts = np.asarray(points, float).reshape(-1, 2)
        keep = np.ones(len(pts), bool)
        keep[1:] = np.any(np.diff(pts, axis=0) != 0.0, axis=1)
        pts = pts[keep]
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        return cls(pts, arc)

    @property
    def length_m(self) -> float:
        return float(self.arc[-1])

    def at(self, s) -> np.ndarray:
        """Points (…, 2) at arc lengths ``s`` [m] (clamped to the line)."""
        s = np.asarray(s, float)
        return np.stack([np.interp(s, self.arc, self.xy[:, 0]),
                         np.interp(s, self.arc, self.xy[:, 1])], axis=-1)

    def samples(self, lo: float, hi: float, step_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths in ``[lo, hi]`` (clamped to the line) at most ``step_m`` apart, ends
        included, and their points."""
        lo, hi = max(lo, 0.0), min(hi, self.length_m)
        n = max(2, int(math.ceil((hi - lo) / step_m)) + 1)
        s = np.linspace(lo, hi, n)
        return s, self.at(s)


def route_conflict(ego: Polyline, other: Polyline, ego_size: tuple[float, float],
                   other_size: tuple[float, float], lateral_margin_m: float = 0.5,
                   long_margin_m: float = 0.05, merge_at: tuple[float, float] | None = None,
                   step_m: float = 0.1) -> RouteConflict | None:
    """The conflict of a vehicle on ``other`` with the ego on ``ego`` (``None``: the routes
    never come close enough for the footprints to touch).

    ``ego_size``, ``other_size``: ``(length, width)`` [m]. A footprint whose centre is at arc
    length ``s`` lies within ``w / 2 + lateral_margin_m`` of the centre line's piece
    ``[s - l / 2, s + l / 2]`` (the margin covers the simulator's lateral tracking and the
    chord of a rectangle on a curve), so two footprints can touch only where two such pieces
    come within ``W = (w_ego + w_other) / 2 + lateral_margin_m``. Both lines are sampled every
    ``step_m``; the pairs of samples within ``W + step_m`` contain every touching pair; the
    occupancy intervals are the hulls of their arc lengths widened by ``l / 2 + step_m / 2 +
    long_margin_m`` (conservative: every overlap lies inside the rectangle they span).

    ``merge_at``: ``(ego arc, other arc)`` of the start of a lane both routes share after
    arriving on different lanes (a merge, :data:`MERGE`: the conflict point is that start;
    the ego's interval ends there, the other's is its side zone, where its footprint can
    touch the ego's anywhere before the merge point). Otherwise a :data:`CROSSING` whose
    conflict point is the closest approach of the two centre lines.
    """
    (l_e, w_e), (l_o, w_o) = ego_size, other_size
    reach = 0.5 * (w_e + w_o) + lateral_margin_m + step_m
    widen_e = 0.5 * l_e + 0.5 * step_m + long_margin_m
    widen_o = 0.5 * l_o + 0.5 * step_m + long_margin_m
    if merge_at is not None:
        a0, b0 = merge_at
        s_e, p_e = ego.samples(0.0, a0 + 0.5 * l_e + step_m, step_m)
        s_o, p_o = other.samples(0.0, b0 + 0.5 * l_e + reach + step_m, step_m)
    else:
        s_e, p_e = ego.samples(0.0, ego.length_m, step_m)
        s_o, p_o = other.samples(0.0, other.length_m, step_m)
    # Every pair of samples (i, j) within reach, i then j ascending: only blocks of `block`
    # consecutive samples whose bounding boxes come within reach are compared sample by
    # sample (a gap between boxes is never more than the distance of two of their samples,
    # rounding included, so no pair is missed). The squared distance is the one the k-d tree
    # this replaces compared with reach ** 2, (x_o - x_e) ** 2 + (y_o - y_e) ** 2, bit for bit.
    block = 32

    def boxes(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per block of samples ``p`` (n, 2): its lowest and highest x and y (nb, 2)."""
        full = -(-p.shape[0] // block) * block
        q = np.concatenate([p, np.repeat(p[-1:], full - p.shape[0], axis=0)])
        q = q.reshape(-1, block, 2)
        return q.min(axis=1), q.max(axis=1)

    lo_e, hi_e = boxes(p_e)
    lo_o, hi_o = boxes(p_o)
    gap = np.maximum(np.maximum(lo_o[None] - hi_e[:, None], lo_e[:, None] - hi_o[None]), 0.0)
    r2 = reach * reach
    be, bo = np.nonzero(gap[..., 0] * gap[..., 0] + gap[..., 1] * gap[..., 1] <= r2)
    k = np.arange(block)
    i = (be[:, None, None] * block + k[None, :, None]).repeat(block, axis=2).ravel()
    j = (bo[:, None, None] * block + k[None, None, :]).repeat(block, axis=1).ravel()
    inside = (i < s_e.shape[0]) & (j < s_o.shape[0])
    i, j = i[inside], j[inside]
    dx, dy = p_o[j, 0] - p_e[i, 0], p_o[j, 1] - p_e[i, 1]
    near = dx * dx + dy * dy <= r2
    if not near.any():
        return None
    i, j = i[near], j[near]
    order = np.argsort(i * s_o.shape[0] + j, kind="stable")
    i, j = i[order], j[order]
    a, b = s_e[i], s_o[j]
    if merge_at is not None:
        a0, b0 = merge_at
        lo_e = float(a[a <= a0].min()) if np.any(a <= a0) else a0
        ego_occ = (lo_e - widen_e - a0, 0.0)
        side = a <= a0 + 0.5 * l_e + 0.5 * step_m
        other_occ = (float(b[side].min()) - widen_o - b0, float(b[side].max()) + widen_o - b0)
        return RouteConflict(MERGE, float(a0), float(b0), ego_occ, other_occ)
    d = np.hypot(*(p_e[i] - p_o[j]).T)
    k = int(np.argmin(d))
    a0, b0 = float(a[k]), float(b[k])
    return RouteConflict(CROSSING, a0, b0,
                         (float(a.min()) - widen_e - a0, float(a.max()) + widen_e - a0),
                         (float(b.min()) - widen_o - b0, float(b.max()) + widen_o - b0))


__all__ = ["CROSSING", "FOLLOW", "MERGE", "Conflict", "Decision", "ExternalPlanner", "Limits",
           "Polyline", "RouteConflict", "conflict_arrays", "idm_follow", "route_conflict"]
