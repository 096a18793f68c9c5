"""The world of N vehicles at the junction: a vehicles table, a conflict table, the closed loop
(docs/method.md §15).

**Vehicles table** (held by :class:`JunctionWorld`: ``routes``, ``limits``, the arrivals'
kinds and times, and the arrays ``s``, ``v``, ``status``): per vehicle its route
(``persuasive.many.junction``), limits, kind and state ``(s, v)`` along its route; vehicle 0
is the AV (absent in a run
``with_av=False``, the reference that measures the delay the AV causes).

**Conflict table** (:class:`ConflictTable`, built once per run by :func:`conflict_table`, the
one builder): one row per pair of vehicles whose routes come close enough for the footprints
to touch: ``follow`` (the same inbound lane; shared up to the box, or to the end on the same
route), ``merge`` (different inbound lanes into one exit lane, conflict point at the box's
far edge) or ``crossing`` (the centre lines' closest approach), with both conflict points,
both occupancy intervals (``persuasive.envs.external.route_conflict``), the right of way
(``persuasive.many.junction.right_of_way``) and each side's stop line. Pairs without a row
can never touch.

**A step** (:meth:`JunctionWorld.step`): every vehicle decides on the same states, then all
advance (the saturated step), then every row is checked for overlap:

- the **AV** drives as the outside-simulator adapters do (``persuasive.envs.external``,
  :class:`~persuasive.envs.external.ExternalPlanner`): one planner per conflicting human, the
  lowest acceleration (``junction.av_plan = "pairwise"``) or one plan against all of them
  (``"joint"``, ``persuasive.many.joint``), IDM behind a leader in its lane, and the one
  shield over every conflict, its yield line at its stop line;
- each **human** (:class:`Human`) computes, in this order: IDM behind the nearest vehicle
  ahead in its lane (or, before a merge, ahead in the exit lane) or behind the start of its
  occupancy interval of any conflict another vehicle is inside of (as behind a standing car:
  it does not drive into an occupied conflict), or the free-road IDM term;
  its own pair policy against the vehicle it conflicts with next (the uncleared crossing or
  merge whose conflict point it reaches first; among several at one point, the other vehicle
  nearest to it), in that pair's coordinates as the two-vehicle world has them, with its own
  role (the right of way's: leader with it, follower without, ``hv.role`` when neither), belief
  and ``p_a``, kept while the pair's conflict lasts; then the lowest of these, within its
  limits. It assumes of the others only what its pair policy assumes of its opponent; it
  does not see a third vehicle at the same conflict until that one is next.
- an **agent** (:meth:`JunctionWorld.step`'s ``actions``) replaces a vehicle's policy; with
  ``shield=True`` its acceleration goes through the same shield as the AV's.

**Collisions.** Footprints (oriented rectangles) that overlap at a step's end. One between
the AV and a human is the AV's unless it is a rear-end by the human (the human behind the AV
in a lane they share), as in the two-vehicle world; it ends the run. Two humans that collide
are taken off the road (counted, ``human_collisions``) and the run goes on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Hashable

import numpy as np

from ..config import Config, ConfigError
from ..envs.external import ExternalPlanner, idm_follow, route_conflict
from ..kinematics import saturated_step
from ..policies.kinds import HV as _HV
from ..policies.kinds import LOG_SIZE
from ..tables import (ACTIVE, CRASHED, CROSSING, DONE, FOLLOW, MERGE, PENDING, WAIT_V_MPS,
                      Conflict, ConflictTable, Limits, RouteConflict, Row, Trace, Vehicles)
from .joint import av_planner
from .junction import (ARMS, Arrivals, JunctionSpec, Route, arrivals, pair_config, possible_routes,
                       right_of_way)

#: Conflict kind codes of the flat row views (:meth:`JunctionWorld._prepare_views`).
K_FOLLOW, K_MERGE, K_CROSSING = 0, 1, 2
KIND_IDS = {FOLLOW: K_FOLLOW, MERGE: K_MERGE, CROSSING: K_CROSSING}
#: The gap between two routes' centre lines laid end to end (:meth:`JunctionWorld.poses`) [m].
_LINE_SPACING_M = 1000.0


@lru_cache(maxsize=4096)
def _route_pair(a: Route, b: Route, size_a: tuple[float, float], size_b: tuple[float, float]
                ) -> tuple[str, RouteConflict | None, RouteConflict | None, float] | None:
    """The conflict of two routes (cached: a junction has few routes)."""
    if a.inbound == b.inbound:
        same = a.movement == b.movement
        return FOLLOW, None, None, math.inf if same else a.entry_m + max(size_a[0], size_b[0])
    if a.outbound == b.outbound:
        ab = route_conflict(a.line, b.line, size_a, size_b, merge_at=(a.exit_m, b.exit_m))
        ba = route_conflict(b.line, a.line, size_b, size_a, merge_at=(b.exit_m, a.exit_m))
        kind = MERGE
    else:
        ab = route_conflict(a.line, b.line, size_a, size_b)
        if ab is None:
            return None
        ba = RouteConflict(CROSSING, ab.other_at_m, ab.ego_at_m, ab.other_occupancy,
                           ab.ego_occupancy)
        kind = CROSSING
    # each side's yield line: its stop line (never after its occupancy's start)
    ab = replace(ab, ego_line_m=min(a.entry_m - ab.ego_at_m, ab.ego_occupancy[0]))
    ba = replace(ba, ego_line_m=min(b.entry_m - ba.ego_at_m, ba.ego_occupancy[0]))
    return kind, ab, ba, math.nan


def av_line(rc: RouteConflict, spec: JunctionSpec, keep_out_m: float, start_m: float
            ) -> RouteConflict:
    """The AV's side of a crossing or merge with its yield line placed by ``spec.av_line``
    (docs/method.md §15.9): ``stop``, the row's (the stop line, or the occupancy's start where
    that comes first); ``outside``, also at or before ``start_m``, the arc where the AV's
    route first meets another's occupancy (:func:`junction_start`), and ``keep_out_m`` or
    more before the conflict point, outside the keep-out circle of the human's pair game."""
    if spec.av_line != "outside" or rc.ego_line_m is None:
        return rc
    return replace(rc, ego_line_m=min(rc.ego_line_m, -keep_out_m, start_m - rc.ego_at_m))


def junction_start(spec: JunctionSpec, mine: Route, size: tuple[float, float],
                   other: tuple[float, float]) -> float:
    """Where the junction begins on route ``mine`` [m]: the lowest start of its occupancy
    interval over the crossings and merges with every route a human of ``spec`` may take
    (vehicles of sizes ``size`` and ``other``, ``(length, width)``); its stop line if none
    comes first."""
    start = mine.entry_m
    for route_ in possible_routes(spec):
        pair = _route_pair(mine, route_, size, other)
        if pair is not None and pair[0] != FOLLOW:
            rc = pair[1]
            start = min(start, rc.ego_at_m + rc.ego_occupancy[0])
    return start


#: The AV starts able to stop this far before its first yield line at its hardest braking [m]
#: (:func:`drawn_arrivals`).
START_MARGIN_M = 1.0


def first_line(spec: JunctionSpec, mine: Route, size: tuple[float, float],
               other: tuple[float, float], keep_out_m: float) -> float:
    """The earliest yield line the AV may get on route ``mine`` [m of arc]: the lowest, over
    every crossing and merge with a route a human of ``spec`` may take, of where
    :func:`av_line` places the AV's line (``spec.av_line = "stop"``: the rows' own lines;
    otherwise the lines ``outside`` places, at or before ``stop``'s, so before any line
    ``foresight`` may pick)."""
    placing = spec if spec.av_line == "stop" else spec.with_(av_line="outside")
    start = junction_start(spec, mine, size, other)
    line = math.inf
    for route_ in possible_routes(spec):
        pair = _route_pair(mine, route_, size, other)
        if pair is not None and pair[0] != FOLLOW:
            rc = av_line(pair[1], placing, keep_out_m, start)
            line = min(line, rc.ego_at_m + rc.ego_line_m)
    return line


def drawn_arrivals(config: Config, spec: JunctionSpec, seed: int) -> Arrivals:
    """The arrivals of run ``seed`` (``persuasive.many.junction.arrivals``) with the AV's
    initial speed capped so that it can stop :data:`START_MARGIN_M` before its earliest yield
    line (:func:`first_line`) at its hardest braking: ``v0 <= sqrt(2 |u_min| (d - margin))``,
    ``d`` its distance to that line (0 where ``d`` is at most the margin). §15.9's bound on the
    AV's wait assumes it can stand at its line; an AV drawn inside its braking distance stops
    inside the human's keep-out circle, and a human that waits for it there waits for ever.
    Only the AV's speed changes; every draw, the humans' and the AV's place, stays as drawn.
    ``spec.av_start = "drawn"``: no cap (the arrivals as drawn). ``config``: the pair
    configuration (:func:`~persuasive.many.junction.pair_config`)."""
    from ..scenarios.base import pair_min_dist

    av_lim, hv_lim = Limits.of(config, "av"), Limits.of(config, "hv")
    arr = arrivals(spec, seed, hv_lim.length_m)
    if spec.av_start == "drawn":
        return arr
    line = first_line(spec, arr.routes[0], (av_lim.length_m, av_lim.width_m),
                      (hv_lim.length_m, hv_lim.width_m), pair_min_dist(config))
    room = max(line - float(arr.s0_m[0]) - START_MARGIN_M, 0.0)
    cap = math.sqrt(-2.0 * av_lim.u_min_mps2 * room)
    if not arr.v0_mps[0] > cap:
        return arr
    v0 = arr.v0_mps.copy()
    v0[0] = cap
    return replace(arr, v0_mps=v0)


def conflict_table(spec: JunctionSpec, arr: Arrivals, limits: list[Limits],
                   keep_out_m: float) -> ConflictTable:
    """The one builder of the conflict table of a run (module docstring); ``keep_out_m``: the
    pair games' safety distance, which with ``spec.av_line = "outside"`` places the AV's
    lines (:func:`av_line`)."""
    rows: list[Row] = []
    start = junction_start(spec, arr.routes[0], (limits[0].length_m, limits[0].width_m),
                           (limits[-1].length_m, limits[-1].width_m))
    of: list[list[int]] = [[] for _ in range(arr.n)]
    t0 = arr.t0_s
    for i in range(arr.n):
        for j in range(i + 1, arr.n):
            a, b = arr.routes[i], arr.routes[j]
            pair = _route_pair(a, b, (limits[i].length_m, limits[i].width_m),
                               (limits[j].length_m, limits[j].width_m))
            if pair is None:
                continue
            kind, ij, ji, until = pair
            if i == 0 and ij is not None:  # the AV's side
                ij = av_line(ij, spec, keep_out_m, start)
            prio = 0 if kind == FOLLOW else right_of_way(
                spec, a, b, (arr.s0_m[i], arr.v0_mps[i]), (arr.s0_m[j], arr.v0_mps[j]),
                float(t0[i]), float(t0[j]))
            of[i].append(len(rows))
            of[j].append(len(rows))
            rows.append(Row(i, j, kind, ij, ji, until, prio))
    return ConflictTable(rows, of, keep_out_m)


class Human:
    """One human's decision (module docstring): its kind's pair policy per opponent (the
    compiled step of the two-vehicle world, the human on the HV side), IDM behind a leader."""

    def __init__(self, config: Config, kind: str, rng: np.random.Generator, games):
        from ..policies import KINDS

        self.config = config.with_overrides({"hv.kind": kind}) if config.hv.kind != kind \
            else config
        self.spec = KINDS[kind]
        self.rng = rng
        self.games = games
        self._pairs: dict[Hashable, list] = {}
        self._diag = np.zeros((self.config.library.n_traj, 10))
        self._log = np.full(LOG_SIZE, np.nan)
        self._empty = games.empty_view()
        self._draws = np.zeros(2)
        self.limits = Limits.of(self.config, "hv")
        self.opponent: int = -1  #: the vehicle of its last pair decision (-1: none)

    def _pair(self, key: Hashable, role: float) -> list:
        """The kept ``[prm, state, k]`` of the pair with ``key`` (made at first need)."""
        got = self._pairs.get(key)
        if got is None:
            from ..policies import policy_params, state_size
            from ..policies.lfg import PRM_ROLE
            from ..policies.step import policy_init
            from .. import packing as slot

            prm = policy_params(self.config, _HV)
            if self.spec.has_role and not math.isnan(role):
                prm[PRM_ROLE] = role
            st = np.zeros(state_size(prm, self.spec.kind))
            policy_init(self.spec.kind, prm, st, float(self.games.P_av[slot.PRIOR_L]))
            got = self._pairs[key] = [prm, st, 0]
        return got

    def forget(self, keep: set) -> None:
        """Drop the pairs whose conflict is over."""
        if len(keep) != len(self._pairs):
            for key in [k for k in self._pairs if k not in keep]:
                del self._pairs[key]

    def pair_accel(self, key: Hashable, role: float, me: tuple[float, float],
                   other: tuple[float, float], dt: float) -> float:
        """The pair policy's acceleration against ``other`` (pair coordinates: each ``s``
        relative to the conflict point)."""
        from ..policies.step import policy_step_buffers

        prm, st, k = self._pair(key, role)
        lim = self.limits
        me = (me[0], min(max(me[1], lim.v_min_mps), lim.v_max_mps))
        other = (other[0], min(max(other[1], lim.v_min_mps), lim.v_max_mps))
        games = self.games
        view = self._empty
        if self.spec.needs_game:  # the full prediction, into this human's own buffers
            from ..game import build_buffers, solve_buffers

            build_buffers(me[0], me[1], games.P_hv, games.disc, *view.hv)
            build_buffers(other[0], other[1], games.P_av, games.disc, *view.av)
            solve_buffers(*view.hv, *view.av, games.P_hv, view.idx, view.q_values, games.work)
        n = self.spec.draws
        if n:
            self._draws[:n] = self.rng.random(n)
        a = policy_step_buffers(
            self.spec.kind, _HV, prm, st, k, other[0], other[1], me[0], me[1], self._draws, -1,
            *view.hv, *view.av, view.idx, view.q_values, games.P_av, games.P_hv, games.disc,
            dt, self._diag, *games.ahead_a, *games.ahead_b, games.ahead, self._log, games.work)
        self._pairs[key][2] = k + 1
        return float(a)


@dataclass
class StepInfo:
    """What one step did (:meth:`JunctionWorld.step`)."""

    verdict: str | None  #: the AV's shield verdict (None: no AV or no shield)
    collisions: list[tuple[int, int, bool]]  #: ``(i, j, caused by the AV)`` this step
    done: bool  #: the run is over (every vehicle off the road, an AV collision, or time)


class JunctionWorld:
    """The N-vehicle closed loop at a junction (module docstring).

    ``config``: the vehicles' limits, the AV's kind and shield, the humans' parameters (a
    human of kind ``k`` is ``config`` with ``hv.kind = k``), ``simulation.dt_s``; ``spec``: the
    junction and its arrivals; ``seed``: the run's; ``with_av=False``: the same run without
    the AV (vehicle 0 never enters the road).
    """

    def __init__(self, config: Config, spec: JunctionSpec, seed: int, with_av: bool = True,
                 arrived: Arrivals | None = None):
        from ..packing import discounts, pack
        from ..scenarios import build_scenario
        from ..scenarios.base import pair_min_dist
        from ..world import GameCache

        config = pair_config(config)
        self.config, self.spec, self.seed, self.with_av = config, spec, int(seed), with_av
        self.dt = float(config.simulation.dt_s)
        self.n_steps = int(round(spec.duration_s / self.dt))
        av_lim, hv_lim = Limits.of(config, "av"), Limits.of(config, "hv")
        #: ``arrived``: the arrivals to use instead of the seed's (foresight's predictions)
        self.arrivals = arr = drawn_arrivals(config, spec, seed) if arrived is None \
            else arrived
        self.n = arr.n
        self.limits = [av_lim] + [hv_lim] * (arr.n - 1)
        #: the pair games' safety distance: their keep-out circle's radius [m]
        self.keep_out_m = pair_min_dist(config)
        #: the foresight's predictions, ``{(line, model crowd): (live, conflicts first, -AV
    #: clear time)}`` (empty without it)
        self.foreseen: dict[tuple[str, str], tuple] = {}
        if spec.av_line == "foresight" and with_av:
            self.spec = spec = spec.with_(av_line=foresee_line(self, config, spec, arr))
        elif spec.av_line == "foresight":
            self.spec = spec = spec.with_(av_line=AV_LINE_CHOICES[0])
        self.table = conflict_table(spec, arr, self.limits, self.keep_out_m)
        self._prepare_views()
        self.routes = arr.routes
        self._lines()
        P_av, P_hv = pack(config, build_scenario(config))
        self.games = GameCache(P_av, P_hv, discounts(config))
        self.s = arr.s0_m.astype(float).copy()
        self.v = arr.v0_mps.astype(float).copy()
        self.a = np.zeros(arr.n)
        self.status = np.full(arr.n, ACTIVE, np.int8)
        self.t0 = arr.t0_s
        self.status[self.t0 > 0.0] = PENDING
        if not with_av:
            self.status[0] = DONE
        self.k = 0
        self.planner = av_planner(config, spec, self.seed) if with_av else None
        self.humans: list[Human | None] = [None]
        for i in range(1, arr.n):
            rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(
                [self.seed, 0x4855, i])))
            self.humans.append(Human(config, arr.kinds[i], rng, self.games))
        self._agent_shields: dict[int, ExternalPlanner] = {}
        self._stand_ins: dict[int, list] = {}
        # opponents = "all": a vehicle this far from its interval or nearer is played [m]
        # (the prediction horizon at the top speed: a game cannot tell one further away
        # from no vehicle)
        self._reach_m = hv_lim.v_max_mps * config.library.n_samples * \
            config.library.sample_dt_s
        #: per step (n_steps + 1, n): positions, speeds; (n_steps, n) accelerations; status
        self.S = np.full((self.n_steps + 1, arr.n), np.nan)
        self.V = np.full((self.n_steps + 1, arr.n), np.nan)
        self.A = np.full((self.n_steps, arr.n), np.nan)
        self.STATUS = np.zeros((self.n_steps + 1, arr.n), np.int8)
        self.verdicts: list[str | None] = []
        self.collisions: list[tuple[float, int, int, bool]] = []  #: (t, i, j, AV-caused)
        self.min_gap_av_m = math.inf  #: the AV's closest footprint gap to any human
        self.opponents = np.full((self.n_steps, arr.n), -1, np.int16)
        self._record()

    # -- what each vehicle sees ----------------------------------------------------------

    def through_m(self, i: int) -> float:
        """The arc past which vehicle ``i`` has left the box (its rear past the far edge)."""
        return self.routes[i].exit_m + 0.5 * self.limits[i].length_m

    def _stand_in_rows(self, i: int) -> list[tuple[int, RouteConflict]]:
        """The conflicts of vehicle ``i``'s route with every route a newcomer may take (for the
        stand-ins of :meth:`conflicts_of`; cached per vehicle)."""
        got = self._stand_ins.get(i)
        if got is None:
            mine = self.routes[i]
            size = (self.limits[i].length_m, self.limits[i].width_m)
            hv = (self.limits[-1].length_m, self.limits[-1].width_m)
            got = []
            start = junction_start(self.spec, mine, size, hv) if i == 0 else math.nan
            for n, other in enumerate(possible_routes(self.spec)):
                pair = _route_pair(mine, other, size, hv)
                if pair is not None and pair[0] != FOLLOW:
                    got.append((n, pair[1] if i != 0 else av_line(
                        pair[1], self.spec, self.keep_out_m, start)))
            self._stand_ins[i] = got
        return got

    def conflicts_of(self, i: int) -> list[Conflict]:
        """Vehicle ``i``'s conflicts as the adapters hand them to the shield and the planners
        (``persuasive.envs.external.Conflict``): crossings and merges not cleared, and the
        vehicles ahead of it in a lane it shares. While humans are still to arrive
        (``arrival = "poisson"``), one **stand-in** per route a newcomer may take, at the start
        of its approach at the top initial speed ``v0_mps[1]`` (where and how fast a newcomer
        appears), marked ``extra["stand_in"]``: the shield checks it, the planner does not
        plan against it, so a newcomer is covered from the moment it appears."""
        out = []
        if PENDING in self.status:
            v_in = float(self.spec.v0_mps[1])
            lim = self.limits[-1]
            for n, rc in self._stand_in_rows(i):
                c = rc.conflict(("stand-in", n), float(self.s[i]), 0.0, v_in, lim,
                                {"stand_in": True})
                if c.kind == CROSSING and (c.ego_s_m > c.ego_occupancy[1]):
                    continue
                if c.kind == MERGE and c.ego_s_m >= 0.0:
                    continue
                out.append(c)
        s, status = self.s, self.status
        for r in self.table.of[i]:
            row = self.table.rows[r]
            j = row.j if row.i == i else row.i
            if status[j] != ACTIVE:
                continue
            if row.kind == FOLLOW:
                if s[j] > s[i] and s[i] <= row.shared_until_m:
                    out.append(Conflict(j, FOLLOW, float(s[i]), float(s[j]), float(self.v[j]),
                                        other=self.limits[j]))
                continue
            rc = row.ij if row.i == i else row.ji
            s_me, s_ot = s[i] - rc.ego_at_m, s[j] - rc.other_at_m
            if row.kind == CROSSING and (s_me > rc.ego_occupancy[1] or
                                         s_ot > rc.other_occupancy[1]):
                continue  # one of them has cleared it: no contact possible
            if row.kind == MERGE and s_me >= 0.0 and s_ot < s_me:
                continue  # merged ahead of the other: the other follows
            prio = row.priority if row.i == i else -row.priority
            out.append(replace(rc.conflict(j, float(s[i]), float(s[j]), float(self.v[j]),
                                           self.limits[j]), right_of_way=float(prio)))
        return out

    def _prepare_views(self) -> None:
        """Per vehicle, its rows as flat tuples seen from it (the loop reads plain floats):
        ``(j, kind, at_me, at_other, lo_me, hi_me, lo_other, hi_other, shared_until, right
        of way, half the two lengths)``."""
        self._views: list[list[tuple]] = [[] for _ in range(self.n)]
        for row in self.table.rows:
            for me, ot, rc, prio in ((row.i, row.j, row.ij, row.priority),
                                     (row.j, row.i, row.ji, -row.priority)):
                half = 0.5 * (self.limits[me].length_m + self.limits[ot].length_m)
                if rc is None:
                    view = (ot, K_FOLLOW, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, row.shared_until_m, 0,
                            half)
                else:
                    view = (ot, KIND_IDS[row.kind], rc.ego_at_m, rc.other_at_m,
                            rc.ego_occupancy[0], rc.ego_occupancy[1], rc.other_occupancy[0],
                            rc.other_occupancy[1], math.nan, prio, half)
                self._views[me].append(view)

    def _human_accel(self, i: int, s: list, v: list, status: list) -> float:
        """Human ``i``'s acceleration (module docstring) at positions ``s``, speeds ``v`` and
        statuses ``status`` (lists, one per vehicle)."""
        h = self.humans[i]
        lim = self.limits[i]
        desired = min(self.config.hv.idm.desired_speed_mps, lim.v_max_mps)
        leader = None
        best = None  # (s_me, s_ot, j, right of way) of the next conflict
        every = self.spec.opponents == "all"
        games = []
        reach_m = self._reach_m
        keep = set()
        s_i = s[i]
        for j, kind, at_me, at_ot, lo_me, hi_me, lo_ot, hi_ot, until, prio, half in \
                self._views[i]:
            if status[j] != ACTIVE:
                continue
            if kind == K_FOLLOW:
                if s[j] > s_i and s_i <= until:
                    gap = s[j] - s_i - half
                    if leader is None or gap < leader[0]:
                        leader = (gap, v[j])
                continue
            s_me, s_ot = s_i - at_me, s[j] - at_ot
            if kind == K_MERGE and s_ot >= 0.0 and s_ot > s_me:
                # the other is in the exit lane ahead: follow it
                gap = s_ot - s_me - half
                if leader is None or gap < leader[0]:
                    leader = (gap, v[j])
                continue
            if s_me > hi_me or s_ot > hi_ot or (kind == K_MERGE and s_me >= 0.0):
                continue  # cleared
            keep.add(j)
            if s_me < lo_me and lo_ot <= s_ot <= hi_ot:
                # the other is in the conflict: stop before it as behind a standing car
                gap = lo_me - s_me
                if leader is None or gap < leader[0]:
                    leader = (gap, 0.0)
            if every:
                if lo_ot - s_ot <= reach_m:
                    games.append((s_me, s_ot, j, prio))
            elif best is None or (s_me, s_ot) > (best[0], best[1]):
                best = (s_me, s_ot, j, prio)
        h.forget(keep)
        a = idm_follow(self.config, v[i], leader, desired)
        if best is not None:
            games.append(best)
        h.opponent = -1
        for s_me, s_ot, j, prio in games:
            role = 0.0 if prio > 0 else (1.0 if prio < 0 else math.nan)
            a_j = h.pair_accel(j, role, (s_me, v[i]), (s_ot, v[j]), self.dt)
            if a_j < a or h.opponent < 0:
                h.opponent = j
            a = min(a, a_j)
        return min(max(a, lim.u_min_mps2), lim.u_max_mps2)

    def agent_shield(self, i: int, proposed: float) -> tuple[float, str | None]:
        """An agent's acceleration through the shield over its conflicts (the AV's shield)."""
        planner = self._agent_shields.get(i)
        if planner is None:
            cfg = self.config
            if i > 0:  # a human agent: its own limits are the ego's
                hv = cfg.vehicle_of("hv")
                cfg = cfg.with_overrides({f"av.vehicle.{k}": getattr(hv, k) for k in (
                    "length_m", "width_m", "v_max_mps", "u_min_mps2", "u_max_mps2")})
            planner = self._agent_shields[i] = ExternalPlanner(cfg, self.seed)
        return planner.shield(float(self.v[i]), proposed, self.conflicts_of(i), self.dt)

    # -- the loop ------------------------------------------------------------------------

    def step(self, actions: dict[int, float] | None = None, shield: bool = True) -> StepInfo:
        """Decide every vehicle's acceleration on the same states, advance all, check every
        conflict (module docstring). ``actions``: accelerations [m/s^2] of the vehicles
        driven from outside (agents), through the shield unless ``shield=False``."""
        if self.k >= self.n_steps:
            raise RuntimeError("the run is over (its duration has passed)")
        actions = actions or {}
        if PENDING in self.status:
            self._enter()
        acc = np.zeros(self.n)
        verdict = None
        s_l, v_l, st_l = self.s.tolist(), self.v.tolist(), self.status.tolist()
        for i in range(self.n):
            if self.status[i] != ACTIVE:
                continue
            lim = self.limits[i]
            if i in actions:
                a = float(actions[i])
                if not math.isfinite(a):
                    raise ConfigError(f"action of vehicle {i} = {a!r} is not finite")
                a = min(max(a, lim.u_min_mps2), lim.u_max_mps2)
                if shield and self.config.shield != "off":
                    a, v_ = self.agent_shield(i, a)
                    if i == 0:
                        verdict = v_
            elif i == 0:
                d = self.planner.act(float(self.v[0]), self.conflicts_of(0), self.dt)
                a, verdict = d.accel_mps2, d.verdict
            else:
                a = self._human_accel(i, s_l, v_l, st_l)
                self.opponents[self.k, i] = self.humans[i].opponent
            acc[i] = a
        if self.with_av:
            self.verdicts.append(verdict)
        for i in range(self.n):
            if self.status[i] == ACTIVE:
                lim = self.limits[i]
                self.s[i], self.v[i] = saturated_step(float(self.s[i]), float(self.v[i]),
                                                      float(acc[i]), self.dt, lim.v_min_mps,
                                                      lim.v_max_mps)
        self.a = acc
        self.A[self.k] = np.where(self.status == ACTIVE, acc, np.nan)
        self.k += 1
        hits = self._collide()
        for i in range(self.n):
            if self.status[i] == ACTIVE and self.s[i] >= self.routes[i].length_m:
                self.status[i] = DONE
        self._record()
        av_hit = any(i == 0 for i, _, _ in hits)
        done = av_hit or self.k >= self.n_steps or not np.any(
            (self.status == ACTIVE) | (self.status == PENDING))
        return StepInfo(verdict, hits, bool(done))

    def _enter(self) -> None:
        """Put on the road every pending vehicle whose arrival time has come and whose lane's
        entry is free (the last vehicle on it a length and ``gap_m[0]`` ahead), in arrival
        order."""
        t = self.k * self.dt
        for i in np.flatnonzero(self.status == PENDING):
            if self.t0[i] > t + 1e-9:
                continue
            lane = self.routes[i].inbound
            need = self.limits[i].length_m + self.spec.gap_m[0]
            blocked = any(self.status[j] == ACTIVE and self.routes[j].inbound == lane and
                          abs(self.s[j] - self.s[i]) < need for j in range(self.n) if j != i)
            if not blocked:
                self.status[i] = ACTIVE

    def _record(self) -> None:
        k = self.k
        self.S[k], self.V[k], self.STATUS[k] = self.s, self.v, self.status
        self.S[k, self.status != ACTIVE] = np.nan
        self.V[k, self.status != ACTIVE] = np.nan

    def _lines(self) -> None:
        """Every route's centre line laid end to end on one arc axis (each route ``i`` from
        ``offset[i]``, :data:`_LINE_SPACING_M` apart), so that one ``np.interp`` places every
        vehicle."""
        arcs, xs, ys, offsets = [], [], [], []
        start = 0.0
        for r in self.routes:
            offsets.append(start)
            arcs.append(r.line.arc + start)
            xs.append(r.line.xy[:, 0])
            ys.append(r.line.xy[:, 1])
            start += r.line.length_m + _LINE_SPACING_M
        self._arc = np.concatenate(arcs)
        self._x, self._y = np.concatenate(xs), np.concatenate(ys)
        self._offset = np.array(offsets)
        self._length = np.array([r.line.length_m for r in self.routes])

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Every vehicle's centre ``(n, 2)`` [m] and unit heading ``(n, 2)`` now (the
        heading: the chord of its centre line 0.25 m either side, clamped to the line)."""
        s = np.clip(self.s, 0.0, self._length)
        lo = np.clip(self.s - 0.25, 0.0, self._length) + self._offset
        hi = np.clip(self.s + 0.25, 0.0, self._length) + self._offset
        at = np.concatenate([s + self._offset, lo, hi])
        x, y = np.interp(at, self._arc, self._x), np.interp(at, self._arc, self._y)
        n = self.n
        xy = np.column_stack([x[:n], y[:n]])
        d = np.column_stack([x[2 * n:] - x[n:2 * n], y[2 * n:] - y[n:2 * n]])
        u = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
        return xy, u

    def _collide(self) -> list[tuple[int, int, bool]]:
        from ..safety.measures import footprint_gaps

        rows = [r for r in self.table.rows if self.status[r.i] == ACTIVE and
                self.status[r.j] == ACTIVE]
        if not rows:
            return []
        xy, u = self.poses()
        i = np.array([r.i for r in rows])
        j = np.array([r.j for r in rows])
        gaps = np.empty(len(rows))
        # one call per pair of sizes (the AV's rows, the humans')
        for sel in (i == 0, i != 0):
            if not sel.any():
                continue
            la, wa = self.limits[int(i[sel][0])].length_m, self.limits[int(i[sel][0])].width_m
            lb, wb = self.limits[1].length_m, self.limits[1].width_m
            out = np.empty(int(sel.sum()))
            ii, jj = i[sel], j[sel]
            footprint_gaps(xy[ii, 0].copy(), xy[ii, 1].copy(), u[ii, 0].copy(), u[ii, 1].copy(),
                           la, wa, xy[jj, 0].copy(), xy[jj, 1].copy(), u[jj, 0].copy(),
                           u[jj, 1].copy(), lb, wb, out)
            gaps[sel] = out
        av_rows = i == 0
        if av_rows.any():
            self.min_gap_av_m = min(self.min_gap_av_m, float(gaps[av_rows].min()))
        hits = []
        t = self.k * self.dt
        for r, g in zip(rows, gaps):
            if g > 0.0 or self.status[r.i] != ACTIVE or self.status[r.j] != ACTIVE:
                continue
            caused = False
            if r.i == 0:
                caused = not self._rear_end_by_human(r)
            hits.append((r.i, r.j, caused))
            self.collisions.append((t, r.i, r.j, caused))
            if r.i != 0:  # two humans: off the road
                self.status[r.i] = self.status[r.j] = CRASHED
        return hits

    def _rear_end_by_human(self, r: Row) -> bool:
        """The AV (``r.i == 0``) is ahead of the human in a lane they share."""
        s_av, s_h = self.s[0], self.s[r.j]
        if r.kind == FOLLOW:
            return s_av > s_h and s_h <= r.shared_until_m
        if r.kind == MERGE:
            rc = r.ij
            return s_av - rc.ego_at_m >= 0.0 and s_av - rc.ego_at_m > s_h - rc.other_at_m
        return False

    def vehicles(self) -> Vehicles:
        """The vehicles table (``persuasive.tables``): the AV (vehicle 0) and the arrivals."""
        arr = self.arrivals
        through = np.array([self.through_m(i) for i in range(self.n)])
        return Vehicles(("av", *arr.kinds[1:]), tuple(self.limits), arr.s0_m, arr.v0_mps,
                        arr.t0_s, through,
                        {"arm": tuple(ARMS[r.arm] for r in self.routes),
                         "movement": tuple(r.movement for r in self.routes),
                         "lane": tuple(r.lane for r in self.routes)})

    def _place(self, i: int, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vehicle ``i``'s centres and headings at arc lengths ``s`` (the heading: the chord
        of its centre line 0.25 m either side)."""
        m = s.size
        p = self.routes[i].line.at(np.concatenate([s, s - 0.25, s + 0.25]))
        d = p[2 * m:] - p[m:2 * m]
        return p[:m, 0], p[:m, 1], np.arctan2(d[:, 1], d[:, 0])

    def trace(self) -> Trace:
        """The run so far as the tables' trace (``persuasive.tables.Trace``; its arrays are
        this world's, not copies)."""
        return Trace(self.vehicles(), self.table, self.seed, self.dt, self.spec.duration_s,
                     self.with_av, self.S, self.V, self.A, self.STATUS, self.k, self.verdicts,
                     self.collisions, self.min_gap_av_m, self.opponents, self._place)

    def frame(self):
        """The run so far per step and vehicle (``persuasive.tables.Trace.frame``; the labels
        ``arm``, ``movement``, ``lane``)."""
        return self.trace().frame()

    @classmethod
    def of(cls, config: Config, seed: int, with_av: bool = True) -> JunctionWorld:
        """The world of a configuration with ``scenario.kind = "junction"`` (its
        ``[junction]`` section, :attr:`Config.junction_spec`)."""
        spec = config.junction_spec
        if spec is None:
            raise ConfigError(f"scenario.kind = {config.scenario.kind} is a two-vehicle "
                              "scenario; the junction world needs scenario.kind = junction")
        return cls(config, spec, seed, with_av)

    def summary(self, reference: JunctionWorld | None = None,
                step_ms: np.ndarray | None = None) -> dict:
        """The run's row (``persuasive.many.measures.summary``; ``reference``: the same seed
        without the AV) and where its AV yielded, ``av_line`` (foresight's pick, if it picked)."""
        from .measures import summary

        return {**summary(self, reference, step_ms), "av_line": self.spec.av_line}

    def run(self) -> JunctionWorld:
        """Step until the run is over; returns itself."""
        while not self.step().done:
            pass
        return self


#: The lines foresight chooses among, ties to the earlier (``JunctionSpec.av_line``).
AV_LINE_CHOICES = ("outside", "stop")
#: The crowds foresight predicts with: every human of one kind (docs/method.md §15.9).
FORESIGHT_CROWDS = ("lfg", "stubborn", "idm")


def foresee_line(world: JunctionWorld, config: Config, spec: JunctionSpec, arr: Arrivals
                 ) -> str:
    """The line foresight picks for ``world``'s run (docs/method.md §15.9): for each line of
    :data:`AV_LINE_CHOICES` and each crowd of :data:`FORESIGHT_CROWDS` (the paper's human
    with the planner's ``p_a_hat``, one that keeps the leader's role, one that goes when the
    way is free), the whole run from the arrivals as they are at the start, with the
    predictions' random numbers (``persuasive.safety.foresight.prediction_seed``); a line's
    value is, in this order, the crowds in which the AV gets through with no deadlock of its
    own and never stands inside the junction, the conflicts it passes first over the crowds,
    and its slowest time through, shorter better. Ties go to the earlier line. The values are
    kept in ``world.foreseen``."""
    from ..safety.foresight import line_value, prediction_seed
    from .measures import summary

    if spec.arrival != "placed":
        raise ConfigError("junction.av_line = 'foresight' predicts the run from the vehicles "
                          "on the road at the start; allowed with junction.arrival = placed")
    p_hat = config.mpc.p_a_hat
    model = config if not isinstance(p_hat, (int, float)) or isinstance(p_hat, bool) \
        else config.with_overrides({"roles.p_a": float(p_hat)})
    seed = prediction_seed(world.seed)
    best, best_value = AV_LINE_CHOICES[0], None
    for line in AV_LINE_CHOICES:
        for crowd in FORESIGHT_CROWDS:
            kinds = ("av",) + (crowd,) * (arr.n - 1)
            run = JunctionWorld(model, spec.with_(av_line=line, hv_kinds=((crowd, 1.0),)), seed,
                                arrived=replace(arr, kinds=kinds)).run()
            row = summary(run)
            live = row["av_through"] and not row["av_caused_deadlock"] and \
                row["av_inside_stood_s"] == 0.0
            t = row["av_clear_s"] if math.isfinite(row["av_clear_s"]) else spec.duration_s
            world.foreseen[(line, crowd)] = (bool(live), int(row["av_first_conflicts"]), -t)
        # the two-vehicle foresight's value (its score with a count of conflicts first)
        value = line_value([world.foreseen[(line, c)] for c in FORESIGHT_CROWDS])
        if best_value is None or value > best_value:
            best, best_value = line, value
    return best


def warm_up(config: Config) -> None:
    """Load (and compile once, here) the kernels a run needs before workers start."""
    JunctionWorld(config, JunctionSpec(n_vehicles=3, duration_s=1.0), 0).run()


def run_summary(config: Config, seed: int) -> dict:
    """The row of ``seed`` for a configuration with ``scenario.kind = "junction"`` (what
    ``persuasive.many.study.run_seed`` returns for :attr:`Config.junction_spec`, without the
    step times, so that it is the same in every process: what
    ``persuasive.simulation.run_summary`` returns for it)."""
    world = JunctionWorld.of(config, seed).run()
    return world.summary(JunctionWorld.of(config, seed, with_av=False).run())


__all__ = ["ACTIVE", "CRASHED", "ConflictTable", "DONE", "Human", "JunctionWorld", "KIND_IDS",
           "PENDING", "Row", "START_MARGIN_M", "StepInfo", "WAIT_V_MPS", "av_line",
           "conflict_table", "drawn_arrivals", "first_line", "junction_start", "run_summary",
           "warm_up"]
