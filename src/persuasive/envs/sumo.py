"""The planner driving an ego vehicle in Eclipse SUMO (issue 18; docs/method.md §14).

SUMO is the transport: the planner against many outside vehicles is
:mod:`persuasive.envs.external` (one game per conflicting vehicle, the most cautious answer,
the shield over all), handed SUMO's vehicles each step by this adapter.

**Networks** (:data:`NETWORKS`), written as node and edge XML and built by SUMO's
``netconvert`` (nothing downloaded; :func:`build_network`): ``intersection``, a 4-arm
unsignalled ``priority`` junction of single-lane two-way roads where the AV comes from the
south on the minor road (no priority) and goes straight across the major road (west-east),
whose traffic in both directions is the conflicting traffic; ``merge``, a single-lane
on-ramp joining a single-lane main road at 30 degrees at a ``priority`` junction (the ramp
yields), the main road's traffic being the conflicting traffic. Roads are 250 m long before
the junction (150 m after it), with a 13.89 m/s (50 km/h) speed limit.

**Traffic** (:func:`traffic`): Poisson arrivals at ``flow`` vehicles per hour on each
conflicting route, drawn from a numpy Generator seeded by the episode's seed (one child
stream per route, exponential headways scaled by the flow, so the same seed at another flow
stretches the same draws); each vehicle is, with probability ``ignore_foes``, of SUMO's type
``reckless``: its junction model ignores foes with right of way and foes already in the
junction (``jmIgnoreFoeProb = jmIgnoreJunctionFoeProb = 1``, ``jmIgnoreFoeSpeed`` above any
speed): it never yields. Every other parameter is SUMO's default passenger car (Krauss,
``sigma = 0.5``, ``accel = 2.6``, ``decel = 4.5``, ``emergencyDecel = 9``), with
``maxSpeed`` at the speed limit.

**The ego** is a SUMO vehicle inserted 30 s into the episode, its front 40 m before the end
of its approach lane at 8 m/s, its size and limits those of the planner's AV vehicle
(:func:`planner_config`: a 5 x 1.8 m car, ``u`` in [-4.5, 2.6] m/s^2, ``v`` in [0, 13.89] m/s,
also the human model's vehicle). A planner driver sets its speed every 0.1 s through libsumo
(``setSpeed(v + a dt)``) with speed mode :data:`SPEED_MODE` (SUMO's safe speed, right of way
and red-light checks off, so SUMO does not protect it; its acceleration limits kept). SUMO runs
with ``--step-method.ballistic`` so that positions follow constant accelerations, the
kinematics the planner and the shield assume (with SUMO's default Euler update a vehicle
moves ``a dt^2 / 2`` further per step than any constant-acceleration motion within its
limits, outside the shield's model of the humans). The baseline driver ``sumo`` is SUMO's own
default driver as the ego (same vehicle, default speed mode); the driver ``none`` runs the
same traffic without the ego, the reference for the time loss the ego causes.

**Projection** (:class:`Projector`): each vehicle's route is a centre line made of its lanes'
shapes, junction lanes included (:class:`~persuasive.envs.external.Polyline`); a vehicle's
centre is at its front's arc length minus half its length. The conflict of each route with
the ego's is built once (:func:`persuasive.envs.external.route_conflict`: crossing or merge,
conflict point, occupancy intervals with :data:`LATERAL_MARGIN_M` for SUMO's lateral
tracking and :data:`LONG_MARGIN_M` along the paths); a vehicle ahead in the ego's lane is a
follow conflict. The other vehicle's limits are its SUMO type's: ``u_min = -emergencyDecel``,
``u_max = accel``, ``v_max = maxSpeed``, so the shield's worst case is SUMO's real envelope.

**Judges** (:class:`EpisodeResult`): SUMO's own collision detection (junction collisions on,
``--collision.mingap-factor 0``: physical overlaps only, ``--collision.action warn``),
SUMO's SSM device on the ego (minimum TTC, minimum PET, maximum DRAC over its conflicts;
SUMO records a conflict only past its default thresholds, TTC < 3 s, DRAC > 3 m/s^2, PET <
2 s), the ego's time to cross (from its insertion until its centre is half a length past the
end of the junction), and the time loss of SUMO's vehicles (tripinfo ``timeLoss``, unfinished
trips included, at the episode's end) against the same episode without the ego, the time the
ego stood inside the junction, and SUMO's vehicles forced to brake: those that braked harder
than 1.5 m/s^2 at least once, less as many in the same episode without the ego.

Determinism: SUMO's ``--seed`` is the episode's seed, the traffic comes from the seed, the
planner's per-vehicle seeds from it too; each episode runs in a worker process (libsumo runs
SUMO inside the process: one SUMO per process), so results do not depend on the workers.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import io
import math
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._processes import scratch_dir
from ..config import AV_KIND_ALIASES, AV_KINDS, SHIELD_KINDS, Config, ConfigError
from ..safety.measures import WAIT_SPEED_MPS, restricted_mean
from .external import (CROSSING, FOLLOW, MERGE, ExternalPlanner, Limits, Polyline,
                       RouteConflict, route_conflict)

SCENARIOS = ("intersection", "merge")
#: The SUMO-driven baseline ego, and the run without an ego.
SUMO_DRIVER, NO_EGO = "sumo", "none"
#: A deceleration above this counts as braking hard [m/s^2]: above Krauss's own dawdling
#: (at most ``sigma * accel`` = 0.5 x 2.6 = 1.3 m/s^2 for SUMO's default car).
HARD_BRAKE_MPS2 = 1.5
#: SUMO's step and the planner's [s].
DT_S = 0.1
#: The ego's insertion time [s] (the traffic has filled the roads by then) and the episode's
#: length after it [s].
EGO_DEPART_S = 30.0
EPISODE_S = 60.0
#: The ego's start: its front this far before the end of its approach lane [m], at this
#: speed [m/s].
EGO_START_M = 40.0
EGO_START_MPS = 8.0
#: The roads' speed limit [m/s] (50 km/h).
SPEED_LIMIT_MPS = 13.89
#: The ego's speed mode: bit 1 (max acceleration) and bit 2 (max deceleration) kept; bit 0
#: (safe speed), bit 3 (right of way) and bit 4 (red lights) off; bit 5 on (disregard right
#: of way within the junction).
SPEED_MODE = 0b100110
#: Margins of the projection [m]: lateral (SUMO's vehicles keep the lane's centre line; a
#: rectangle on a curve lies within its chord's sagitta of the line, under 0.3 m on these
#: junctions) and along the paths (the ego's last braking step, under ``|u_min| dt^2 / 8``,
#: and rounding).
LATERAL_MARGIN_M = 0.5
LONG_MARGIN_M = 0.05
#: Flows of the README's study [veh/h per conflicting route].
FLOW_LOW, FLOW_HIGH = 300.0, 900.0
#: The SUMO vehicle types: SUMO's default passenger car at the speed limit.
HUMAN_TYPE = {"length": 5.0, "width": 1.8, "accel": 2.6, "decel": 4.5, "emergencyDecel": 9.0,
              "maxSpeed": SPEED_LIMIT_MPS, "sigma": 0.5}
RECKLESS_PARAMS = {"jmIgnoreFoeProb": 1.0, "jmIgnoreFoeSpeed": 1000.0,
                   "jmIgnoreJunctionFoeProb": 1.0}
NETCONVERT_TIMEOUT_S = 120.0
#: The stand-ins for vehicles not inserted yet (:func:`entry_vehicles`): key prefix, and the
#: front's position along the route's first lane [m] (SUMO inserts a 5 m car's front at
#: 5.1 m; 0.9 m more for margin).
ENTRY_PREFIX = "entry:"
ENTRY_FRONT_M = 6.0


# -- networks -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Network:
    """A network's nodes ``(id, x, y, type)``, edges ``(id, from, to, priority)`` (``lanes``
    lanes each, at ``speed_mps``), the ego's route and the conflicting routes.

    The fields after ``junction`` are for networks other than :data:`NETWORKS` (the
    four-way junction of ``persuasive.many.sumo``); their defaults write :data:`NETWORKS`'
    files as they always were: ``lane_width_m`` (None: SUMO's default width),
    ``junction_radius_m`` (the ``radius`` of the ``junction`` node; None: netconvert's
    default), ``connections`` ``(from edge, to edge, from lane, to lane)`` (SUMO's lane
    indices, 0 the rightmost; empty: netconvert computes them)."""

    name: str
    nodes: tuple[tuple[str, float, float, str], ...]
    edges: tuple[tuple[str, str, str, int], ...]
    ego_route: tuple[str, ...]
    traffic_routes: tuple[tuple[str, ...], ...]
    #: the junction the ego crosses or merges at
    junction: str
    lanes: int = 1
    speed_mps: float = SPEED_LIMIT_MPS
    lane_width_m: float | None = None
    junction_radius_m: float | None = None
    connections: tuple[tuple[str, str, int, int], ...] = ()

    def nodes_xml(self) -> str:
        def radius(n: str) -> str:
            return (f' radius="{self.junction_radius_m:g}"' if n == self.junction
                    and self.junction_radius_m is not None else "")

        rows = "".join(f'  <node id="{n}" x="{x:g}" y="{y:g}" type="{t}"{radius(n)}/>\n'
                       for n, x, y, t in self.nodes)
        return f"<nodes>\n{rows}</nodes>\n"

    def edges_xml(self) -> str:
        width = "" if self.lane_width_m is None else f' width="{self.lane_width_m:g}"'
        rows = "".join(f'  <edge id="{e}" from="{a}" to="{b}" priority="{p}" '
                       f'numLanes="{self.lanes}" speed="{self.speed_mps:g}"{width}/>\n'
                       for e, a, b, p in self.edges)
        return f"<edges>\n{rows}</edges>\n"

    def connections_xml(self) -> str:
        rows = "".join(f'  <connection from="{a}" to="{b}" fromLane="{i}" toLane="{j}"/>\n'
                       for a, b, i, j in self.connections)
        return f"<connections>\n{rows}</connections>\n"


def _intersection() -> Network:
    arm_in, arm_out = 250.0, 150.0
    nodes = (("C", 0.0, 0.0, "priority"), ("W", -arm_in, 0.0, "dead_end"),
             ("E", arm_in, 0.0, "dead_end"), ("S", 0.0, -arm_in, "dead_end"),
             ("N", 0.0, arm_out, "dead_end"))
    edges = (("W2C", "W", "C", 2), ("C2E", "C", "E", 2), ("E2C", "E", "C", 2),
             ("C2W", "C", "W", 2), ("S2C", "S", "C", 1), ("C2N", "C", "N", 1),
             ("N2C", "N", "C", 1), ("C2S", "C", "S", 1))
    return Network("intersection", nodes, edges, ("S2C", "C2N"),
                   (("W2C", "C2E"), ("E2C", "C2W")), "C")


def _merge() -> Network:
    angle = math.radians(30.0)
    ramp = 250.0
    nodes = (("A", -250.0, 0.0, "dead_end"), ("M", 0.0, 0.0, "priority"),
             ("B", 150.0, 0.0, "dead_end"),
             ("R", -ramp * math.cos(angle), -ramp * math.sin(angle), "dead_end"))
    edges = (("A2M", "A", "M", 2), ("R2M", "R", "M", 1), ("M2B", "M", "B", 2))
    return Network("merge", nodes, edges, ("R2M", "M2B"), (("A2M", "M2B"),), "M")


NETWORKS = {"intersection": _intersection(), "merge": _merge()}


def _die_with_parent_preexec() -> None:  # pragma: no cover - runs in the child
    """In a child before ``exec``: the kernel kills it when its parent dies (Linux)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def spawn_tied(args: Sequence[str], **kwargs: Any) -> subprocess.Popen:
    """``subprocess.Popen(args)`` for a child that dies with this process, SIGKILL included
    (``prctl(PR_SET_PDEATHSIG)`` before ``exec`` on Linux)."""
    if sys.platform.startswith("linux"):
        kwargs["preexec_fn"] = _die_with_parent_preexec
    return subprocess.Popen(list(args), **kwargs)


def sumo_binaries() -> dict[str, str]:
    """Paths of the ``eclipse-sumo`` wheel's ``netconvert``, checked with libsumo's presence;
    :class:`ConfigError` (one line) when the ``sumo`` extra is missing."""
    hint = "pip install -e '.[sumo]' in the persuasive checkout"
    try:
        import sumo  # the eclipse-sumo wheel
        home = Path(sumo.SUMO_HOME)
    except (ImportError, AttributeError):
        raise ConfigError(f"persuasive sumo needs Eclipse SUMO (eclipse-sumo): {hint}") from None
    try:
        found = importlib.util.find_spec("libsumo") is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        raise ConfigError(f"persuasive sumo needs libsumo: {hint}")
    netconvert = home / "bin" / "netconvert"
    if not netconvert.is_file():
        raise ConfigError(f"persuasive sumo: SUMO's netconvert is missing from {home}: {hint}")
    return {"netconvert": str(netconvert), "home": str(home)}


def build_network(network: Network, folder: str | Path, netconvert: str | None = None) -> Path:
    """Write ``network``'s node and edge files (and its connection file, if it has
    connections) into ``folder`` and build ``net.net.xml`` with ``netconvert`` (a child that
    dies with this process); :class:`ConfigError` with netconvert's first error line when it
    fails."""
    folder = Path(folder)
    netconvert = netconvert or sumo_binaries()["netconvert"]
    (folder / "net.nod.xml").write_text(network.nodes_xml(), encoding="utf-8")
    (folder / "net.edg.xml").write_text(network.edges_xml(), encoding="utf-8")
    out = folder / "net.net.xml"
    args = [netconvert, "--node-files", str(folder / "net.nod.xml"), "--edge-files",
            str(folder / "net.edg.xml"), "--output-file", str(out), "--no-turnarounds", "true",
            "--offset.disable-normalization", "true", "--no-warnings", "true"]
    if network.connections:  # only these: netconvert adds none from these edges
        (folder / "net.con.xml").write_text(network.connections_xml(), encoding="utf-8")
        args += ["--connection-files", str(folder / "net.con.xml")]
    try:
        proc = spawn_tied(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    except OSError as exc:
        raise ConfigError(f"SUMO's netconvert cannot start: {exc.strerror or exc}") from None
    try:
        _, err = proc.communicate(timeout=NETCONVERT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise ConfigError(f"SUMO's netconvert did not build the {network.name} network within "
                          f"{NETCONVERT_TIMEOUT_S:g} s") from None
    if proc.returncode != 0 or not out.is_file():
        lines = [ln.strip() for ln in (err or "").splitlines() if ln.strip()]
        first = next((ln for ln in lines if ln.lower().startswith("error")), lines[0] if lines
                     else f"exit status {proc.returncode}")
        raise ConfigError(f"SUMO's netconvert cannot build the {network.name} network: {first}")
    return out


def lane_shapes(net_file: str | Path) -> dict[str, np.ndarray]:
    """Every lane's shape (n, 2) [m] in a ``.net.xml``, junction lanes included."""
    shapes = {}
    for lane in ET.parse(net_file).getroot().iter("lane"):
        pts = [tuple(map(float, p.split(","))) for p in lane.get("shape", "").split()]
        shapes[lane.get("id")] = np.array(pts, float).reshape(-1, 2)
    return shapes


# -- traffic --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Departure:
    """One SUMO vehicle of the traffic."""

    vehicle: str
    route: int  #: index in the network's traffic routes
    depart_s: float
    reckless: bool


def traffic(network: Network, seed: int, flow_veh_h: float, ignore_foes: float,
            until_s: float) -> list[Departure]:
    """Poisson arrivals on each conflicting route from ``seed`` (module docstring), sorted by
    departure time."""
    out = []
    children = np.random.SeedSequence([int(seed), 18]).spawn(len(network.traffic_routes))
    mean = 3600.0 / flow_veh_h
    for r, child in enumerate(children):
        rng = np.random.Generator(np.random.PCG64(child))
        t, i = 0.0, 0
        while True:
            t += mean * float(rng.exponential())
            u = float(rng.random())
            if t >= until_s:
                break
            out.append(Departure(f"r{r}.{i}", r, round(t, 1), u < ignore_foes))
            i += 1
    out.sort(key=lambda d: (d.depart_s, d.route, d.vehicle))
    return out


def _vtype(name: str, attrs: dict[str, float], params: dict[str, str] | None = None) -> str:
    text = " ".join(f'{k}="{v:g}"' for k, v in attrs.items())
    inner = "".join(f'    <param key="{k}" value="{v}"/>\n' for k, v in (params or {}).items())
    return (f'  <vType id="{name}" {text}>\n{inner}  </vType>\n' if inner
            else f'  <vType id="{name}" {text}/>\n')


def routes_xml(network: Network, departures: Sequence[Departure], ego: Limits | None,
               ego_length: float | None = None) -> str:
    """SUMO's route file: the types, the routes, the traffic and (``ego`` given) the ego."""
    parts = ["<routes>\n", _vtype("human", HUMAN_TYPE),
             _vtype("reckless", {**HUMAN_TYPE, **RECKLESS_PARAMS})]
    if ego is not None:
        parts.append(_vtype("ego", {"length": ego.length_m, "width": ego.width_m,
                                    "accel": ego.u_max_mps2, "decel": -ego.u_min_mps2,
                                    "emergencyDecel": -ego.u_min_mps2,
                                    "maxSpeed": ego.v_max_mps, "speedFactor": 1.0,
                                    "speedDev": 0.0},
                            {"has.ssm.device": "true"}))
    for r, edges in enumerate(network.traffic_routes):
        parts.append(f'  <route id="traffic{r}" edges="{" ".join(edges)}"/>\n')
    parts.append(f'  <route id="ego" edges="{" ".join(network.ego_route)}"/>\n')
    rows = [(d.depart_s, f'  <vehicle id="{d.vehicle}" type="{"reckless" if d.reckless else "human"}" '
             f'route="traffic{d.route}" depart="{d.depart_s:.1f}" departSpeed="desired" '
             f'departLane="best"/>\n') for d in departures]
    if ego is not None:
        rows.append((EGO_DEPART_S, f'  <vehicle id="ego" type="ego" route="ego" '
                     f'depart="{EGO_DEPART_S:.1f}" departPos="{ego_length:.2f}" '
                     f'departSpeed="{EGO_START_MPS:g}"/>\n'))
    rows.sort(key=lambda r: r[0])  # stable: the ego after the traffic of the same time
    parts += [r[1] for r in rows]
    parts.append("</routes>\n")
    return "".join(parts)


# -- the planner's configuration --------------------------------------------------------------


def planner_config(kind: str = "persuasive", shield: str = "worst-case",
                   scenario: str = "intersection") -> Config:
    """The planner's configuration in SUMO: corrected mode, ``av.kind = kind``, ``av.shield
    = shield``, the paper's scenario of the same kind (``intersection`` or ``merge``: the game
    each conflict is played as) and both vehicles a SUMO passenger car (5 x 1.8 m,
    ``u`` in [-4.5, 2.6] m/s^2, ``v`` in [0, 13.89] m/s, 3.2 m lanes)."""
    if kind not in AV_KINDS and kind not in AV_KIND_ALIASES:
        raise ConfigError(f"--planner = {kind!r} is out of range; allowed: "
                          f"{' | '.join(AV_KINDS)}")
    if shield not in SHIELD_KINDS:
        raise ConfigError(f"--shield = {shield!r} is out of range; allowed: "
                          f"{' | '.join(SHIELD_KINDS)}")
    return Config(mode="corrected").with_overrides({
        "av.kind": kind, "av.shield": shield, "scenario.kind": scenario,
        "vehicle.length_m": HUMAN_TYPE["length"], "vehicle.width_m": HUMAN_TYPE["width"],
        "vehicle.lane_width_m": 3.2, "vehicle.v_max_mps": SPEED_LIMIT_MPS,
        "vehicle.u_min_mps2": -HUMAN_TYPE["decel"], "vehicle.u_max_mps2": HUMAN_TYPE["accel"]})


def horizon_s(config: Config) -> float:
    """The planner's prediction horizon [s]."""
    return config.library.n_samples * config.library.sample_dt_s


# -- projection ------------------------------------------------------------------------------


@dataclass
class Route:
    """A route's lanes, its centre line and, per lane, ``(start in SUMO's coordinate, start
    along the centre line, scale)`` [m, m, -] (scale: the lane shape's length over SUMO's
    lane length, which differ on junction lanes, e.g. by 0.064 %).

    **The route's coordinate is SUMO's own**: a vehicle at ``lane_pos_m`` on a lane is at
    that lane's start plus ``lane_pos_m``, the sum of SUMO's lane lengths before it, so that
    a vehicle that moves ``v dt`` in SUMO moves exactly ``v dt`` in the shield's coordinates.
    The geometry (where the footprints can touch) is found on the centre line and carried
    over by :meth:`from_line`, the exact piecewise-linear map between the two."""

    edges: tuple[str, ...]
    lanes: tuple[str, ...]
    line: Polyline
    offsets: dict[str, tuple[float, float, float]]
    #: SUMO's right of way on the route's first link into a junction (``hasPrio`` of
    #: ``lane.getLinks``; None: the route enters no junction): what the responsibility shield
    #: reads as the right of way (docs/method.md §12.13)
    has_priority: bool | None = None

    def arc(self, lane: str, lane_pos_m: float) -> float | None:
        """The route coordinate of a point at ``lane_pos_m`` on ``lane`` (``None``: not on
        this route)."""
        entry = self.offsets.get(lane)
        if entry is None:
            return None
        return entry[0] + lane_pos_m

    def line_start(self, lane: str) -> float:
        """Where ``lane`` starts along the centre line [m]."""
        return self.offsets[lane][1]

    def from_line(self, s_m: float) -> float:
        """The route coordinate of the point at arc length ``s_m`` of the centre line
        (beyond either end, the line's length continues at scale 1)."""
        starts = [(e[1], e[0], e[2]) for e in self.offsets.values()]
        line_at, sumo_at, scale = starts[0]
        for entry in starts[1:]:
            if entry[0] > s_m:
                break
            line_at, sumo_at, scale = entry
        if s_m < 0.0:
            return s_m
        last_line, last_sumo, last_scale = starts[-1]
        end_line = self.line.length_m
        if s_m > end_line:
            return last_sumo + (end_line - last_line) / last_scale + (s_m - end_line)
        return sumo_at + (s_m - line_at) / scale


class Projector:
    """SUMO's vehicles as :class:`~persuasive.envs.external.Conflict` of the ego's route
    (module docstring). ``links(lane)`` and ``shape(lane)``, ``length(lane)``: libsumo's
    ``lane.getLinks``, ``lane.getShape``, ``lane.getLength`` (or equivalents, for tests).

    A route is its edges and the lane it starts on (``first_lane``; None: the first edge's
    lane 0, the only lane of :data:`NETWORKS`' roads); from there it follows the one link of
    each lane into the next edge (networks whose lanes keep their lane through a junction,
    vehicles that do not change lanes)."""

    def __init__(self, ego_edges: Sequence[str], ego_size: tuple[float, float], links, shape,
                 length, ego_lane: str | None = None):
        self._links, self._shape, self._length = links, shape, length
        self._routes: dict[tuple, Route] = {}
        self._conflicts: dict[tuple, Any] = {}
        self._seen: dict[tuple, Any] = {}
        self.ego_size = ego_size
        self.ego = self.route(tuple(ego_edges), ego_lane)

    def route(self, edges: tuple[str, ...], first_lane: str | None = None) -> Route:
        """The route over ``edges`` from ``first_lane`` (class docstring), made once."""
        first = first_lane or f"{edges[0]}_0"
        route = self._routes.get((edges, first))
        if route is not None:
            return route
        lanes = [first]
        has_priority = None
        for nxt in edges[1:]:
            lane = lanes[-1]
            while True:  # through the junction's internal lanes to the next edge
                if lane.startswith(":"):
                    # its one link, through the next internal lane if it has one (a left
                    # turn that SUMO splits at its waiting position inside the junction)
                    links = list(self._links(lane))
                    step = (links[0][4] or links[0][0]) if links else None
                else:
                    link = next((ln for ln in self._links(lane)
                                 if ln[0].rsplit("_", 1)[0] == nxt), None)
                    step = None if link is None else (link[4] or link[0])
                    if link is not None and has_priority is None and link[4]:
                        has_priority = bool(link[1])  # the first link into a junction
                if step is None:
                    raise ConfigError(f"SUMO route {' '.join(edges)}: no connection from "
                                      f"{lane} to {nxt}")
                lanes.append(step)
                lane = step
                if not step.startswith(":"):
                    break
        points, offsets, start, sumo_start = [], {}, 0.0, 0.0
        for lane in lanes:
            pts = np.asarray(self._shape(lane), float).reshape(-1, 2)
            seg = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
            length = float(self._length(lane))
            offsets[lane] = (sumo_start, start, seg / length)
            start += seg
            sumo_start += length
            points.append(pts if not points else pts[1:] if np.allclose(pts[0], points[-1][-1])
                          else pts)
        route = Route(edges, tuple(lanes), Polyline.of(np.concatenate(points)), offsets,
                      has_priority)
        self._routes[(edges, first)] = route
        return route

    def geometry(self, edges: tuple[str, ...], other_size: tuple[float, float],
                 first_lane: str | None = None):
        """The :class:`~persuasive.envs.external.RouteConflict` of a route with the ego's
        (``None``: no conflict), made once per route and size."""
        key = (edges, first_lane, other_size)
        if key in self._conflicts:
            return self._conflicts[key]
        other = self.route(edges, first_lane)
        ego = self.ego
        shared = [ln for ln in ego.lanes if ln in other.offsets and not ln.startswith(":")]
        geo = None
        if shared:
            lane = shared[0]
            ie, io = ego.lanes.index(lane), other.lanes.index(lane)
            a0, b0 = ego.line_start(lane), other.line_start(lane)
            if ie > 0 and io > 0 and ego.lanes[ie - 1] != other.lanes[io - 1]:
                geo = route_conflict(ego.line, other.line, self.ego_size, other_size,
                                     LATERAL_MARGIN_M, LONG_MARGIN_M, merge_at=(a0, b0))
            else:  # the same lane: a leader (or a follower, which the shield leaves alone)
                geo = RouteConflict(FOLLOW, a0, b0, (-math.inf, -math.inf),
                                    (-math.inf, -math.inf))
        else:
            geo = route_conflict(ego.line, other.line, self.ego_size, other_size,
                                 LATERAL_MARGIN_M, LONG_MARGIN_M)
        geo = None if geo is None else in_route_coordinates(geo, ego, other)
        if geo is not None and geo.kind != FOLLOW:
            entry = junction_entry(ego, geo.ego_at_m)
            if entry is not None:  # the ego yields with its front before the junction
                geo = replace(geo, ego_line_m=entry - 0.5 * self.ego_size[0] - geo.ego_at_m)
        self._conflicts[key] = geo
        return geo

    def of(self, edges: tuple[str, ...], other_size: tuple[float, float],
           slack: tuple[float, float] = (0.0, 0.0), first_lane: str | None = None):
        """``(route, geometry, the ego's interval ended sum(slack) later)`` of a vehicle on
        ``edges`` from ``first_lane`` (``None``: no conflict with the ego's route), made once
        per route, size and slack: what :func:`conflicts_of` needs of a vehicle besides its
        state."""
        key = (edges, first_lane, other_size, slack)
        try:
            return self._seen[key]
        except KeyError:
            pass
        geo = self.geometry(edges, other_size, first_lane)
        entry = None
        if geo is not None:
            lo, hi = geo.ego_occupancy
            widened = (lo, hi + slack[0] + slack[1]) if any(slack) else geo.ego_occupancy
            entry = (self.route(edges, first_lane), geo, widened)
        self._seen[key] = entry
        return entry


def junction_entry(route: Route, at_m: float) -> float | None:
    """Where ``route`` enters the junction of its conflict point ``at_m`` (route coordinate):
    the start of the last run of internal lanes (SUMO's ``:``-lanes, inside the junction's
    polygon) that starts at or before it; None if none does."""
    entry, inside = None, False
    for lane in route.lanes:
        internal = lane.startswith(":")
        start = route.offsets[lane][0]
        if internal and not inside and start <= at_m:
            entry = start
        inside = internal
    return entry


def in_route_coordinates(geo: RouteConflict, ego: Route, other: Route) -> RouteConflict:
    """``geo``, found along the two centre lines, in the routes' own coordinates
    (:class:`Route`): the conflict points and every interval end carried over by the exact
    map (monotone, so an interval stays the interval of the same points)."""

    def interval(route: Route, at: float, occ: tuple[float, float], at_r: float):
        return tuple(o if not math.isfinite(o) else route.from_line(at + o) - at_r
                     for o in occ)

    a0, b0 = ego.from_line(geo.ego_at_m), other.from_line(geo.other_at_m)
    return RouteConflict(geo.kind, a0, b0, interval(ego, geo.ego_at_m, geo.ego_occupancy, a0),
                         interval(other, geo.other_at_m, geo.other_occupancy, b0))


@dataclass(frozen=True)
class VehicleState:
    """One SUMO vehicle at one step (front bumper ``x, y``; SUMO's angle: degrees clockwise
    from north)."""

    vehicle: str
    edges: tuple[str, ...]
    lane: str
    lane_pos_m: float
    x_m: float
    y_m: float
    angle_deg: float
    speed_mps: float
    length_m: float
    width_m: float
    limits: Limits
    #: the lane its route starts on (None: the first edge's lane 0; :class:`Projector`)
    first_lane: str | None = None


def ballistic_slack(limits: Limits, dt_s: float = DT_S) -> tuple[float, float]:
    """How far SUMO's ballistic update can put the ego from the exact constant-acceleration
    motion the shield assumes, within one step [m]: ``(ahead, behind)``.

    A step in which the speed reaches 0 moves it ``(v + 0) dt / 2``, up to ``|u_min| dt^2 /
    8`` further than braking to a stop; a step in which it reaches ``v_max`` moves it
    ``(v + v_max) dt / 2``, up to ``u_max dt^2 / 8`` less than the exact motion. Each can
    happen once along a fallback (it stops once, it saturates once)."""
    return (-limits.u_min_mps2 * dt_s ** 2 / 8.0 + 1e-6,
            limits.u_max_mps2 * dt_s ** 2 / 8.0 + 1e-6)


def conflicts_of(projector: Projector, ego: VehicleState, others: Sequence[VehicleState],
                 clear_m: float, slack: tuple[float, float] = (0.0, 0.0)) -> list:
    """The conflicts of the ego with ``others`` (vehicles with none, or past their conflict
    for good, are left out). ``slack`` (:func:`ballistic_slack`): the ego is placed
    ``slack[0]`` further along and its occupancy intervals end ``sum(slack)`` later, so that
    SUMO's stopping and saturating steps stay inside what the shield certifies."""
    ego_arc = projector.ego.arc(ego.lane, ego.lane_pos_m)
    if ego_arc is None:
        return []
    ego_arc += slack[0] - 0.5 * ego.length_m
    slack = (float(slack[0]), float(slack[1]))
    out = []
    for o in others:
        found = projector.of(o.edges, (o.length_m, o.width_m), slack, o.first_lane)
        if found is None:
            continue
        route, geo, widened = found
        arc = route.arc(o.lane, o.lane_pos_m)
        if arc is None:
            continue
        arc -= 0.5 * o.length_m
        if geo.kind == CROSSING and arc - geo.other_at_m > max(geo.other_occupancy[1],
                                                                clear_m):
            continue  # past the ego's path for good
        c = geo.conflict(o.vehicle, ego_arc, arc, o.speed_mps, o.limits,
                         ego_occupancy=widened)
        mine, theirs = projector.ego.has_priority, route.has_priority
        if mine is not None and theirs is not None:  # SUMO's right of way at the junction
            c = replace(c, right_of_way=float(int(mine) - int(theirs)))
        if str(o.vehicle).startswith(ENTRY_PREFIX):  # no driver: no duty, no response
            c.extra["placeholder"] = True
        out.append(c)
    return out


def entry_vehicles(network: Network, limits: Limits) -> list[VehicleState]:
    """One stand-in per conflicting route for the vehicles SUMO may still insert there
    (keys :data:`ENTRY_PREFIX` and the route's index): at the route's start, its front
    :data:`ENTRY_FRONT_M` along the first lane, at the type's ``v_max``.

    SUMO inserts every vehicle of the traffic at its route's start (its front 5.1 m along
    the lane, at most at ``maxSpeed``), so whatever enters later can be nowhere that this
    stand-in, which may do anything within the type's limits from now, could not be; a
    trajectory certified against it is certified against every vehicle not yet inserted,
    and the stand-in stays where it is, so the certification holds at every later step
    (docs/method.md §14.4). Without it the ego may enter a conflict where no vehicle is in
    view and then find one inserted, outside the shield's invariant set."""
    return [VehicleState(f"{ENTRY_PREFIX}{r}", tuple(edges), f"{edges[0]}_0", ENTRY_FRONT_M,
                         math.nan, math.nan, math.nan, limits.v_max_mps, limits.length_m,
                         limits.width_m, limits)
            for r, edges in enumerate(network.traffic_routes)]


def decide(planner: ExternalPlanner, projector: Projector, ego: VehicleState,
           others: Sequence[VehicleState], clear_m: float,
           slack: tuple[float, float]) -> tuple[Any, list]:
    """The planner's decision for the ego among ``others`` (``ExternalPlanner.act`` on
    :func:`conflicts_of` with the ballistic ``slack``) and the conflicts it saw.

    An ego at rest is re-anchored: the stop that brought it there may have taken it up to
    ``slack[0]`` beyond the exact braking motion (the overshoot the shift was for), and
    shifting its new position once more would count that overshoot twice, so that an ego
    certified to stand before its interval could find itself inside it and no fallback
    certified. Standing still, and starting from rest at ``u_max``, never stop within a step,
    so SUMO moves the ego exactly as the shield assumes: when the shifted shield certifies no
    fallback at rest, the shield is asked again without the shift (the intervals still end
    ``slack[1]`` later, for the step that reaches ``v_max``) to stand for a step, and applies
    its answer if that one is certified (verdict ``brake`` when the ego stands, ``go``)."""
    conflicts = conflicts_of(projector, ego, others, clear_m, slack)
    decision = planner.act(ego.speed_mps, conflicts, DT_S)
    if decision.verdict == "uncertified" and ego.speed_mps <= 0.0:
        exact = conflicts_of(projector, ego, others, clear_m, (0.0, slack[1]))
        u_min = planner.ego.u_min_mps2
        if planner.duties is not None:  # this answer replaces the first for the rule's clocks
            planner.duties.undo()
        a, verdict = planner.shield(0.0, u_min, exact, DT_S)
        if verdict != "uncertified":
            decision = replace(decision, accel_mps2=a,
                               verdict="brake" if a == u_min else "go")
    return decision, conflicts


# -- one episode ----------------------------------------------------------------------------


def driver_name(kind: str, shield: str) -> str:
    """How a planner driver is named in results: ``kind`` and its shield."""
    return f"{kind}/{shield}"


@dataclass(frozen=True)
class EpisodeResult:
    """One episode of one driver (module docstring)."""

    scenario: str
    seed: int
    driver: str  #: "kind/shield", "sumo" (SUMO's own ego) or "none" (no ego)
    flow_veh_h: float
    ignore_foes: float
    collision: bool  #: SUMO reported a collision involving the ego
    collisions: int  #: distinct (collider, victim) pairs involving the ego
    ego_collider: int  #: of which SUMO names the ego as the collider
    junction_collisions: int  #: of which on a junction
    crossed: bool
    time_to_cross_s: float | None
    min_ttc_s: float | None  #: SUMO's SSM device (None: no conflict past its threshold)
    min_pet_s: float | None
    max_drac_mps2: float | None
    traffic_time_loss_s: float  #: SUMO's vehicles' time loss in the episode
    caused_time_loss_s: float | None  #: minus the same episode without the ego
    sumo_vehicles: int
    ego_steps: int  #: steps the planner decided (0 for sumo and none)
    shield_overrides: int  #: of which the shield replaced the proposal
    uncertified: int  #: of which no fallback was certified
    decide_ms_median: float | None  #: the planner plus shield per step (median) [ms]
    max_in_view: int  #: most vehicles handed to the planner at one step
    #: the worst-case guarantee covered the episode: a planner ego with the worst-case
    #: shield, every step certified (False for SUMO's own driver and without the shield)
    guarantee_held: bool = False
    #: time the ego stood (below 0.1 m/s, SUMO's waiting threshold) inside a junction, on one
    #: of its internal lanes [s]: where it blocks others (every driver, SUMO's own too)
    junction_stood_s: float = 0.0
    #: SUMO's vehicles that braked harder than :data:`HARD_BRAKE_MPS2` at least once (above
    #: what Krauss's own dawdling can do), and of those how many more than in the same episode
    #: without the ego: the vehicles the ego forced to brake (None without the reference)
    hard_braking_vehicles: int = 0
    forced_to_brake: int | None = None
    #: SUMO's own ego only (None for the others), judged by the worst-case shield it does not
    #: use: its steps, how many of them the shield would have admitted as they were driven
    #: (the acceleration of each step against the conflicts at its start), and whether it
    #: admits the step that took the ego into the junction (None: it never entered)
    judged_steps: int | None = None
    judged_admitted: int | None = None
    entry_admitted: bool | None = None
    #: what the shield's overrides cost (issue 25 item 6): the mean over the planner's steps
    #: of |applied - proposed| [m/s^2] (0 where admitted; 0 for sumo and none)
    override_mps2: float = 0.0
    #: the responsibility rule (a planner with ``av.shield = "responsibility"``, and SUMO's
    #: own ego judged by it, docs/method.md §12.13; None otherwise): the ego's collisions at
    #: its own fault, and the vehicle-steps in which one of SUMO's vehicles broke its duty
    collisions_ego_at_fault: int | None = None
    duty_breaches: int | None = None

    @property
    def uncertified_steps(self) -> int:
        """:attr:`uncertified` under the name every other summary uses."""
        return self.uncertified

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class EpisodeOutput:
    """An episode's result and, when asked for, its per-step logs."""

    result: EpisodeResult
    #: per step and vehicle: t_s, vehicle, x_m, y_m, angle_deg, speed_mps, lane, reckless
    steps: dict[str, list] | None = None
    #: per ego decision: t_s, in_view, targets, proposed_mps2, accel_mps2, verdict, decide_ms
    decisions: dict[str, list] | None = None
    #: (in_view, decide_ms) of every decision
    timings: list[tuple[int, float]] = field(default_factory=list)


_LIBSUMO = None


def _libsumo():
    """libsumo, imported once per process with its import-time notice (a pyarrow version
    check printed on stdout) silenced."""
    global _LIBSUMO
    if _LIBSUMO is None:
        with contextlib.redirect_stdout(io.StringIO()):
            import libsumo
        _LIBSUMO = libsumo
    return _LIBSUMO


def sumo_args(net_file: Path, routes: Path, folder: Path, seed: int, end_s: float,
              ego: bool) -> list[str]:
    """SUMO's command line of an episode (module docstring)."""
    args = ["sumo", "--net-file", str(net_file), "--route-files", str(routes),
            "--step-length", f"{DT_S:g}", "--step-method.ballistic", "true",
            "--collision.check-junctions", "true", "--collision.action", "warn",
            "--collision.mingap-factor", "0", "--seed", str(int(seed)), "--end", f"{end_s:g}",
            "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
            "--error-log", str(folder / "errors.log"),
            "--tripinfo-output", str(folder / "tripinfo.xml"),
            "--tripinfo-output.write-unfinished", "true"]
    if ego:
        args += ["--device.ssm.measures", "TTC DRAC PET", "--device.ssm.range", "50",
                 "--device.ssm.file", str(folder / "ssm.xml")]
    return args


def _type_limits(ls, vtype: str) -> Limits:
    """A SUMO vehicle type's size and limits: ``u_min = -emergencyDecel``, ``u_max =
    accel``, ``v_max = maxSpeed``."""
    t = ls.vehicletype
    return Limits(t.getLength(vtype), t.getWidth(vtype), -t.getEmergencyDecel(vtype),
                  t.getAccel(vtype), 0.0, t.getMaxSpeed(vtype))


def _limits_of(ls, vid: str, cache: dict) -> tuple[Limits, str]:
    vtype = ls.vehicle.getTypeID(vid)
    entry = cache.get(vtype)
    if entry is None:
        entry = cache[vtype] = _type_limits(ls, vtype)
    return entry, vtype


def _state_of(ls, vid: str, known: dict, types: dict) -> VehicleState:
    """A vehicle's :class:`VehicleState` now; its route and type, fixed for a vehicle's life
    in these networks, are read once (``known``: vehicle -> (edges, limits))."""
    entry = known.get(vid)
    if entry is None:
        entry = known[vid] = (tuple(ls.vehicle.getRoute(vid)), _limits_of(ls, vid, types)[0])
    edges, limits = entry
    x, y = ls.vehicle.getPosition(vid)
    return VehicleState(vid, edges, ls.vehicle.getLaneID(vid), ls.vehicle.getLanePosition(vid),
                        x, y, ls.vehicle.getAngle(vid), ls.vehicle.getSpeed(vid),
                        limits.length_m, limits.width_m, limits)


def _ssm(path: Path) -> tuple[float | None, float | None, float | None]:
    """(min TTC, min PET, max DRAC) of the ego's SSM output."""
    if not path.is_file():
        return None, None, None
    ttc, pet, drac = [], [], []
    for conflict in ET.parse(path).getroot().iter("conflict"):
        for tag, out in (("minTTC", ttc), ("PET", pet), ("maxDRAC", drac)):
            el = conflict.find(tag)
            if el is not None and el.get("value") not in (None, "NA"):
                out.append(float(el.get("value")))
    return (min(ttc) if ttc else None, min(pet) if pet else None,
            max(drac) if drac else None)


def _time_loss(path: Path) -> tuple[float, int]:
    """Total time loss [s] and count of SUMO's vehicles (the ego left out) in a tripinfo."""
    total, n = 0.0, 0
    for trip in ET.parse(path).getroot().iter("tripinfo"):
        if trip.get("id") == "ego":
            continue
        total += float(trip.get("timeLoss", 0.0))
        n += 1
    return total, n


def run_episode(scenario: str, seed: int, driver: str, flow_veh_h: float, ignore_foes: float,
                net_file: str | Path, logs: bool = False,
                reference_time_loss_s: float | None = None,
                reference_hard_braking: int | None = None) -> EpisodeOutput:
    """One episode in this process's SUMO (libsumo): ``driver`` is ``"kind/shield"`` (the
    planner), :data:`SUMO_DRIVER` or :data:`NO_EGO` (module docstring)."""
    ls = _libsumo()
    network = NETWORKS[scenario]
    net_file = Path(net_file)
    end_s = EGO_DEPART_S + EPISODE_S
    planner = None
    if driver not in (SUMO_DRIVER, NO_EGO):
        kind, shield = driver.split("/")
        config = planner_config(kind, shield, scenario)
        planner = ExternalPlanner(config, seed, plan_horizon_s=horizon_s(config))
        ego_limits = planner.ego
    else:
        ego_limits = Limits.of(planner_config(scenario=scenario), "av")
    with_ego = driver != NO_EGO
    # SUMO's own ego, judged by the worst-case shield (issue 25: the share of its entries the
    # certificate would admit); the judge plans nothing, it only filters what SUMO drove
    judge = (ExternalPlanner(planner_config(scenario=scenario), seed)
             if driver == SUMO_DRIVER else None)
    # and by the responsibility rule (docs/method.md §12.13): its fault in a collision and
    # the traffic's breaches, by the same rule as a planner with that shield
    rule_judge = (ExternalPlanner(planner_config(shield="responsibility", scenario=scenario),
                                  seed) if driver == SUMO_DRIVER else None)
    rules = planner if planner is not None and planner.config.shield == "responsibility" \
        else rule_judge
    judged = admitted = 0
    entry_ok: bool | None = None
    before: tuple[float, list] | None = None
    folder = scratch_dir("sumo-")  # the command's scratch: removed if this worker is killed
    departures = traffic(network, seed, flow_veh_h, ignore_foes, end_s)
    reckless = {d.vehicle for d in departures if d.reckless}
    approach = lane_shapes(net_file)[f"{network.ego_route[0]}_0"]
    approach_len = float(np.sum(np.hypot(*np.diff(approach, axis=0).T)))
    routes = folder / "routes.rou.xml"
    routes.write_text(routes_xml(network, departures, ego_limits if with_ego else None,
                                 approach_len - EGO_START_M), encoding="utf-8")
    steps = {k: [] for k in ("t_s", "vehicle", "x_m", "y_m", "angle_deg", "speed_mps",
                             "lane", "reckless")} if logs else None
    decisions = {k: [] for k in ("t_s", "in_view", "targets", "proposed_mps2", "accel_mps2",
                                 "verdict", "decide_ms")} if logs else None
    timings: list[tuple[int, float]] = []
    pairs: dict[tuple[str, str], str] = {}
    faults: dict[tuple[str, str], str] = {}  # the responsibility rule's, per pair
    overrides = uncertified = ego_steps = max_view = 0
    override_sum = 0.0
    stood_steps = 0
    hard: set[str] = set()
    crossed_at = depart_at = None
    types: dict[str, Limits] = {}
    known: dict[str, tuple] = {}
    try:
        ls.start(sumo_args(net_file, routes, folder, seed, end_s, with_ego))
        try:
            projector = Projector(network.ego_route, (ego_limits.length_m, ego_limits.width_m),
                                  ls.lane.getLinks, ls.lane.getShape, ls.lane.getLength)
            cross_lane = f"{network.ego_route[-1]}_0"
            cross_arc = projector.ego.offsets[cross_lane][0] + 0.5 * ego_limits.length_m
            clear = (planner._clear_m if planner is not None
                     else judge._clear_m if judge is not None else 0.0)
            slack = ballistic_slack(ego_limits)
            entries = entry_vehicles(network, _type_limits(ls, "human"))
            steered = False
            while ls.simulation.getTime() < end_s - 1e-9:
                ls.simulationStep()
                t = round(ls.simulation.getTime(), 6)
                for c in ls.simulation.getCollisions():
                    if "ego" in (c.collider, c.victim):
                        if (c.collider, c.victim) not in pairs and rules is not None \
                                and rules.duties is not None:  # the rule's, when it happens
                            faults[(c.collider, c.victim)] = rules.duties.fault()
                        pairs.setdefault((c.collider, c.victim), c.type)
                ids = ls.vehicle.getIDList()
                for vid in ids:  # who brakes hard (SUMO's vehicles; judged for every driver)
                    if vid != "ego" and vid not in hard and \
                            ls.vehicle.getAcceleration(vid) < -HARD_BRAKE_MPS2:
                        hard.add(vid)
                if not logs:  # only what the judges and the planner read
                    ids = (() if "ego" not in ids
                           else ids if planner is not None or judge is not None
                           else ("ego",))
                states, ego = [], None
                for vid in ids:
                    st = _state_of(ls, vid, known, types)
                    if logs:
                        for k, v in (("t_s", t), ("vehicle", vid), ("x_m", st.x_m),
                                     ("y_m", st.y_m), ("angle_deg", st.angle_deg),
                                     ("speed_mps", st.speed_mps), ("lane", st.lane),
                                     ("reckless", vid in reckless)):
                            steps[k].append(v)
                    if vid == "ego":
                        ego = st
                    else:
                        states.append(st)
                if ego is None:
                    continue
                if depart_at is None:
                    depart_at = t
                stood_steps += ego.lane.startswith(":") and ego.speed_mps < WAIT_SPEED_MPS
                arc = projector.ego.arc(ego.lane, ego.lane_pos_m)
                if crossed_at is None and arc is not None and \
                        arc - 0.5 * ego.length_m >= cross_arc:
                    crossed_at = t
                if judge is not None:
                    if before is not None:  # the step just driven, from its start
                        _, verdict = judge.shield(before[0], ls.vehicle.getAcceleration("ego"),
                                                  before[1], DT_S, driven=True)
                        rule_judge.shield(before[0], ls.vehicle.getAcceleration("ego"),
                                          before[1], DT_S, driven=True)
                        judged += 1
                        admitted += verdict == "admitted"
                        if entry_ok is None and ego.lane.startswith(":"):
                            entry_ok = verdict == "admitted"
                    before = (ego.speed_mps,
                              conflicts_of(projector, ego, states + entries, clear, slack))
                if planner is None:
                    continue
                if not steered:
                    ls.vehicle.setSpeedMode("ego", SPEED_MODE)
                    steered = True
                t0 = time.perf_counter()
                decision, conflicts = decide(planner, projector, ego, states + entries, clear,
                                             slack)
                ms = 1e3 * (time.perf_counter() - t0)
                in_view = sum(not str(c.key).startswith(ENTRY_PREFIX) for c in conflicts)
                v_next = min(max(ego.speed_mps + decision.accel_mps2 * DT_S,
                                 ego_limits.v_min_mps), ego_limits.v_max_mps)
                ls.vehicle.setSpeed("ego", v_next)
                ego_steps += 1
                overridden = decision.verdict not in (None, "admitted")
                overrides += overridden
                if overridden and math.isfinite(decision.proposed_mps2):
                    override_sum += abs(decision.accel_mps2 - decision.proposed_mps2)
                uncertified += decision.verdict == "uncertified"
                max_view = max(max_view, in_view)
                timings.append((in_view, ms))
                if logs:
                    for k, v in (("t_s", t), ("in_view", in_view),
                                 ("targets", decision.targets),
                                 ("proposed_mps2", decision.proposed_mps2),
                                 ("accel_mps2", decision.accel_mps2),
                                 ("verdict", decision.verdict or ""), ("decide_ms", ms)):
                        decisions[k].append(v)
        finally:
            ls.close()
        loss, n_sumo = _time_loss(folder / "tripinfo.xml")
        ttc, pet, drac = _ssm(folder / "ssm.xml") if with_ego else (None, None, None)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    duties = None if rules is None else rules.duties
    result = EpisodeResult(
        scenario=scenario, seed=int(seed), driver=driver, flow_veh_h=float(flow_veh_h),
        ignore_foes=float(ignore_foes), collision=bool(pairs), collisions=len(pairs),
        ego_collider=sum(c == "ego" for c, _ in pairs),
        collisions_ego_at_fault=None if duties is None else sum(
            faults.get(p, "ego") == "ego" for p in pairs),
        duty_breaches=None if duties is None else duties.other_breaches,
        junction_collisions=sum(kind == "junction" for kind in pairs.values()),
        crossed=crossed_at is not None,
        time_to_cross_s=None if crossed_at is None else round(crossed_at - depart_at, 6),
        min_ttc_s=ttc, min_pet_s=pet, max_drac_mps2=drac, traffic_time_loss_s=loss,
        caused_time_loss_s=None if reference_time_loss_s is None or not with_ego
        else loss - reference_time_loss_s,
        sumo_vehicles=n_sumo, ego_steps=ego_steps, shield_overrides=overrides,
        uncertified=uncertified,
        decide_ms_median=float(np.median([m for _, m in timings])) if timings else None,
        max_in_view=max_view,
        guarantee_held=bool(planner is not None and planner.config.shield == "worst-case"
                            and ego_steps > 0 and uncertified == 0),
        junction_stood_s=round(stood_steps * DT_S, 6),
        hard_braking_vehicles=len(hard),
        forced_to_brake=None if reference_hard_braking is None or not with_ego
        else len(hard) - reference_hard_braking,
        judged_steps=judged if judge is not None else None,
        judged_admitted=admitted if judge is not None else None,
        entry_admitted=entry_ok,
        override_mps2=override_sum / ego_steps if ego_steps else 0.0)
    return EpisodeOutput(result, steps, decisions, timings)


def run_seed(scenario: str, seed: int, drivers: Sequence[str], flow_veh_h: float,
             ignore_foes: float, net_file: str, logs: bool) -> list[EpisodeOutput]:
    """Every driver on one seed, after the run without the ego (the time-loss reference)."""
    ref = run_episode(scenario, seed, NO_EGO, flow_veh_h, ignore_foes, net_file).result
    return [run_episode(scenario, seed, d, flow_veh_h, ignore_foes, net_file, logs,
                        ref.traffic_time_loss_s, ref.hard_braking_vehicles)
            for d in drivers]


# -- a study: episodes on worker processes ---------------------------------------------------


def _run_seed_task(task: tuple) -> list[EpisodeOutput]:  # pragma: no cover - in workers
    return run_seed(*task)


@dataclass(frozen=True)
class SumoReport:
    """Every episode of a study and what it needs to be read (:meth:`summary`)."""

    scenario: str
    flow_veh_h: float
    ignore_foes: float
    seeds: tuple[int, ...]
    drivers: tuple[str, ...]
    episodes: tuple[EpisodeResult, ...]
    #: (in_view, decide_ms) of every planner decision, per driver
    timings: dict[str, list[tuple[int, float]]]
    wall_time_s: float
    workers: int

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per driver: collisions, crossings, times, SSM extremes, time loss, shield counts."""
        out = {}
        for driver in self.drivers:
            eps = [e for e in self.episodes if e.driver == driver]
            crossed = [e.time_to_cross_s for e in eps if e.time_to_cross_s is not None]
            ttc = [e.min_ttc_s for e in eps if e.min_ttc_s is not None]
            pet = [e.min_pet_s for e in eps if e.min_pet_s is not None]
            drac = [e.max_drac_mps2 for e in eps if e.max_drac_mps2 is not None]
            caused = [e.caused_time_loss_s for e in eps if e.caused_time_loss_s is not None]
            times = self.timings.get(driver, [])
            ten = [ms for n, ms in times if n >= 10]
            out[driver] = {
                "episodes": len(eps),
                "collision_episodes": sum(e.collision for e in eps),
                "collisions": sum(e.collisions for e in eps),
                "ego_collider": sum(e.ego_collider for e in eps),
                "junction_collisions": sum(e.junction_collisions for e in eps),
                "crossed": len(crossed),
                "mean_time_to_cross_s": float(np.mean(crossed)) if crossed else None,
                # over every episode, one that never crossed counted at EPISODE_S: a mean over
                # the crossing ones alone rewards failing the hard ones (issue 25 item 6)
                "restricted_mean_time_to_cross_s": restricted_mean(
                    [e.time_to_cross_s for e in eps], EPISODE_S),
                "min_ttc_s": float(np.min(ttc)) if ttc else None,
                "ttc_episodes": len(ttc),
                "min_pet_s": float(np.min(pet)) if pet else None,
                "max_drac_mps2": float(np.max(drac)) if drac else None,
                "mean_caused_time_loss_s": float(np.mean(caused)) if caused else None,
                "mean_traffic_time_loss_s": float(np.mean([e.traffic_time_loss_s
                                                           for e in eps])) if eps else None,
                "shield_overrides": sum(e.shield_overrides for e in eps),
                "override_pct": (100.0 * sum(e.shield_overrides for e in eps)
                                 / max(1, sum(e.ego_steps for e in eps))),
                "override_mps2_mean": float(np.mean([e.override_mps2 for e in eps]))
                if eps else None,
                "uncertified": sum(e.uncertified for e in eps),
                "guarantee_held_episodes": sum(e.guarantee_held for e in eps),
                "junction_stood_s": float(sum(e.junction_stood_s for e in eps)),
                "forced_to_brake": sum(e.forced_to_brake for e in eps
                                       if e.forced_to_brake is not None),
                "junction_stood_episodes": sum(e.junction_stood_s > 0 for e in eps),
                "entries_judged": sum(e.entry_admitted is not None for e in eps),
                "entries_admitted": sum(bool(e.entry_admitted) for e in eps),
                "steps_admitted_pct": (100.0 * sum(e.judged_admitted for e in eps)
                                       / max(1, sum(e.judged_steps for e in eps)))
                if any(e.judged_steps is not None for e in eps) else None,
                "collisions_ego_at_fault": sum(e.collisions_ego_at_fault for e in eps
                                               if e.collisions_ego_at_fault is not None)
                if any(e.collisions_ego_at_fault is not None for e in eps) else None,
                "duty_breaches": sum(e.duty_breaches for e in eps
                                     if e.duty_breaches is not None)
                if any(e.duty_breaches is not None for e in eps) else None,
                "decisions": len(times),
                "decide_ms_median": float(np.median([m for _, m in times])) if times else None,
                "decisions_10_in_view": len(ten),
                "decide_ms_median_10_in_view": float(np.median(ten)) if ten else None,
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "flow_veh_h": self.flow_veh_h,
                "ignore_foes": self.ignore_foes, "seeds": [self.seeds[0], self.seeds[-1]],
                "drivers": list(self.drivers), "workers": self.workers,
                "wall_time_s": self.wall_time_s, "summary": self.summary(),
                "episodes": [e.to_dict() for e in self.episodes]}


#: Most episodes (seeds) one study may have: about a day of SUMO on two cores (every seed
#: runs each driver and the reference run without the ego), and what the report holds in
#: memory; more is a mistake, not a study.
MAX_EPISODES = 10_000


def planner_kernels() -> tuple:
    """The compiled functions the planner's decisions run (for the first-use notice)."""
    from ..policies.step import policy_step_buffers
    from ..safety.shield import shield_filter

    return policy_step_buffers, shield_filter


def check_study(scenario: str, episodes: int, seed: int, flow_veh_h: float,
                ignore_foes: float, planner: str, shields: Sequence[str],
                workers: int | None) -> None:
    """Refuse bad arguments with one line naming the parameter and its range."""
    if scenario not in SCENARIOS:
        raise ConfigError(f"--scenario = {scenario!r} is out of range; allowed: "
                          f"{' | '.join(SCENARIOS)}")
    if (isinstance(episodes, bool) or not isinstance(episodes, int)
            or not 1 <= episodes <= MAX_EPISODES):
        raise ConfigError(f"--episodes = {episodes!r} is out of range; allowed: integer in "
                          f"[1, {MAX_EPISODES}]")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**31 - episodes:
        raise ConfigError(f"--seed = {seed!r} is out of range; allowed: integer in "
                          "[0, 2^31 - episodes)")
    if not (isinstance(flow_veh_h, (int, float)) and math.isfinite(flow_veh_h)
            and 0.0 < flow_veh_h <= 3600.0):
        raise ConfigError(f"--flow = {flow_veh_h!r} is out of range; allowed: (0, 3600] "
                          "vehicles per hour")
    if not (isinstance(ignore_foes, (int, float)) and 0.0 <= ignore_foes <= 1.0):
        raise ConfigError(f"--ignore-foes = {ignore_foes!r} is out of range; allowed: [0, 1]")
    if not shields:
        raise ConfigError(f"--shield is empty; allowed: comma-separated "
                          f"{' | '.join(SHIELD_KINDS)}")
    for sh_ in shields:
        planner_config(planner, sh_, scenario)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise ConfigError(f"--workers = {workers!r} is out of range; allowed: integer >= 1")


def run_study(scenario: str = "intersection", episodes: int = 10, seed: int = 1,
              flow_veh_h: float = FLOW_LOW, ignore_foes: float = 0.0,
              planner: str = "persuasive", shields: Sequence[str] = ("worst-case",),
              workers: int | None = None, logs: bool = False,
              progress=None) -> tuple[SumoReport, list[EpisodeOutput], Path | None]:
    """``episodes`` seeds from ``seed``, each driven by the planner with every shield of
    ``shields`` and by SUMO's own driver (after the run without the ego), on the worker
    processes of a local Dask cluster (started from the fork server, dying with this
    process; :mod:`persuasive._processes`), a bounded number of seeds in flight. An
    interrupt (Ctrl-C) kills the workers at once. Returns the report, the outputs (with logs when
    ``logs``) and the built network's folder (the caller removes it; ``None`` if none)."""
    check_study(scenario, episodes, seed, flow_veh_h, ignore_foes, planner, shields, workers)
    binaries = sumo_binaries()
    kind = planner_config(planner, shields[0], scenario).av.kind
    drivers = tuple(dict.fromkeys([driver_name(kind, s) for s in shields] + [SUMO_DRIVER]))
    t0 = time.perf_counter()
    folder = scratch_dir("sumo-net-")
    try:
        net = build_network(NETWORKS[scenario], folder, binaries["netconvert"])
        _warm_up(scenario, drivers)
        seeds = tuple(range(seed, seed + episodes))
        tasks = [(scenario, s, drivers, float(flow_veh_h), float(ignore_foes), str(net), logs)
                 for s in seeds]
        from ..sweep.runner import run_all

        n = min(workers or os.cpu_count() or 1, len(tasks))  # as run_all starts them
        outputs = [o for outs in run_all(_run_seed_task, tasks, n, progress) for o in outs]
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    timings: dict[str, list] = {}
    for o in outputs:
        timings.setdefault(o.result.driver, []).extend(o.timings)
    report = SumoReport(scenario, float(flow_veh_h), float(ignore_foes), seeds, drivers,
                        tuple(o.result for o in outputs), timings,
                        time.perf_counter() - t0, n)
    return report, outputs, folder


def _warm_up(scenario: str, drivers: Sequence[str]) -> None:
    """Compile (once) and load the planner's kernels here, so that the workers load them from
    the cache and never compile them at the same time."""
    from .external import Conflict

    for d in drivers:
        if d == SUMO_DRIVER:
            continue
        kind, shield = d.split("/")
        config = planner_config(kind, shield, scenario)
        p = ExternalPlanner(config, 0)
        kind_c = MERGE if scenario == "merge" else CROSSING
        p.act(8.0, [Conflict(0, kind_c, -30.0, -30.0, 8.0, (-5.0, 0.0), (-5.0, 5.0)),
                    Conflict(1, FOLLOW, 10.0, 30.0, 8.0)], DT_S)


def frames_of(outputs: Sequence[EpisodeOutput]) -> dict[str, Any]:
    """The per-step logs of ``outputs`` as DataFrames: ``steps`` (every vehicle) and
    ``decisions`` (the planner's), each with the episode's seed and driver."""
    import pandas as pd

    parts = {"steps": [], "decisions": []}
    for o in outputs:
        for name, data in (("steps", o.steps), ("decisions", o.decisions)):
            if data:
                df = pd.DataFrame(data)
                df.insert(0, "driver", o.result.driver)
                df.insert(0, "seed", o.result.seed)
                parts[name].append(df)
    return {k: (pd.concat(v, ignore_index=True) if v else pd.DataFrame())
            for k, v in parts.items()}


__all__ = ["DT_S", "EGO_DEPART_S", "EPISODE_S", "MAX_EPISODES", "NETWORKS", "NO_EGO", "SCENARIOS",
           "SPEED_MODE", "SUMO_DRIVER", "ballistic_slack", "EpisodeOutput", "EpisodeResult", "Network",
           "Projector", "SumoReport", "VehicleState", "build_network", "check_study",
           "conflicts_of", "decide", "driver_name", "entry_vehicles", "frames_of", "run_study",
           "lane_shapes", "planner_config", "planner_kernels", "routes_xml",
           "run_episode", "run_seed", "spawn_tied", "sumo_binaries", "traffic"]
