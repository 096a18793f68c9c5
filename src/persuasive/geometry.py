"""Paths, the distance between two vehicles on them, and footprint collisions (docs/method.md §10).

Each vehicle moves along its own **path**, a curve in the plane parameterised by arc length:
``s`` [m] is the signed distance along the path to the path's reference point (negative
before it), as in the paper's intersection. A path is at most three pieces:

- a straight line before ``b1`` (direction ``u0``, through ``p1 = xy(b1)``);
- a circular arc from ``b1`` to ``b2`` (centre ``c``, radius ``r``, polar angle ``phi1`` of
  ``p1`` seen from ``c``, turning left (+1) or right (-1)); absent when ``r == 0``;
- a straight line after ``b2`` (direction ``u2``, through ``p2 = xy(b2)``).

Straight directions are stored as unit vectors, not angles, so that the axis directions are
exact (``(1, 0)``, ``(0, 1)``) and a straight path adds and multiplies nothing it need not.

The **conflict** between two paths decides the distance the game and the safety checks use
(``persuasive.packing.CONFLICT_*``): ``ALONG_PATHS`` combines each vehicle's distance along its
path to the conflict point, ``sqrt(s_a^2 + s_b^2)`` (the paper's intersection, where it is the
distance between the centres, and the left turn, where the centres of two oncoming vehicles in
adjacent lanes must not count as close); ``EUCLIDEAN`` (angled crossings, the merge) the
distance between the vehicles' centres ``xy(s)``. Both are compared with the exact threshold of
:func:`persuasive.packing.sqrt_threshold`.

A **zone** is a conservative interval of positions per path outside which the vehicle is at
least ``min_dist`` from every point of the other path (:func:`zone_interval`); the kernels
only test pairs of samples inside it, so it may be a superset but never miss a sample.

Collisions of the run's outcome are overlaps of the vehicles' footprints, oriented rectangles
of the vehicle's length and width centred on ``xy(s)`` and aligned with the path's direction
(:func:`footprints_overlap`, the separating-axis test).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
from numba import njit


# Offsets inside the path's slots (``slot.PATH_B1 ..``) and of :meth:`Path.geometry_vector`.
_B1, _B2, _X1, _Y1, _UX0, _UY0, _CX, _CY, _R, _PHI1, _TURN, _X2, _Y2, _UX2, _UY2 = range(15)
N_GEOMETRY = 15


@njit(cache=True, inline="always")
def path_point(G: np.ndarray, o: int, s: float) -> tuple[float, float]:
    """``xy(s)`` [m] of the path whose geometry starts at ``G[o]`` (see the module docstring)."""
    b1 = G[o + _B1]
    if s < b1:
        d = s - b1
        return G[o + _X1] + d * G[o + _UX0], G[o + _Y1] + d * G[o + _UY0]
    b2 = G[o + _B2]
    if s < b2:
        r = G[o + _R]
        angle = G[o + _PHI1] + G[o + _TURN] * (s - b1) / r
        return G[o + _CX] + r * math.cos(angle), G[o + _CY] + r * math.sin(angle)
    d = s - b2
    return G[o + _X2] + d * G[o + _UX2], G[o + _Y2] + d * G[o + _UY2]


@njit(cache=True)
def path_points(G: np.ndarray, s: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """:func:`path_point` of every position in ``s`` (any shape) into ``x``, ``y``."""
    sf, xf, yf = s.ravel(), x.ravel(), y.ravel()
    for i in range(sf.size):
        xf[i], yf[i] = path_point(G, 0, sf[i])


@njit(cache=True, inline="always")
def pair_unsafe_along(sq_a: float, sq_b: float, thr: float) -> bool:
    """Conflict along the paths: ``sqrt(s_a^2 + s_b^2) < min_dist``, with the squares of the
    distances along the paths to the conflict point given."""
    return sq_a + sq_b < thr


@njit(cache=True, inline="always")
def pair_unsafe_xy(xa: float, ya: float, xb: float, yb: float, thr: float) -> bool:
    """Euclidean conflict: ``sqrt((x_a - x_b)^2 + (y_a - y_b)^2) < min_dist``."""
    dx = xa - xb
    dy = ya - yb
    return dx * dx + dy * dy < thr


@dataclass(frozen=True)
class VehicleShape:
    """One vehicle's size and limits (its own, or the shared ``[vehicle]`` section's)."""

    length_m: float
    width_m: float
    v_min_mps: float
    v_max_mps: float
    u_min_mps2: float
    u_max_mps2: float


@dataclass(frozen=True)
class Path:
    """One vehicle's path, its lines and its conflict zone (see the module docstring).

    Build with :meth:`straight`, :meth:`bend` or :meth:`turn`; the lines and the zone are set
    by the scenario (:func:`dataclasses.replace`).
    """

    vehicle: VehicleShape
    b1: float
    b2: float
    p1: tuple[float, float]
    u0: tuple[float, float]
    arc: tuple[float, float, float, float, float]  #: (cx, cy, r, phi1, turn); r = 0: no arc
    p2: tuple[float, float]
    u2: tuple[float, float]
    yield_s: float = -math.inf  #: stop target of the library's stop trajectory [m]
    first_s: float = -math.inf  #: the line whose first arrival decides who went first [m]
    clear_s: float = math.inf  #: past it the vehicle no longer conflicts [m]
    zone: tuple[float, float] = (-math.inf, math.inf)  #: conservative conflict window [m]
    #: conservative interval of positions where the footprint may touch the other vehicle's
    #: (:func:`occupancy_interval`; the safety shield and the surrogate measures use it) [m]
    occupancy: tuple[float, float] = (-math.inf, math.inf)
    #: the shield's occupancy interval: the same with both footprints enlarged by half the
    #: clearance ``av.shield_margin_m`` on every side (docs/method.md §12.2); None: no
    #: clearance, :attr:`occupancy` itself (:attr:`shield_interval`)
    shield_occupancy: tuple[float, float] | None = None
    _G: np.ndarray = field(default=None, repr=False, compare=False)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        object.__setattr__(self, "_G", np.array(self.geometry_vector_tuple(), dtype=np.float64))

    @property
    def shield_interval(self) -> tuple[float, float]:
        """The occupancy interval the shield certifies with (:attr:`shield_occupancy`)."""
        return self.occupancy if self.shield_occupancy is None else self.shield_occupancy

    def inflated(self, margin_m: float) -> Path:
        """The same path with the footprint enlarged by ``margin_m`` on every side (length
        and width ``+ 2 margin_m``): two inflated footprints overlap whenever the true ones
        come within ``2 margin_m`` of each other (each contains its footprint's points within
        ``margin_m``; at the corners also a little farther), so an occupancy interval computed
        on them keeps that clearance."""
        veh = self.vehicle
        return replace(self, vehicle=replace(veh, length_m=veh.length_m + 2.0 * margin_m,
                                             width_m=veh.width_m + 2.0 * margin_m),
                       occupancy=(-math.inf, math.inf), shield_occupancy=None)

    # -- construction ------------------------------------------------------------------------

    @classmethod
    def straight(cls, vehicle: VehicleShape, point: tuple[float, float],
                 direction: tuple[float, float]) -> Path:
        """A straight path through ``point`` at ``s = 0`` with unit ``direction``."""
        return cls(vehicle, 0.0, 0.0, point, direction, (0.0, 0.0, 0.0, 0.0, 0.0), point,
                   direction)

    @classmethod
    def bend(cls, vehicle: VehicleShape, point: tuple[float, float],
             before: tuple[float, float], after: tuple[float, float]) -> Path:
        """Straight in direction ``before`` up to ``point`` (``s = 0``), then ``after``."""
        return cls(vehicle, 0.0, 0.0, point, before, (0.0, 0.0, 0.0, 0.0, 0.0), point, after)

    @classmethod
    def turn(cls, vehicle: VehicleShape, start: tuple[float, float], heading_rad: float,
             radius_m: float, angle_rad: float, s_start: float) -> Path:
        """Straight until ``start`` (at ``s = s_start``) with ``heading_rad``, then an arc of
        ``radius_m`` turning by ``angle_rad`` (> 0 left), then straight on."""
        turn = 1.0 if angle_rad > 0 else -1.0
        u0 = (_exact_cos(heading_rad), _exact_sin(heading_rad))
        # the centre lies to the left (turn > 0) or right of the heading
        cx = start[0] - turn * radius_m * u0[1]
        cy = start[1] + turn * radius_m * u0[0]
        phi1 = math.atan2(start[1] - cy, start[0] - cx)
        phi2 = phi1 + angle_rad
        p2 = (cx + radius_m * math.cos(phi2), cy + radius_m * math.sin(phi2))
        h2 = heading_rad + angle_rad
        u2 = (_exact_cos(h2), _exact_sin(h2))
        b2 = s_start + radius_m * abs(angle_rad)
        return cls(vehicle, s_start, b2, start, u0, (cx, cy, radius_m, phi1, turn), p2, u2)

    # -- evaluation --------------------------------------------------------------------------

    def geometry_vector_tuple(self) -> tuple[float, ...]:
        cx, cy, r, phi1, turn = self.arc
        return (self.b1, self.b2, *self.p1, *self.u0, cx, cy, r, phi1, turn, *self.p2, *self.u2)

    @property
    def is_straight(self) -> bool:
        """One straight line: no arc and the same direction before and after ``b1``."""
        return self.arc[2] == 0.0 and self.u0 == self.u2

    @property
    def half_diagonal_m(self) -> float:
        """Half the diagonal of the vehicle's footprint [m]: no point of it is further from
        the centre."""
        return 0.5 * math.hypot(self.vehicle.length_m, self.vehicle.width_m)

    def geometry_vector(self) -> np.ndarray:
        """The path's kernel slots (``slot.PATH_B1 .. slot.PATH_UY2``)."""
        return self._G.copy()

    def xy(self, s: Any) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(x, y)`` [m] at path positions ``s`` (any shape)."""
        s = np.asarray(s, dtype=np.float64)
        # C-contiguous arrays: the kernel writes through ravel(), which copies anything else
        x, y = np.empty(s.shape), np.empty(s.shape)
        path_points(self._G, np.ascontiguousarray(s).reshape(s.shape), x, y)
        return x, y

    def direction(self, s: Any) -> tuple[np.ndarray, np.ndarray]:
        """Unit direction of travel ``(ux, uy)`` at ``s`` (exact on straight pieces)."""
        s = np.asarray(s, dtype=np.float64)
        cx, cy, r, phi1, turn = self.arc
        ux = np.where(s < self.b1, self.u0[0], self.u2[0]).astype(float)
        uy = np.where(s < self.b1, self.u0[1], self.u2[1]).astype(float)
        on_arc = (s >= self.b1) & (s < self.b2)
        if r > 0 and np.any(on_arc):
            angle = phi1 + turn * (s[on_arc] - self.b1) / r
            ux[on_arc] = -turn * np.sin(angle)
            uy[on_arc] = turn * np.cos(angle)
        return ux, uy

    def heading(self, s: Any) -> np.ndarray:
        """Heading [rad] at ``s``, ``atan2(uy, ux)``."""
        ux, uy = self.direction(s)
        return np.arctan2(uy, ux)

    def polyline(self, s_lo: float, s_hi: float, step_m: float = 0.05) -> np.ndarray:
        """Points ``(k, 2)`` of the path every ``step_m`` from ``s_lo`` to ``s_hi``."""
        s = np.linspace(s_lo, s_hi, max(2, int(math.ceil((s_hi - s_lo) / step_m)) + 1))
        x, y = self.xy(s)
        return np.stack([x, y], axis=1)


def _exact_cos(angle: float) -> float:
    """``cos`` with the quadrant angles exact (0, ±1)."""
    q = angle / (math.pi / 2)
    if q == round(q):
        return (1.0, 0.0, -1.0, 0.0)[int(round(q)) % 4]
    return math.cos(angle)


def _exact_sin(angle: float) -> float:
    q = angle / (math.pi / 2)
    if q == round(q):
        return (0.0, 1.0, 0.0, -1.0)[int(round(q)) % 4]
    return math.sin(angle)


def unit(angle_deg: float) -> tuple[float, float]:
    """The unit vector at ``angle_deg`` [deg], exact at multiples of 90 deg."""
    a = math.radians(angle_deg)
    if angle_deg % 90 == 0:
        return _exact_cos(math.pi / 2 * (angle_deg // 90)), _exact_sin(math.pi / 2 * (angle_deg // 90))
    return math.cos(a), math.sin(a)


@functools.lru_cache(maxsize=64)
def zone_interval(path: Path, other: Path, min_dist_m: float, reach_m: float = 150.0,
                  step_m: float = 0.01) -> tuple[float, float]:
    """A conservative interval of ``s`` on ``path`` outside which every point of ``other``
    (within ``reach_m`` of its reference point) is at least ``min_dist_m`` away.

    Computed numerically: ``path`` every ``step_m`` against ``other`` every ``step_m`` (a
    k-d tree query), widened by a margin that covers both spacings. Only the first and the last
    sample that close are needed: each is searched from its end, passing over the samples that
    the distance of one already found shows to be far (the path moves no farther than its arc
    length). An end of the interval that reaches the end of the scanned range is
    unbounded (e.g. two vehicles sharing a lane after a merge).
    """
    from scipy.spatial import cKDTree

    pts_other = other.polyline(-reach_m, reach_m, step_m)
    s = np.arange(-reach_m, reach_m + step_m / 2, step_m)
    x, y = path.xy(s)
    margin = 2.0 * step_m  # sampled distances over-estimate by at most step/2 on each curve
    # the same nearest distances, found faster: a tree without compacted nodes (the samples
    # of a shared lane are collinear with the query points, which made compacted nodes slow
    # to search: 0.66 s against 0.1 s at the merge), and no search beyond twice the distance
    # that counts (farther points read inf, and are outside either way)
    tree = cKDTree(pts_other, compact_nodes=False)
    pts = np.stack([x, y], axis=1)
    near = min_dist_m + margin

    def inside(rows: np.ndarray) -> np.ndarray:
        return rows[tree.query(pts[rows], distance_upper_bound=2.0 * near)[0] < near]

    def clear(k: int, upward: bool) -> int:
        # the path moves at most |s_j - s_k| between samples j and k, so every sample within
        # the nearest distance's excess over ``near`` (less a slack for rounding) is outside
        room = float(tree.query(pts[k])[0]) - near - _LIPSCHITZ_SLACK_M
        if not room > 0.0:
            return 0
        if upward:
            return int(np.searchsorted(s, s[k] + room, side="left")) - k
        return k - int(np.searchsorted(s, s[k] - room, side="right")) + 1

    # only the first and the last sample inside count: each found from its end, far stretches
    # passed over (the same queries as every sample's where it matters, far fewer of them)
    first = _first_hit(inside, 0, s.size, upward=True, clear=clear)
    if first is None:
        return (math.inf, math.inf)  # never in conflict: an empty window
    last = _first_hit(inside, first, s.size, upward=False, clear=clear)
    lo = -math.inf if first == 0 else float(s[first] - margin)
    hi = math.inf if last == s.size - 1 else float(s[last] + margin)
    return lo, hi


#: Slack [m] for rounding in :func:`zone_interval`'s skips of far samples (the path's points
#: and the tree's distances are exact to about 1e-12 m).
_LIPSCHITZ_SLACK_M = 1e-6


@functools.lru_cache(maxsize=64)
def occupancy_interval(path: Path, other: Path,
                       other_range: tuple[float, float] = (-math.inf, math.inf),
                       step_m: float = 0.05, reach_m: float = 150.0) -> tuple[float, float]:
    """A conservative interval ``[lo, hi]`` of positions ``s`` on ``path`` outside which the
    vehicle's footprint cannot overlap the other vehicle's, wherever the other is on ``other``
    within ``other_range`` (docs/method.md §12.1).

    Two straight paths and an unbounded ``other_range``: exact. The union of the other's
    footprints is a strip of its width along its line, and the footprint (length ``l``, width
    ``w``) centred at ``p + s u`` meets it when the centre's distance to the line is at most
    ``w_o / 2 + (l / 2) |sin| + (w / 2) |cos|`` of the angle between the lines (at the paper's
    intersection ``|s| <= 3.75 m``, the paper's collision test).

    Otherwise numerical: both paths are sampled every ``step_m`` within ``reach_m`` of their
    reference points (each straight piece and the arc on its own, ends included, so a kink is
    never straddled), the footprints are tested pairwise with the separating-axis test (the
    pairs of samples within reach of each other, a k-d tree's), each enlarged on every side by
    the farthest a footprint point moves between a position and its nearest sample
    (``step/2 (1 + r/R)``: ``r`` the half-diagonal, ``R`` the arc radius), and the hull of the
    positions found is widened by ``step/2``. Every true overlap therefore lies inside the
    result. Only the hull's ends are needed: the own samples are tested from each end up to
    the first with an overlap. ``(inf, inf)``: never; an end at the scanned range is
    unbounded.
    Results are kept per pair of paths (a study builds the same geometry many times).
    """
    if path.is_straight and other.is_straight and other_range == (-math.inf, math.inf):
        return _straight_occupancy(path, other)
    from scipy.spatial import cKDTree

    s_own = _samples(path, -reach_m, reach_m, step_m)
    lo_o, hi_o = max(other_range[0], -reach_m), min(other_range[1], reach_m)
    s_oth = _samples(other, lo_o, hi_o, step_m)
    m_own = step_m / 2 * (1.0 + path.half_diagonal_m / _radius(path))
    m_oth = step_m / 2 * (1.0 + other.half_diagonal_m / _radius(other))
    reach = path.half_diagonal_m + other.half_diagonal_m + m_own + m_oth
    # only the samples within reach of the other path can take part
    xo, yo = path.xy(s_own)
    xt, yt = other.xy(s_oth)
    own_pts, oth_pts = np.stack([xo, yo], axis=1), np.stack([xt, yt], axis=1)
    keep_o = cKDTree(oth_pts).query(own_pts, distance_upper_bound=reach)[0] <= reach
    keep_t = cKDTree(own_pts).query(oth_pts, distance_upper_bound=reach)[0] <= reach
    if not keep_o.any() or not keep_t.any():
        return (math.inf, math.inf)
    edge_lo, edge_hi = bool(keep_o[0]), bool(keep_o[-1])
    s_own, s_oth = s_own[keep_o], s_oth[keep_t]
    va, vb = path.vehicle, other.vehicle
    pairs = _SamplePairs(own_pts[keep_o], path.direction(s_own),
                         va.length_m + 2 * m_own, va.width_m + 2 * m_own,
                         cKDTree(oth_pts[keep_t]), oth_pts[keep_t], other.direction(s_oth),
                         vb.length_m + 2 * m_oth, vb.width_m + 2 * m_oth, reach)
    # only the hull counts: the lowest and the highest own sample with a hit, each found by
    # scanning from its end (the same pairs and tests as all of them, far fewer of them)
    first = _first_hit(pairs.hits, 0, s_own.size, upward=True)
    if first is None:
        return (math.inf, math.inf)
    last = _first_hit(pairs.hits, first, s_own.size, upward=False)
    lo = float(s_own[first]) - step_m / 2
    hi = float(s_own[last]) + step_m / 2
    # an end of the scanned range that still overlaps is unbounded (e.g. a shared lane)
    return (-math.inf if edge_lo and first == 0 else lo,
            math.inf if edge_hi and last == s_own.size - 1 else hi)


@dataclass(frozen=True)
class _SamplePairs:
    """The own samples of :func:`occupancy_interval` against the other's: which own sample's
    (enlarged) footprint overlaps the footprint of some other sample within ``reach`` of it
    (a k-d tree's ball, then :func:`footprints_overlap`).

    ``own_xy: (n_own, 2)``, ``oth_xy: (n_oth, 2)`` [m]; ``own_u``, ``oth_u`` the unit
    directions ``(ux, uy)`` at them; ``tree`` the k-d tree of ``oth_xy``; lengths and widths
    [m] the enlarged footprints'.
    """

    own_xy: np.ndarray
    own_u: tuple[np.ndarray, np.ndarray]
    own_l: float
    own_w: float
    tree: Any
    oth_xy: np.ndarray
    oth_u: tuple[np.ndarray, np.ndarray]
    oth_l: float
    oth_w: float
    reach: float

    def hits(self, rows: np.ndarray) -> np.ndarray:
        """The own samples among ``rows`` that overlap some other sample."""
        near = self.tree.query_ball_point(self.own_xy[rows], self.reach)
        counts = np.fromiter((len(n) for n in near), dtype=np.int64, count=len(near))
        if counts.sum() == 0:
            return rows[:0]
        i = np.repeat(rows, counts)
        j = np.concatenate([np.asarray(n, dtype=np.int64) for n in near if n])
        hit = footprints_overlap(self.own_xy[i, 0], self.own_xy[i, 1],
                                 (self.own_u[0][i], self.own_u[1][i]), self.own_l, self.own_w,
                                 self.oth_xy[j, 0], self.oth_xy[j, 1],
                                 (self.oth_u[0][j], self.oth_u[1][j]), self.oth_l, self.oth_w)
        return i[hit]


def _first_hit(hits: Callable[[np.ndarray], np.ndarray], lo: int, hi: int, upward: bool,
               clear: Callable[[int, bool], int] | None = None, chunk: int = 16) -> int | None:
    """The lowest (``upward``) or highest row in ``[lo, hi)`` with a hit, None if none:
    ``hits(rows)`` the rows among ``rows`` that have one, asked in blocks from that end, each
    block twice the last. ``clear(row, upward)``, if given: how many rows from ``row`` on, in
    the scan's direction, surely have none; as many are passed over unasked when they are at
    least a block."""
    done = 0
    while done < hi - lo:
        if clear is not None:
            skip = clear(lo + done if upward else hi - 1 - done, upward)
            if skip >= chunk:
                done += skip
                continue
        size = min(chunk, hi - lo - done)
        a = lo + done if upward else hi - done - size
        found = hits(np.arange(a, a + size))
        if found.size:
            return int(found.min() if upward else found.max())
        done += size
        chunk *= 2
    return None


def _radius(path: Path) -> float:
    return path.arc[2] if path.arc[2] > 0.0 else math.inf


def _samples(path: Path, lo: float, hi: float, step_m: float) -> np.ndarray:
    """Positions every ``step_m`` or closer from ``lo`` to ``hi``, each piece of the path
    (straight, arc, straight) sampled with its own ends (the last position before a kink
    included)."""
    cuts = sorted({lo, hi, *(b for b in (path.b1, path.b2) if lo < b < hi)})
    parts = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        n = max(2, int(math.ceil((b - a) / step_m)) + 1)
        piece = np.linspace(a, b, n)
        if b in (path.b1, path.b2) and b != hi:  # the piece ends just before the next one
            piece[-1] = math.nextafter(b, -math.inf)
        parts.append(piece)
    return np.unique(np.concatenate(parts + [np.array(cuts[1:-1])]))


def _straight_occupancy(path: Path, other: Path) -> tuple[float, float]:
    """:func:`occupancy_interval` of two straight paths (exact; see there)."""
    (px, py), (ux, uy) = path.p1, path.u0
    (qx, qy), (wx, wy) = other.p1, other.u0
    k = wx * uy - wy * ux  # sin of the angle between the lines (signed)
    c = wx * (py - qy) - wy * (px - qx)  # signed distance of path's s = 0 from other's line
    va, vb = path.vehicle, other.vehicle
    reach = vb.width_m / 2 + (va.length_m / 2) * abs(k) + (va.width_m / 2) * abs(
        ux * wx + uy * wy)
    if k == 0.0:  # parallel lines: always or never within reach
        return (-math.inf, math.inf) if abs(c) <= reach else (math.inf, math.inf)
    a, b = (-reach - c) / k, (reach - c) / k
    return (min(a, b), max(a, b))


def footprints_overlap(xa: np.ndarray, ya: np.ndarray, ua: tuple[np.ndarray, np.ndarray],
                       la: float, wa: float, xb: np.ndarray, yb: np.ndarray,
                       ub: tuple[np.ndarray, np.ndarray], lb: float, wb: float) -> np.ndarray:
    """Whether two oriented rectangles overlap (touching counts), elementwise.

    Rectangle A is centred at ``(xa, ya)`` with unit direction ``ua`` (its length along it) and
    size ``la x wa`` [m]; likewise B. Separating-axis test over the four edge normals. For axis
    directions ``(1, 0)`` and ``(0, 1)`` it is exactly the paper's test ``|s_a| <= (l + w)/2``
    and ``|s_b| <= (l + w)/2``.
    """
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in
                                   (xa, ya, ua[0], ua[1], xb, yb, ub[0], ub[1])))
    out = np.empty(arrays[0].shape, dtype=np.bool_)
    _overlap(*(np.ascontiguousarray(a).ravel() for a in arrays), la, wa, lb, wb, out.ravel())
    return out


@njit(cache=True, _nrt=False)
def _overlap(xa, ya, uax, uay, xb, yb, ubx, uby, la, wa, lb, wb, out):
    """The separating-axis test of :func:`footprints_overlap`, element by element."""
    for i in range(out.size):
        dx, dy = xb[i] - xa[i], yb[i] - ya[i]
        hit = True
        for k in range(4):
            if k == 0:
                ax, ay = uax[i], uay[i]
            elif k == 1:
                ax, ay = -uay[i], uax[i]
            elif k == 2:
                ax, ay = ubx[i], uby[i]
            else:
                ax, ay = -uby[i], ubx[i]
            ra = (la / 2) * abs(uax[i] * ax + uay[i] * ay) + \
                (wa / 2) * abs(-uay[i] * ax + uax[i] * ay)
            rb = (lb / 2) * abs(ubx[i] * ax + uby[i] * ay) + \
                (wb / 2) * abs(-uby[i] * ax + ubx[i] * ay)
            if not abs(dx * ax + dy * ay) <= ra + rb:
                hit = False
                break
        out[i] = hit


__all__ = ["Path", "VehicleShape", "footprints_overlap", "occupancy_interval", "path_point",
           "path_points", "unit", "zone_interval"]
