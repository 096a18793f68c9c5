"""A four-way unsignalised junction as data (docs/method.md §15.1).

Four arms, ``0`` east, ``1`` north, ``2`` west, ``3`` south, each with ``lanes`` (1 or 2)
lanes in each direction, right-hand traffic. A route is an arm, a movement (``left``,
``straight``, ``right``) and an inbound lane; its centre line (:class:`Route`) runs along the
inbound lane for ``approach_m``, through the junction's square box (its half side is the
road's half width, ``lanes * lane_width_m``), and out along the exit lane for ``exit_m``. In
the box a straight route is a segment and a turn a cubic Bezier curve tangent to both lanes.
With two lanes, left turns use the inner lane, right turns the outer, straight movements
either (drawn); a route keeps its lane index through the box.

The arrivals (:func:`arrivals`) are drawn from the run's seed alone: every vehicle's arm,
movement, lane, distance to the stop line and speed; the AV's arm and movement are set
(:attr:`JunctionSpec.av_arm`, :attr:`JunctionSpec.av_movement`). ``placed`` (default): all on
the road at the start, vehicles in one lane one behind the other, each a drawn gap behind the
one ahead; a spec whose vehicles do not fit on its approaches is refused. ``poisson``: the
humans arrive as a Poisson flow of ``flow_veh_h`` on each arm (arms drawn uniformly from the
merged flow), each entering at the start of its approach at its arrival time, or as soon as
its lane's entry is free; the AV enters there too, at ``av_arrival_s``.

The right of way of two vehicles on crossing or merging routes
(:func:`right_of_way`, ``+1``: the first has it, ``-1``: the second, ``0``: neither):

- ``major``: arms 0 and 2 (east-west) are the major road: a vehicle from it has the right of
  way over one from arms 1 and 3; between two vehicles on the same road (opposite arms) a
  left turn yields to a straight or right movement;
- ``right-before-left``: the vehicle coming from the other's right has it; opposite arms as
  above;
- ``first-come``: the vehicle that would reach its stop line first at its initial speed
  (its arrival time plus its distance over ``max(v, 1 m/s)``) has it; ties: neither.

Named variants (:data:`VARIANTS`) fix the priority and the movement mix: ``major``,
``all-way`` (first come), ``right-before-left`` and ``left-heavy`` (first come, 60 % left
turns).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from ..config import (ARMS, ARRIVALS, MOVEMENTS, OPPONENTS, PRIORITIES, VARIANTS, ConfigError,
                      JunctionParams, JunctionSpec)
from ..envs.external import Polyline

#: Arm offsets of each movement's exit (right-hand traffic: a left turn from the east arm,
#: heading west, leaves by the south arm).
EXIT_OFFSET = {"left": 3, "straight": 2, "right": 1}
#: Sample spacing of a route's centre line in the box [m].
CURVE_STEP_M = 0.5


def pair_config(config):
    """The configuration every pair game and planner of a junction run reads: ``config``
    itself for a two-vehicle scenario; for ``scenario.kind = "junction"`` the same with the
    paper's ``intersection`` as the geometry of the pair games (the humans' games and the
    AV's planners are solved in it, docs/method.md §15.3) and no ``[junction]`` section."""
    if config.scenario.kind != "junction":
        return config
    return replace(config, scenario=replace(config.scenario, kind="intersection"),
                   junction=JunctionParams())


# -- routes -----------------------------------------------------------------------------------


def _unit(arm: int) -> np.ndarray:
    angle = 0.5 * math.pi * arm
    return np.array([math.cos(angle), math.sin(angle)])


def _right_of(d: np.ndarray) -> np.ndarray:
    return np.array([d[1], -d[0]])


@dataclass(frozen=True)
class Route:
    """One route through the junction: its centre line and where it enters and leaves the box.

    ``entry_m``, ``exit_m``: arc lengths [m] of the stop line and of the box's far edge;
    ``inbound``, ``outbound``: ``(arm, lane)`` of its lanes (lane 0 next to the centre line).
    """

    arm: int
    movement: str
    lane: int
    line: Polyline = field(compare=False)
    entry_m: float
    exit_m: float
    inbound: tuple[int, int]
    outbound: tuple[int, int]

    @property
    def length_m(self) -> float:
        return self.line.length_m

    @property
    def exit_arm(self) -> int:
        return (self.arm + EXIT_OFFSET[self.movement]) % 4


@lru_cache(maxsize=256)
def route(spec_geometry: tuple, arm: int, movement: str, lane: int) -> Route:
    """The :class:`Route` of ``(arm, movement, lane)`` on the geometry
    ``(lanes, lane_width_m, approach_m, exit_m)`` (:func:`geometry_of`)."""
    lanes, w, approach, exit_len = spec_geometry
    half = lanes * w
    u_in = _unit(arm)
    d = -u_in  # heading into the junction
    offset = (lane + 0.5) * w
    p_entry = u_in * half + _right_of(d) * offset
    p_start = p_entry + u_in * approach
    out_arm = (arm + EXIT_OFFSET[movement]) % 4
    u_out = _unit(out_arm)
    p_exit = u_out * half + _right_of(u_out) * offset
    p_end = p_exit + u_out * exit_len
    if movement == "straight":
        box = np.array([p_entry, p_exit])
    else:  # a cubic Bezier tangent to both lanes (an arc's usual handle length)
        chord = float(np.hypot(*(p_exit - p_entry)))
        handle = 0.39 * chord
        c1, c2 = p_entry + d * handle, p_exit - u_out * handle
        n = max(8, int(math.ceil(1.3 * chord / CURVE_STEP_M)))
        t = np.linspace(0.0, 1.0, n + 1)[:, None]
        box = ((1 - t) ** 3 * p_entry + 3 * (1 - t) ** 2 * t * c1 + 3 * (1 - t) * t ** 2 * c2
               + t ** 3 * p_exit)
    line = Polyline.of(np.vstack([p_start, box, p_end]))
    entry = float(approach)
    exit_ = float(line.arc[-1] - exit_len)
    return Route(arm, movement, lane, line, entry, exit_, (arm, lane), (out_arm, lane))


def geometry_of(spec: JunctionSpec) -> tuple:
    """The part of a spec the routes depend on (a cache key)."""
    return (spec.lanes, spec.lane_width_m, spec.approach_m, spec.exit_m)


def possible_routes(spec: JunctionSpec) -> tuple[Route, ...]:
    """Every route a human of ``spec`` may take (the movements of a positive share)."""
    geo = geometry_of(spec)
    out = []
    for arm in range(4):
        for m, share in zip(MOVEMENTS, spec.mix):
            if share <= 0.0:
                continue
            lanes = {lane_of(spec, m, 0.0), lane_of(spec, m, 0.99)}
            out.extend(route(geo, arm, m, lane) for lane in sorted(lanes))
    return tuple(out)


def lane_of(spec: JunctionSpec, movement: str, u: float) -> int:
    """The inbound lane a movement uses (module docstring); ``u``: a uniform for the straight
    movement's choice with two lanes."""
    if spec.lanes == 1:
        return 0
    if movement == "left":
        return 0
    if movement == "right":
        return 1
    return 0 if u < 0.5 else 1


# -- arrivals ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Arrivals:
    """Every vehicle's route and initial state; vehicle 0 is the AV.

    ``route``: per vehicle; ``s0_m`` ``(n,)``: arc length along its route; ``v0_mps`` ``(n,)``;
    ``kind``: per vehicle (``"av"`` for vehicle 0, else a human kind); ``t0_s`` ``(n,)``:
    arrival times.
    """

    routes: tuple[Route, ...]
    s0_m: np.ndarray
    v0_mps: np.ndarray
    kinds: tuple[str, ...]
    #: when each vehicle arrives at ``s0_m`` [s] (all 0 with ``arrival = "placed"``)
    t0_s: np.ndarray

    @property
    def n(self) -> int:
        return len(self.routes)


def arrivals(spec: JunctionSpec, seed: int, vehicle_length_m: float = 5.0) -> Arrivals:
    """Draw the arrivals of run ``seed`` (module docstring). The humans' draws come first and
    do not depend on the AV's: vehicle ``i``'s draws are the same with and without the AV."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed), 0x4A4E])))
    geo = geometry_of(spec)
    mix = np.asarray(spec.mix) / sum(spec.mix)
    names = [k for k, _ in spec.hv_kinds]
    shares = np.array([s for _, s in spec.hv_kinds]) / sum(s for _, s in spec.hv_kinds)
    n_h = spec.n_vehicles - 1
    u = rng.random((n_h, 6))  # arm, movement, lane, kind, place order, speed per human
    routes = [route(geo, spec.av_arm, spec.av_movement, lane_of(spec, spec.av_movement, 0.5))]
    kinds = ["av"]
    for i in range(n_h):
        arm = min(int(u[i, 0] * 4), 3)
        movement = MOVEMENTS[min(int(np.searchsorted(np.cumsum(mix), u[i, 1], side="right")),
                                 2)]
        routes.append(route(geo, arm, movement, lane_of(spec, movement, u[i, 2])))
        kinds.append(names[min(int(np.searchsorted(np.cumsum(shares), u[i, 3], side="right")),
                               len(names) - 1)])
    av_u = rng.random(2)  # the AV's place order and speed
    order = np.r_[av_u[0], u[:, 4]]
    speed_u = np.r_[av_u[1], u[:, 5]]
    v0 = spec.v0_mps[0] + speed_u * (spec.v0_mps[1] - spec.v0_mps[0])
    gaps = rng.random(spec.n_vehicles)  # one per vehicle: its place in its lane
    s0 = np.empty(spec.n_vehicles)
    t0 = np.zeros(spec.n_vehicles)
    lanes: dict[tuple[int, int], list[int]] = {}
    for i, r in enumerate(routes):
        lanes.setdefault(r.inbound, []).append(i)
    if spec.arrival == "poisson":  # drawn after the placed draws: those keep their bits
        t0[1:] = np.cumsum(rng.exponential(3600.0 / (4.0 * spec.flow_veh_h), n_h))
        s0[:] = 0.0  # every vehicle enters at the start of its approach
        t0[0] = spec.av_arrival_s
        lanes = {}
    for lane, members in lanes.items():
        members.sort(key=lambda i: (order[i], i))
        dist = None
        for i in members:
            if dist is None:
                dist = spec.first_m[0] + gaps[i] * (spec.first_m[1] - spec.first_m[0])
            else:
                dist += vehicle_length_m + spec.gap_m[0] + gaps[i] * (spec.gap_m[1] -
                                                                      spec.gap_m[0])
            if dist > spec.approach_m - 0.5 * vehicle_length_m:
                raise ConfigError(
                    f"junction.n_vehicles = {spec.n_vehicles} does not fit: lane "
                    f"{ARMS[lane[0]]}/{lane[1]} needs more than junction.approach_m = "
                    f"{spec.approach_m:g} m (seed {seed}); allowed: fewer vehicles, more lanes "
                    "or a longer approach")
            s0[i] = routes[i].entry_m - dist
    return Arrivals(tuple(routes), s0, v0, tuple(kinds), t0)


def right_of_way(spec: JunctionSpec, a: Route, b: Route, x_a: tuple[float, float],
                 x_b: tuple[float, float], t_a0: float = 0.0, t_b0: float = 0.0) -> int:
    """Who has the right of way between vehicles on routes ``a`` and ``b`` (module docstring):
    ``+1`` the first, ``-1`` the second, ``0`` neither; ``x_a``, ``x_b``: their initial
    ``(s, v)``, ``t_a0``, ``t_b0`` their arrival times [s] (for ``first-come``)."""
    if spec.priority == "first-come":
        t_a = t_a0 + (a.entry_m - x_a[0]) / max(x_a[1], 1.0)
        t_b = t_b0 + (b.entry_m - x_b[0]) / max(x_b[1], 1.0)
        return 0 if t_a == t_b else (1 if t_a < t_b else -1)
    rel = (b.arm - a.arm) % 4
    if rel == 2 or rel == 0:  # the same road: a left turn yields to the other movements
        left_a, left_b = a.movement == "left", b.movement == "left"
        return 0 if left_a == left_b else (-1 if left_a else 1)
    if spec.priority == "major":
        return 1 if a.arm % 2 == 0 else -1  # adjacent arms: one is on the major road
    # right before left: b comes from a's right when it is on the arm after a's (rel 1)
    return -1 if rel == 1 else 1


__all__ = ["ARMS", "ARRIVALS", "Arrivals", "EXIT_OFFSET", "JunctionSpec", "MOVEMENTS", "OPPONENTS", "PRIORITIES",
           "Route", "VARIANTS", "arrivals", "geometry_of", "lane_of", "possible_routes", "right_of_way", "route",
           "pair_config"]
