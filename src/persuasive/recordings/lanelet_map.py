"""Lanelet2 maps: the rule of a junction for each pair, from the map where one is given
(docs/guide/recordings.md, "Maps").

INTERACTION ships a Lanelet2 map (``.osm``) per location; inD ships one per site. The map is
read with the ``lanelet2`` package (the library Lanelet2's authors publish; ``pip install
'persuasive[maps]'``), projected with its ``UtmProjector`` from an origin (INTERACTION's maps:
latitude and longitude 0, its devkit's default; inD: the recording's ``latLocation`` and
``lonLocation``), so that the map's metres are the track files' metres.

**Which lanelets a vehicle drove.** The lanelets that contain (``lanelet2.geometry.
findWithin2d`` at distance 0) the vehicle's smoothed centre at its steps before its
occupancy interval and at most :data:`APPROACH_M` before the conflict point: its approach,
where its footprint cannot yet touch the other's path (inside the junction the lanelets of
other directions overlap its own).

**The rule of a pair** (:func:`pair_rule`), from the regulatory elements of those lanelets:

- ``right_of_way`` (Lanelet2's ``RightOfWay``): a vehicle has the right of way when one of its
  lanelets is one of an element's right-of-way lanelets and one of the other's is a yield
  lanelet of the same element; ``priority`` is 1 or 2 (the vehicle of the pair). An element
  that would give it to both (a map that contradicts itself for these lanelets) gives
  ``none``;
- ``all_way_stop`` (``AllWayStop``): both vehicles' lanelets are in one element; ``priority``
  0, and each vehicle's stop line, where its path crosses the stop line of its lanelet in the
  element (``stop_1_m``, ``stop_2_m``: ``s`` relative to the conflict point; NaN where the map
  gives none or the path does not cross it);
- ``none``: the map has no rule between their lanelets (or neither vehicle is on a lanelet);
- ``unknown``: no map was given (pairs files written without ``--map``).

A right-of-way element is taken before an all-way stop when both apply. The baselines of the
held-out evaluation read the rule (``persuasive.recordings.baselines``): the map's right of
way where it gives one, arrival order at its stop line at an all-way stop, else right before
left from the approach.

:func:`write_map` writes the map of one of the project's scenarios (a lanelet per path, its
lane width wide, and the rule), so that the fixtures of ``recordings export --map-rule`` are
licence-clean files in Lanelet2's format.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from .formats import RecordingError, file_head

#: The rules a pair can have (module docstring).
CONTROLS = ("unknown", "none", "right_of_way", "all_way_stop")
#: How far before the conflict point a vehicle's approach is read [m].
APPROACH_M = 50.0
#: At most this many approach points per vehicle are looked up [-].
APPROACH_POINTS = 12
#: The rules ``recordings export --map-rule`` writes: the AV's right of way, the HV's, or an
#: all-way stop (stop lines at each path's yield line).
MAP_RULES = ("av", "hv", "all-way-stop")


def _lanelet2():
    try:
        import lanelet2  # noqa: F401 - the package's submodules are read below
        import lanelet2.core  # noqa: F401
        import lanelet2.geometry  # noqa: F401
        import lanelet2.io  # noqa: F401
        import lanelet2.projection  # noqa: F401
    except ImportError:
        raise RecordingError("reading or writing a Lanelet2 map needs the lanelet2 package "
                             "(pip install 'persuasive[maps]'; wheels for Python 3.11-3.13)"
                             ) from None
    return lanelet2


def check_origin(origin: Sequence[float]) -> tuple[float, float]:
    """The map's projection origin ``(lat, lon)`` [deg]; :class:`RecordingError` when it is not
    one."""
    if len(origin) != 2:
        raise RecordingError(f"map origin = {tuple(origin)!r} is out of range; allowed: LAT,LON "
                             "in degrees")
    lat, lon = (float(v) for v in origin)
    if not (math.isfinite(lat) and -80.0 <= lat <= 84.0 and math.isfinite(lon)
            and -180.0 <= lon <= 180.0):
        raise RecordingError(f"map origin = {lat:g},{lon:g} is out of range; allowed: latitude "
                             "in [-80, 84] and longitude in [-180, 180] degrees (UTM)")
    return lat, lon


@dataclass(frozen=True)
class RoadMap:
    """A Lanelet2 map as the pairs read it: the map, and per lanelet ID its rules."""

    path: str
    origin: tuple[float, float]
    lanelets: object = field(repr=False)  #: the ``lanelet2.core.LaneletMap``
    #: lanelet ID -> [(element ID, "right_of_way" or "yield")]
    right_of_way: dict = field(repr=False, default_factory=dict)
    #: lanelet ID -> [(element ID, stop line (k, 2) [m] or None)]
    all_way_stop: dict = field(repr=False, default_factory=dict)
    #: per lanelet ``(ID, polygon (k, 2) [m], simple)``, as the map's point queries test it
    #: (:func:`lanelet_shapes`; empty: :func:`annotate_pairs` asks lanelet2 for every point)
    shapes: tuple = field(repr=False, default=())

    @property
    def n_lanelets(self) -> int:
        return len(self.lanelets.laneletLayer)


def read_map(path: str | Path, origin: Sequence[float] = (0.0, 0.0)) -> RoadMap:
    """Read a Lanelet2 map (``.osm``), projected from ``origin`` ``(lat, lon)`` [deg];
    :class:`RecordingError` (one line naming the file) when it cannot be read or holds no
    lanelet."""
    lanelet2 = _lanelet2()
    from lanelet2.core import AllWayStop, RightOfWay

    lat, lon = check_origin(origin)
    name = str(path)
    p = Path(path)
    if b"<osm" not in file_head(p, 512, "map file"):
        raise RecordingError(f"map file {name!r} is not a Lanelet2 map (an OSM XML file, "
                             "<osm ...>)")
    projector = lanelet2.projection.UtmProjector(lanelet2.io.Origin(lat, lon))
    try:
        lmap, errors = lanelet2.io.loadRobust(str(p), projector)
    except Exception as exc:  # noqa: BLE001 - the C++ reader raises several kinds
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RecordingError(f"map file {name!r} cannot be read: {text}") from None
    if len(lmap.laneletLayer) == 0:
        detail = f" ({errors[0]})" if errors else ""
        raise RecordingError(f"map file {name!r} holds no lanelet{detail}")
    row: dict[int, list] = {}
    stop: dict[int, list] = {}
    for element in lmap.regulatoryElementLayer:
        if isinstance(element, RightOfWay):
            for ll in element.rightOfWayLanelets():
                row.setdefault(ll.id, []).append((element.id, "right_of_way"))
            for ll in element.yieldLanelets():
                row.setdefault(ll.id, []).append((element.id, "yield"))
        elif isinstance(element, AllWayStop):
            lanelets = list(element.lanelets())
            lines = list(element.stopLines())
            for j, ll in enumerate(lanelets):
                line = lines[j] if len(lines) == len(lanelets) else None
                xy = None if line is None else np.array([[q.x, q.y] for q in line], float)
                stop.setdefault(ll.id, []).append((element.id, xy))
    return RoadMap(name, (lat, lon), lmap, row, stop, lanelet_shapes(lmap))


#: Points within this of a lanelet's boundary [m] are left to lanelet2
#: (:func:`lanelets_of_points`): far above the rounding of coordinates of a few hundred m.
BOUNDARY_M = 1e-6


def lanelet_shapes(lanelet_map) -> tuple:
    """Per lanelet of ``lanelet_map`` (a ``lanelet2.core.LaneletMap``): ``(ID, polygon,
    simple)``, the polygon ``(k, 2)`` [m] being the lanelet's ``polygon2d()`` (its left
    bound, then its right bound backwards), the one lanelet2's ``findWithin2d`` measures a
    point's distance to; ``simple``: at least 3 vertices, no edge shorter than
    :data:`BOUNDARY_M`, and no two edges that do not follow each other within
    :data:`BOUNDARY_M` of each other (its inside is then the same by every rule)."""
    shapes = []
    for ll in lanelet_map.laneletLayer:
        poly = np.array([[q.x, q.y] for q in ll.polygon2d()], float).reshape(-1, 2)
        shapes.append((int(ll.id), poly, _simple(poly)))
    return tuple(shapes)


def _simple(poly: np.ndarray) -> bool:
    k = poly.shape[0]
    if k < 3:
        return False
    a, b = poly, np.roll(poly, -1, axis=0)
    if np.any(np.hypot(*(b - a).T) <= BOUNDARY_M):
        return False
    for i in range(k):
        for j in range(i + 2, k):
            if i == 0 and j == k - 1:
                continue  # the closing edge follows the first
            if _segment_gap(a[i], b[i], a[j], b[j]) <= BOUNDARY_M:
                return False
    return True


def _segment_gap(p0, p1, q0, q1) -> float:
    """The distance between segments ``p0 p1`` and ``q0 q1`` [m] (0 when they cross)."""
    d1, d2, r = p1 - p0, q1 - q0, q0 - p0
    den = d1[0] * d2[1] - d1[1] * d2[0]
    if den != 0.0:
        t = (r[0] * d2[1] - r[1] * d2[0]) / den
        u = (r[0] * d1[1] - r[1] * d1[0]) / den
        if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0:
            return 0.0
    return float(min(_point_gap(p0, q0[None], q1[None])[0], _point_gap(p1, q0[None], q1[None])[0],
                     _point_gap(q0, p0[None], p1[None])[0], _point_gap(q1, p0[None], p1[None])[0]))


def _point_gap(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances [m] from points ``q`` (..., 2) to the segments ``a b`` (each (..., 2))."""
    d = b - a
    den = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        t = ((q[..., 0] - a[..., 0]) * d[..., 0] + (q[..., 1] - a[..., 1]) * d[..., 1]) / den
    t = np.clip(np.where(den > 0.0, t, 0.0), 0.0, 1.0)
    return np.hypot(a[..., 0] + t * d[..., 0] - q[..., 0], a[..., 1] + t * d[..., 1] - q[..., 1])


def lanelets_of_points(road_map: RoadMap, points: np.ndarray) -> list:
    """Per point ``(x, y)`` [m] of ``points`` (m, 2): the IDs of the lanelets that contain
    it, as a set, or None where it is left to lanelet2 (:func:`lanelets_at`).

    lanelet2's ``findWithin2d`` at distance 0 keeps the lanelets whose bounding box holds
    the point and whose polygon is at distance 0 from it (inside, or on its boundary). Here
    that test is made without lanelet2 where its answer cannot depend on rounding: the
    point's distance to every edge of the polygon is more than :data:`BOUNDARY_M` and the
    polygon is simple, so inside by the even-odd count of a ray's crossings is inside by any
    rule (lanelet2's included) and no point on the boundary is in question. A point within
    :data:`BOUNDARY_M` of an edge, or in the box of a polygon that is not simple, is None."""
    points = np.asarray(points, float).reshape(-1, 2)
    found = [set() for _ in range(points.shape[0])]
    unsure = np.zeros(points.shape[0], bool)
    for ident, poly, simple in road_map.shapes:
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        at = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
        if not at.size:
            continue
        if not simple:
            unsure[at] = True
            continue
        q = points[at][:, None, :]  # (n, 1, 2) against the edges (1, k, 2)
        a, b = poly[None], np.roll(poly, -1, axis=0)[None]
        near = _point_gap(q, a, b).min(axis=1) <= BOUNDARY_M
        qy, qx = q[..., 1], q[..., 0]
        crosses = (a[..., 1] > qy) != (b[..., 1] > qy)
        with np.errstate(invalid="ignore", divide="ignore"):
            x_at = a[..., 0] + (qy - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
        inside = np.count_nonzero(crosses & (qx < x_at), axis=1) % 2 == 1
        unsure[at[near]] = True
        for i in at[inside & ~near].tolist():
            found[i].add(ident)
    return [None if u else f for f, u in zip(found, unsure.tolist())]


def lanelets_at(road_map: RoadMap, x: np.ndarray, y: np.ndarray) -> set[int]:
    """The IDs of the lanelets that contain any of the points ``(x, y)`` [m]."""
    found: set[int] = set()
    for point in zip(np.asarray(x, float).tolist(), np.asarray(y, float).tolist()):
        found.update(_lanelets_at_point(road_map, point))
    return found


def _lanelets_at_point(road_map: RoadMap, point: tuple[float, float]) -> tuple[int, ...]:
    """The IDs of the lanelets that contain the point ``(x, y)`` [m] (``findWithin2d`` at
    distance 0)."""
    from lanelet2.core import BasicPoint2d
    from lanelet2.geometry import findWithin2d

    return tuple(int(ll.id) for _, ll in findWithin2d(road_map.lanelets.laneletLayer,
                                                      BasicPoint2d(*point), 0.0))


def approach_points(s: np.ndarray, x: np.ndarray, y: np.ndarray, occ_lo: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """A vehicle's approach (module docstring): at most :data:`APPROACH_POINTS` of its steps
    with ``-APPROACH_M <= s < occ_lo``, evenly spread."""
    idx = np.flatnonzero((s >= -APPROACH_M) & (s < min(occ_lo, 0.0)))
    if idx.size > APPROACH_POINTS:
        idx = idx[np.linspace(0, idx.size - 1, APPROACH_POINTS).round().astype(int)]
    return x[idx], y[idx]


def stop_line_s(s: np.ndarray, x: np.ndarray, y: np.ndarray, line: np.ndarray) -> float:
    """Where the path through ``(x, y)`` (with ``s`` at its points) first crosses the polyline
    ``line`` ``(k, 2)``: ``s`` there [m], NaN where it does not."""
    p0 = np.stack([x[:-1], y[:-1]], axis=1)
    d = np.stack([np.diff(x), np.diff(y)], axis=1)
    best = math.inf
    for a, b in zip(line[:-1], line[1:]):
        e = b - a
        den = d[:, 0] * e[1] - d[:, 1] * e[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            w = a[None, :] - p0
            t = (w[:, 0] * e[1] - w[:, 1] * e[0]) / den
            u = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / den
        hit = np.flatnonzero((den != 0.0) & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0))
        if hit.size:
            j = int(hit[0])
            best = min(best, float(s[j] + t[j] * (s[j + 1] - s[j])))
    return best if math.isfinite(best) else math.nan


def pair_rule(road_map: RoadMap, s: np.ndarray, x: np.ndarray, y: np.ndarray,
              occupancy: np.ndarray) -> tuple[str, int, tuple[float, float]]:
    """``(control, priority, (stop_1, stop_2))`` of a pair (module docstring) from its steps:
    ``s, x, y`` ``(2, n)`` [m] per vehicle, ``occupancy`` ``(2, 2)`` [m]."""
    lanes = [lanelets_at(road_map, *approach_points(s[i], x[i], y[i], occupancy[i, 0]))
             for i in range(2)]
    return _rule_of_lanes(road_map, lanes, s, x, y)


def _rule_of_lanes(road_map: RoadMap, lanes: Sequence[set[int]], s: np.ndarray,
                   x: np.ndarray, y: np.ndarray) -> tuple[str, int, tuple[float, float]]:
    """:func:`pair_rule` from the lanelets of each vehicle's approach ``lanes``."""
    rules = [{(e, role) for ll in lanes[i] for e, role in road_map.right_of_way.get(ll, ())}
             for i in range(2)]
    has = [{e for e, role in rules[i] if role == "right_of_way"} for i in range(2)]
    owes = [{e for e, role in rules[i] if role == "yield"} for i in range(2)]
    first = bool(has[0] & owes[1])
    second = bool(has[1] & owes[0])
    if first != second:
        return "right_of_way", 1 if first else 2, (math.nan, math.nan)
    stops = [{e: line for ll in lanes[i] for e, line in road_map.all_way_stop.get(ll, ())}
             for i in range(2)]
    shared = sorted(set(stops[0]) & set(stops[1]))
    if shared and not (first and second):
        e = shared[0]
        where = tuple(math.nan if stops[i][e] is None or len(stops[i][e]) < 2
                      else stop_line_s(s[i], x[i], y[i], stops[i][e]) for i in range(2))
        return "all_way_stop", 0, where
    return "none", 0, (math.nan, math.nan)


def annotate_pairs(pairs: Sequence, road_map: RoadMap) -> list:
    """The pairs (``persuasive.recordings.pairs.Pair``) with their rule from ``road_map``, as
    :func:`pair_rule` gives it for each.

    The approach points of all pairs are chosen at once (:func:`approach_indices`) and each
    distinct point is classified once (a vehicle's approach points recur among its pairs: on
    a site-size recording 43 % of them are distinct), without lanelet2 where the answer is
    certain (:func:`lanelets_of_points`). A vehicle's lanelets are taken point by point from
    lanelet2 itself, in :func:`pair_rule`'s order, where one of its points is left to
    lanelet2, and where two of its lanelets share an all-way stop (which of their stop lines
    :func:`pair_rule` reads depends on that order)."""
    if not pairs:
        return []
    n = np.array([p.n_steps for p in pairs], np.int64)
    approach = []  # per vehicle: per pair, its approach points [(x, y)]
    for i in range(2):
        s = np.concatenate([p.s[i] for p in pairs])
        idx, per_pair = approach_indices(s, n, [p.occupancy[i][0] for p in pairs])
        x = np.concatenate([p.x[i] for p in pairs])[idx].tolist()
        y = np.concatenate([p.y[i] for p in pairs])[idx].tolist()
        ends = np.cumsum(per_pair).tolist()
        approach.append([list(zip(x[e - c:e], y[e - c:e]))
                         for e, c in zip(ends, per_pair.tolist())])
    distinct = list(dict.fromkeys(q for vehicle in approach for points in vehicle
                                  for q in points))
    sure = dict(zip(distinct, lanelets_of_points(road_map, np.array(distinct, float))
                    if road_map.shapes and distinct else [None] * len(distinct)))
    asked: dict[tuple[float, float], tuple[int, ...]] = {}  # lanelet2's answers

    def plain(points: list) -> set[int]:
        found: set[int] = set()
        for point in points:
            ids = asked.get(point)
            if ids is None:
                ids = asked[point] = _lanelets_at_point(road_map, point)
            found.update(ids)
        return found

    def lanes_of(points: list) -> set[int]:
        found: set[int] = set()
        for point in points:
            ids = sure[point]
            if ids is None:
                return plain(points)
            found |= ids
        stops = [e for ll in found for e, _ in road_map.all_way_stop.get(ll, ())]
        return plain(points) if len(stops) != len(set(stops)) else found

    out = []
    for k, p in enumerate(pairs):
        lanes = [lanes_of(approach[i][k]) for i in range(2)]
        control, priority, stops = _rule_of_lanes(road_map, lanes, p.s, p.x, p.y)
        out.append(_with_rule(p, control, priority, stops))
    return out


def _with_rule(pair, control: str, priority: int, stops: tuple[float, float]):
    """``dataclasses.replace(pair, control=..., priority=..., stop_s=...)`` for a pair (a
    frozen dataclass without ``__post_init__``): a copy with the three fields set, without
    ``replace``'s call of ``__init__`` with every field (a tenth of the map's time)."""
    out = copy.copy(pair)
    object.__setattr__(out, "control", control)
    object.__setattr__(out, "priority", priority)
    object.__setattr__(out, "stop_s", stops)
    return out


def approach_indices(s: np.ndarray, n: np.ndarray, occ_lo) -> tuple[np.ndarray, np.ndarray]:
    """:func:`approach_points` of several vehicles at once: their positions ``s`` [m] one
    after the other, ``n[k]`` of vehicle ``k``, with occupancy starts
    ``occ_lo[k]`` [m]. Returns the indices into ``s`` of all their approach points, vehicle
    after vehicle, and how many each has (the same points as :func:`approach_points`: the
    steps with ``-APPROACH_M <= s < min(occ_lo, 0)``, spread as ``np.linspace(0, m - 1,
    APPROACH_POINTS).round()`` of their ``m`` when more)."""
    upper = np.repeat(np.minimum(np.asarray(occ_lo, float), 0.0), n)
    mask = (s >= -APPROACH_M) & (s < upper)
    at = np.flatnonzero(mask)
    below = np.concatenate([[0], np.cumsum(mask)])
    end = np.cumsum(n)
    m = below[end] - below[end - n]  # vehicle k's steps in its approach
    first = np.cumsum(m) - m  # where vehicle k's points begin in `at`
    spread = m > APPROACH_POINTS
    # np.linspace(0, m - 1, APPROACH_POINTS) as numpy makes it: k * step, the last m - 1
    grid = np.arange(APPROACH_POINTS, dtype=float)[None, :] * (
        (m[spread] - 1).astype(float) / (APPROACH_POINTS - 1))[:, None]
    grid[:, -1] = m[spread] - 1
    take = np.minimum(m, APPROACH_POINTS)
    local = np.arange(int(take.sum())) - np.repeat(np.cumsum(take) - take, take)
    local[np.repeat(spread, take)] = grid.round().astype(np.int64).ravel()
    return at[np.repeat(first, take) + local], take


def _line(points: np.ndarray, attributes: dict):
    from lanelet2.core import AttributeMap, LineString3d, Point3d, getId

    return LineString3d(getId(), [Point3d(getId(), float(px), float(py), 0.0)
                                  for px, py in points], AttributeMap(attributes))


def write_map(path: str | Path, scenario, rule: str, origin: Sequence[float] = (0.0, 0.0),
              margin_m: float = 60.0) -> None:
    """Write the Lanelet2 map of ``scenario`` (a ``persuasive.scenarios`` scenario) to
    ``path``: a lanelet per vehicle's path, from ``margin_m`` before its yield line to
    ``margin_m`` past its clearing point, ``scenario.lane_width_m`` wide, and the rule
    ``rule`` (:data:`MAP_RULES`): the AV's lanelet has the right of way over the HV's
    (``"av"``), the reverse (``"hv"``), or an all-way stop with a stop line across each lanelet
    at its path's yield line. Projected from ``origin`` as :func:`read_map` reads it."""
    lanelet2 = _lanelet2()
    from lanelet2.core import (AllWayStop, AttributeMap, Lanelet, LaneletMap,
                               LaneletWithStopLine, RightOfWay, getId)

    if rule not in MAP_RULES:
        raise RecordingError(f"map rule = {rule!r} is out of range; allowed: "
                             f"{', '.join(MAP_RULES)}")
    lat, lon = check_origin(origin)
    half = scenario.lane_width_m / 2.0
    lanes, stops = {}, {}
    for who in ("av", "hv"):
        path_of = getattr(scenario, who)
        s = np.arange(path_of.yield_s - margin_m, path_of.clear_s + margin_m + 1e-9, 1.0)
        x, y, heading = (np.asarray(v, float) for v in scenario.positions(who, s))
        nx, ny = -np.sin(heading), np.cos(heading)
        left = _line(np.stack([x + half * nx, y + half * ny], 1),
                     {"type": "line_thin", "subtype": "solid"})
        right = _line(np.stack([x - half * nx, y - half * ny], 1),
                      {"type": "line_thin", "subtype": "solid"})
        lanes[who] = Lanelet(getId(), left, right,
                             AttributeMap({"type": "lanelet", "subtype": "road",
                                           "location": "urban", "one_way": "yes"}))
        sx, sy, sh = (float(np.asarray(v).ravel()[0])
                      for v in scenario.positions(who, np.array([path_of.yield_s])))
        ux, uy = -math.sin(sh), math.cos(sh)
        stops[who] = _line(np.array([[sx + half * ux, sy + half * uy],
                                     [sx - half * ux, sy - half * uy]]), {"type": "stop_line"})
    attrs = AttributeMap({"type": "regulatory_element"})
    if rule == "all-way-stop":
        attrs["subtype"] = "all_way_stop"
        element = AllWayStop(getId(), attrs, [LaneletWithStopLine(lanes[w], stops[w])
                                              for w in ("av", "hv")])
    else:
        attrs["subtype"] = "right_of_way"
        winner, loser = ("av", "hv") if rule == "av" else ("hv", "av")
        element = RightOfWay(getId(), attrs, [lanes[winner]], [lanes[loser]])
    lmap = LaneletMap()
    for who in ("av", "hv"):
        lanes[who].addRegulatoryElement(element)
        lmap.add(lanes[who])
    projector = lanelet2.projection.UtmProjector(lanelet2.io.Origin(lat, lon))
    lanelet2.io.write(str(path), lmap, projector)


__all__ = ["APPROACH_M", "BOUNDARY_M", "CONTROLS", "MAP_RULES", "RoadMap", "annotate_pairs",
           "approach_indices", "check_origin", "lanelet_shapes", "lanelets_at",
           "lanelets_of_points", "pair_rule", "read_map", "stop_line_s", "write_map"]
