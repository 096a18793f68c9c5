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

import math
from dataclasses import dataclass, field, replace
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
    return RoadMap(name, (lat, lon), lmap, row, stop)


def lanelets_at(road_map: RoadMap, x: np.ndarray, y: np.ndarray) -> set[int]:
    """The IDs of the lanelets that contain any of the points ``(x, y)`` [m]."""
    from lanelet2.core import BasicPoint2d
    from lanelet2.geometry import findWithin2d

    found: set[int] = set()
    layer = road_map.lanelets.laneletLayer
    for px, py in zip(np.asarray(x, float), np.asarray(y, float)):
        for _, ll in findWithin2d(layer, BasicPoint2d(float(px), float(py)), 0.0):
            found.add(int(ll.id))
    return found


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
    """The pairs (``persuasive.recordings.pairs.Pair``) with their rule from ``road_map``."""
    out = []
    for p in pairs:
        control, priority, stops = pair_rule(road_map, p.s, p.x, p.y,
                                             np.asarray(p.occupancy, float))
        out.append(replace(p, control=control, priority=priority, stop_s=stops))
    return out


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


__all__ = ["APPROACH_M", "CONTROLS", "MAP_RULES", "RoadMap", "annotate_pairs", "check_origin",
           "lanelets_at", "pair_rule", "read_map", "stop_line_s", "write_map"]
