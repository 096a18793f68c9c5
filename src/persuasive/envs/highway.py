"""The persuasive planner driving highway-env's ego at its intersection (issue 13).

highway-env's ``intersection-v2`` (``intersection-v1`` on versions without it) is a four-way
crossing of two-lane roads, filled with highway-env's own IDM traffic that turns left, right
or goes straight. The ego drives straight through (route ``o0 -> o2``, destination ``"o2"``)
with a longitudinal-only ``ContinuousAction`` (lateral control off: the ego's path is a
straight line) at ``simulation_frequency = policy_frequency = 10`` Hz, the planner's 0.1 s
step. The action range is the planner's ``[u_min, u_max]`` and the speed range its
``[v_min, v_max]``.

The planner knows one conflict between two vehicles; highway-env's traffic was not modelled
for it. Each other vehicle is therefore **projected onto its conflict with the ego's path**
(:class:`Projector`): the conflict point is the first point where its own lane sequence
(current lane, then its route) comes within :data:`CONFLICT_BAND_M` (2.5 m) of the ego's
path line, to cross it or to merge into it (a merging vehicle runs beside the ego's lane for
metres before it joins it: the exact merge point would be met too late); its position
relative to that point, measured along its own lanes (negative before it), and its speed form
the planner's human state ``(s_HV, v_HV)``, and the ego's position relative to the same
point, along its path, the AV state. The planner then sees each conflict as the paper's
right-angle crossing. A vehicle's lane sequence and conflict point are kept from when it is
first seen, so that a vehicle past the point is still measured against it until it has
cleared it.

Which vehicle the planner plans against, and the shield: **all of them**, through the adapter every
outside simulator shares (``persuasive.envs.external.ExternalPlanner``): one planner per
conflicting vehicle (each keeps its own belief on that driver's role), the lowest of their
accelerations, an IDM gap to a vehicle ahead in the ego's lane, full throttle without a conflict,
and the safety shield over every conflicting vehicle and every vehicle ahead in the lane (corrected
mode: the worst-case shield; ``--shield`` sets it). For the shield each projected vehicle also gets
its **occupancy**: the stretch of its lanes where its footprint can touch the ego's (its centre
within ``ego width / 2 + its half-diagonal +`` :data:`TRACK_MARGIN_M` of the ego's line) and the
stretch of the ego's path facing it (widened by ``ego length / 2 + its half-diagonal``); a vehicle
whose lanes stay in that band to their end joins the ego's lane (a merge, with its merge point
where its lane centre comes within :data:`SAME_LANE_M` of the ego's line), one in the ego's lane
ahead of it is followed (the traffic is :class:`ForwardIDMVehicle`, highway-env's ``IDMVehicle``
that stops at rest instead of driving backwards). A vehicle that was followed and turns out of
the ego's lane stays a vehicle to follow until it has left the stretch of its lanes where its
footprint can touch the ego's, taken as standing where its nearest corner is (it may stop
there, and its progress along the ego's line is not its speed): as a crossing it would put both
vehicles inside their occupancy intervals at once, where no fallback is certified (seed 72,
the ego proposing full throttle: 53 uncertified steps before this rule). Its limits are
highway-env's own: ``IDMVehicle`` accelerates at most at its ``COMFORT_ACC_MAX``, brakes at
most at its ``ACC_MAX`` and never drives faster than the larger
of its speed and the speed limit of every lane on its way (:func:`speed_bound`: the IDM clips its
target to the lane's limit, whatever target ``RegulatedRoad`` sets while it makes a vehicle yield
and after); every episode checks that every vehicle stayed inside that envelope
(:class:`EnvelopeCheck`, ``envelope_excesses``). Two other vehicles that crash are wrecks
(:func:`is_wreck`), counted per episode (:class:`WreckCount`) and outside the guarantee: no
drivers any more, they roll on straight, off their lanes, and the shield sees each as a leader
standing at speed 0 where the footprints it can still take first meet the ego's corridor,
until it has rolled out of it before the ego could get there (:meth:`Projector.wreck_front`).
highway-env integrates positions with the speed of
the step's start (Euler): a braking ego rolls further than the planner's exact step says, by
``v dt / 2`` from speed ``v`` plus at most ``b dt^2 / 8`` for the last, partial step of
deceleration ``b`` (the speed is clipped at 0), and an accelerating one lags behind it. The shield
therefore takes the ego, for each first step it checks, that much further along than the exact
kinematics after that step (:func:`euler_shift`: the Euler step's own displacement against the
exact one, plus :func:`euler_lead`, the exact Euler surplus of a stop at ``u_min`` from the new
speed; 0 for an ego at rest that stays at rest), and the far end of the ego's occupancy is widened
by ``v_max dt`` for the lag (at ``u_max = 1 m/s^2`` it stays below that for the 10 s it takes the
ego to accelerate from rest to ``v_max``); the other vehicles' near ends by their ``v_max dt / 2``
(an Euler vehicle that stops, stops that much further). The acceleration is finally limited so that
the speed stays in ``[v_min, v_max]`` within the step.

The comparison driver (``default``) is highway-env's own: the ego becomes one of the env's
``IDMVehicle`` (its parameters as the env sets them for traffic, lane changes off, routed to
``o2``), which highway-env's ``RegulatedRoad`` makes yield to traffic of higher priority, the
behaviour highway-env gives every vehicle it drives itself. Both drivers run the same seeds
(``env.reset(seed=...)``), so every episode starts from the same traffic. The default ego is
judged, step by step, by the planner's shield, which it does not use (:class:`DefaultJudge`):
how many of its steps, and whether the step that took it into the junction, the shield would
have admitted as it drove them (a ceiling on what any planner behind that shield can do).

Per episode (:class:`EpisodeResult`): collision, whether the ego crossed the intersection
(left its inner lane) and arrived (highway-env's ``has_arrived``), who crossed first (against
each *contested* vehicle: one whose conflict point both vehicles were within
:data:`CONTEST_RANGE_M` of at the same step, the paper's start being 20 +- 5 m before it; who
reached the conflict point first), the ego's time to cross and the minimum centre distance to
any other vehicle.

Headless rendering: pygame draws the ``rgb_array`` frames with SDL's ``offscreen`` video
driver (set here when ``SDL_VIDEODRIVER`` is unset or ``dummy``: with ``dummy`` pygame runs
headless too, but highway-env's viewer then draws nothing and every frame is black).
"""

from __future__ import annotations

import bisect
import contextlib
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..config import AV_KIND_ALIASES, AV_KINDS, Config, ConfigError
from ..safety.measures import restricted_mean

#: highway-env ids tried in order (the issue names ``intersection-v2``).
HIGHWAY_ENV_IDS = ("intersection-v2", "intersection-v1")
#: The ego's route: straight through, from ``o0`` to ``o2``.
DESTINATION = "o2"
#: highway-env's simulation and policy frequency [Hz] (the planner's step is 1 / 10 s).
FREQUENCY_HZ = 10
#: A vehicle contests the ego's crossing when both were this close before the conflict point
#: at the same step [m].
CONTEST_RANGE_M = 25.0
#: Lateral distance under which a point is on the ego's path line [m].
ON_PATH_M = 1e-6
#: The conflict starts where the other's path comes this close to the ego's path line [m]:
#: half of highway-env's 4 m lane plus 0.5 m, so that a vehicle merging from the side is met
#: before it is in the lane, while the oncoming lane (4 m away) is no conflict.
CONFLICT_BAND_M = 2.5
#: Largest spacing of the samples of a curved lane searched for the conflict [m].
SAMPLE_M = 0.25
#: A vehicle this close to the ego's path line, heading within 30 degrees of it, is in the
#: ego's lane [m].
SAME_LANE_M = 1.0
SAME_LANE_COS = math.cos(math.radians(30.0))
#: Driver names of the report.
DEFAULT_DRIVER = "default"
#: Lateral allowance for how far a vehicle strays from its lane's centre line [m].
TRACK_MARGIN_M = 0.25
#: Spacing of the lane samples searched for a vehicle's occupancy [m].
OCCUPANCY_SAMPLE_M = 0.1
#: How far a wreck still rolls per m/s of its speed [s]: highway-env's crashed vehicle steers
#: straight and brakes with ``acceleration = -speed`` (``Vehicle.clip_actions``, 1/s), so each
#: Euler step keeps ``1 - dt`` of its speed and it rolls ``sum_k v (1 - dt)^k dt = v * 1 s``
#: along its heading, whatever its lane.
WRECK_ROLL_S = 1.0
#: Lateral margin of the ego's corridor against a wreck's footprint [m] (as a track's).
WRECK_MARGIN_M = TRACK_MARGIN_M
#: Steps searched for when a rolling wreck leaves the ego's corridor (20 s, longer than an
#: episode; not found: it stays).
WRECK_CLEAR_STEPS = 200


def _import_highway_env():
    """``highway_env``, imported with a headless pygame (:func:`headless_video`)."""
    headless_video()
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import highway_env  # noqa: F401
    except ImportError:
        raise ConfigError("persuasive highway needs highway-env: pip install -e '.[highway]' "
                          "in the persuasive checkout") from None
    return highway_env


def headless_video() -> None:
    """Let pygame draw without a display: SDL's ``offscreen`` video driver, unless another
    driver is set. ``dummy`` is replaced too: highway-env (1.12) draws nothing when
    ``SDL_VIDEODRIVER=dummy`` (its viewer disables itself), so its frames would be black."""
    if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
        os.environ["SDL_VIDEODRIVER"] = "offscreen"


def highway_env_id() -> str:
    """The intersection id the installed highway-env provides (:data:`HIGHWAY_ENV_IDS`)."""
    _import_highway_env()
    from gymnasium.envs.registration import registry

    for env_id in HIGHWAY_ENV_IDS:
        if env_id in registry:
            return env_id
    raise ConfigError(f"highway-env provides none of {', '.join(HIGHWAY_ENV_IDS)}")


#: The ego's strongest braking [m/s^2]: highway-env's own drivers brake comfortably at
#: 5 m/s^2 (``COMFORT_ACC_MIN``) and at most at 6; the paper's 2 m/s^2 cannot stop the ego
#: from highway-env's initial 10 m/s in the room its traffic leaves it (the shield then has no
#: fallback from the first step on).
EGO_BRAKING_MPS2 = 5.0


def planner_config(kind: str = "persuasive", shield: str | None = None) -> Config:
    """The planner's configuration: corrected mode (the :class:`~persuasive.Planner`'s
    default; paper mode's quirk Q3 reads a human role highway-env's drivers do not have) with
    ``av.kind = kind``, ``av.shield = shield`` (default: corrected mode's, worst-case) and the
    ego braking at up to :data:`EGO_BRAKING_MPS2`."""
    if kind not in AV_KINDS and kind not in AV_KIND_ALIASES:
        raise ConfigError(f"--planner = {kind!r} is out of range; allowed: "
                          f"{' | '.join(AV_KINDS)}")
    overrides = {"av.kind": kind, "av.vehicle.u_min_mps2": -EGO_BRAKING_MPS2}
    if shield:
        overrides["av.shield"] = shield
    return Config(mode="corrected").with_overrides(overrides)


def highway_config(config: Config) -> dict[str, Any]:
    """highway-env's configuration for the ego (see the module docstring)."""
    veh = config.vehicle_of("av")
    if config.simulation.dt_s * FREQUENCY_HZ != 1.0:
        raise ConfigError(f"simulation.dt_s = {config.simulation.dt_s!r} is out of range; "
                          f"allowed: {1 / FREQUENCY_HZ} (highway-env runs at {FREQUENCY_HZ} Hz)")
    return {
        "action": {"type": "ContinuousAction", "longitudinal": True, "lateral": False,
                   "acceleration_range": (veh.u_min_mps2, veh.u_max_mps2),
                   "speed_range": (veh.v_min_mps, veh.v_max_mps)},
        "destination": DESTINATION,
        "simulation_frequency": FREQUENCY_HZ,
        "policy_frequency": FREQUENCY_HZ,
        "other_vehicles_type": TRAFFIC_VEHICLE,
    }


#: The class of highway-env's traffic (and of its own ego driver): :class:`ForwardIDMVehicle`.
TRAFFIC_VEHICLE = "persuasive.envs.highway.ForwardIDMVehicle"


def _forward_idm_class():
    from highway_env.vehicle.behavior import IDMVehicle

    class ForwardIDMVehicle(IDMVehicle):
        """highway-env's ``IDMVehicle`` that never drives backwards: a braking step ends at rest
        at the latest. highway-env's own lets the IDM's braking behind a close leader carry the
        speed below 0 (its ``MIN_SPEED`` is -40 m/s, and its clip acts only from the next step),
        so its vehicles reversed, out of the envelope the shield assumes (``v_min = 0``); cars
        waiting at a junction do not roll backwards. Everything else is highway-env's (the env
        sets the same IDM parameters on it as on its default class)."""

        def step(self, dt: float) -> None:
            if not self.crashed and self.speed >= 0.0:
                self.action["acceleration"] = max(float(self.action["acceleration"]),
                                                  -self.speed / dt)
            super().step(dt)

    ForwardIDMVehicle.__module__ = __name__
    ForwardIDMVehicle.__qualname__ = "ForwardIDMVehicle"
    return ForwardIDMVehicle


def __getattr__(name: str):
    # built on first use, so that importing this module does not import highway-env
    if name == "ForwardIDMVehicle":
        cls = _forward_idm_class()
        globals()[name] = cls
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def make_highway_env(config: Config, render_mode: str | None = None):
    """highway-env's intersection, configured for the ego (:func:`highway_config`)."""
    import gymnasium as gym

    env_id = highway_env_id()
    return gym.make(env_id, config=highway_config(config), render_mode=render_mode)


# -- the projection ------------------------------------------------------------------------


@dataclass(frozen=True)
class EgoPath:
    """The ego's straight path: ``origin`` (2,) [m], unit ``direction`` (2,), ``length_m``;
    ``exit_u_m``: where it leaves the intersection (the start of its last lane) [m];
    ``entry_u_m``: where it enters it (the end of its first lane; None for a route of fewer
    than three lanes), the ego's yield line (docs/method.md §12.8)."""

    origin: np.ndarray
    direction: np.ndarray
    length_m: float
    exit_u_m: float
    entry_u_m: float | None = None
    #: highway-env's priority of the ego's lane through the intersection (``RegulatedRoad``
    #: makes the lower yield; the horizontal road's lanes have 3, the ego's vertical one 1)
    priority: int = 0

    @classmethod
    def from_lanes(cls, network, lanes: list[tuple]) -> EgoPath:
        """From consecutive straight, collinear lanes; :class:`ConfigError` otherwise."""
        from highway_env.road.lane import StraightLane

        objs = [network.get_lane(index) for index in lanes]
        if not all(isinstance(lane, StraightLane) for lane in objs):
            raise ConfigError("the ego's route is not straight (lateral control is off)")
        origin = np.array(objs[0].start, float)
        direction = np.array(objs[0].direction, float)
        path = cls(origin, direction, 0.0, 0.0)
        for lane in objs:
            (_, lat0), (_, lat1) = path.coordinates(lane.start), path.coordinates(lane.end)
            if abs(lat0) > ON_PATH_M or abs(lat1) > ON_PATH_M:
                raise ConfigError("the ego's route is not one straight line")
        length = float(sum(lane.length for lane in objs))
        exit_u = float(sum(lane.length for lane in objs[:-1]))
        entry_u = float(objs[0].length) if len(objs) >= 3 else None
        inner = objs[1] if len(objs) >= 3 else objs[0]
        return cls(origin, direction, length, exit_u, entry_u,
                   int(getattr(inner, "priority", 0)))

    def coordinates(self, point) -> tuple[float, float]:
        """``(u, lateral)`` [m] of ``point``: along the path from its origin, and to its left."""
        d = np.asarray(point, float) - self.origin
        ux, uy = self.direction
        return float(d[0] * ux + d[1] * uy), float(-d[0] * uy + d[1] * ux)


@dataclass
class Track:
    """What is kept of one other vehicle: its lane sequence from when it was first seen, the
    cumulative length before each lane [m], and its conflict with the ego's path (``None``
    when its lanes never enter it): index of the lane, longitudinal position on that lane
    [m], arc length from the start of the sequence [m], the point (2,) and its ``u`` on the
    ego's path [m]."""

    vehicle: Any
    lanes: list[tuple]
    offsets: list[float]
    conflict_lane: int | None = None
    conflict_long_m: float = math.nan
    conflict_arc_m: float = math.nan
    point: np.ndarray | None = None
    conflict_u_m: float = math.nan
    #: the shield's view (module docstring): "crossing" or "merge" (None: no footprint
    #: conflict), the arc and ego positions of the conflict's origin, and the two occupancy
    #: intervals relative to it [m]
    kind: str | None = None
    origin_arc_m: float = math.nan
    origin_u_m: float = math.nan
    ego_occupancy: tuple[float, float] = (math.nan, math.nan)
    other_occupancy: tuple[float, float] = (math.nan, math.nan)


@dataclass(frozen=True)
class Projection:
    """One other vehicle on its conflict with the ego's path: the planner's two states."""

    other_s_m: float  #: the vehicle's position relative to the conflict point, along its lanes
    other_v_mps: float  #: its speed
    ego_s_m: float  #: the ego's position relative to the same point, along its path
    point: tuple[float, float]  #: the conflict point [m]
    track: Track = field(repr=False, compare=False)


def ego_route(u) -> list[tuple]:
    """The ego's lanes from where it stands to :data:`DESTINATION` in highway-env's
    intersection ``u`` (an unwrapped env after reset): its lane, then the shortest path's."""
    network, start = u.road.network, u.vehicle.lane_index
    nodes = network.shortest_path(start[1], DESTINATION)
    return [tuple(start)] + [(a, b, 0) for a, b in zip(nodes[:-1], nodes[1:])]


def lane_sequence(vehicle, network) -> list[tuple]:
    """The lanes a vehicle will drive: the one it follows now, then the rest of its route."""
    current = getattr(vehicle, "target_lane_index", None) or vehicle.lane_index
    lanes = [tuple(current)]
    route = [tuple(r) for r in (getattr(vehicle, "route", None) or [])]
    starts = [i for i, r in enumerate(route) if r[:2] == lanes[0][:2]]
    rest = route[starts[0] + 1:] if starts else route
    for r in rest:
        index = r if r[2] is not None else (r[0], r[1], 0)
        network.get_lane(index)  # a lane of the network
        lanes.append(index)
    return lanes


def _lane_samples(lane) -> np.ndarray:
    """Longitudinal positions [m] where a lane is searched for the conflict: its ends for a
    straight lane, at most :data:`SAMPLE_M` apart otherwise."""
    from highway_env.road.lane import StraightLane

    if isinstance(lane, StraightLane):
        return np.array([0.0, lane.length])
    n = max(2, int(math.ceil(lane.length / SAMPLE_M)) + 1)
    return np.linspace(0.0, lane.length, n)


def find_conflict(network, lanes: list[tuple], ego: EgoPath,
                  band_m: float = CONFLICT_BAND_M) -> tuple[int, float] | None:
    """Where a lane sequence first comes within ``band_m`` of the ego's path: ``(lane index in
    lanes, longitudinal position on that lane [m])``, or ``None``.

    Lanes at the start that lie on the ego's path (the vehicle is in the ego's lane) are
    skipped; after them, the first point where the lateral offset from the ego's path line,
    coming from beyond ``band_m``, reaches ``band_m`` (crossing the path or merging into it;
    found exactly on a straight lane, by bisection on a curved one), within the ego's path.
    Leaving the path (a turn out of the ego's lane) is no entry.
    """
    from highway_env.road.lane import StraightLane

    objs = [network.get_lane(index) for index in lanes]
    first = 0
    while first < len(objs) and isinstance(objs[first], StraightLane) and all(
            abs(ego.coordinates(p)[1]) <= ON_PATH_M for p in (objs[first].start,
                                                             objs[first].end)):
        first += 1
    prev = None  # (lane, longitudinal, lateral) of the previous sample
    for i in range(first, len(objs)):
        lane = objs[i]
        for x in _lane_samples(lane):
            x = float(x)
            lat = ego.coordinates(lane.position(x, 0.0))[1]
            if prev is not None and abs(prev[2]) > band_m and (
                    abs(lat) <= band_m or (lat > 0) != (prev[2] > 0)):
                target = math.copysign(band_m, prev[2])
                lo = prev[1] if prev[0] == i else 0.0
                hit = _solve(lane, ego, lo, x, target, isinstance(lane, StraightLane))
                u_hit = ego.coordinates(lane.position(hit, 0.0))[0]
                if 0.0 <= u_hit <= ego.length_m:
                    return i, hit
            prev = (i, x, lat)
    return None


def _solve(lane, ego: EgoPath, lo: float, hi: float, target: float, straight: bool) -> float:
    """The longitudinal position in ``[lo, hi]`` where the lane's lateral offset from the ego's
    path line equals ``target`` (it is beyond ``target`` at ``lo`` and not at ``hi``)."""
    f_lo = ego.coordinates(lane.position(lo, 0.0))[1] - target
    f_hi = ego.coordinates(lane.position(hi, 0.0))[1] - target
    if straight:  # the offset is linear along a straight lane
        return lo + (hi - lo) * f_lo / (f_lo - f_hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = ego.coordinates(lane.position(mid, 0.0))[1] - target
        if (f_mid > 0) == (f_lo > 0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


class Projector:
    """Projects other vehicles onto their conflict with the ego's path (module docstring).

    ``network``: the road network; ``ego_lanes``: the ego's route as lane indices.
    """

    def __init__(self, network, ego_lanes: list[tuple], ego_size: tuple[float, float] = (5.0, 2.0),
                 euler_margin_m: float = 0.0, ego_v_max_mps: float = math.inf):
        self.network = network
        self.ego = EgoPath.from_lanes(network, ego_lanes)
        self.ego_size = ego_size  #: the ego's (length, width) [m]
        self.euler_margin_m = euler_margin_m  #: widening for Euler steps [m] (module docstring)
        #: the ego's top speed [m/s]: a wreck that has left its corridor for good before the
        #: ego can get there at that speed is none of its business (:meth:`wreck_front`;
        #: ``inf``: every wreck that can still touch the corridor counts)
        self.ego_v_max_mps = ego_v_max_mps
        self._tracks: dict[int, Track] = {}
        #: vehicles followed in the ego's lane, kept while they turn out of it (module docstring)
        self._leaders: set[int] = set()

    def track(self, vehicle) -> Track:
        """The vehicle's :class:`Track`, made when it is first seen (or when it has left the
        lanes it was first seen on)."""
        track = self._tracks.get(id(vehicle))
        if track is not None and track.vehicle is vehicle and self._lane_position(
                track, vehicle) is not None:
            return track
        lanes = lane_sequence(vehicle, self.network)
        offsets = np.concatenate([[0.0], np.cumsum(
            [self.network.get_lane(i).length for i in lanes])])[:-1].tolist()
        track = Track(vehicle, lanes, offsets)
        found = find_conflict(self.network, lanes, self.ego)
        if found is not None:
            i, long_m = found
            point = self.network.get_lane(lanes[i]).position(long_m, 0.0)
            track.conflict_lane, track.conflict_long_m = i, long_m
            track.conflict_arc_m = offsets[i] + long_m
            track.point = np.asarray(point, float)
            track.conflict_u_m = self.ego.coordinates(point)[0]
        self._occupancy(track, vehicle)
        self._tracks[id(vehicle)] = track
        return track

    def known_track(self, vehicle) -> Track | None:
        """The vehicle's :class:`Track` if it has one (none made)."""
        return self._tracks.get(id(vehicle))

    def _occupancy(self, track: Track, vehicle) -> None:
        """The shield's view of a track (module docstring): the first stretch of its lanes,
        not yet behind the vehicle, where its footprint can touch the ego's."""
        ego_len, ego_wid = self.ego_size
        r_o = 0.5 * math.hypot(vehicle.LENGTH, vehicle.WIDTH)
        band = 0.5 * ego_wid + r_o + TRACK_MARGIN_M
        reach = 0.5 * ego_len + r_o
        arcs, us, lats = [], [], []
        for lane_index, offset in zip(track.lanes, track.offsets):
            lane = self.network.get_lane(lane_index)
            n = max(2, int(math.ceil(lane.length / OCCUPANCY_SAMPLE_M)) + 1)
            for x in np.linspace(0.0, lane.length, n):
                u, lat = self.ego.coordinates(lane.position(float(x), 0.0))
                arcs.append(offset + float(x))
                us.append(u)
                lats.append(lat)
        arcs, us, lats = np.array(arcs), np.array(us), np.array(lats)
        inside = (np.abs(lats) <= band) & (us >= -reach) & (us <= self.ego.length_m + reach)
        now = self.arc_position(track, vehicle)
        idx = np.flatnonzero(inside)
        if idx.size == 0:
            return
        # the contiguous stretches of samples in the band; the first not behind the vehicle
        breaks = np.flatnonzero(np.diff(idx) > 1)
        starts, ends = np.r_[idx[0], idx[breaks + 1]], np.r_[idx[breaks], idx[-1]]
        ahead = np.flatnonzero(arcs[ends] >= now)
        if ahead.size == 0:
            return
        a, b = starts[ahead[0]], ends[ahead[0]]
        h = OCCUPANCY_SAMPLE_M
        u_lo = float(us[a:b + 1].min()) - reach
        u_hi = float(us[a:b + 1].max()) + reach + 2.0 * self.euler_margin_m  # the lag of GO
        other_lead = 0.5 * highway_limits(vehicle).v_max_mps / FREQUENCY_HZ
        if b == arcs.size - 1:  # in the band to the end of its lanes: it joins the ego's lane
            on_line = np.flatnonzero(np.abs(lats[a:b + 1]) <= SAME_LANE_M)
            m = a + (int(on_line[0]) if on_line.size else int(np.argmin(np.abs(lats[a:b + 1]))))
            track.kind = "merge"
            track.origin_arc_m, track.origin_u_m = float(arcs[m]), float(us[m])
            track.ego_occupancy = (u_lo - track.origin_u_m, 0.0)
            track.other_occupancy = (float(arcs[a]) - h - other_lead - track.origin_arc_m,
                                     0.5 * (ego_len + vehicle.LENGTH) + ego_len + 1.0)
        else:
            track.kind = "crossing"
            if track.conflict_lane is not None:  # the planner's origin (the band's entry)
                track.origin_arc_m, track.origin_u_m = track.conflict_arc_m, track.conflict_u_m
            else:
                track.origin_arc_m, track.origin_u_m = float(arcs[a]), float(us[a])
            track.ego_occupancy = (u_lo - track.origin_u_m, u_hi - track.origin_u_m)
            track.other_occupancy = (float(arcs[a]) - h - other_lead - track.origin_arc_m,
                                     float(arcs[b]) + h - track.origin_arc_m)

    @staticmethod
    def _lane_position(track: Track, vehicle) -> int | None:
        current = getattr(vehicle, "target_lane_index", None) or vehicle.lane_index
        for i, index in enumerate(track.lanes):
            if index[:2] == tuple(current)[:2]:
                return i
        return None

    def arc_position(self, track: Track, vehicle) -> float:
        """The vehicle's arc length along its kept lane sequence [m]."""
        i = self._lane_position(track, vehicle)
        lane = self.network.get_lane(track.lanes[i])
        return track.offsets[i] + float(lane.local_coordinates(vehicle.position)[0])

    def in_ego_lane(self, vehicle) -> bool:
        """On the ego's path line and heading along it (a leader or a follower)."""
        _, lat = self.ego.coordinates(vehicle.position)
        return abs(lat) <= SAME_LANE_M and float(np.dot(vehicle.direction, self.ego.direction)) \
            >= SAME_LANE_COS

    def project(self, vehicle, ego_vehicle) -> Projection | None:
        """The vehicle on its conflict with the ego's path, or ``None`` (no conflict, or it
        is in the ego's lane)."""
        if self.in_ego_lane(vehicle):
            return None
        track = self.track(vehicle)
        if track.conflict_lane is None:
            return None
        other_s = self.arc_position(track, vehicle) - track.conflict_arc_m
        ego_s = self.ego.coordinates(ego_vehicle.position)[0] - track.conflict_u_m
        return Projection(float(other_s), float(vehicle.speed), float(ego_s),
                          (float(track.point[0]), float(track.point[1])), track)

    def conflicts(self, ego_vehicle, vehicles: Iterable, stand_ins: Iterable = ()) -> list:
        """Every other vehicle that can touch the ego, as the shared adapter's
        :class:`~persuasive.envs.external.Conflict` (module docstring): a crossing or merging
        vehicle relative to its conflict's origin, a vehicle ahead in the ego's lane to follow.
        Vehicles behind the ego in its lane, or whose lanes never come near it, are left out.
        ``stand_ins`` (:func:`spawn_stand_ins`): the same for the vehicles not spawned yet,
        marked ``extra["stand_in"]`` (the shield checks them, the planner does not plan
        against them). A wreck (:func:`is_wreck`) whose footprint can touch the ego's
        corridor is a leader standing at speed 0 with its rear where it first meets the
        corridor (:meth:`wreck_front`), keyed ``("wreck", id)`` and marked
        ``extra["wreck"]`` (no driver: the responsibility rule judges no duty of it)."""
        u_ego = self.ego.coordinates(ego_vehicle.position)[0]
        out = [c for v in vehicles if v is not ego_vehicle
               for c in [self._conflict(v, u_ego)] if c is not None]
        for v in stand_ins:
            c = self._conflict(v, u_ego)
            if c is not None:
                c.extra["stand_in"] = True
                out.append(c)
        return out

    def _conflict(self, v, u_ego: float):
        from .external import CROSSING, FOLLOW, MERGE, Conflict

        limits = highway_limits(v)
        if is_wreck(v):  # a standing obstacle, wherever it drifted: no lane, no driver
            front = self.wreck_front(v, u_ego)
            if front is None:
                return None
            return Conflict(("wreck", id(v)), FOLLOW, u_ego, front + 0.5 * float(v.LENGTH),
                            0.0, other=limits, extra={"wreck": True})
        if self.in_ego_lane(v):
            u = self.ego.coordinates(v.position)[0]
            if u <= u_ego:
                return None
            self._leaders.add(id(v))
            return Conflict(id(v), FOLLOW, u_ego, u, float(v.speed), other=limits)
        if id(v) in self._leaders:
            leaving = self.leaving_leader(v, u_ego)
            if leaving is not None:
                return Conflict(id(v), FOLLOW, u_ego, leaving, 0.0, other=limits)
            self._leaders.discard(id(v))
        track = self.track(v)
        if track.kind is None:
            return None
        s_other = self.arc_position(track, v) - track.origin_arc_m
        s_ego = u_ego - track.origin_u_m
        if track.kind == "merge" and s_other >= 0.0:  # it has joined the lane
            return Conflict(id(v), FOLLOW, s_ego, s_other, float(v.speed), other=limits) \
                if s_other > s_ego else None
        entry = self.ego.entry_u_m  # it yields with its front before the intersection
        line = None if entry is None else entry - 0.5 * self.ego_size[0] - track.origin_u_m
        return Conflict(id(track), CROSSING if track.kind == "crossing" else MERGE, s_ego,
                        s_other, float(v.speed), track.ego_occupancy, track.other_occupancy,
                        limits, ego_line_m=line, right_of_way=self.right_of_way(track))

    def _wreck_span(self, v, steps: int | None = 0) -> tuple[float, float] | None:
        """:func:`corridor_span` of :func:`wreck_region` ``(v, steps)`` in the ego's corridor,
        ``ego width / 2 +`` :data:`WRECK_MARGIN_M` of its line."""
        uv = np.array([self.ego.coordinates(p) for p in wreck_region(v, steps)])
        return corridor_span(uv[:, 0], uv[:, 1], 0.5 * self.ego_size[1] + WRECK_MARGIN_M)

    def wreck_front(self, v, u_ego: float) -> float | None:
        """Where a wreck (:func:`is_wreck`) first meets the ego's corridor, along the ego's
        line [m]: the lowest ``u`` of the hull of every footprint it can still take
        (:func:`wreck_region`) within ``ego width / 2 +`` :data:`WRECK_MARGIN_M` of the line.
        None when none of it is in the corridor, or all of it is behind the ego's rear, or it
        rolls out of the corridor for good (:meth:`wreck_clear_s`, a step more) before the
        ego, at its top speed, could reach that point. The shield takes it as a leader
        standing with its rear there (module docstring).

        Both tests are kept from step to step: the hull only shrinks as the wreck rolls on
        (the point only moves away), and the time it needs to leave falls by the step while
        the ego's least time to the point falls by at most as much (it moves at most ``v_max
        dt`` a step); a wreck left out is never taken in again."""
        span = self._wreck_span(v)
        if span is None or span[1] < u_ego - 0.5 * self.ego_size[0]:
            return None
        gap = span[0] - (u_ego + 0.5 * self.ego_size[0])
        if gap > 0.0 and gap / self.ego_v_max_mps > self.wreck_clear_s(v) + 1.0 / FREQUENCY_HZ:
            return None
        return span[0]

    def wreck_clear_s(self, v) -> float:
        """After how long a rolling wreck has left the ego's corridor for good [s]: the first
        step ``k`` from which the hull of its footprints (:func:`wreck_region` ``(v, k)``)
        misses the corridor, times the step (``inf``: it comes to rest in the corridor, or
        not within :data:`WRECK_CLEAR_STEPS`)."""
        if self._wreck_span(v, None) is not None:
            return math.inf
        for k in range(WRECK_CLEAR_STEPS + 1):
            if self._wreck_span(v, k) is None:
                return k / FREQUENCY_HZ
        return math.inf

    def leaving_leader(self, v, u_ego: float) -> float | None:
        """For a followed vehicle turning out of the ego's lane: where to take it on the ego's
        line while it has not yet left the stretch of its lanes where its footprint can touch
        the ego's (its track's occupancy, the same stretch a crossing would be certified
        against) and its nearest corner is ahead of the ego, as a vehicle of its length whose
        rear is that corner; None once it is out (module docstring)."""
        track = self.track(v)
        if track.kind is None or (self.arc_position(track, v) - track.origin_arc_m
                                  > track.other_occupancy[1]):
            return None
        d = np.asarray(v.direction, float)
        n = np.array([-d[1], d[0]])
        p = np.asarray(v.position, float)
        corners = [p + 0.5 * sx * v.LENGTH * d + 0.5 * sy * v.WIDTH * n
                   for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)]
        nearest = min(self.ego.coordinates(c)[0] for c in corners)
        if nearest <= u_ego:
            return None
        return float(nearest + 0.5 * v.LENGTH)

    def right_of_way(self, track: Track) -> float:
        """Who has the right of way at a track's conflict, by highway-env's own rule
        (``RegulatedRoad.respect_priorities``: the lane of lower priority yields): 1 the ego,
        -1 the other, 0 equal (highway-env then makes the one behind yield, which no fixed
        rule says in advance: neither)."""
        i = track.conflict_lane
        if i is None:  # a footprint conflict only: the lane where its occupancy starts
            i = max(0, bisect.bisect_right(track.offsets, track.origin_arc_m) - 1)
        other = int(getattr(self.network.get_lane(track.lanes[i]), "priority", 0))
        return float(np.sign(self.ego.priority - other))

    def leader(self, ego_vehicle, vehicles: Iterable) -> tuple[float, float] | None:
        """The nearest vehicle ahead in the ego's lane: ``(bumper gap [m], speed [m/s])``."""
        u_ego = self.ego.coordinates(ego_vehicle.position)[0]
        best = None
        for v in vehicles:
            if v is ego_vehicle or not self.in_ego_lane(v):
                continue
            gap = self.ego.coordinates(v.position)[0] - u_ego - 0.5 * (v.LENGTH
                                                                         + ego_vehicle.LENGTH)
            if self.ego.coordinates(v.position)[0] > u_ego and (best is None or gap < best[0]):
                best = (float(gap), float(v.speed))
        return best


def is_wreck(vehicle) -> bool:
    """highway-env has marked the vehicle ``crashed`` (``RoadObject.handle_collisions`` sets it
    on both vehicles of a collision, for good): from then on it drives no more, it brakes and
    rolls straight on (:data:`WRECK_ROLL_S`)."""
    return bool(getattr(vehicle, "crashed", False))


def wreck_region(vehicle, steps: int | None = 0) -> np.ndarray:
    """Points (n, 2) [m] whose convex hull holds every footprint a wreck can take from
    ``steps`` highway-env steps from now on (None: at rest). Its position after ``k`` Euler
    steps is ``p + v (1 - (1 - dt / T)^k) T`` along its heading (``T`` =
    :data:`WRECK_ROLL_S`), and the push highway-env has set for its next step (``impact``:
    the separation of an overlap, applied once) adds to every one after now: the corners of
    its footprint now, pushed or not, and at rest (``steps = 0``, 16 points), after ``k``
    steps and at rest (8), or at rest (4)."""
    d = np.asarray(vehicle.direction, float)
    n = np.array([-d[1], d[0]])
    p = np.asarray(vehicle.position, float)
    corners = np.array([p + 0.5 * sx * vehicle.LENGTH * d + 0.5 * sy * vehicle.WIDTH * n
                        for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)])
    roll = float(vehicle.speed) * WRECK_ROLL_S * d
    impact = getattr(vehicle, "impact", None)
    push = np.zeros(2) if impact is None else np.asarray(impact, float).reshape(2)
    if steps is None:
        shifts = np.array([roll + push])
    elif steps == 0:
        shifts = np.array([np.zeros(2), roll, push, roll + push])
    else:
        done = 1.0 - (1.0 - 1.0 / (FREQUENCY_HZ * WRECK_ROLL_S)) ** steps
        shifts = np.array([done * roll + push, roll + push])
    return (shifts[:, None, :] + corners[None, :, :]).reshape(-1, 2)


def corridor_span(u: np.ndarray, lat: np.ndarray, half_m: float) -> tuple[float, float] | None:
    """The range of ``u`` over the convex hull of the points ``(u, lat)`` within ``|lat| <=
    half_m`` (None: the hull misses the strip). Exact: the hull's part in the strip is a
    convex polygon whose vertices are points in the strip or crossings of the hull's edges
    with ``lat = +-half_m``; the crossings of every pair of points hold those and lie in the
    hull themselves."""
    u, lat = np.asarray(u, float), np.asarray(lat, float)
    found = [u[np.abs(lat) <= half_m]]
    i, j = np.triu_indices(len(u), 1)
    for edge in (half_m, -half_m):
        a, b = lat[i] - edge, lat[j] - edge
        cross = a * b < 0.0
        t = a[cross] / (a[cross] - b[cross])
        found.append(u[i][cross] + t * (u[j][cross] - u[i][cross]))
    found = np.concatenate(found)
    if found.size == 0:
        return None
    return float(found.min()), float(found.max())


def speed_bound(vehicle) -> float:
    """The highest speed a highway-env IDM vehicle can reach from now on [m/s] (module
    docstring): the larger of its speed and the speed limit of every lane on its way.

    ``IDMVehicle.acceleration`` clips the target speed to ``[0, lane.speed_limit]``, so the
    IDM never accelerates above its lane's limit, whatever target ``RegulatedRoad`` sets (0
    while it yields, then the lane's limit again) and whatever its spawn speed (drawn around
    8 m/s, it can start above a 10 m/s limit: then it slows down). A lane without a limit
    leaves the target unclipped, and the target speed counts too (and the lane's limit, which
    ``RegulatedRoad`` restores)."""
    network = vehicle.road.network if getattr(vehicle, "road", None) is not None else None
    lanes = [getattr(vehicle, "lane", None)]
    if network is not None:
        for index in list(getattr(vehicle, "route", None) or ()):
            with contextlib.suppress(KeyError, IndexError, ValueError):
                lanes.append(network.get_lane(index))
    bound = float(vehicle.speed)
    unlimited = False
    for lane in lanes:
        limit = getattr(lane, "speed_limit", None) if lane is not None else None
        if limit is None:
            unlimited = True
        else:
            bound = max(bound, float(limit))
    if unlimited:
        bound = max(bound, float(getattr(vehicle, "target_speed", vehicle.speed)))
    return bound


def highway_limits(vehicle):
    """A highway-env vehicle's envelope for the shield (module docstring): its IDM accelerates
    at most at ``COMFORT_ACC_MAX`` and brakes at most at ``ACC_MAX``, and never drives faster
    than :func:`speed_bound` (the class's ``MAX_SPEED`` of 40 m/s would hold too, and would
    freeze the ego)."""
    from .external import Limits

    u_max = float(getattr(vehicle, "COMFORT_ACC_MAX", 3.0))
    u_min = -float(getattr(vehicle, "ACC_MAX", 6.0))
    return Limits(float(vehicle.LENGTH), float(vehicle.WIDTH), u_min, u_max, 0.0,
                  max(speed_bound(vehicle), 1e-3))


class EnvelopeCheck:
    """Whether every vehicle stayed inside the envelope the shield assumed for it: at each
    observation, its speed against the bound and its speed change against the accelerations
    of its limits at the previous one (:func:`highway_limits`)."""

    #: tolerance of the comparisons [m/s]
    TOL_MPS = 1e-9

    #: the kinds of excess: above the speed bound, below ``v_min`` (driving backwards: the
    #: IDM's braking behind a close leader does not stop at 0), a speed gain beyond ``u_max``,
    #: a speed loss beyond ``u_min`` by a driver. A speed loss beyond ``u_min`` of a vehicle
    #: that crashed in that step (highway-env sets both vehicles of a collision to the slower
    #: one's speed at once) is no driver's braking: it is counted apart, in
    #: :attr:`crash_stops`, and the guarantee assumes none (docs/method.md §12.7)
    KINDS = ("over_speed", "reversing", "over_accel", "over_brake")

    def __init__(self, dt_s: float, limits=None):
        self.dt_s = dt_s
        self._limits = limits if limits is not None else highway_limits
        self._last: dict[int, tuple[float, Any]] = {}
        self.kinds = dict.fromkeys(self.KINDS, 0)  #: vehicle-steps per kind of excess
        self.max_excess_mps = 0.0  #: the largest excess of speed or speed change [m/s]
        #: vehicle-steps in which a vehicle that crashed (into another, not the ego) lost
        #: more speed than its ``u_min`` allows
        self.crash_stops = 0

    @property
    def excesses(self) -> int:
        """Vehicle-steps outside the assumed envelope."""
        return sum(self.kinds.values())

    def observe(self, vehicles: Iterable, ego) -> None:
        seen = {}
        for v in vehicles:
            if v is ego:
                continue
            speed = float(v.speed)
            before = self._last.get(id(v))
            if before is not None:
                v0, lim = before
                terms = (speed - lim.v_max_mps, lim.v_min_mps - speed,
                         speed - v0 - lim.u_max_mps2 * self.dt_s,
                         v0 + lim.u_min_mps2 * self.dt_s - speed)
                crashed = bool(getattr(v, "crashed", False))
                for kind, excess in zip(self.KINDS, terms):
                    if excess > self.TOL_MPS:
                        if kind == "over_brake" and crashed:
                            self.crash_stops += 1
                            continue
                        self.kinds[kind] += 1
                        self.max_excess_mps = max(self.max_excess_mps, excess)
            seen[id(v)] = (speed, self._limits(v))
        self._last = seen


class WreckCount:
    """The other vehicles wrecked in an episode (:func:`is_wreck`), whatever their speed loss
    (:attr:`EnvelopeCheck.crash_stops` counts only a loss beyond ``u_min``: two slow cars
    crash without one), and whether the ego ran into one. A vehicle that crashed together
    with the ego, and touches no third one, is the ego's collision, not a wreck; a vehicle
    that crashed in an earlier observation and touches the ego when it crashes is a wreck
    the ego ran into (:attr:`hit`). Touching: highway-env's own test, the footprints
    overlapping now or within the step at their velocities (``are_polygons_intersecting``,
    as ``handle_collisions`` calls it)."""

    def __init__(self, dt_s: float):
        self.dt_s = dt_s
        #: per wreck (by id, the vehicle kept so that the id is not reused): the mark handed
        #: to :meth:`observe` when it was first seen wrecked
        self._wrecks: dict[int, tuple[Any, Any]] = {}
        self._pending: list = []  # vehicles the ego touched at the last observation
        #: the marks of the wrecks the ego ran into (empty: none, or no collision)
        self.hit: list = []

    @property
    def wrecks(self) -> int:
        """Other vehicles wrecked so far."""
        return len(self._wrecks)

    def _touch(self, a, b) -> bool:
        from highway_env import utils

        if np.linalg.norm(np.asarray(a.position) - np.asarray(b.position)) > 0.5 * (
                a.diagonal + b.diagonal) + (abs(a.speed) + abs(b.speed)) * self.dt_s:
            return False  # highway-env's own pre-check, for both velocities
        hit, will, _ = utils.are_polygons_intersecting(
            a.polygon(), b.polygon(), a.velocity * self.dt_s, b.velocity * self.dt_s)
        return bool(hit or will)

    def observe(self, vehicles: Iterable, ego, mark: Any = None) -> None:
        """After a step: record the vehicles newly wrecked (with ``mark``) and, if the ego
        has crashed, the wrecks it ran into."""
        others = [v for v in vehicles if v is not ego]
        partners: list = []
        if ego.crashed:  # a push set at the last step (a collision found ahead) counts too
            partners = [v for v in others if self._touch(ego, v)] + self._pending
            if not self.hit:
                self.hit = [self._wrecks[id(v)][1] for v in partners if id(v) in self._wrecks
                            and self._wrecks[id(v)][0] is v]
        else:
            self._pending = [v for v in others if self._touch(ego, v)]
        for v in others:
            if not is_wreck(v) or (id(v) in self._wrecks and self._wrecks[id(v)][0] is v):
                continue
            if any(p is v for p in partners) and not any(
                    self._touch(v, w) for w in others if w is not v):
                continue  # the ego's collision
            self._wrecks[id(v)] = (v, mark)


#: highway-env spawns vehicles during an episode (``IntersectionEnv._spawn_vehicle``): on an
#: outer lane ``o{r} -> ir{r}``, ``5 + N(0, 1)`` m along it, at ``8 + N(0, 1)`` m/s, to any other
#: exit. The stand-ins for the vehicles not spawned yet take that noise up to 5 standard
#: deviations (exceeded with probability 3e-7 per spawn: the domain the guarantee states): at
#: 10 m, at 13 m/s.
SPAWN_FRONT_M, SPAWN_SPEED_MPS = 5.0 + 5.0, 8.0 + 5.0


def spawn_stand_ins(env) -> list:
    """One stand-in per route highway-env may spawn a vehicle on (every entry but the ego's,
    every other exit), at the furthest spawn position and the highest spawn speed
    (:data:`SPAWN_FRONT_M`, :data:`SPAWN_SPEED_MPS`); never stepped, so it stays there. A
    spawned vehicle starts behind its route's stand-in and no faster, so it arrives no
    earlier: a trajectory certified against the stand-ins is certified against every vehicle
    spawned later (the entry stand-ins of SUMO, docs/method.md §14.4). Without them the ego
    could stand inside the occupancy interval of a route that was empty when it entered and
    have no certified choice once a vehicle spawned there (seed 1: 46 steps)."""
    from highway_env import utils

    u = env.unwrapped
    cls = utils.class_from_path(u.config["other_vehicles_type"])
    ego_entry = u.vehicle.lane_index[0]
    out = []
    for r0 in range(4):
        if f"o{r0}" == ego_entry:  # spawned behind the ego in its lane: a follower
            continue
        for r1 in range(4):
            if r1 != r0:
                v = cls.make_on_lane(u.road, (f"o{r0}", f"ir{r0}", 0),
                                     longitudinal=SPAWN_FRONT_M, speed=SPAWN_SPEED_MPS)
                v.plan_route_to(f"o{r1}")
                out.append(v)
    return out


class PlannerDriver:
    """The ego driven by the planner through the shared adapter
    (:class:`~persuasive.envs.external.ExternalPlanner`: one planner per conflicting vehicle,
    the most cautious answer, an IDM gap to a leader, the shield over all, the vehicles not
    spawned yet included: :func:`spawn_stand_ins`)."""

    def __init__(self, config: Config, seed: int, planner_class: type | None = None):
        from .external import ExternalPlanner

        self.config = config
        self.planner = (planner_class or ExternalPlanner)(config, seed)
        self.planner.duty_slack_m = duty_slack(config)
        self.last_targets = 0  #: vehicles planned against at the last step
        self.interventions = 0  #: steps where the shield overrode the planner
        self.uncertified = 0  #: of which no fallback was certified
        self.steps = 0  #: steps driven
        self.override_sum = 0.0  #: sum of |applied - proposed| over the overridden steps
        self.stand_ins: list | None = None  #: made at the first step

    def act(self, env, projector: Projector) -> float:
        av = self.config.vehicle_of("av")
        ego = env.unwrapped.vehicle
        if self.stand_ins is None:
            self.stand_ins = spawn_stand_ins(env)
        conflicts = projector.conflicts(ego, env.unwrapped.road.vehicles, self.stand_ins)
        dt = 1.0 / FREQUENCY_HZ
        v = float(ego.speed)

        def lead(a: float) -> float:  # the Euler step's lead after a first step at a
            return euler_shift(v, a, abs(av.u_min_mps2), dt, av.v_max_mps)

        decision = self.planner.act(v, conflicts, dt, shield_lead_m=lead)
        self.last_targets = decision.targets
        self.steps += 1
        if decision.verdict not in (None, "admitted"):
            self.interventions += 1
            if math.isfinite(decision.proposed_mps2):
                self.override_sum += abs(decision.accel_mps2 - decision.proposed_mps2)
        self.uncertified += decision.verdict == "uncertified"
        a = min(max(decision.accel_mps2, av.u_min_mps2, (av.v_min_mps - float(ego.speed)) / dt),
                av.u_max_mps2, (av.v_max_mps - float(ego.speed)) / dt)
        return float(a)


class DefaultJudge:
    """highway-env's own ego judged by the planner's shield, which it does not use (the SUMO
    judge's counterpart, ``persuasive.envs.sumo``): before each step the conflicts it faces
    (the stand-ins included) and its speed; after it, the acceleration it drove
    (``(v' - v) / dt``, highway-env's Euler speed update) put to the shield as a proposal,
    with the Euler lead of :class:`PlannerDriver`. The shield's fallbacks are the planner's
    (its limits, ``u_max`` 1 m/s^2); highway-env's driver accelerates at up to 3 m/s^2."""

    def __init__(self, config: Config, seed: int, env):
        from .external import ExternalPlanner

        self.config = config
        self.planner = ExternalPlanner(config, seed)
        self.planner.duty_slack_m = duty_slack(config)
        self.stand_ins = self.make_stand_ins(env)
        self.steps = 0  #: steps judged
        self.admitted = 0  #: of which the shield admitted the acceleration driven
        self.entry_admitted: bool | None = None  #: the verdict on the step into the junction
        self._before: tuple[float, float, list] | None = None

    def make_stand_ins(self, env) -> list:
        """The vehicles not spawned yet (:func:`spawn_stand_ins`)."""
        return spawn_stand_ins(env)

    def lead(self, v: float, first: float) -> float:
        """The Euler lead after a first step at ``first`` from speed ``v`` (as the planner's,
        :func:`euler_shift`)."""
        av = self.config.vehicle_of("av")
        return euler_shift(v, first, abs(av.u_min_mps2), 1.0 / FREQUENCY_HZ, av.v_max_mps)

    def before(self, env, projector: Projector) -> None:
        ego = env.unwrapped.vehicle
        u = projector.ego.coordinates(ego.position)[0]
        conflicts = projector.conflicts(ego, env.unwrapped.road.vehicles, self.stand_ins)
        self._before = (float(ego.speed), u, conflicts)

    def after(self, env, projector: Projector) -> None:
        v, u, conflicts = self._before
        ego = env.unwrapped.vehicle
        if ego.crashed:  # a crash's stop is no driver's acceleration
            return
        dt = 1.0 / FREQUENCY_HZ
        a = (float(ego.speed) - v) / dt
        _, verdict = self.planner.shield(v, a, conflicts, dt, lambda first: self.lead(v, first),
                                         driven=True)
        self.steps += 1
        self.admitted += verdict == "admitted"
        entry = projector.ego.entry_u_m
        if self.entry_admitted is None and entry is not None and u < entry <= \
                projector.ego.coordinates(ego.position)[0]:
            self.entry_admitted = verdict == "admitted"


def euler_lead(v_mps: float, brake_mps2: float, dt_s: float) -> float:
    """How much further highway-env's Euler steps take a vehicle braking at ``brake_mps2``
    from ``v_mps`` to rest than the exact stop ``v^2 / (2 b)`` [m] (module docstring).

    Each step moves ``v_k dt`` with the speed ``v_k = v - k b dt`` of its start, the last one
    with the speed clipped at 0 (the driver never asks for more braking than stops the
    vehicle within the step), so the Euler stop is ``dt * sum_k v_k`` over the steps whose
    start speed is positive: exactly ``v dt / 2`` more than the exact stop when ``v`` is a
    multiple of ``b dt``, at most ``v dt / 2 + b dt^2 / 8``, and 0 at rest (a stopped ego
    does not roll)."""
    if v_mps <= 0.0:
        return 0.0
    m = math.ceil(v_mps / (brake_mps2 * dt_s)) - 1  # the last step with a positive start speed
    euler = dt_s * ((m + 1) * v_mps - brake_mps2 * dt_s * m * (m + 1) / 2.0)
    return max(euler - v_mps * v_mps / (2.0 * brake_mps2), 0.0)


def euler_shift(v_mps: float, a_mps2: float, brake_mps2: float, dt_s: float,
                v_max_mps: float) -> float:
    """How much further highway-env's Euler steps take a vehicle at ``v_mps`` that applies
    ``a_mps2`` for one step, then brakes at ``brake_mps2`` to rest, than the exact kinematics
    the shield certifies with [m] (module docstring).

    The Euler step moves ``v dt`` where the exact one moves the integral of the speed
    (clipped to ``[0, v_max]``), and from the new speed ``v'`` the Euler stop rolls
    :func:`euler_lead` ``(v')`` further. This is what the shield must add for the state after
    the step it admits: a lead of the *current* speed alone is too small after an
    acceleration from rest (0 at rest, but ``0.004 m`` after one step at 1 m/s^2), and a
    stopped ego then finds no fallback one step later."""
    v1 = min(max(v_mps + a_mps2 * dt_s, 0.0), v_max_mps)
    if a_mps2 == 0.0 or v1 == v_mps + a_mps2 * dt_s:
        exact = 0.5 * (v_mps + v1) * dt_s
    else:  # the speed reaches its bound within the step, then holds it
        t = (v1 - v_mps) / a_mps2
        exact = 0.5 * (v_mps + v1) * t + v1 * (dt_s - t)
    return v_mps * dt_s - exact + euler_lead(v1, brake_mps2, dt_s)


def duty_slack(config: Config) -> float:
    """How much further highway-env's Euler steps can roll another vehicle braking to rest
    than the exact stop, at most [m]: ``v_max dt / 2 + b dt^2 / 8`` (:func:`euler_lead`)
    at its ``v_max`` and strongest braking; the responsibility rule forgives that much of
    its position against the responsible envelope's stop (``DutyWatch.slack_m``)."""
    hv = config.vehicle_of("hv")
    dt = 1.0 / FREQUENCY_HZ
    return 0.5 * hv.v_max_mps * dt - hv.u_min_mps2 * dt * dt / 8.0


def euler_margin(config: Config) -> float:
    """``v_max dt / 2`` [m]: how much further highway-env's Euler step lets the ego roll
    than the exact step, at most (module docstring)."""
    return 0.5 * config.vehicle_of("av").v_max_mps / FREQUENCY_HZ


def clear_distance(config: Config) -> float:
    """Where a vehicle has cleared the conflict of the planner's scenario [m] (7.5)."""
    from ..record import static_setup

    return float(static_setup(config)[0].hv.clear_s)


def install_default_ego(env) -> Any:
    """Replace the ego by one of highway-env's own ``IDMVehicle`` (module docstring; the
    traffic's class, :class:`ForwardIDMVehicle`, with the parameters the env sets on it)."""
    from highway_env import utils

    u = env.unwrapped
    old = u.vehicle
    ego = utils.class_from_path(u.config["other_vehicles_type"])(u.road, np.array(old.position, float), heading=old.heading,
                     speed=old.speed, target_lane_index=old.lane_index,
                     enable_lane_change=False)
    ego.plan_route_to(DESTINATION)
    u.road.vehicles[u.road.vehicles.index(old)] = ego
    u.controlled_vehicles = [ego]
    return ego


def _action(config: Config, accel: float) -> np.ndarray:
    """The ``ContinuousAction`` in ``[-1, 1]`` that highway-env maps to ``accel``."""
    veh = config.vehicle_of("av")
    lo, hi = veh.u_min_mps2, veh.u_max_mps2
    return np.array([2.0 * (accel - lo) / (hi - lo) - 1.0])


# -- episodes ------------------------------------------------------------------------------


@dataclass(frozen=True)
class EpisodeResult:
    """One episode of one driver (module docstring)."""

    seed: int
    driver: str  #: the planner's kind, or "default" (highway-env's IDM ego)
    collision: bool
    crossed: bool  #: the ego left the intersection's inner lane
    arrived: bool  #: highway-env's has_arrived at the end
    first: str  #: against the contested vehicles: "ego", "other", "mixed" or "none"
    ego_first: int  #: contested vehicles the ego reached the conflict point before
    other_first: int  #: contested vehicles that reached it before the ego
    contested: int  #: vehicles that contested the ego's crossing
    time_to_cross_s: float | None  #: when the ego left the inner lane [s]
    min_distance_m: float  #: minimum centre distance to any other vehicle [m]
    #: the same over the vehicles whose lanes enter the ego's path or that are in its lane
    #: (oncoming traffic passes 4 m beside the ego and sets ``min_distance_m``) [m]
    min_conflict_distance_m: float
    steps: int
    shield_interventions: int = 0  #: steps where the shield overrode the planner
    #: vehicle-steps in which another vehicle left the envelope the shield assumed for it
    #: (speed above its bound, or a speed change beyond its accelerations; 0 expected)
    envelope_excesses: int = 0
    max_envelope_excess_mps: float = 0.0  #: the largest such excess [m/s]
    #: the same per kind (:attr:`EnvelopeCheck.KINDS`)
    envelope_excess_kinds: dict = field(default_factory=dict)
    uncertified_steps: int = 0  #: steps where the shield had no certified choice
    #: the worst-case guarantee covered the episode: a planner ego with the worst-case shield,
    #: every step certified, every other vehicle inside the envelope the shield assumed and
    #: no crash between two other vehicles (:attr:`crash_stops`, :attr:`wrecks`)
    guarantee_held: bool = False
    #: vehicle-steps in which another vehicle, crashing into a third, lost more speed than
    #: its ``u_min`` allows (not a driver's braking: outside the envelope's assumption)
    crash_stops: int = 0
    #: other vehicles wrecked in a crash that was not the ego's (:class:`WreckCount`), with
    #: or without a speed loss beyond ``u_min``: a crash between two other vehicles is
    #: outside the guarantee's assumptions, and the shield sees each wreck as a standing
    #: obstacle from then on (:meth:`Projector.wreck_front`)
    wrecks: int = 0
    #: highway-env's own ego only (None for the planner), judged by the planner's shield it
    #: does not use: its steps, how many of them the shield would have admitted as they were
    #: driven (the acceleration of each step against the conflicts at its start, the
    #: stand-ins included), and whether it admits the step that took the ego into the
    #: intersection, past its entry line (None: it never entered); a ceiling on what that
    #: shield lets any planner do (issue 25 item 4)
    judged_steps: int | None = None
    judged_admitted: int | None = None
    entry_admitted: bool | None = None
    #: the episode's length as highway-env sets it (``duration``) [s]: a non-crossing
    #: episode's time to cross in the restricted mean (:meth:`HighwayReport.summary`)
    horizon_s: float = 13.0
    #: what the shield's overrides cost (issue 25 item 6, as in SUMO): the mean over the
    #: planner's steps of |applied - proposed| [m/s^2] (0 where admitted; 0 for the default)
    override_mps2: float = 0.0
    #: the responsibility rule (``av.shield = "responsibility"``, docs/method.md §12.13),
    #: for the planner and for highway-env's own ego alike: who is at fault for the
    #: episode's collision ("ego" or "other"; None: no collision, or another shield kind),
    #: and the vehicle-steps in which another vehicle broke its duty under the rule. The ego
    #: run into a wreck (which owes nothing): "wreck" when some step since that vehicle was
    #: wrecked had no certified answer (it came into the ego's way too late), "ego" when
    #: every step was certified against it
    fault: str | None = None
    duty_breaches: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class _Contest:
    ego_at: int | None = None
    other_at: int | None = None
    contested: bool = False


def run_episode(seed: int, driver: str = "persuasive", config: Config | None = None,
                frames: list | None = None, judge_class: type | None = None,
                planner_class: type | None = None) -> EpisodeResult:
    """One episode of highway-env's intersection with ``seed``.

    ``driver``: an AV kind (the planner drives the ego, :class:`PlannerDriver`) or
    ``"default"`` (highway-env's IDM ego, :func:`install_default_ego`). ``config``: the
    planner's (default :func:`planner_config` of ``driver``). ``frames``: a list that receives
    the ``rgb_array`` frames (after the reset and after each step). ``judge_class``: what
    judges highway-env's own ego (default :class:`DefaultJudge`; a subclass may judge it on
    other assumptions, ``benchmarks/highway_ceiling.py``). ``planner_class``: the adapter
    the planner drives through (default :class:`~persuasive.envs.external.ExternalPlanner`; a
    subclass may propose otherwise behind the same shield, ``benchmarks/highway_ceiling.py``).
    """
    if driver != DEFAULT_DRIVER:
        config = config if config is not None else planner_config(driver)
        driver = config.av.kind
    else:
        config = config if config is not None else planner_config()
    env = make_highway_env(config, render_mode="rgb_array" if frames is not None else None)
    try:
        env.reset(seed=seed)
        u = env.unwrapped
        network = u.road.network
        ego_lanes = ego_route(u)
        veh = u.vehicle
        projector = Projector(network, ego_lanes, (float(veh.LENGTH), float(veh.WIDTH)),
                              euler_margin(config), config.vehicle_of("av").v_max_mps)
        judge = None
        if driver == DEFAULT_DRIVER:
            install_default_ego(env)
            planner = None
            if config.shield != "off":
                judge = (judge_class or DefaultJudge)(config, seed, env)
        else:
            planner = PlannerDriver(config, seed, planner_class)
        if frames is not None:
            frames.append(env.render())
        contests: dict[int, _Contest] = {}
        state = {"min_d": math.inf, "min_conflict_d": math.inf, "cross": None}
        envelope = EnvelopeCheck(1.0 / FREQUENCY_HZ)
        wrecks = WreckCount(1.0 / FREQUENCY_HZ)

        def duty_watch():
            adapter = planner.planner if planner is not None else getattr(judge, "planner", None)
            return None if adapter is None else adapter.duties

        def observe(k: int) -> list[Projection]:
            ego = u.vehicle
            envelope.observe(u.road.vehicles, ego)
            watch = duty_watch()  # a wreck's mark: the ego's uncertified steps before it
            wrecks.observe(u.road.vehicles, ego, 0 if watch is None else watch.ego_breaches)
            projections = []
            for v in u.road.vehicles:
                if v is ego:
                    continue
                d = float(np.linalg.norm(np.asarray(v.position) - np.asarray(ego.position)))
                state["min_d"] = min(state["min_d"], d)
                p = projector.project(v, ego)
                if p is not None or projector.in_ego_lane(v):
                    state["min_conflict_d"] = min(state["min_conflict_d"], d)
                if p is None:
                    continue
                projections.append(p)
                c = contests.setdefault(id(p.track), _Contest())
                if -CONTEST_RANGE_M <= p.ego_s_m <= 0.0 and -CONTEST_RANGE_M <= p.other_s_m <= 0.0:
                    c.contested = True
                if c.ego_at is None and p.ego_s_m >= 0.0:
                    c.ego_at = k
                if c.other_at is None and p.other_s_m >= 0.0:
                    c.other_at = k
            if state["cross"] is None and projector.ego.coordinates(ego.position)[0] >= \
                    projector.ego.exit_u_m:
                state["cross"] = k
            return projections

        projections = observe(0)
        k, terminated, truncated = 0, False, False
        while not (terminated or truncated):
            accel = 0.0 if planner is None else planner.act(env, projector)
            if judge is not None:
                judge.before(env, projector)
            _, _, terminated, truncated, _ = env.step(_action(config, accel))
            if judge is not None:
                judge.after(env, projector)
            k += 1
            if frames is not None:
                frames.append(env.render())
            projections = observe(k)
        ego = u.vehicle
        duties = duty_watch()
        fault = duties.fault() if duties is not None and ego.crashed else None
        if fault is not None and wrecks.hit:  # a wreck owes nothing (EpisodeResult.fault)
            fault = "wreck" if duties.ego_breaches > min(wrecks.hit) else "ego"
        ego_first = other_first = contested = 0
        for c in contests.values():
            if not c.contested:
                continue
            contested += 1
            if c.ego_at is None and c.other_at is None:
                continue
            if c.other_at is None or (c.ego_at is not None and c.ego_at < c.other_at):
                ego_first += 1
            elif c.ego_at is None or c.other_at < c.ego_at:
                other_first += 1
        first = "none"
        if ego_first and other_first:
            first = "mixed"
        elif ego_first:
            first = "ego"
        elif other_first:
            first = "other"
        dt = 1.0 / FREQUENCY_HZ
        return EpisodeResult(
            seed=int(seed), driver=driver, collision=bool(ego.crashed),
            crossed=state["cross"] is not None, arrived=bool(u.has_arrived(ego)), first=first,
            ego_first=ego_first, other_first=other_first, contested=contested,
            time_to_cross_s=None if state["cross"] is None else round(state["cross"] * dt, 10),
            min_distance_m=float(state["min_d"]),
            min_conflict_distance_m=float(state["min_conflict_d"]), steps=k,
            shield_interventions=0 if planner is None else planner.interventions,
            envelope_excesses=envelope.excesses,
            max_envelope_excess_mps=envelope.max_excess_mps,
            envelope_excess_kinds=dict(envelope.kinds),
            uncertified_steps=0 if planner is None else planner.uncertified,
            guarantee_held=bool(planner is not None and config.shield == "worst-case"
                                and planner.uncertified == 0 and envelope.excesses == 0
                                and envelope.crash_stops == 0 and wrecks.wrecks == 0),
            crash_stops=envelope.crash_stops, wrecks=wrecks.wrecks,
            judged_steps=None if judge is None else judge.steps,
            judged_admitted=None if judge is None else judge.admitted,
            entry_admitted=None if judge is None else judge.entry_admitted,
            horizon_s=float(u.config["duration"]),
            override_mps2=0.0 if planner is None or not planner.steps
            else planner.override_sum / planner.steps,
            fault=fault, duty_breaches=0 if duties is None else duties.other_breaches)
    finally:
        env.close()


@dataclass(frozen=True)
class HighwayReport:
    """Episodes of the planner and of highway-env's default ego on the same seeds."""

    env_id: str
    planner: str
    seeds: tuple[int, ...]
    episodes: tuple[EpisodeResult, ...]
    shield: str = "off"  #: the planner's safety shield

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per driver: counts of collisions, crossings, arrivals and of who went first; the
        mean time to cross (over crossing episodes) and the smallest and median minimum
        distance."""
        out = {}
        for driver in (self.planner, DEFAULT_DRIVER):
            eps = [e for e in self.episodes if e.driver == driver]
            times = [e.time_to_cross_s for e in eps if e.time_to_cross_s is not None]
            dists = [e.min_distance_m for e in eps]
            conflict = [e.min_conflict_distance_m for e in eps]
            out[driver] = {
                "episodes": len(eps),
                "collisions": sum(e.collision for e in eps),
                "crossed": sum(e.crossed for e in eps),
                "arrived": sum(e.arrived for e in eps),
                "ego_first": sum(e.ego_first for e in eps),
                "other_first": sum(e.other_first for e in eps),
                "mean_time_to_cross_s": float(np.mean(times)) if times else None,
                # over every episode, one that never crossed counted at the episode's length:
                # a mean over the crossing ones alone rewards failing the hard ones
                "restricted_mean_time_to_cross_s": restricted_mean(
                    [e.time_to_cross_s for e in eps], [e.horizon_s for e in eps]),
                "override_mps2_mean": float(np.mean([e.override_mps2 for e in eps]))
                if eps else None,
                "min_distance_m": float(np.min(dists)) if dists else None,
                "median_min_distance_m": float(np.median(dists)) if dists else None,
                "min_conflict_distance_m": float(np.min(conflict)) if conflict else None,
                "median_min_conflict_distance_m": float(np.median(conflict)) if conflict
                else None,
                "shield_interventions": sum(e.shield_interventions for e in eps),
                "envelope_excesses": sum(e.envelope_excesses for e in eps),
                "max_envelope_excess_mps": max((e.max_envelope_excess_mps for e in eps),
                                               default=0.0),
                "envelope_excess_kinds": {k: sum(e.envelope_excess_kinds.get(k, 0) for e in eps)
                                          for k in EnvelopeCheck.KINDS},
                "crash_stops": sum(e.crash_stops for e in eps),
                "crash_stop_episodes": sum(e.crash_stops > 0 for e in eps),
                "wrecks": sum(e.wrecks for e in eps),
                "wreck_episodes": sum(e.wrecks > 0 for e in eps),
                "uncertified_steps": sum(e.uncertified_steps for e in eps),
                "guarantee_held_episodes": sum(e.guarantee_held for e in eps),
            }
            if self.shield == "responsibility":  # the rule's fault and duties
                out[driver].update({
                    "collisions_ego_at_fault": sum(e.fault == "ego" for e in eps),
                    "collisions_other_at_fault": sum(e.fault == "other" for e in eps),
                    "collisions_wreck_at_fault": sum(e.fault == "wreck" for e in eps),
                    "duty_breaches": sum(e.duty_breaches for e in eps)})
            judged = [e for e in eps if e.judged_steps is not None]
            if judged:  # highway-env's own ego, judged by the planner's shield
                steps = sum(e.judged_steps for e in judged)
                out[driver].update({
                    "entries_judged": sum(e.entry_admitted is not None for e in judged),
                    "entries_admitted": sum(bool(e.entry_admitted) for e in judged),
                    "steps_admitted_pct": 100.0 * sum(e.judged_admitted for e in judged)
                    / max(1, steps)})
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"env_id": self.env_id, "planner": self.planner, "shield": self.shield,
                "seeds": list(self.seeds),
                "episodes": [e.to_dict() for e in self.episodes], "summary": self.summary()}


def run_highway(episodes: int = 5, planner: str = "persuasive", seed: int = 1,
                frames: list | None = None, shield: str | None = None) -> HighwayReport:
    """``episodes`` episodes (seeds ``seed .. seed + episodes - 1``), each driven by the
    planner (``shield``: its safety shield, default worst-case) and by highway-env's default
    ego. ``frames`` receives the frames of the planner's first episode."""
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ConfigError(f"--episodes = {episodes!r} is out of range; allowed: integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**31 - episodes:
        raise ConfigError(f"--seed = {seed!r} is out of range; allowed: integer in "
                          f"[0, 2^31 - episodes)")
    config = planner_config(planner, shield)
    seeds = tuple(range(seed, seed + episodes))
    results = []
    for i, s in enumerate(seeds):
        results.append(run_episode(s, config.av.kind, config, frames if i == 0 else None))
        results.append(run_episode(s, DEFAULT_DRIVER, config))
    return HighwayReport(highway_env_id(), config.av.kind, seeds, tuple(results), config.shield)


def write_video(frames: list[np.ndarray], path: str | Path, fps: int = FREQUENCY_HZ) -> Path:
    """Write frames as MP4 (H.264) or GIF, by extension, atomically (as ``persuasive
    animate``: :func:`persuasive.plots.files.write_frames`)."""
    from ..plots.files import write_frames

    return write_frames(frames, path, fps)


__all__ = ["CONTEST_RANGE_M", "EgoPath", "EpisodeResult", "HighwayReport", "PlannerDriver",
           "Projection", "Projector", "find_conflict", "highway_env_id", "install_default_ego",
           "make_highway_env", "planner_config", "run_episode", "run_highway", "write_video"]
