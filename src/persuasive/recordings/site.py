"""A recording at a real site's size, made here: SUMO's own drivers at a four-way unsignalised
junction, written as INTERACTION track files with the junction's Lanelet2 map
(docs/guide/recordings.md, "A site-size recording made here"; issue 42).

The recorded datasets cannot be redistributed, so the scale targets of the recordings'
commands are measured on a site made here, of the size of a real one (one unsignalised
junction, 60 files, about 10,500 vehicle tracks over 4.3 h). :func:`make_site` writes it.

**The junction** (:func:`site_network`, :func:`build_site_network`): four arms of ``arm_m``
(300 m) meeting at the node ``C`` at ``(0, 0)``, built by SUMO's ``netconvert``
(``persuasive.envs.sumo.build_network``) as a ``priority`` junction: the major road
west-east, ``lanes`` lanes per direction, has the right of way; the minor road south-north
yields, with ``minor_lanes`` lanes on its approaches and one on its exits; 13.89 m/s
(50 km/h). netconvert gives the lanes their movements (on two lanes: the right lane straight
and right, the left lane straight and left; on the minor road's, right and straight, and
left) and the junction SUMO's right of way (the minor road yields to the major road, a left
turn to the opposing straight and right turns). The major road has fixed-time signals
``signal_m`` (200 m) from the junction on both arms, outside the view, red ``red_s`` of
every ``cycle_s`` (27 of 60 s), both in step: the major road's traffic reaches the junction
in platoons, with gaps the minor road's drivers cross in, as between the signals of a town.
(With Poisson arrivals on the major road, SUMO's minor-road drivers crossed two lanes each
way at 1,700 vehicles an hour at fewer than 100 vehicles an hour per arm, and the minor
road's queues grew without end.)

**The traffic** (:func:`routes_xml`): SUMO ``<flow>`` elements, one per arm and turn, with
Poisson arrivals (``period="exp(rate)"``) at ``major_flow_veh_h`` per major arm (500 per
lane unless given) and ``minor_flow_veh_h`` per minor arm, split by the turning shares
``major_turns`` and ``minor_turns`` (left, straight, right), inserted on the best lane at
the highest safe speed.
Each vehicle draws its type from a ``vTypeDistribution`` of :data:`N_CAR_TYPES` passenger cars
and :data:`N_TRUCK_TYPES` trucks (a share ``truck_share``), whose Krauss parameters are drawn
once from the seed (:func:`vehicle_types`: ``accel``, ``decel``, ``sigma``, ``tau``,
``minGap``, length and width around SUMO's defaults); each vehicle also draws its own
``speedFactor`` (SUMO's ``speedDev``: 0.1 for cars, 0.05 for trucks). SUMO runs headless
(libsumo) at 0.1 s steps, ballistic updates, lane changes over 3 s
(``--lanechange.duration``: a sideways move, not a jump of a lane width in one step), seed
``seed``, for ``warmup_s`` (the roads fill) and then ``hours``. Its collision check (physical
overlaps, junctions included), its teleports (a vehicle stuck for 300 s) and its emergency
braking are counted, and the queues sampled every second (halting vehicles on each approach
edge of the junction, vehicles waiting to be inserted).

**The recording** is SUMO's floating-car data, read every step through a context
subscription on the junction (position, angle, speed, type), converted as
:mod:`persuasive.recordings.sumo_fcd` converts an fcd file (the centre half a length behind
the front bumper along the heading, ``psi = pi / 2 - radians(angle)``, ``vx, vy`` the speed
along it; ``agent_type`` from the type's class, ``car`` or ``truck``), and kept where the
centre lies in the camera's view, the square ``|x|, |y| <= view_m``. The recorded time is
cut into ``files`` recordings of equal length (``vehicle_tracks_000.csv`` ...), each with its
own frames (``frame_id = k + 1``, ``timestamp_ms = 100 k`` from the file's start) and track
IDs (``1, 2, ...`` in order of first appearance): a vehicle present at a cut is two tracks,
one in each file, and a vehicle that leaves the view and comes back is a new track, as a
tracker would number them. Rows are sorted by track and frame; numbers are written to the
millimetre. Each file is written when its time is over, so memory holds one file's
samples, not the run's.

**The map** (:func:`write_site_map`, ``site.osm``): the junction as Lanelet2 lanelets in the
tracks' frame (SUMO's coordinates, projected from ``origin`` (0, 0) as
:func:`persuasive.recordings.lanelet_map.read_map` reads it): one lanelet per lane of the
junction's edges (neighbouring lanes share their boundary, dashed) and one per movement
through the junction (SUMO's internal lanes of the connection, its lane's width wide, with
its ``turn_direction``); and the right of way of a priority sign: per minor approach a
``RightOfWay`` element, the major road's approach lanes over its lanes, its stop line across
their ends.

**The files**: the track files, ``site.osm``, ``site.net.xml`` and ``site.rou.xml`` (SUMO's
inputs, to run it again: ``sumo -n site.net.xml -r site.rou.xml`` with :func:`sumo_args`'
options) and ``site.json`` (:meth:`SiteResult.to_dict`: the parameters, the flows, the
counts, SUMO's reports, SUMO's version). The folder is written as a whole (everything into a
temporary sibling, then renamed into place), so an interrupted run leaves nothing.

Determinism: the vehicle types come from ``numpy.random.SeedSequence([seed, 42])``, SUMO's
draws (arrivals, types, speed factors, dawdling) from its ``--seed``, the map's IDs are
counted from 1; the same parameters give the same files, byte for byte.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .formats import INTERACTION_COLUMNS, RecordingError
from .sumo_fcd import AGENT_TYPES

#: The junction's node, and the arms: name -> unit vector from the junction to the arm's end.
NODE = "C"
ARMS = {"W": (-1, 0), "E": (1, 0), "S": (0, -1), "N": (0, 1)}
MAJOR_ARMS, MINOR_ARMS = ("W", "E"), ("S", "N")
#: The turns, in the order of ``major_turns`` and ``minor_turns``.
TURNS = ("left", "straight", "right")
#: The road's speed limit [m/s] (50 km/h, as ``persuasive sumo``'s networks).
SPEED_LIMIT_MPS = 13.89
#: Members of the vehicle-type distribution [-].
N_CAR_TYPES, N_TRUCK_TYPES = 100, 20
#: The files of a site folder (``persuasive._files`` owned-name patterns).
MAP_NAME, JSON_NAME, NET_NAME, ROUTES_NAME = "site.osm", "site.json", "site.net.xml", \
    "site.rou.xml"
OWNED = ("vehicle_tracks_*.csv", MAP_NAME, JSON_NAME, NET_NAME, ROUTES_NAME)
#: SUMO's step, INTERACTION's frame [s].
STEP_S = 0.1
#: The shortest recording a file may hold [s].
MIN_FILE_S = 10.0
#: The major road's default arrivals per arm and lane [veh/h] (1,000 per arm on two lanes:
#: with 300 per minor arm, 2,600 vehicles an hour, the real site's size over 4 h).
MAJOR_FLOW_PER_LANE = 500.0
#: The amber time of the major road's signals [s].
AMBER_S = 3.0
#: Tag of the seed sequence of the vehicle types (the issue's number).
SEED_TAG = 42


def _check(name: str, value, ok: bool, allowed: str) -> None:
    if not ok:
        raise RecordingError(f"{name} = {value!r} is out of range; allowed: {allowed}")


@dataclass(frozen=True)
class SiteParams:
    """The site: its junction, traffic and recording (module docstring). Defaults: 2,600
    vehicles an hour entering, the size of the real site over 4 h."""

    hours: float = 4.0  #: recorded time [h]
    seed: int = 1  #: SUMO's seed and the vehicle types' [-]
    lanes: int = 2  #: lanes per direction on the major road [-]
    minor_lanes: int = 2  #: lanes of the minor road's approaches (its exits have one) [-]
    files: int = 60  #: recordings the time is cut into [-]
    view_m: float = 60.0  #: the camera's view: the square |x|, |y| <= view_m [m]
    arm_m: float = 300.0  #: length of each arm to the junction's centre [m]
    #: the major road's signals: distance from the junction's centre [m], cycle [s] and red
    #: time [s] of their fixed program (green the rest, less the amber's 3 s)
    signal_m: float = 200.0
    cycle_s: float = 60.0
    red_s: float = 27.0
    warmup_s: float = 300.0  #: simulated before the recording starts [s]
    #: arrivals per major arm [veh/h]; None: :data:`MAJOR_FLOW_PER_LANE` per lane
    major_flow_veh_h: float | None = None
    minor_flow_veh_h: float = 300.0  #: arrivals per minor arm [veh/h]
    major_turns: tuple[float, float, float] = (0.1, 0.8, 0.1)  #: left, straight, right [-]
    minor_turns: tuple[float, float, float] = (0.35, 0.3, 0.35)  #: left, straight, right [-]
    truck_share: float = 0.05  #: share of trucks among the vehicles [-]

    def __post_init__(self) -> None:
        if self.major_flow_veh_h is None and isinstance(self.lanes, int):
            object.__setattr__(self, "major_flow_veh_h", MAJOR_FLOW_PER_LANE * self.lanes)
        h = self.hours
        _check("hours", h, isinstance(h, (int, float)) and math.isfinite(h) and 0.0 < h <= 24.0,
               "(0, 24] hours")
        _check("seed", self.seed, isinstance(self.seed, int) and 0 <= self.seed < 2 ** 31,
               f"an integer in [0, {2 ** 31 - 1}]")
        _check("lanes", self.lanes, isinstance(self.lanes, int) and 1 <= self.lanes <= 3,
               "an integer in [1, 3]")
        _check("minor_lanes", self.minor_lanes, isinstance(self.minor_lanes, int)
               and 1 <= self.minor_lanes <= 2, "1 or 2")
        most = int(h * 3600.0 // MIN_FILE_S) if _finite(h) and h > 0 else 1
        _check("files", self.files, isinstance(self.files, int) and 1 <= self.files <= most,
               f"an integer in [1, {most}] (each file at least {MIN_FILE_S:g} s of the "
               f"{h:g} h)")
        _check("arm_m", self.arm_m, _finite(self.arm_m) and 100.0 <= self.arm_m <= 2000.0,
               "[100, 2000] m")
        _check("view_m", self.view_m, _finite(self.view_m)
               and 20.0 <= self.view_m <= self.arm_m - 20.0,
               f"[20, arm_m - 20 = {self.arm_m - 20.0:g}] m")
        _check("signal_m", self.signal_m, _finite(self.signal_m)
               and self.view_m + 20.0 <= self.signal_m <= self.arm_m - 50.0,
               f"[view_m + 20, arm_m - 50] = [{self.view_m + 20.0:g}, "
               f"{self.arm_m - 50.0:g}] m")
        _check("cycle_s", self.cycle_s, _finite(self.cycle_s)
               and 30.0 <= self.cycle_s <= 180.0, "[30, 180] s")
        _check("red_s", self.red_s, _finite(self.red_s)
               and 5.0 <= self.red_s <= self.cycle_s - AMBER_S - 10.0,
               f"[5, cycle_s - {AMBER_S + 10.0:g} = {self.cycle_s - AMBER_S - 10.0:g}] s")
        _check("warmup_s", self.warmup_s, _finite(self.warmup_s)
               and 0.0 <= self.warmup_s <= 3600.0, "[0, 3600] s")
        for name in ("major_flow_veh_h", "minor_flow_veh_h"):
            v = getattr(self, name)
            _check(name, v, _finite(v) and 0.0 < v <= 3000.0, "(0, 3000] vehicles per hour")
        for name in ("major_turns", "minor_turns"):
            v = tuple(getattr(self, name))
            _check(name, v, len(v) == 3 and all(_finite(p) and p >= 0.0 for p in v)
                   and abs(sum(v) - 1.0) <= 1e-9, "three shares >= 0 (left, straight, "
                   "right) summing to 1")
        _check("truck_share", self.truck_share, _finite(self.truck_share)
               and 0.0 <= self.truck_share <= 1.0, "[0, 1]")

    @property
    def frames(self) -> int:
        """Recorded frames [-]."""
        return int(round(self.hours * 3600.0 / STEP_S))

    def flows(self) -> dict[str, float]:
        """Arrivals per movement ``"<arm>_<turn>"`` [veh/h] (movements with a share of 0
        left out)."""
        out = {}
        for arm in ARMS:
            major = arm in MAJOR_ARMS
            flow = self.major_flow_veh_h if major else self.minor_flow_veh_h
            for turn, share in zip(TURNS, self.major_turns if major else self.minor_turns):
                if share > 0.0:
                    out[f"{arm}_{turn}"] = flow * share
        return out


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


# -- network and traffic ---------------------------------------------------------------------


def _target(arm: str, turn: str) -> str:
    """The arm a vehicle from ``arm`` leaves by after ``turn`` (right-hand traffic)."""
    hx, hy = (-c for c in ARMS[arm])  # heading into the junction
    out = {"straight": (hx, hy), "left": (-hy, hx), "right": (hy, -hx)}[turn]
    return next(a for a, v in ARMS.items() if v == out)


def _signal(arm: str) -> str:
    return f"{arm}X"


def route_edges(arm: str, turn: str) -> tuple[str, ...]:
    """SUMO's edges of a movement: into the junction (a major arm through its signal:
    ``W2WX WX2C``; a minor one ``S2C``), then out (``C2WX WX2W``, ``C2N``)."""
    out = _target(arm, turn)
    into = (f"{arm}2{_signal(arm)}", f"{_signal(arm)}2{NODE}") if arm in MAJOR_ARMS \
        else (f"{arm}2{NODE}",)
    away = (f"{NODE}2{_signal(out)}", f"{_signal(out)}2{out}") if out in MAJOR_ARMS \
        else (f"{NODE}2{out}",)
    return into + away


def approach_edges() -> tuple[str, ...]:
    """The edges that end at the junction, one per arm (``WX2C``, ``EX2C``, ``S2C``,
    ``N2C``)."""
    return tuple(route_edges(arm, "straight")[1 if arm in MAJOR_ARMS else 0] for arm in ARMS)


def site_network(params: SiteParams):
    """The junction as a ``persuasive.envs.sumo.Network`` whose edges carry their lane counts
    (module docstring): the arms' ends, the major road's signals and the junction as nodes,
    two-way roads between them."""
    from ..envs.sumo import Network

    @dataclass(frozen=True)
    class SiteNetwork(Network):
        lanes: int = 2
        minor_lanes: int = 2

        def edges_xml(self) -> str:
            def n(p, to):
                return self.lanes if p == 2 else self.minor_lanes if to == NODE else 1

            rows = "".join(
                f'  <edge id="{e}" from="{a}" to="{b}" priority="{p}" '
                f'numLanes="{n(p, b)}" speed="{SPEED_LIMIT_MPS:g}"/>\n'
                for e, a, b, p in self.edges)
            return f"<edges>\n{rows}</edges>\n"

    nodes = [(NODE, 0.0, 0.0, "priority")]
    edges = []
    for arm, (vx, vy) in ARMS.items():
        nodes.append((arm, params.arm_m * vx, params.arm_m * vy, "dead_end"))
        chain = [arm, NODE]
        if arm in MAJOR_ARMS:
            nodes.append((_signal(arm), params.signal_m * vx, params.signal_m * vy,
                          "traffic_light"))
            chain = [arm, _signal(arm), NODE]
        p = 2 if arm in MAJOR_ARMS else 1
        for u, v in zip(chain[:-1], chain[1:]):
            edges += [(f"{u}2{v}", u, v, p), (f"{v}2{u}", v, u, p)]
    routes = tuple(route_edges(arm, turn) for arm in ARMS for turn in TURNS)
    return SiteNetwork("site", tuple(nodes), tuple(edges), routes[0], routes, NODE,
                       params.lanes, params.minor_lanes)


def signal_programs(net_file: str | Path, params: SiteParams) -> str:
    """SUMO's ``tlLogic`` of the major road's signals (``netconvert --tllogic-files``): one
    fixed program for all their links, green, amber (:data:`AMBER_S`), red ``red_s``, both
    signals in step (the gaps they leave meet at the junction)."""
    import sumolib

    net = sumolib.net.readNet(str(net_file))
    rows = ["<tlLogics>"]
    for arm in MAJOR_ARMS:
        n = len(net.getTLS(_signal(arm)).getConnections())
        green = params.cycle_s - params.red_s - AMBER_S
        rows.append(f'  <tlLogic id="{_signal(arm)}" type="static" programID="0" offset="0">')
        for dur, state in ((green, "G"), (AMBER_S, "y"), (params.red_s, "r")):
            rows.append(f'    <phase duration="{dur:g}" state="{state * n}"/>')
        rows.append("  </tlLogic>")
    rows.append("</tlLogics>")
    return "\n".join(rows) + "\n"


def build_site_network(folder: str | Path, params: SiteParams) -> Path:
    """Build the site's network (module docstring) as ``folder / site.net.xml``: netconvert
    builds the nodes and edges (``persuasive.envs.sumo.build_network``), then once more with
    the signals' programs; netconvert's header comment (the date and the temporary paths) is
    left out, so the same parameters give the same file. :class:`RecordingError` with
    netconvert's first error line."""
    import re
    import subprocess

    from ..envs.sumo import NETCONVERT_TIMEOUT_S, build_network, sumo_binaries

    netconvert = sumo_binaries()["netconvert"]
    with tempfile.TemporaryDirectory(prefix="site-net-") as tmp:
        first = build_network(site_network(params), tmp, netconvert)
        programs = Path(tmp) / "signals.tll.xml"
        programs.write_text(signal_programs(first, params), encoding="utf-8")
        second = Path(tmp) / NET_NAME
        try:
            proc = subprocess.run([netconvert, "--sumo-net-file", str(first),
                                   "--tllogic-files", str(programs), "--output-file",
                                   str(second), "--no-warnings", "true"], capture_output=True,
                                  text=True, timeout=NETCONVERT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise RecordingError("SUMO's netconvert did not add the site's signals within "
                                 f"{NETCONVERT_TIMEOUT_S:g} s") from None
        if proc.returncode != 0 or not second.is_file():
            lines = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
            raise RecordingError("SUMO's netconvert cannot add the site's signals: "
                                 + (lines[0] if lines else f"exit status {proc.returncode}"))
        text = re.sub(r"<!-- generated on .*?-->\n*", "", second.read_text(encoding="utf-8"),
                      count=1, flags=re.S)
    out = Path(folder) / NET_NAME
    out.write_text(text, encoding="utf-8")
    return out


def vehicle_types(params: SiteParams) -> list[dict[str, str]]:
    """The members of the vehicle-type distribution (module docstring), attributes as SUMO
    writes them; drawn from ``SeedSequence([seed, 42])``.

    Cars (``passenger``): ``accel`` N(2.6, 0.4) in [1.6, 3.6], ``decel`` N(4.5, 0.5) in
    [3.5, 5.5] m/s^2, ``sigma`` U(0.3, 0.7), ``tau`` N(1.0, 0.15) in [0.7, 1.4] s,
    ``minGap`` N(2.5, 0.3) in [1.8, 3.2] m, length N(4.6, 0.3) in [3.8, 5.4] m, width
    N(1.82, 0.07) in [1.65, 2.0] m, ``speedDev`` 0.1. Trucks (``truck``): ``accel``
    N(1.3, 0.2) in [0.9, 1.8], ``decel`` N(4.0, 0.3) in [3.2, 4.8], ``sigma`` U(0.3, 0.6),
    ``tau`` N(1.2, 0.15) in [0.9, 1.6], ``minGap`` N(3.0, 0.3) in [2.4, 3.6], length
    N(9.0, 1.5) in [7.0, 12.0], width N(2.45, 0.05) in [2.3, 2.55], ``speedDev`` 0.05. Every
    type: ``emergencyDecel`` 9 m/s^2, ``maxSpeed`` the speed limit; a car's probability
    ``(1 - truck_share) / N_CAR_TYPES``, a truck's ``truck_share / N_TRUCK_TYPES``."""
    rng = np.random.default_rng(np.random.SeedSequence([int(params.seed), SEED_TAG]))

    def normal(mean, sd, lo, hi, n):
        return np.clip(rng.normal(mean, sd, n), lo, hi)

    out = []
    for kind, n, share in (("car", N_CAR_TYPES, 1.0 - params.truck_share),
                           ("truck", N_TRUCK_TYPES, params.truck_share)):
        car = kind == "car"
        draws = {
            "accel": normal(2.6, 0.4, 1.6, 3.6, n) if car else normal(1.3, 0.2, 0.9, 1.8, n),
            "decel": normal(4.5, 0.5, 3.5, 5.5, n) if car else normal(4.0, 0.3, 3.2, 4.8, n),
            "sigma": rng.uniform(0.3, 0.7, n) if car else rng.uniform(0.3, 0.6, n),
            "tau": normal(1.0, 0.15, 0.7, 1.4, n) if car else normal(1.2, 0.15, 0.9, 1.6, n),
            "minGap": normal(2.5, 0.3, 1.8, 3.2, n) if car else normal(3.0, 0.3, 2.4, 3.6, n),
            "length": normal(4.6, 0.3, 3.8, 5.4, n) if car else normal(9.0, 1.5, 7.0, 12.0, n),
            "width": normal(1.82, 0.07, 1.65, 2.0, n) if car else normal(2.45, 0.05, 2.3, 2.55,
                                                                         n),
        }
        if share <= 0.0:  # drawn all the same: the cars' draws do not depend on the trucks'
            continue
        for k in range(n):
            t = {"id": f"{kind}{k:03d}", "vClass": "passenger" if car else "truck",
                 **{name: f"{v[k]:.2f}" for name, v in draws.items()},
                 "emergencyDecel": "9", "maxSpeed": f"{SPEED_LIMIT_MPS:g}",
                 "speedDev": "0.1" if car else "0.05", "probability": f"{share / n:.6g}"}
            out.append(t)
    return out


def routes_xml(params: SiteParams, end_s: float) -> str:
    """SUMO's route file of the site: the type distribution ``site``, a route and a Poisson
    ``flow`` per movement from 0 to ``end_s`` (module docstring)."""
    lines = ["<routes>", '  <vTypeDistribution id="site">']
    for t in vehicle_types(params):
        attrs = " ".join(f'{k}="{v}"' for k, v in t.items())
        lines.append(f"    <vType {attrs}/>")
    lines.append("  </vTypeDistribution>")
    flows = params.flows()
    for name in flows:
        arm, turn = name.split("_")
        lines.append(f'  <route id="{name}" edges="{" ".join(route_edges(arm, turn))}"/>')
    for name, veh_h in flows.items():
        lines.append(f'  <flow id="{name}" type="site" route="{name}" begin="0" '
                     f'end="{end_s:g}" period="exp({veh_h / 3600.0:.9g})" departLane="best" '
                     'departSpeed="max"/>')
    lines.append("</routes>")
    return "\n".join(lines) + "\n"


def sumo_args(net: Path, routes: Path, params: SiteParams, end_s: float) -> list[str]:
    """SUMO's command line of the site's run (module docstring)."""
    return ["sumo", "--net-file", str(net), "--route-files", str(routes),
            "--step-length", f"{STEP_S:g}", "--step-method.ballistic", "true",
            "--lanechange.duration", "3", "--seed", str(int(params.seed)),
            "--begin", "0", "--end", f"{end_s:g}",
            "--collision.check-junctions", "true", "--collision.action", "warn",
            "--collision.mingap-factor", "0", "--no-step-log", "true", "--no-warnings", "true",
            "--duration-log.disable", "true"]


# -- the recording --------------------------------------------------------------------------


@dataclass
class _Buffer:
    """One file's samples, in the order they were seen."""

    vehicle: list = field(default_factory=list)  # index into the run's vehicle IDs
    frame: list = field(default_factory=list)
    x: list = field(default_factory=list)  # front bumper [m]
    y: list = field(default_factory=list)
    angle: list = field(default_factory=list)  # navigational [deg]
    speed: list = field(default_factory=list)
    vtype: list = field(default_factory=list)  # index into the run's types

    def __len__(self) -> int:
        return len(self.frame)


def file_rows(buf: _Buffer, types: Sequence[tuple[float, float, str]], view_m: float
              ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The INTERACTION rows of one file's samples (module docstring): centres in the view,
    tracks numbered by first appearance (a vehicle absent for a frame starts a new track),
    sorted by track and frame; and the run's index of each row's vehicle."""
    veh = np.asarray(buf.vehicle, np.int64)
    frame = np.asarray(buf.frame, np.int64)
    kind = np.asarray(buf.vtype, np.int64)
    length = np.array([t[0] for t in types])[kind]
    width = np.array([t[1] for t in types])[kind]
    agent = np.array([t[2] for t in types], dtype=object)[kind]
    angle = np.radians(np.asarray(buf.angle, float))
    half = length / 2.0
    x = np.asarray(buf.x, float) - half * np.sin(angle)  # navigational: 0 north, clockwise
    y = np.asarray(buf.y, float) - half * np.cos(angle)
    seen = np.arange(frame.shape[0])
    keep = (np.abs(x) <= view_m) & (np.abs(y) <= view_m)
    veh, frame, kind, seen = veh[keep], frame[keep], kind[keep], seen[keep]
    x, y, angle, length, width, agent = (a[keep] for a in (x, y, angle, length, width, agent))
    speed = np.asarray(buf.speed, float)[keep]
    order = np.lexsort((frame, veh))
    veh, frame, seen = veh[order], frame[order], seen[order]
    new = np.ones(veh.shape[0], bool)
    new[1:] = (veh[1:] != veh[:-1]) | (frame[1:] != frame[:-1] + 1)
    segment = np.cumsum(new) - 1
    first_seen = seen[new]
    track_of_segment = np.empty(first_seen.shape[0], np.int64)
    track_of_segment[np.argsort(first_seen, kind="stable")] = np.arange(first_seen.shape[0]) + 1
    track = track_of_segment[segment]
    rows = np.lexsort((frame, track))
    idx = order[rows]
    track, frame = track[rows], frame[rows]
    psi = np.angle(np.exp(1j * (math.pi / 2.0 - angle[idx])))
    v = speed[idx]
    out = {"track_id": track, "frame_id": frame + 1, "timestamp_ms": frame * 100,
           "agent_type": agent[idx], "x": x[idx], "y": y[idx], "vx": v * np.cos(psi),
           "vy": v * np.sin(psi), "psi_rad": psi, "length": length[idx], "width": width[idx]}
    return {c: out[c] for c in INTERACTION_COLUMNS}, veh[rows]


def _millimetres(x: np.ndarray):
    """``x`` [m] as text with three decimals, as ``"%.3f"`` prints a number rounded to the
    millimetre (``-0.000`` printed ``0.000``), built column-wise by pyarrow."""
    import pyarrow as pa
    import pyarrow.compute as pc

    mm = np.round(np.asarray(x, float) * 1000.0).astype(np.int64)
    whole = pa.array(np.abs(mm) // 1000).cast(pa.string())
    frac = pc.utf8_lpad(pa.array(np.abs(mm) % 1000).cast(pa.string()), 3, "0")
    sign = pa.array(np.where(mm < 0, "-", ""))
    return pc.binary_join_element_wise(sign, whole, ".", frac, "")


def write_tracks(path: str | Path, rows: dict[str, np.ndarray]) -> None:
    """Write an INTERACTION track file (atomically) from columns named as
    :data:`~persuasive.recordings.formats.INTERACTION_COLUMNS`: what
    :func:`~persuasive.recordings.formats.write_interaction` writes (integers, the class, the
    numbers with three decimals), through pyarrow's CSV writer (a 4-hour site is 2.2 million
    rows)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from .._files import atomic_write

    cols = {}
    for c in INTERACTION_COLUMNS:
        v = rows[c]
        if c in ("track_id", "frame_id", "timestamp_ms"):
            cols[c] = pa.array(np.asarray(v, np.int64))
        elif c == "agent_type":
            cols[c] = pa.array(np.asarray(v, object).astype(str))
        else:
            cols[c] = _millimetres(v)
    table = pa.table(cols)
    options = pacsv.WriteOptions(quoting_style="none", quoting_header="none")
    atomic_write(path, lambda p: pacsv.write_csv(table, p, options))


@dataclass(frozen=True)
class SiteResult:
    """What :func:`make_site` wrote and what SUMO reported (module docstring)."""

    params: SiteParams
    folder: str
    files: tuple[str, ...]
    tracks_per_file: tuple[int, ...]
    samples: int  #: rows over all files [-]
    vehicles_inserted: int  #: vehicles SUMO inserted, warm-up included [-]
    vehicles_recorded: int  #: distinct vehicles seen in the view [-]
    trucks_recorded: int
    collisions: int  #: distinct colliding pairs SUMO reported [-]
    teleports: int  #: vehicles SUMO teleported (stuck for 300 s) [-]
    emergency_braking: int  #: distinct vehicles that braked harder than their decel [-]
    #: per approach edge: mean and largest number of halting vehicles, sampled every second
    queue_mean: dict = field(default_factory=dict)
    queue_max: dict = field(default_factory=dict)
    #: vehicles waiting to be inserted: largest, and at the end [-]
    backlog_max: int = 0
    backlog_end: int = 0
    sumo_version: str = ""
    map_lanelets: int = 0  #: lanelets of site.osm [-]
    map_right_of_way: int = 0  #: its RightOfWay elements [-]
    #: SUMO's report of each colliding pair: time [s], collider, victim, type, lane
    collision_reports: tuple = ()
    wall_s: float = 0.0  #: the run's wall time (not in site.json) [s]

    @property
    def tracks(self) -> int:
        return int(sum(self.tracks_per_file))

    @property
    def recorded_h(self) -> float:
        return self.params.frames * STEP_S / 3600.0

    def to_dict(self) -> dict:
        """``site.json``: everything but the wall time (so that it is the same for a seed)."""
        p = asdict(self.params)
        return {"seed": p.pop("seed"), "hours": p.pop("hours"), "files": len(self.files),
                "recorded_hours": round(self.recorded_h, 6), "tracks": self.tracks,
                "tracks_per_file": list(self.tracks_per_file), "samples": self.samples,
                "vehicles_inserted": self.vehicles_inserted,
                "vehicles_recorded": self.vehicles_recorded,
                "trucks_recorded": self.trucks_recorded,
                "flows_veh_h": {k: round(v, 6) for k, v in self.params.flows().items()},
                "params": {k: list(v) if isinstance(v, tuple) else v for k, v in p.items()},
                "sumo": {"version": self.sumo_version, "collisions": self.collisions,
                         "collision_reports": list(self.collision_reports),
                         "teleports": self.teleports,
                         "emergency_braking": self.emergency_braking,
                         "queue_mean_veh": self.queue_mean, "queue_max_veh": self.queue_max,
                         "insertion_backlog_max": self.backlog_max,
                         "insertion_backlog_end": self.backlog_end},
                "map": {"file": MAP_NAME, "lanelets": self.map_lanelets,
                        "right_of_way": self.map_right_of_way, "origin": [0.0, 0.0]},
                "track_files": list(self.files)}


def _file_bounds(frames: int, files: int) -> np.ndarray:
    """First frame of each file, and the end: equal lengths, to a frame."""
    return (np.arange(files + 1) * frames) // files


def record_site(folder: str | Path, params: SiteParams,
                progress: Callable[[int, int], None] | None = None) -> SiteResult:
    """Build the site in ``folder`` (an existing, empty working folder) and write all its files
    there (module docstring); ``progress(k, files)`` after file ``k`` is written."""
    from ..envs.sumo import _libsumo

    t_start = time.perf_counter()
    folder = Path(folder)
    bounds = _file_bounds(params.frames, params.files)
    warm = int(round(params.warmup_s / STEP_S))
    end_s = (warm + params.frames) * STEP_S
    build_site_network(folder, params)
    (folder / ROUTES_NAME).write_text(routes_xml(params, end_s), encoding="utf-8")
    map_counts = write_site_map(folder / MAP_NAME, folder / NET_NAME)

    ls = _libsumo()
    tc = ls.constants
    ls.start(sumo_args(folder / NET_NAME, folder / ROUTES_NAME, params, end_s))
    try:
        version = str(ls.getVersion()[1])
        radius = params.view_m * math.sqrt(2.0) + 10.0  # the front of any centre in view
        variables = [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_TYPE]
        ls.junction.subscribeContext(NODE, tc.CMD_GET_VEHICLE_VARIABLE, radius, variables)
        approaches = list(approach_edges())
        vehicle_ix: dict[str, int] = {}
        type_ix: dict[str, int] = {}
        types: list[tuple[float, float, str]] = []
        trucks: set[int] = set()
        collided: dict[tuple[str, str], dict] = {}  # the first report of each pair
        braked: set[str] = set()
        teleports = inserted = 0
        queue_sum = {e: 0 for e in approaches}
        queue_max = {e: 0 for e in approaches}
        backlog_max = samples = 0
        names, counts = [], []
        recorded: set[int] = set()

        def step() -> None:
            nonlocal teleports, inserted
            ls.simulationStep()
            teleports += ls.simulation.getStartingTeleportNumber()
            inserted += ls.simulation.getDepartedNumber()
            for c in ls.simulation.getCollisions():
                collided.setdefault((c.collider, c.victim), {
                    "time_s": round(ls.simulation.getTime(), 1), "collider": c.collider,
                    "victim": c.victim, "type": c.type, "lane": c.lane})
            if ls.simulation.getEmergencyStoppingVehiclesNumber():
                braked.update(ls.simulation.getEmergencyStoppingVehiclesIDList())

        for _ in range(warm):
            step()
        n_queue = 0
        for k in range(params.files):
            buf = _Buffer()
            for f in range(int(bounds[k + 1] - bounds[k])):
                step()
                for vid, r in ls.junction.getContextSubscriptionResults(NODE).items():
                    t = r[tc.VAR_TYPE]
                    ti = type_ix.get(t)
                    if ti is None:
                        ti = type_ix[t] = len(types)
                        vclass = ls.vehicletype.getVehicleClass(t)
                        types.append((ls.vehicletype.getLength(t), ls.vehicletype.getWidth(t),
                                      AGENT_TYPES.get(vclass, vclass)))
                    px, py = r[tc.VAR_POSITION]
                    buf.vehicle.append(vehicle_ix.setdefault(vid, len(vehicle_ix)))
                    buf.frame.append(f)
                    buf.x.append(px)
                    buf.y.append(py)
                    buf.angle.append(r[tc.VAR_ANGLE])
                    buf.speed.append(r[tc.VAR_SPEED])
                    buf.vtype.append(ti)
                if (bounds[k] + f) % 10 == 0:  # every second
                    n_queue += 1
                    for e in approaches:
                        h = ls.edge.getLastStepHaltingNumber(e)
                        queue_sum[e] += h
                        queue_max[e] = max(queue_max[e], h)
                    backlog_max = max(backlog_max, len(ls.simulation.getPendingVehicles()))
            rows, vehicles = file_rows(buf, types, params.view_m)
            name = f"vehicle_tracks_{k:03d}.csv"
            write_tracks(folder / name, rows)
            names.append(name)
            counts.append(int(np.unique(rows["track_id"]).size))
            samples += int(rows["track_id"].shape[0])
            recorded.update(vehicles.tolist())
            trucks.update(vehicles[rows["agent_type"] == "truck"].tolist())
            if progress is not None:
                progress(k, params.files)
        backlog_end = len(ls.simulation.getPendingVehicles())
    finally:
        ls.close()
    result = SiteResult(
        params, str(folder), tuple(names), tuple(counts), samples, inserted, len(recorded),
        len(trucks), len(collided), teleports, len(braked),
        {e: round(queue_sum[e] / max(n_queue, 1), 3) for e in approaches},
        dict(queue_max), backlog_max, backlog_end, version, map_counts["lanelets"],
        map_counts["right_of_way"], tuple(collided.values()), time.perf_counter() - t_start)
    return result


def make_site(out: str | Path, params: SiteParams, force: bool = False,
              progress: Callable[[int, int], None] | None = None) -> SiteResult:
    """Write the site into folder ``out`` as a whole (module docstring): refused, before any
    work, when ``out`` holds anything and ``force`` is not given; with ``force`` this
    function's own earlier files (:data:`OWNED`) are replaced and others kept."""
    from .._files import atomic_folder, check_replaceable_folder

    check_replaceable_folder(out, force, "site folder", OWNED)
    with atomic_folder(out, "site folder", OWNED) as tmp:
        result = record_site(tmp, params, progress)
        (Path(tmp) / JSON_NAME).write_text(json.dumps(result.to_dict(), indent=1) + "\n",
                                           encoding="utf-8")
    return replace(result, folder=str(out))


# -- the map --------------------------------------------------------------------------------


def _offset(shape: np.ndarray, d: float) -> np.ndarray:
    """The polyline ``shape`` ``(n, 2)`` moved ``d`` to its left [m] (at each vertex along the
    mean of its segments' normals, scaled to keep the distance on a bend)."""
    seg = np.diff(shape, axis=0)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    normal = np.stack([-seg[:, 1], seg[:, 0]], axis=1)
    at = np.vstack([normal[:1], normal[:-1] + normal[1:], normal[-1:]])
    at /= np.linalg.norm(at, axis=1, keepdims=True)
    cos = np.ones(shape.shape[0])
    cos[1:-1] = np.maximum(np.sum(at[1:-1] * normal[:-1], axis=1), 0.5)
    return shape + d * at / cos[:, None]


def _clean(shape: Sequence[tuple[float, float]]) -> np.ndarray:
    """A lane shape without repeated points."""
    pts = np.asarray(shape, float)[:, :2]
    keep = np.ones(pts.shape[0], bool)
    keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-6
    return pts[keep]


def write_site_map(path: str | Path, net_file: str | Path, origin: Sequence[float] = (0.0, 0.0)
                   ) -> dict[str, int]:
    """Write the Lanelet2 map of the site's SUMO network ``net_file`` to ``path`` (module
    docstring), projected from ``origin`` ``(lat, lon)`` [deg] as
    :func:`persuasive.recordings.lanelet_map.read_map` reads it; returns counts of lanelets
    and right-of-way elements.

    The right of way is a priority sign's: per minor approach, one ``RightOfWay`` element
    whose right-of-way lanelets are the major approaches' lanes and whose yield lanelets are
    its own lanes, its stop line across their ends (Lanelet2's ``ref_line``). The movements
    through the junction carry no element: their lanelets overlap (a straight vehicle's centre
    lies in its lane's left-turn lanelet for the first metres), and
    :func:`persuasive.recordings.lanelet_map.pair_rule` takes every lanelet of a vehicle's
    approach, which may end inside the junction; SUMO's rule between movements of one road
    (a left turn yields to the opposing straight and right turns) written there labelled 15 %
    of those pairs the wrong way round on a 1-hour site, so it is left out (``none``).

    IDs are counted from 1, so the same network gives the same file."""
    import itertools

    import sumolib

    from .lanelet_map import _lanelet2, check_origin

    lanelet2 = _lanelet2()
    from lanelet2.core import (AttributeMap, Lanelet, LaneletMap, LineString3d, Point3d,
                               RightOfWay)

    lat, lon = check_origin(origin)
    ids = itertools.count(1)
    net = sumolib.net.readNet(str(net_file), withInternal=True)
    node = net.getNode(NODE)

    def line(points: np.ndarray, attributes: dict):
        return LineString3d(next(ids), [Point3d(next(ids), float(px), float(py), 0.0)
                                        for px, py in points], AttributeMap(attributes))

    def lanelet(left, right, attrs=None):
        return Lanelet(next(ids), left, right, AttributeMap(
            {"type": "lanelet", "subtype": "road", "location": "urban", "one_way": "yes",
             **(attrs or {})}))

    def normal(edges):  # with internal lanes read, a node's edges include its internal ones
        return sorted((e for e in edges if e.getFunction() != "internal"),
                      key=lambda e: e.getID())

    incoming = normal(node.getIncoming())
    road: dict[str, object] = {}  # normal lane ID -> lanelet
    for edge in normal({*node.getIncoming(), *node.getOutgoing()}):
        lanes = sorted(edge.getLanes(), key=lambda ln: ln.getIndex())  # rightmost first
        right = None
        for j, lane in enumerate(lanes):
            shape, half = _clean(lane.getShape()), lane.getWidth() / 2.0
            if right is None:
                right = line(_offset(shape, -half), {"type": "line_thin", "subtype": "solid"})
            outer = j == len(lanes) - 1
            left = line(_offset(shape, half), {"type": "line_thin",
                                               "subtype": "solid" if outer else "dashed"})
            road[lane.getID()] = lanelet(left, right)
            right = left
    # one lanelet per movement through the junction: its internal lanes, end to end
    links = {}
    for edge in incoming:
        for lane in edge.getLanes():
            for conn in lane.getOutgoing():
                links[node.getLinkIndex(conn)] = conn
    movement: dict[int, object] = {}  # SUMO's link index -> lanelet
    for index, conn in sorted(links.items()):
        parts, via, width = [], conn.getViaLaneID(), conn.getFromLane().getWidth()
        while via:
            lane = net.getLane(via)
            parts.append(_clean(lane.getShape()))
            nxt = [c.getViaLaneID() for c in lane.getOutgoing() if c.getViaLaneID()]
            via = nxt[0] if nxt else ""
        shape = _clean(np.vstack(parts))
        turn = {"l": "left", "r": "right"}.get(conn.getDirection(), "straight")
        movement[index] = lanelet(line(_offset(shape, width / 2.0), {"type": "virtual"}),
                                  line(_offset(shape, -width / 2.0), {"type": "virtual"}),
                                  {"turn_direction": turn})
    elements = []

    def right_of_way(over, under, stop=None):
        attrs = AttributeMap({"type": "regulatory_element", "subtype": "right_of_way"})
        element = RightOfWay(next(ids), attrs, list(over), list(under), stop)
        for ll in (*over, *under):
            ll.addRegulatoryElement(element)
        elements.append(element)

    top = max(e.getPriority() for e in incoming)
    major = [road[ln.getID()] for e in incoming if e.getPriority() == top
             for ln in e.getLanes()]
    for edge in incoming:
        if edge.getPriority() == top:
            continue
        lanes = sorted(edge.getLanes(), key=lambda ln: ln.getIndex())
        shape = _clean(lanes[0].getShape())
        hx, hy = (shape[-1] - shape[-2]) / np.linalg.norm(shape[-1] - shape[-2])
        ends = [_clean(ln.getShape())[-1] + side * ln.getWidth() / 2.0 * np.array([-hy, hx])
                for ln in lanes for side in (-1.0, 1.0)]
        right_of_way(major, [road[ln.getID()] for ln in lanes],
                     line(np.array([ends[0], ends[-1]]), {"type": "stop_line"}))
    lmap = LaneletMap()
    for ll in (*road.values(), *movement.values()):
        lmap.add(ll)
    projector = lanelet2.projection.UtmProjector(lanelet2.io.Origin(lat, lon))
    lanelet2.io.write(str(path), lmap, projector)
    return {"lanelets": len(road) + len(movement), "right_of_way": len(elements)}


__all__ = ["ARMS", "JSON_NAME", "MAJOR_ARMS", "MAP_NAME", "MINOR_ARMS", "N_CAR_TYPES",
           "N_TRUCK_TYPES", "NODE", "OWNED", "SiteParams", "SiteResult", "TURNS", "file_rows",
           "make_site", "record_site", "route_edges", "routes_xml", "site_network",
           "sumo_args", "vehicle_types", "write_site_map"]
