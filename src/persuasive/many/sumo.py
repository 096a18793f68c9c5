"""The four-way junction in Eclipse SUMO: SUMO's own driver as the AV against our planner, on
the same arrivals (issue 41 item 3; docs/method.md §14.7, docs/guide/junction.md).

For a :class:`~persuasive.config.JunctionSpec` and a seed, the junction of
:mod:`persuasive.many.junction` and the arrivals of :func:`~persuasive.many.world.drawn_arrivals`
are rebuilt in SUMO, and the AV (vehicle 0) is driven three ways among the same SUMO-driven
humans, paired by seed: not at all (``none``, the reference of the time the others lose),
by SUMO's own driver (``sumo``) and by our planner (``"kind/shield"``, SUMO's adapter,
:mod:`persuasive.envs.sumo`). SUMO is the transport and the judge; the adapter's projection,
:func:`~persuasive.envs.sumo.decide`, :func:`~persuasive.envs.sumo.sumo_args` and its readers
are used as they are.

**Network** (:func:`junction_network`, built by
:func:`persuasive.envs.sumo.build_network`): a centre node ``C`` and per arm ``a`` (0 east,
1 north, 2 west, 3 south) an inbound edge ``in{a}`` from a node ``approach_m`` before the
box and an outbound edge ``out{a}`` to a node ``exit_m`` after it, ``lanes`` lanes of
``lane_width_m`` each way at the speed limit (the highest ``v_max`` of the configuration's
vehicles: no vehicle's limit is cut by the road's). The centre node has ``radius = 0``: with
it netconvert's junction is the spec's box (half side ``lanes * lane_width_m``) and every
inbound lane ends at the box's edge, our stop line, so that SUMO's approach lane is
``approach_m`` long (``build(radius_m=None)`` keeps netconvert's default radius, a larger
box). SUMO's turning curves inside the box lie within 0.6 m of our Bezier curves (0.1 m on a
right turn, 0.3 and 0.5 m on a left turn with one and two 4 m lanes), straight paths on ours,
and SUMO caps the speed on its curves (4.4 m/s on a right turn, 6.6 and 8.4 m/s on those left
turns). Our lane ``l`` (0 next to the centre line) is SUMO's index ``lanes - 1 - l`` (0 the
rightmost).
Connections, written out (netconvert adds no others): with one lane, left, straight and right
from it; with two, left from the inner lane, right from the outer, straight from both, each
into the exit lane of the same index (a route keeps its lane through the box, as ours do).

**Junction type** (:data:`JUNCTION_TYPES`): ``major`` -> ``priority`` (arms 0 and 2, east-west,
the major road: edge priority 2 against 1; on each road a left turn yields to the oncoming
straight and right movements, as our rule); ``right-before-left`` -> ``right_before_left``;
``first-come`` (the ``all-way`` variants) -> ``allway_stop``. SUMO has no first-come junction
without stopping: ``allway_stop`` is its rule that serves vehicles in the order they arrive
(after a full stop at the line), the closest to ours, which gives the way to who would reach
the stop line first; the alternatives serve by direction (``right_before_left``) or not at
all (``traffic_light_unregulated``, ``unregulated``: nobody yields, SUMO's drivers would
collide). The price: every SUMO-driven vehicle, SUMO's AV included, stops at the line once,
which our AV (like every planner driver, SUMO's right of way off) does not.

**What SUMO's drivers do not see**: netconvert gives no foe relation to two left turns from
opposite arms (right-hand traffic: they pass each other; it warns "Intersecting left turns
... increase junction radius" when their lanes touch, as on this box); with our 2.5 m wide
cars their footprints touch at the box's centre, so SUMO's humans collide there at times
(counted as human collisions, in the run without the AV as well; with one lane the turning
curves of the larger default box do not avoid it either: a left-turner waiting at its
position inside the box is touched by the oncoming straight traffic). SUMO's AV would too
if it turned left; the planner's AV, whose conflicts are geometric, does not.

**Arrivals as routes** (:func:`routes_xml`): every vehicle's edges ``in{arm} out{exit arm}``,
``departLane`` its SUMO lane, ``departSpeed`` its drawn speed, ``depart`` 0 (``placed``) or its
arrival time (``poisson``; the AV at ``av_arrival_s``), and ``departPos`` its front: our
position is the centre's arc length along our route, the stop line at ``entry_m``, so the
front is ``entry_m - s0 - length / 2`` before the stop line, which on SUMO's approach lane
(front positions, the lane's end the stop line) is ``lane_length - entry_m + s0 + length / 2``
(checked against the built network: SUMO's lane is used, whatever its length). Placed
vehicles are inserted as drawn (``insertionChecks="none"``: SUMO would otherwise hold back a
follower whose drawn gap is below its safe gap, changing the arrivals); Poisson vehicles keep
SUMO's checks, which delay an insertion until the entry is free, as our world does. Vehicle
ids: ``ego`` (the AV, as the adapter's readers expect) and ``h{i}`` (human ``i``).

**Vehicles**: the humans are SUMO's default driver (Krauss car following, ``sigma = 0.5``,
SUMO's defaults, its default speed factor distribution, minimum gap and junction model) with
the size and limits of the configuration's ``hv`` vehicle: ``length``, ``width``,
``accel = u_max``, ``decel = emergencyDecel = -u_min``, ``maxSpeed = v_max`` (by default
5 x 2.5 m, 1 m/s^2 up, 2 m/s^2 down, 10 m/s: our junction's humans' envelope, and the
worst-case shield's model of them). Every vehicle keeps its drawn lane (lane changes off,
``laneChangeMode 0`` from its insertion; with two lanes SUMO would otherwise change lanes for
speed, and a route keeps its lane in our world). The AV is a vehicle of the ``av`` limits,
``speedFactor 1`` (it may drive the speed limit), with SUMO's SSM device; driven by SUMO
(``sumo``) it keeps SUMO's default speed mode and obeys the junction's rule; driven by the
planner its speed is set every 0.1 s through libsumo with the adapter's speed mode (SUMO's
safe speed and right of way off), as in :func:`persuasive.envs.sumo.run_episode`.

**The planner** (:func:`junction_planner_config`): the configuration's AV kind and shield
(worst case by default) in the junction's pair-game geometry
(:func:`persuasive.many.junction.pair_config`: the paper's intersection), the configuration's
vehicles; :class:`~persuasive.envs.external.ExternalPlanner` with the planner's horizon (one
planner per conflicting human, the lowest acceleration, the shield over all: the junction's
``pairwise`` AV; ``junction.av_plan`` and ``junction.av_line`` are not read: the adapter's
yield line is SUMO's junction entry, §14.4). Each vehicle's route is projected from the lane
it starts on (:class:`~persuasive.envs.sumo.Projector`'s ``first_lane``). While Poisson humans
are still to be inserted, the shield also checks one stand-in per route a newcomer may take,
at its insertion front position at the top initial speed ``v0_mps[1]`` (the junction's
stand-ins, §15.4).

**Measures** (:class:`EpisodeResult`): the AV through (its centre half a length past the
box's far edge: its rear out of the box) within :data:`EPISODE_S` of its depart, and its time
to clear from its depart (its scheduled one, so that a Poisson AV held at a busy entry counts
the wait; SUMO shows a vehicle inserted at ``t`` where it was put, at ``t + dt``, and moves it
from then on, so that step is taken off); SUMO's collisions (the adapter's options: physical
overlaps, junctions included) as distinct (collider, victim) pairs: with the AV, AV-caused
(every one but a rear-end into the AV by the vehicle behind it in a lane, SUMO's
``collision`` type with the AV the victim: our world's convention), and between two humans;
the time the others lost (tripinfo ``timeLoss`` summed over the humans, unfinished trips
included) less the same seed without the AV; SUMO's SSM device on the AV (the minimum PET
and TTC of the conflicts it records, as the adapter's); the time the AV stood inside the box;
the planner's shield overrides and uncertified steps. An episode ends :data:`EPISODE_S` after
the AV's depart, or as soon as every vehicle has left.

Determinism: the arrivals, SUMO's ``--seed`` and the planner's seeds all come from the seed;
each seed's episodes run in one worker process (libsumo: one SUMO per process, started and
closed per episode), so the results do not depend on the number of workers.
"""

from __future__ import annotations

import math
import os
import shutil
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._processes import scratch_dir
from ..config import (AV_KIND_ALIASES, AV_KINDS, MOVEMENTS, SHIELD_KINDS, Config, ConfigError,
                      JunctionSpec)
from ..envs import sumo as S
from ..envs.external import ExternalPlanner, Limits
from ..safety.measures import WAIT_SPEED_MPS, restricted_mean
from .junction import EXIT_OFFSET, Arrivals, Route, lane_of, pair_config, possible_routes
from .world import drawn_arrivals

#: The SUMO junction type of each of our priorities (module docstring).
JUNCTION_TYPES = {"major": "priority", "right-before-left": "right_before_left",
                  "first-come": "allway_stop"}
#: The AV's SUMO id (the adapter's readers leave it out of the others' time loss).
AV_ID = "ego"
#: How long after its depart the AV has to get through [s], and the episode's length after it.
EPISODE_S = 60.0
#: SUMO's step and the planner's [s].
DT_S = S.DT_S
#: Krauss's driver imperfection, SUMO's default (written out so that the file says it).
SIGMA = 0.5
#: The drivers besides the planners.
SUMO_DRIVER, NO_AV = S.SUMO_DRIVER, S.NO_EGO
#: The centre node's turning radius [m]: 0 makes netconvert's junction our box.
RADIUS_M = 0.0
#: Most seeds a study may run per number of vehicles (as ``persuasive sumo``'s episodes).
MAX_SEEDS = S.MAX_EPISODES


# -- the network --------------------------------------------------------------------------------


def sumo_lane(spec: JunctionSpec, lane: int) -> int:
    """SUMO's lane index (0 the rightmost) of our lane ``lane`` (0 next to the centre line)."""
    return spec.lanes - 1 - int(lane)


def speed_limit_mps(config: Config) -> float:
    """The roads' speed limit: the highest ``v_max`` of the configuration's vehicles [m/s]."""
    return max(config.vehicle_of("av").v_max_mps, config.vehicle_of("hv").v_max_mps)


def _unit(arm: int) -> tuple[float, float]:
    angle = 0.5 * math.pi * arm
    return round(math.cos(angle), 12), round(math.sin(angle), 12)


def connections(spec: JunctionSpec) -> tuple[tuple[str, str, int, int], ...]:
    """Every ``(from edge, to edge, from lane, to lane)`` (SUMO's lane indices) our routes use
    (module docstring), arm by arm, movements in :data:`MOVEMENTS` order."""
    out = []
    for arm in range(4):
        for movement in MOVEMENTS:
            lanes = sorted({lane_of(spec, movement, 0.0), lane_of(spec, movement, 0.99)})
            exit_arm = (arm + EXIT_OFFSET[movement]) % 4
            for lane in lanes:
                k = sumo_lane(spec, lane)
                out.append((f"in{arm}", f"out{exit_arm}", k, k))
    return tuple(out)


def junction_network(spec: JunctionSpec, config: Config | None = None,
                     radius_m: float | None = RADIUS_M) -> S.Network:
    """The SUMO network of ``spec`` (module docstring); ``config``: the vehicles (the speed
    limit; default: corrected mode's); ``radius_m``: the centre node's turning radius (None:
    netconvert's default, 4 m, which widens the box by about that much on every side)."""
    config = config or Config(mode="corrected")
    half = spec.lanes * spec.lane_width_m
    nodes = [("C", 0.0, 0.0, JUNCTION_TYPES[spec.priority])]
    edges = []
    for arm in range(4):
        ux, uy = _unit(arm)
        a, b = half + spec.approach_m, half + spec.exit_m
        nodes.append((f"S{arm}", ux * a, uy * a, "dead_end"))
        nodes.append((f"T{arm}", ux * b, uy * b, "dead_end"))
        prio = 2 if spec.priority == "major" and arm % 2 == 0 else 1
        edges.append((f"in{arm}", f"S{arm}", "C", prio))
        edges.append((f"out{arm}", "C", f"T{arm}", prio))
    av = av_route_edges(spec)
    return S.Network(f"junction-{spec.priority}-{spec.lanes}", tuple(nodes), tuple(edges), av,
                     (), "C", lanes=spec.lanes, speed_mps=speed_limit_mps(config),
                     lane_width_m=spec.lane_width_m, junction_radius_m=radius_m,
                     connections=connections(spec))


def route_edges(r: Route) -> tuple[str, str]:
    """The SUMO edges of one of our routes."""
    return f"in{r.arm}", f"out{r.exit_arm}"


def av_route_edges(spec: JunctionSpec) -> tuple[str, str]:
    """The AV's SUMO edges (its arm and movement are the spec's)."""
    return f"in{spec.av_arm}", f"out{(spec.av_arm + EXIT_OFFSET[spec.av_movement]) % 4}"


def build(spec: JunctionSpec, folder: str | Path, config: Config | None = None,
          netconvert: str | None = None, radius_m: float | None = RADIUS_M) -> Path:
    """Build ``spec``'s network into ``folder`` (``net.net.xml``); :class:`ConfigError` in one
    line (naming the spec) when SUMO cannot build it."""
    if radius_m is not None and not (isinstance(radius_m, (int, float))
                                     and 0.0 <= radius_m < math.inf):
        raise ConfigError(f"radius_m = {radius_m!r} is out of range; allowed: None "
                          "(netconvert's default) or a finite number >= 0 [m]")
    try:
        return S.build_network(junction_network(spec, config, radius_m), folder, netconvert)
    except ConfigError as exc:
        raise ConfigError(f"{exc} (junction: {spec.lanes} lane(s) of {spec.lane_width_m:g} m, "
                          f"approach {spec.approach_m:g} m, exit {spec.exit_m:g} m)") from None


# -- the arrivals as routes ----------------------------------------------------------------------


@dataclass(frozen=True)
class Departure:
    """One vehicle of the arrivals in SUMO's terms."""

    vehicle: str  #: ``ego`` or ``h{i}``
    edges: tuple[str, str]
    lane: int  #: SUMO's index
    depart_s: float
    pos_m: float  #: the front's position on the first lane [m]
    speed_mps: float
    placed: bool  #: inserted as drawn (no insertion checks)

    @property
    def first_lane(self) -> str:
        return f"{self.edges[0]}_{self.lane}"


def departures(spec: JunctionSpec, arr: Arrivals, limits: Sequence[Limits],
               approach_lengths: dict[str, float]) -> list[Departure]:
    """Every vehicle's :class:`Departure` (module docstring); ``approach_lengths``: SUMO's
    length of each inbound lane [m]; ``limits``: per vehicle (the AV first)."""
    out = []
    placed = spec.arrival == "placed"
    for i, r in enumerate(arr.routes):
        edges = route_edges(r)
        k = sumo_lane(spec, r.lane)
        lane_len = approach_lengths[f"{edges[0]}_{k}"]
        front = lane_len - (r.entry_m - float(arr.s0_m[i])) + 0.5 * limits[i].length_m
        pos = min(max(front, 0.0), lane_len)  # a Poisson vehicle's rear is before the lane
        out.append(Departure(AV_ID if i == 0 else f"h{i}", edges, k,
                             round(float(arr.t0_s[i]), 1), pos, float(arr.v0_mps[i]), placed))
    return out


def _vtype(name: str, lim: Limits, extra: dict[str, float],
           params: dict[str, str] | None = None) -> str:
    return S._vtype(name, {"length": lim.length_m, "width": lim.width_m,
                           "accel": lim.u_max_mps2, "decel": -lim.u_min_mps2,
                           "emergencyDecel": -lim.u_min_mps2, "maxSpeed": lim.v_max_mps,
                           **extra}, params)


def routes_xml(deps: Sequence[Departure], av: Limits, human: Limits, with_av: bool) -> str:
    """SUMO's route file of the arrivals: the two types and every vehicle (the AV left out
    without it), sorted by departure time (ties in the arrivals' order)."""
    parts = ["<routes>\n", _vtype("human", human, {"sigma": SIGMA})]
    if with_av:
        parts.append(_vtype("ego", av, {"speedFactor": 1.0, "speedDev": 0.0},
                            {"has.ssm.device": "true"}))
    rows = []
    for n, d in enumerate(deps):
        if d.vehicle == AV_ID and not with_av:
            continue
        checks = ' insertionChecks="none"' if d.placed else ""
        rows.append((d.depart_s, n, f'  <vehicle id="{d.vehicle}" type='
                     f'"{"ego" if d.vehicle == AV_ID else "human"}" depart="{d.depart_s:.1f}" '
                     f'departLane="{d.lane}" departPos="{d.pos_m:.3f}" departSpeed='
                     f'"{d.speed_mps:.3f}"{checks}>\n    <route edges="{" ".join(d.edges)}"/>\n'
                     "  </vehicle>\n"))
    rows.sort(key=lambda r: (r[0], r[1]))
    parts += [r[2] for r in rows]
    parts.append("</routes>\n")
    return "".join(parts)


# -- the planner ---------------------------------------------------------------------------------


def junction_planner_config(kind: str = "persuasive", shield: str = "worst-case",
                            config: Config | None = None) -> Config:
    """The planner's configuration at the junction in SUMO: ``config`` (default corrected
    mode) in the junction's pair-game geometry (``pair_config``) with ``av.kind = kind`` and
    ``av.shield = shield``; its vehicles are the configuration's."""
    if kind not in AV_KINDS and kind not in AV_KIND_ALIASES:
        raise ConfigError(f"--av = {kind!r} is out of range; allowed: {' | '.join(AV_KINDS)}")
    if shield not in SHIELD_KINDS:
        raise ConfigError(f"--shield = {shield!r} is out of range; allowed: "
                          f"{' | '.join(SHIELD_KINDS)}")
    base = pair_config(config or Config(mode="corrected"))
    return base.with_overrides({"av.kind": kind, "av.shield": shield})


def _planner_of(driver: str, config: Config | None, seed: int) -> ExternalPlanner:
    """The planner of ``"kind/shield"``: the adapter's, or for ``lfg-rule`` Li et al.'s
    worst-pair planner (``persuasive.many.rule.RulePlanner``, as in our junction; its roles
    from SUMO's right of way at the junction, the projection's ``Conflict.right_of_way``:
    the link's priority; equal priorities, first come)."""
    kind, shield = driver.split("/")
    cfg = junction_planner_config(kind, shield, config)
    if kind == "lfg-rule":
        from .rule import RulePlanner

        return RulePlanner(cfg, seed, plan_horizon_s=S.horizon_s(cfg))
    return ExternalPlanner(cfg, seed, plan_horizon_s=S.horizon_s(cfg))


# -- one episode ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class EpisodeResult:
    """One seed driven one way (module docstring)."""

    seed: int
    n_vehicles: int  #: the AV included
    priority: str
    lanes: int
    driver: str  #: ``none``, ``sumo`` or ``kind/shield``
    av_through: bool  #: the AV's rear left the box within :data:`EPISODE_S` of its depart
    av_clear_s: float | None  #: from its depart to then [s] (None: not through)
    av_collisions: int  #: distinct (collider, victim) pairs with the AV
    av_caused_collisions: int  #: of which not a rear-end into the AV
    human_collisions: int  #: distinct pairs of two humans
    traffic_time_loss_s: float  #: the humans' tripinfo ``timeLoss``, summed [s]
    caused_time_loss_s: float | None  #: less the same seed without the AV [s]
    humans: int  #: humans in the tripinfo
    min_pet_s: float | None  #: SUMO's SSM on the AV (None: no conflict past its thresholds)
    min_ttc_s: float | None
    av_inside_stood_s: float  #: the AV stood (below 0.1 m/s) inside the box [s]
    ego_steps: int  #: planner decisions (0 for ``none`` and ``sumo``)
    shield_overrides: int  #: of which the shield replaced the proposal
    uncertified: int  #: of which no fallback was certified
    t_end_s: float  #: the episode's last step [s]

    @property
    def caused_delay_s(self) -> float | None:
        """:attr:`caused_time_loss_s` per human [s] (our junction's ``caused_delay_s`` is a
        mean over the humans too)."""
        if self.caused_time_loss_s is None:
            return None
        return self.caused_time_loss_s / max(1, self.n_vehicles - 1)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "caused_delay_s": self.caused_delay_s}


def _stand_ins(spec: JunctionSpec, human: Limits, approach_lengths: dict[str, float]
               ) -> list[S.VehicleState]:
    """One stand-in per route a newcomer may take (``possible_routes``), at its insertion
    front position at ``v0_mps[1]`` (module docstring)."""
    out = []
    for n, r in enumerate(possible_routes(spec)):
        edges = route_edges(r)
        lane = f"{edges[0]}_{sumo_lane(spec, r.lane)}"
        front = approach_lengths[lane] - r.entry_m + 0.5 * human.length_m
        pos = max(front, 0.0)
        out.append(S.VehicleState(f"{S.ENTRY_PREFIX}{n}", edges, lane, pos, math.nan,
                                  math.nan, math.nan, float(spec.v0_mps[1]), human.length_m,
                                  human.width_m, human, first_lane=lane))
    return out


def _approach_lengths(net_file: Path) -> dict[str, float]:
    """SUMO's length of every inbound lane of the junction (the shape's arc length) [m]."""
    out = {}
    for lane, pts in S.lane_shapes(net_file).items():
        if lane.startswith("in"):
            out[lane] = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
    return out


def run_episode(spec: JunctionSpec, seed: int, driver: str, net_file: str | Path,
                config: Config | None = None,
                reference_time_loss_s: float | None = None) -> EpisodeResult:
    """One episode of seed ``seed`` in this process's SUMO (libsumo): ``driver`` is
    :data:`NO_AV`, :data:`SUMO_DRIVER` or ``"kind/shield"`` (module docstring); ``config``:
    the vehicles and the planner's base (default corrected mode)."""
    ls = S._libsumo()
    net_file = Path(net_file)
    base = config or Config(mode="corrected")
    with_av = driver != NO_AV
    planner = _planner_of(driver, base, seed) if driver not in (NO_AV, SUMO_DRIVER) else None
    cfg = pair_config(base)
    av_lim, hv_lim = Limits.of(cfg, "av"), Limits.of(cfg, "hv")
    arr = drawn_arrivals(cfg, spec, seed)
    limits = [av_lim] + [hv_lim] * (arr.n - 1)
    lengths = _approach_lengths(net_file)
    deps = departures(spec, arr, limits, lengths)
    first_lane = {d.vehicle: d.first_lane for d in deps}
    av_dep = deps[0]
    # SUMO shows a vehicle inserted at t where it was put, at t + dt: it moves from then on
    end_s = av_dep.depart_s + EPISODE_S + DT_S
    pending = {d.vehicle for d in deps[1:] if d.depart_s < end_s - 1e-9}
    stand_ins = (_stand_ins(spec, hv_lim, lengths)
                 if planner is not None and spec.arrival == "poisson" else [])
    folder = scratch_dir("sumo-junction-")
    pairs: dict[tuple[str, str], str] = {}
    overrides = uncertified = steps = stood = 0
    through_at = None
    t = 0.0
    known: dict[str, tuple] = {}
    types: dict[str, Limits] = {}
    try:
        routes = folder / "routes.rou.xml"
        routes.write_text(routes_xml(deps, av_lim, hv_lim, with_av), encoding="utf-8")
        ls.start(S.sumo_args(net_file, routes, folder, seed, end_s, with_av))
        try:
            projector = through_arc = clear = slack = None
            if with_av:
                projector = S.Projector(av_dep.edges, (av_lim.length_m, av_lim.width_m),
                                        ls.lane.getLinks, ls.lane.getShape, ls.lane.getLength,
                                        av_dep.first_lane)
                exit_lane = projector.ego.lanes[-1]
                through_arc = projector.ego.offsets[exit_lane][0] + 0.5 * av_lim.length_m
                slack = S.ballistic_slack(av_lim)
                clear = planner._clear_m if planner is not None else 0.0
            steered = False
            while ls.simulation.getTime() < end_s - 1e-9:
                ls.simulationStep()
                t = round(ls.simulation.getTime(), 6)
                for vid in ls.simulation.getDepartedIDList():
                    ls.vehicle.setLaneChangeMode(vid, 0)  # every vehicle keeps its lane
                    pending.discard(vid)
                for c in ls.simulation.getCollisions():
                    pairs.setdefault((c.collider, c.victim), c.type)
                ids = ls.vehicle.getIDList()
                if with_av and AV_ID in ids:
                    av = _state(ls, AV_ID, known, types, first_lane)
                    stood += av.lane.startswith(":") and av.speed_mps < WAIT_SPEED_MPS
                    arc = projector.ego.arc(av.lane, av.lane_pos_m)
                    if through_at is None and arc is not None and \
                            arc - 0.5 * av.length_m >= through_arc:
                        through_at = t
                    if planner is not None:
                        if not steered:
                            ls.vehicle.setSpeedMode(AV_ID, S.SPEED_MODE)
                            steered = True
                        others = [_state(ls, v, known, types, first_lane)
                                  for v in ids if v != AV_ID]
                        if pending:
                            others += stand_ins
                        decision, _ = S.decide(planner, projector, av, others, clear, slack)
                        v_next = min(max(av.speed_mps + decision.accel_mps2 * DT_S,
                                         av_lim.v_min_mps), av_lim.v_max_mps)
                        ls.vehicle.setSpeed(AV_ID, v_next)
                        steps += 1
                        overrides += decision.verdict not in (None, "admitted")
                        uncertified += decision.verdict == "uncertified"
                if ls.simulation.getMinExpectedNumber() == 0:
                    break  # every vehicle has left, none is to come
        finally:
            ls.close()
        loss, humans = S._time_loss(folder / "tripinfo.xml")
        ttc, pet, _ = S._ssm(folder / "ssm.xml") if with_av else (None, None, None)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    av_pairs = {p: k for p, k in pairs.items() if AV_ID in p}
    caused = sum(not (kind == "collision" and p[1] == AV_ID) for p, kind in av_pairs.items())
    clear_s = None if through_at is None else round(through_at - DT_S - av_dep.depart_s, 6)
    return EpisodeResult(
        seed=int(seed), n_vehicles=spec.n_vehicles, priority=spec.priority, lanes=spec.lanes,
        driver=driver, av_through=clear_s is not None and clear_s <= EPISODE_S + 1e-9,
        av_clear_s=clear_s, av_collisions=len(av_pairs), av_caused_collisions=caused,
        human_collisions=len(pairs) - len(av_pairs), traffic_time_loss_s=loss,
        caused_time_loss_s=None if reference_time_loss_s is None or not with_av
        else loss - reference_time_loss_s,
        humans=humans, min_pet_s=pet, min_ttc_s=ttc,
        av_inside_stood_s=round(stood * DT_S, 6), ego_steps=steps, shield_overrides=overrides,
        uncertified=uncertified, t_end_s=t)


def _state(ls, vid: str, known: dict, types: dict, first_lane: dict) -> S.VehicleState:
    """The adapter's :class:`~persuasive.envs.sumo.VehicleState` with the lane its route
    starts on."""
    return replace(S._state_of(ls, vid, known, types), first_lane=first_lane[vid])


def run_seed(spec: JunctionSpec, seed: int, drivers: Sequence[str], net_file: str | Path,
             config: Config | None = None) -> list[EpisodeResult]:
    """The run without the AV (the time-loss reference), then every driver, on one seed."""
    ref = run_episode(spec, seed, NO_AV, net_file, config)
    return [ref] + [run_episode(spec, seed, d, net_file, config, ref.traffic_time_loss_s)
                    for d in drivers]


def _run_seed_task(task: tuple) -> list[EpisodeResult]:  # pragma: no cover - in workers
    return run_seed(*task)


# -- a study -------------------------------------------------------------------------------------


def drivers_of(avs: Sequence[str], shield: str = "worst-case") -> tuple[str, ...]:
    """SUMO's driver, then one planner driver per AV kind (``kind/shield``)."""
    return (SUMO_DRIVER, *dict.fromkeys(S.driver_name(a, shield) for a in avs))


@dataclass(frozen=True)
class Study:
    """Every episode of a study, in (vehicles, seed, driver) order."""

    vehicles: tuple[int, ...]
    seeds: tuple[int, ...]
    drivers: tuple[str, ...]  #: without ``none``, which every seed also ran
    variant: str
    lanes: int
    episodes: tuple[EpisodeResult, ...]
    wall_time_s: float
    workers: int

    def of(self, n: int, driver: str) -> list[EpisodeResult]:
        """The episodes of ``n`` vehicles and ``driver``, in seed order."""
        return [e for e in self.episodes if e.n_vehicles == n and e.driver == driver]

    def table(self) -> list[dict[str, Any]]:
        """Per number of vehicles and planner driver, paired by seed with SUMO's driver
        (:func:`paired_row`)."""
        return [paired_row(self.of(n, SUMO_DRIVER), self.of(n, d), d) for n in self.vehicles
                for d in self.drivers if d != SUMO_DRIVER]

    def to_dict(self) -> dict[str, Any]:
        """The study as plain values (non-finite numbers as None: JSON without NaN)."""
        return _finite({"vehicles": list(self.vehicles),
                        "seeds": [self.seeds[0], self.seeds[-1]],
                        "drivers": list(self.drivers), "variant": self.variant,
                        "lanes": self.lanes, "workers": self.workers,
                        "wall_time_s": self.wall_time_s, "table": self.table(),
                        "episodes": [e.to_dict() for e in self.episodes]})


def _finite(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def paired_row(sumo: Sequence[EpisodeResult], ours: Sequence[EpisodeResult],
               driver: str) -> dict[str, Any]:
    """One row of the paired table: each driver's AV-through rate (with its 95 % Wilson
    interval), the paired difference ours - SUMO's in points with the normal 95 % interval of
    the mean paired difference over seeds (``mean +- 1.96 s / sqrt(n)``), the restricted
    mean time to clear (a run not through counted at :data:`EPISODE_S`), the delay caused
    per human (mean over seeds of the time loss caused over ``n - 1``) and its paired
    difference, collisions, PET and the shield's counts."""
    from ..sweep.metrics import mean_interval, wilson

    if [e.seed for e in sumo] != [e.seed for e in ours]:
        raise ValueError("paired_row needs the same seeds for both drivers")
    n = len(sumo)

    def through(es):
        k = sum(e.av_through for e in es)
        lo, hi = wilson(k, len(es))
        return 100.0 * k / max(1, len(es)), [100.0 * lo, 100.0 * hi]

    def delays(es):
        return np.array([np.nan if e.caused_delay_s is None else e.caused_delay_s for e in es])

    (p_s, ci_s), (p_o, ci_o) = through(sumo), through(ours)
    d_through = mean_interval(100.0 * (np.array([e.av_through for e in ours], float)
                                       - np.array([e.av_through for e in sumo], float)))
    ds, do = delays(sumo), delays(ours)
    keep = np.isfinite(ds) & np.isfinite(do)
    d_delay = mean_interval(do[keep] - ds[keep])
    pets = {k: [e.min_pet_s for e in es if e.min_pet_s is not None]
            for k, es in (("sumo", sumo), ("ours", ours))}
    steps = sum(e.ego_steps for e in ours)
    return {
        "n_vehicles": sumo[0].n_vehicles if sumo else None, "driver": driver, "seeds": n,
        "through_pct_sumo": p_s, "through_ci_sumo": ci_s,
        "through_pct_ours": p_o, "through_ci_ours": ci_o,
        "through_diff_points": d_through[0], "through_diff_ci": [d_through[1], d_through[2]],
        "clear_s_sumo": restricted_mean([e.av_clear_s for e in sumo], EPISODE_S),
        "clear_s_ours": restricted_mean([e.av_clear_s for e in ours], EPISODE_S),
        "caused_delay_s_sumo": float(np.nanmean(ds)) if n else None,
        "caused_delay_s_ours": float(np.nanmean(do)) if n else None,
        "delay_diff_s": d_delay[0], "delay_diff_ci": [d_delay[1], d_delay[2]],
        "av_caused_collisions_sumo": sum(e.av_caused_collisions for e in sumo),
        "av_caused_collisions_ours": sum(e.av_caused_collisions for e in ours),
        "av_collisions_sumo": sum(e.av_collisions for e in sumo),
        "av_collisions_ours": sum(e.av_collisions for e in ours),
        "human_collisions_sumo": sum(e.human_collisions for e in sumo),
        "human_collisions_ours": sum(e.human_collisions for e in ours),
        "min_pet_s_sumo": min(pets["sumo"], default=None),
        "min_pet_s_ours": min(pets["ours"], default=None),
        "inside_stood_s_sumo": float(sum(e.av_inside_stood_s for e in sumo)),
        "inside_stood_s_ours": float(sum(e.av_inside_stood_s for e in ours)),
        "override_pct": 100.0 * sum(e.shield_overrides for e in ours) / max(1, steps),
        "uncertified": sum(e.uncertified for e in ours),
    }


def check_study(vehicles: Sequence[int], seeds: int, seed: int, avs: Sequence[str],
                shield: str, workers: int | None, variant: str, lanes: int) -> None:
    """Refuse bad arguments with one line naming the argument and its range."""
    if not vehicles:
        raise ConfigError("--vehicles is empty; allowed: comma-separated integers in [1, 64]")
    for n in vehicles:
        JunctionSpec.of(variant, n_vehicles=n, lanes=lanes)  # refuses n, variant, lanes
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= MAX_SEEDS:
        raise ConfigError(f"--seeds = {seeds!r} is out of range; allowed: integer in "
                          f"[1, {MAX_SEEDS}]")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**31 - seeds:
        raise ConfigError(f"--seed = {seed!r} is out of range; allowed: integer in "
                          "[0, 2^31 - seeds)")
    if not avs:
        raise ConfigError(f"--av is empty; allowed: comma-separated {' | '.join(AV_KINDS)}")
    for a in avs:
        junction_planner_config(a, shield)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise ConfigError(f"--workers = {workers!r} is out of range; allowed: integer >= 1")


def _warm_up(drivers: Sequence[str], config: Config | None) -> None:
    """Load (compile once) the planner's kernels here, so that the workers load them from the
    cache and never compile them at the same time."""
    from ..envs.external import CROSSING, FOLLOW, MERGE, Conflict

    for d in drivers:
        if d in (SUMO_DRIVER, NO_AV):
            continue
        p = _planner_of(d, config, 0)
        p.act(5.0, [Conflict(0, CROSSING, -20.0, -20.0, 5.0, (-5.0, 0.0), (-5.0, 5.0)),
                    Conflict(1, MERGE, -25.0, -15.0, 5.0, (-5.0, 0.0), (-5.0, 5.0)),
                    Conflict(2, FOLLOW, 10.0, 30.0, 5.0)], DT_S)


def run_study(vehicles: Sequence[int] = (2, 4), seeds: int = 10, seed: int = 1,
              avs: Sequence[str] = ("persuasive",), shield: str = "worst-case",
              workers: int | None = None, variant: str = "major", lanes: int = 1,
              config: Config | None = None, progress=None, **spec_fields: Any) -> Study:
    """``seeds`` seeds from ``seed`` for every number of vehicles, each run without the AV,
    with SUMO's driver and with every planner of ``avs`` (``shield``), on the worker
    processes of a local Dask cluster (:func:`persuasive.envs.sumo.run_study`'s, a bounded
    number of seeds in flight); ``spec_fields`` set more of the spec. The episodes come back
    in (vehicles, seed, driver) order, the same whatever the workers."""
    check_study(vehicles, seeds, seed, avs, shield, workers, variant, lanes)
    binaries = S.sumo_binaries()
    drivers = drivers_of(avs, shield)
    t0 = time.perf_counter()
    folder = scratch_dir("sumo-junction-nets-")
    try:
        specs, nets = {}, {}
        for n in vehicles:
            spec = JunctionSpec.of(variant, n_vehicles=n, lanes=lanes, **spec_fields)
            sub = folder / f"n{n}"
            sub.mkdir()
            specs[n], nets[n] = spec, build(spec, sub, config, binaries["netconvert"])
        _warm_up(drivers, config)
        tasks = [(specs[n], s, drivers, str(nets[n]), config) for n in vehicles
                 for s in range(seed, seed + seeds)]
        from ..sweep.runner import run_all

        k = min(workers or os.cpu_count() or 1, len(tasks))  # as run_all starts them
        done = run_all(_run_seed_task, tasks, k, progress)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    episodes = tuple(e for out in done for e in out)
    return Study(tuple(vehicles), tuple(range(seed, seed + seeds)), drivers, variant, lanes,
                 episodes, time.perf_counter() - t0, k)


__all__ = ["AV_ID", "EPISODE_S", "JUNCTION_TYPES", "NO_AV", "SUMO_DRIVER", "Departure",
           "EpisodeResult", "Study", "build", "connections", "departures", "drivers_of",
           "junction_network", "junction_planner_config", "paired_row", "route_edges",
           "routes_xml", "run_episode", "run_seed", "run_study", "speed_limit_mps",
           "sumo_lane"]
