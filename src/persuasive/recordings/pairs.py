"""Crossing pairs from recorded tracks, projected onto the project's scenario form, with labels
(docs/guide/recordings.md).

**Finding pairs.** Two smoothed vehicle tracks (:mod:`persuasive.recordings.tracks`) of one
recording are a candidate when they are both present for at least ``min_common_s`` and their
bounding boxes meet. Their paths must then cross at an angle in ``angle_range_deg`` or merge
(:mod:`persuasive.recordings.geometry` says how both are found), and both vehicles must be
**approaching**: each is first seen before its occupancy interval (it is observed arriving),
and there is a time at which both are within ``near_m`` of the conflict point along their
paths (``|s| <= near_m``; the two stretches of time overlap).

**Projection.** Each vehicle's path is a :class:`persuasive.envs.external.Polyline` through
its own smoothed centres (cut to ``CUT_M`` = 30 m before and after the point where the paths
meet), and
:func:`persuasive.envs.external.route_conflict` gives the conflict of the pair, with the
vehicles' recorded lengths and widths: the kind (crossing: the two centre lines' crossing is
the conflict point, exactly where they intersect, not at route_conflict's sampling step;
merge: the merging vehicle's first point on the other's path is the conflict point,
``merge_at``), each vehicle's position of the conflict point on its path, and the occupancy
intervals (where its footprint can touch the other's path,
relative to the conflict point). Vehicle 1 is route_conflict's ego: in a merge the merging
vehicle, in a crossing the lower track ID. Per 10 Hz step that both are present: ``s``
(relative to the conflict point, negative before it), ``v`` and ``a`` of both; and where the
steps lie in each vehicle's track (``track_k0``: the track's sample of the pair's first step,
``track_n``: the track's samples), which the fit's measurement model needs (the filter
differs near a track's ends, ``persuasive.recordings.tracks.acceleration_band``).

**Speed.** :func:`find_pairs` projects every candidate at once, in one compiled kernel
(:func:`project_candidates`) that computes, bit for bit, what :func:`_project` computes for
one pair through ``Polyline`` and ``route_conflict``: the cut, the samples, the pairs of
samples within reach, the labels, with numpy's arithmetic written out (``searchsorted``,
``linspace``, ``interp``, the C library's ``hypot``); a candidate it leaves (a merge that
route_conflict refuses) goes through :func:`_project`. The steps of all the pairs are then
gathered at once. On the site-size recording of docs/guide/recordings.md a file's 650 or so
candidates take about 20 ms in the kernel, against about 0.4 s through :func:`_project`
(issue 42).

**Labels** (every approaching pair is kept; the labels never filter):

- ``first``: who passed the conflict point first: the vehicle whose ``s`` reaches 0 earlier
  (linear interpolation between steps); ``"same time"`` on equal times, ``"neither"`` when
  neither reaches it while recorded, the one that does when only one does;
- ``pet_area_s``: the **post-encroachment time at the conflict area**, the literature's
  (Allen, Shin and Cooper 1978, with the vehicles' lengths): from the moment the first
  vehicle's rear leaves the conflict area to the moment the second vehicle's front reaches
  it. The conflict area (:func:`conflict_area`, paths taken as straight lines through the
  conflict point at the pair's recorded angle ``theta``) is, for a crossing, the intersection
  of the two swept paths, each the strip of its own vehicle's recorded width ``w_k`` about
  its path (the recordings have no lanes; a vehicle's swept path stands for its lane): a
  parallelogram that reaches ``a_k = (w_o / 2 + |cos theta| w_k / 2) / sin theta`` either
  side of the conflict point along vehicle ``k``'s path (``o`` the other vehicle; the first
  term is where ``k``'s centre line lies within ``w_o / 2`` of the other path, the second the
  corners of ``k``'s own width, 0 at right angles). Vehicle ``k``'s footprint (a rectangle
  ``L_k`` by ``w_k`` along its path) overlaps the area while its centre is in ``[-a_k - L_k /
  2, a_k + L_k / 2]``: its front reaches the area at ``s = -a_k - L_k / 2``, its rear leaves
  at ``s = a_k + L_k / 2``. For a merge the area is the merge point itself, a line across the
  shared lane (``a_k = 0``: past it the two paths are one lane, and any stretch of it would be
  an arbitrary length): the first vehicle's rear passes it at ``s = L / 2``, the second's
  front reaches it at ``s = -L / 2``; two footprints on it at once are side by side where the
  merging vehicle's centre line is within ``merge_gap_m`` of the lane's. Times are
  interpolated linearly between steps. The first vehicle is the one whose front reaches the
  area first; 0 when both footprints
  overlapped the area at once (a conflict: two footprints in the area at one time, which
  never happens to vehicles that pass each other side by side clear of it); NaN when one
  never reaches it while recorded, or the first is still in it when its track ends before the
  other arrives;
- ``pet_s``: the post-encroachment time on the **occupancy intervals**, as the simulator's
  (``persuasive.safety.measures``): from the moment the vehicle that entered its occupancy
  interval first leaves it to the moment the other enters its own; 0 when both were inside
  at once; NaN as ``pet_area_s``. The intervals are where a footprint can touch the other's
  path (widened by both widths, a lateral margin and the sampling step: 9.7-18 m long on a
  real junction, issue 42), so two vehicles that pass side by side, centres metres apart,
  often read 0 here and more than 0 in ``pet_area_s``; it is kept for the simulator's measure
  and for files that read it;
- ``second_slowed``: the second passer (the other than ``first``) slowed down: its speed
  fell by at least ``slow_drop_mps`` (default 1 m/s) below the highest speed it had earlier in
  its approach, the stretch from the moment it is within ``near_m`` before the conflict
  point to the moment it reaches it (or its track ends); ``second_speed_drop_mps`` is that
  largest fall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numba import njit, prange

from .formats import STEP_S, RecordingError
from .geometry import (CHUNK, G_CROSS, G_CROSS_ANGLE, G_CROSS_SI, G_CROSS_SJ, G_MERGE_IJ,
                       G_MERGE_IJ_ANGLE, G_MERGE_IJ_SI, G_MERGE_IJ_SJ, G_MERGE_JI,
                       G_MERGE_JI_ANGLE, G_MERGE_JI_SI, G_MERGE_JI_SJ, N_GEOMETRY, chunk_boxes,
                       pair_geometry)
from .tracks import Tracks

#: Kinds of pair (``persuasive.envs.external``'s names).
CROSSING, MERGE = "crossing", "merge"
#: The labels of ``first``.
FIRST_LABELS = ("1", "2", "same time", "neither")
#: Key of the pairs file's metadata in its Parquet schema.
PAIRS_METADATA = b"persuasive.pairs"
#: How far before and after the point where the paths meet the polylines handed to
#: route_conflict reach [m] (a footprint 1 m wider than the lane touches a path crossed at 20
#: degrees within 9 m of the point, one merging at 10 degrees within 17 m)
CUT_M = 30.0


@dataclass(frozen=True)
class PairParams:
    """How pairs are found and labelled (module docstring)."""

    #: crossing angles kept [deg]: 0 same direction, 90 right angles, 180 head on
    angle_range_deg: tuple[float, float] = (20.0, 160.0)
    near_m: float = 40.0  #: both within this of the conflict point at one time [m]
    min_common_s: float = 1.0  #: both tracks present together at least this long [s]
    merge_gap_m: float = 1.0  #: on the other's path: centre lines within this [m]
    merge_apart_m: float = 3.0  #: beside the other's path before: at least this away [m]
    merge_run_m: float = 15.0  #: on the other's path for at least this arc [m]
    slow_drop_mps: float = 1.0  #: the second passer slowed: a speed drop of this [m/s]
    lateral_margin_m: float = 0.5  #: route_conflict's lateral margin [m]
    long_margin_m: float = 0.05  #: route_conflict's margin along the path [m]
    step_m: float = 0.25  #: route_conflict's sampling step [m]

    def __post_init__(self) -> None:
        lo, hi = self.angle_range_deg
        if not (0.0 <= lo < hi <= 180.0):
            raise RecordingError(f"angle range = [{lo:g}, {hi:g}] is out of range; allowed: "
                                 "0 <= low < high <= 180 degrees")
        for name in ("near_m", "min_common_s", "merge_gap_m", "merge_run_m", "slow_drop_mps",
                     "step_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise RecordingError(f"{name} = {value!r} is out of range; allowed: a "
                                     "positive number")
        if not (math.isfinite(self.merge_apart_m) and self.merge_apart_m > self.merge_gap_m):
            raise RecordingError(f"merge_apart_m = {self.merge_apart_m!r} is out of range; "
                                 f"allowed: more than merge_gap_m = {self.merge_gap_m:g}")
        for name in ("lateral_margin_m", "long_margin_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise RecordingError(f"{name} = {value!r} is out of range; allowed: a "
                                     "number >= 0")


@dataclass(frozen=True)
class Pair:
    """One approaching pair (module docstring): identity, conflict, labels and steps.

    Step arrays ``(n,)``: ``t`` [s]; per vehicle ``k`` in 0, 1 (vehicle 1, 2): ``s[k]`` [m]
    relative to its conflict point, ``v[k]`` [m/s], ``a[k]`` [m/s^2], ``x[k]``, ``y[k]`` [m]
    (smoothed centre), ``heading[k]`` [rad] (the file's)."""

    pair: int
    recording: str
    kind: str
    angle_deg: float  #: crossing angle, or the merging vehicle's angle to the lane [deg]
    tracks: tuple[int, int]
    classes: tuple[str, str]
    lengths_m: tuple[float, float]
    widths_m: tuple[float, float]
    occupancy: tuple[tuple[float, float], tuple[float, float]]  #: [m], per vehicle
    conflict_xy: tuple[float, float]  #: the conflict point on vehicle 1's path [m]
    first: str
    pet_s: float  #: post-encroachment time on the occupancy intervals [s] (module docstring)
    pet_area_s: float  #: post-encroachment time at the conflict area [s] (module docstring)
    t_pass_s: tuple[float, float]  #: when each reached its conflict point (NaN: never) [s]
    second_slowed: bool | None  #: None: no second passer
    second_speed_drop_mps: float
    t: np.ndarray = field(repr=False)
    s: np.ndarray = field(repr=False)  #: (2, n)
    v: np.ndarray = field(repr=False)
    a: np.ndarray = field(repr=False)
    x: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    heading: np.ndarray = field(repr=False)
    #: indices of the two tracks in the :class:`Tracks` they came from (for figures)
    index: tuple[int, int] = (-1, -1)
    #: per vehicle, the sample of its track at the pair's first step, and its track's samples
    track_k0: tuple[int, int] = (0, 0)
    track_n: tuple[int, int] = (0, 0)
    #: the junction's rule from a Lanelet2 map (``persuasive.recordings.lanelet_map``):
    #: "unknown" (no map), "none", "right_of_way" or "all_way_stop"; ``priority``: the vehicle
    #: (1, 2) with the right of way, 0 for none; ``stop_s``: each one's stop line at an
    #: all-way stop, relative to its conflict point [m] (NaN: none)
    control: str = "unknown"
    priority: int = 0
    stop_s: tuple[float, float] = (math.nan, math.nan)

    @property
    def n_steps(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class PairsResult:
    """The pairs of a set of tracks, and how many tracks they came from."""

    pairs: list[Pair]
    tracks: Tracks = field(repr=False)
    candidates: int  #: candidate pairs compared (times and boxes meet)
    params: PairParams
    #: the Lanelet2 map the rules came from (``{"path", "origin"}``); None: no map
    road_map: dict | None = None


def candidates(tracks: Tracks, params: PairParams) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs ``(i, j)``, ``i < j`` in time order: same recording, both present
    for at least ``min_common_s``, bounding boxes within ``merge_apart_m``."""
    n = tracks.n_tracks
    if n < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    st = tracks.starts
    t0, t1 = tracks.t[st[:-1]], tracks.t[st[1:] - 1]
    rec = np.unique(tracks.recording, return_inverse=True)[1]
    order = np.lexsort((t0, rec))
    r_o, t0_o, t1_o = rec[order], t0[order], t1[order]
    # the last track of the same recording starting before each track ends (less min_common)
    key_start = r_o * 1e7 + t0_o
    key_end = r_o * 1e7 + t1_o - params.min_common_s + 1e-6
    last = np.searchsorted(key_start, key_end, side="right") - 1
    counts = np.maximum(last - np.arange(n), 0)
    a = np.repeat(np.arange(n), counts)
    b = a + 1 + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
    i, j = order[a], order[b]
    common = np.minimum(t1[i], t1[j]) - np.maximum(t0[i], t0[j])
    keep = common >= params.min_common_s - 1e-9
    i, j = i[keep], j[keep]
    box = _track_boxes(tracks)
    r = params.merge_apart_m
    meet = ((box[i, 0] <= box[j, 2] + r) & (box[j, 0] <= box[i, 2] + r)
            & (box[i, 1] <= box[j, 3] + r) & (box[j, 1] <= box[i, 3] + r))
    return i[meet], j[meet]


def _track_boxes(tracks: Tracks) -> np.ndarray:
    st = tracks.starts[:-1]
    out = np.empty((tracks.n_tracks, 4))
    out[:, 0] = np.minimum.reduceat(tracks.x, st)
    out[:, 1] = np.minimum.reduceat(tracks.y, st)
    out[:, 2] = np.maximum.reduceat(tracks.x, st)
    out[:, 3] = np.maximum.reduceat(tracks.y, st)
    return out


def find_pairs(tracks: Tracks, params: PairParams | None = None) -> PairsResult:
    """Every approaching crossing or merging pair of ``tracks`` (module docstring), in order
    of recording and time; pair IDs count from 0 in that order.

    Every candidate is projected at once by the compiled :func:`project_candidates` (module
    docstring, "Speed"), which computes what :func:`_project` computes per pair, bit for
    bit; :func:`_project` itself runs only for a candidate the kernel leaves to it."""
    params = params or PairParams()
    n_candidates, meets = meetings(tracks, params)
    return PairsResult(_pairs_of(tracks, params, meets), tracks, n_candidates, params)


def meetings(tracks: Tracks, params: PairParams) -> tuple[int, list[tuple]]:
    """The candidate pairs of ``tracks`` whose paths cross or merge
    (:mod:`persuasive.recordings.geometry`), with each one's roles: ``(number of candidates,
    [(i, j, kind, s_i, s_j, angle_deg)])``, ``i`` vehicle 1 (route_conflict's ego: the
    merging vehicle, or the lower track ID of a crossing), ``s_i``, ``s_j`` the arcs [m] on
    each track's path where the paths meet, in candidate order. :func:`_project` of each is
    its pair, or None."""
    ci, cj = candidates(tracks, params)
    out = np.zeros((ci.shape[0], N_GEOMETRY))
    if ci.shape[0]:
        cstart, v0, v1, box = chunk_boxes(tracks.x, tracks.y, tracks.starts, CHUNK)
        lo, hi = params.angle_range_deg
        pair_geometry(tracks.x, tracks.y, tracks.s, tracks.starts, cstart, v0, v1, box, ci,
                      cj, float(lo), float(hi), params.merge_gap_m, params.merge_apart_m,
                      params.merge_run_m, out)
    meets = []
    for p in np.flatnonzero((out[:, G_CROSS] > 0) | (out[:, G_MERGE_JI] > 0)
                            | (out[:, G_MERGE_IJ] > 0)):
        i, j, g = int(ci[p]), int(cj[p]), out[p]
        if g[G_CROSS] > 0:
            if tracks.track[i] > tracks.track[j]:
                meets.append((j, i, CROSSING, g[G_CROSS_SJ], g[G_CROSS_SI], g[G_CROSS_ANGLE]))
            else:
                meets.append((i, j, CROSSING, g[G_CROSS_SI], g[G_CROSS_SJ], g[G_CROSS_ANGLE]))
        # the merging vehicle is vehicle 1; both merging: the steeper approach merges
        elif g[G_MERGE_JI] > 0 and (g[G_MERGE_IJ] == 0
                                    or g[G_MERGE_JI_ANGLE] >= g[G_MERGE_IJ_ANGLE]):
            meets.append((j, i, MERGE, g[G_MERGE_JI_SJ], g[G_MERGE_JI_SI],
                          g[G_MERGE_JI_ANGLE]))
        else:
            meets.append((i, j, MERGE, g[G_MERGE_IJ_SI], g[G_MERGE_IJ_SJ],
                          g[G_MERGE_IJ_ANGLE]))
    return int(ci.shape[0]), meets


def _pairs_of(tracks: Tracks, params: PairParams, meets: list[tuple]) -> list[Pair]:
    """The pairs of the candidates ``meets`` (:func:`meetings`), sorted and numbered: the
    compiled projection of all of them, :func:`_project` where it leaves one to the plain
    path, and the steps of the pairs gathered at once."""
    n = len(meets)
    vi = np.array([m[0] for m in meets], np.int64)
    vj = np.array([m[1] for m in meets], np.int64)
    si = np.array([m[3] for m in meets], float)
    sj = np.array([m[4] for m in meets], float)
    out = np.zeros((n, N_PROJECTION))
    plain = np.zeros(n, bool)
    area = np.zeros((n, 4))
    for p, (i, j, kind, _, _, angle) in enumerate(meets):
        try:
            (e1, l1), (e2, l2) = conflict_area(
                kind, angle, (float(tracks.length_m[i]), float(tracks.length_m[j])),
                (float(tracks.width_m[i]), float(tracks.width_m[j])))
        except RecordingError:
            plain[p] = True  # _project raises it, if the pair gets that far
            continue
        area[p] = e1, l1, e2, l2
    if n:
        project_candidates(tracks.t, tracks.x, tracks.y, tracks.s, tracks.v, tracks.starts,
                           np.asarray(tracks.length_m, float),
                           np.asarray(tracks.width_m, float), vi, vj,
                           np.array([m[2] == MERGE for m in meets], np.bool_), si, sj, area,
                           params.near_m, params.lateral_margin_m, params.long_margin_m,
                           params.step_m, out)
    plain |= out[:, P_STATUS] == PLAIN
    keep = np.flatnonzero(~plain & (out[:, P_STATUS] == A_PAIR))
    # the steps both are present: t_lo to t_hi, from sample k0 of each track
    st, T = tracks.starts, tracks.t
    ti0, tj0 = T[st[vi[keep]]], T[st[vj[keep]]]
    t_lo = np.maximum(ti0, tj0)
    t_hi = np.minimum(T[st[vi[keep] + 1] - 1], T[st[vj[keep] + 1] - 1])
    n_steps = np.rint((t_hi - t_lo) / STEP_S).astype(np.int64) + 1
    k0 = np.stack([np.rint((t_lo - ti0) / STEP_S).astype(np.int64),
                   np.rint((t_lo - tj0) / STEP_S).astype(np.int64)])
    t_first = np.round(T[st[vi[keep]] + k0[0]], 1)
    # find_pairs' order: recording, first step, track IDs (then the candidates' order)
    found = []
    for q, p in enumerate(keep.tolist()):
        i, j = meets[p][0], meets[p][1]
        found.append(((str(tracks.recording[i]), float(t_first[q]),
                       (int(tracks.track[i]), int(tracks.track[j])), p), q))
    for p in np.flatnonzero(plain).tolist():
        pair = _project(tracks, params, *meets[p])
        if pair is not None:
            found.append(((pair.recording, float(pair.t[0]), pair.tracks, p), pair))
    found.sort(key=lambda f: f[0])
    kept = np.array([q for _, q in found if not isinstance(q, Pair)], np.int64)
    steps = _steps_of(tracks, vi[keep][kept], vj[keep][kept], k0[:, kept], n_steps[kept],
                      out[keep[kept]][:, [P_CP_1, P_CP_2]])
    at = dict(zip(kept.tolist(), range(kept.shape[0])))
    ends = np.concatenate([[0], np.cumsum(n_steps[kept])])
    pairs = []
    for pair_id, (key, q) in enumerate(found):
        if isinstance(q, Pair):
            pairs.append(_with_id(q, pair_id))
            continue
        r = at[q]
        p = int(keep[q])
        i, j, kind, _, _, angle = meets[p]
        g = out[p].tolist()
        drop = g[P_DROP]
        a, b = int(ends[r]), int(ends[r + 1])
        pairs.append(Pair(
            pair=pair_id, recording=key[0], kind=kind, angle_deg=float(angle), tracks=key[2],
            classes=(str(tracks.agent_class[i]), str(tracks.agent_class[j])),
            lengths_m=(float(tracks.length_m[i]), float(tracks.length_m[j])),
            widths_m=(float(tracks.width_m[i]), float(tracks.width_m[j])),
            occupancy=((g[P_OCC_1_LO], g[P_OCC_1_HI]), (g[P_OCC_2_LO], g[P_OCC_2_HI])),
            conflict_xy=(g[P_X], g[P_Y]), first=FIRST_LABELS[int(g[P_FIRST])],
            pet_s=g[P_PET], pet_area_s=g[P_PET_AREA], t_pass_s=(g[P_PASS_1], g[P_PASS_2]),
            second_slowed=None if g[P_SECOND] < 0 else bool(drop >= params.slow_drop_mps),
            second_speed_drop_mps=drop,
            **{name: (arr[a:b] if arr.ndim == 1 else arr[:, a:b])
               for name, arr in steps.items()},
            index=(i, j), track_k0=(int(k0[0, q]), int(k0[1, q])),
            track_n=(int(st[i + 1] - st[i]), int(st[j + 1] - st[j]))))
    return pairs


def _steps_of(tracks: Tracks, vi: np.ndarray, vj: np.ndarray, k0: np.ndarray,
              n_steps: np.ndarray, cp: np.ndarray) -> dict[str, np.ndarray]:
    """The step arrays of several pairs at once, one pair after the other (as
    :func:`_project` makes each): vehicle 1 of pair ``r`` is track ``vi[r]`` from its sample
    ``k0[0, r]``, vehicle 2 track ``vj[r]`` from ``k0[1, r]``, ``n_steps[r]`` steps,
    ``s`` relative to the conflict points ``cp[r]`` ``(2,)`` [m]."""
    st = tracks.starts
    within = np.arange(int(n_steps.sum())) - np.repeat(np.cumsum(n_steps) - n_steps, n_steps)
    rows = [np.repeat(st[v] + k, n_steps) + within for v, k in ((vi, k0[0]), (vj, k0[1]))]
    cp_steps = np.repeat(cp, n_steps, axis=0)

    def both(values: np.ndarray) -> np.ndarray:
        return np.stack([values[rows[0]], values[rows[1]]])

    return {"t": np.round(tracks.t[rows[0]], 1),
            "s": np.stack([tracks.s[rows[0]] - cp_steps[:, 0],
                           tracks.s[rows[1]] - cp_steps[:, 1]]),
            "v": both(tracks.v), "a": both(tracks.a), "x": both(tracks.x), "y": both(tracks.y),
            "heading": both(tracks.heading)}


def _with_id(pair: Pair, k: int) -> Pair:
    from dataclasses import replace

    return replace(pair, pair=k)


def _cut(tracks: Tracks, i: int, s_at: float, reach: float):
    """Track ``i``'s path from ``s_at - reach`` to ``s_at + reach`` as a Polyline and the arc
    of its first vertex on the whole path."""
    from ..envs.external import Polyline

    rows = tracks.rows(i)
    s = tracks.s[rows]
    a = max(int(np.searchsorted(s, s_at - reach, side="right")) - 1, 0)
    b = min(int(np.searchsorted(s, s_at + reach, side="left")) + 1, s.shape[0])
    xy = np.stack([tracks.x[rows][a:b], tracks.y[rows][a:b]], axis=1)
    return Polyline.of(xy), float(s[a])


def _times_at(t: np.ndarray, s: np.ndarray, targets: Sequence[float]) -> list[float]:
    """When ``s`` (non-decreasing, at times ``t``) first reaches each of ``targets`` [m],
    interpolated linearly between samples [s]; NaN where it never does (at the first sample
    already: the moment is unobserved, NaN too). One search for all targets (a pair's few
    targets: cheaper than array operations on them)."""
    n = s.shape[0]
    out = []
    for target, k in zip(targets, np.searchsorted(s, targets, side="left").tolist()):
        if k == 0 or k == n:
            out.append(math.nan)
            continue
        ds = s[k] - s[k - 1]
        f = (target - s[k - 1]) / ds if ds > 0 else 1.0
        out.append(float(t[k - 1] + f * (t[k] - t[k - 1])))
    return out


def _near_window(t: np.ndarray, s: np.ndarray, near: float) -> tuple[float, float]:
    """The times ``s`` is within ``near`` of 0 (``s`` non-decreasing): ``(first, last)``;
    ``(inf, -inf)`` when never."""
    a = int(np.searchsorted(s, -near, side="left"))
    b = int(np.searchsorted(s, near, side="right")) - 1
    if a > b:
        return math.inf, -math.inf
    return float(t[a]), float(t[b])


def _project(tracks: Tracks, params: PairParams, i: int, j: int, kind: str, si: float,
             sj: float, angle: float) -> Pair | None:
    """The :class:`Pair` of tracks ``i`` (vehicle 1) and ``j`` whose paths meet at arcs
    ``si``, ``sj``, or None when they are not both approaching (module docstring)."""
    from ..envs.external import route_conflict

    ri, rj = tracks.rows(i), tracks.rows(j)
    ti, tj = tracks.t[ri], tracks.t[rj]
    # cheap tests first, on the kernel's meeting point: both within near_m at one time
    a0, a1 = _near_window(ti, tracks.s[ri] - si, params.near_m)
    b0, b1 = _near_window(tj, tracks.s[rj] - sj, params.near_m)
    if max(a0, b0) > min(a1, b1) + 1e-9:
        return None
    pi_, off_i = _cut(tracks, i, si, CUT_M)
    pj_, off_j = _cut(tracks, j, sj, CUT_M)
    if pi_.xy.shape[0] < 2 or pj_.xy.shape[0] < 2:
        return None
    size_i = (float(tracks.length_m[i]), float(tracks.width_m[i]))
    size_j = (float(tracks.length_m[j]), float(tracks.width_m[j]))
    rc = route_conflict(pi_, pj_, size_i, size_j, params.lateral_margin_m,
                        params.long_margin_m,
                        merge_at=(si - off_i, sj - off_j) if kind == MERGE else None,
                        step_m=params.step_m)
    if rc is None:
        return None
    cp_i, cp_j = off_i + rc.ego_at_m, off_j + rc.other_at_m
    occ = (tuple(map(float, rc.ego_occupancy)), tuple(map(float, rc.other_occupancy)))
    if (rc.kind == CROSSING and abs(si - cp_i) <= params.step_m
            and abs(sj - cp_j) <= params.step_m):
        # the exact crossing of the two centre lines (the kernel's), not route_conflict's
        # closest pair of samples step_m apart: that one is up to step_m / 2 off on each
        # path, an offset every s of the pair would carry (the intervals, widened by step_m /
        # 2 beyond the samples, are moved with the point and stay conservative)
        occ = tuple((lo + c - e, hi + c - e) for (lo, hi), c, e
                    in zip(occ, (cp_i, cp_j), (si, sj)))
        cp_i, cp_j = si, sj
    s_i, s_j = tracks.s[ri] - cp_i, tracks.s[rj] - cp_j
    # approaching: each observed before its occupancy interval, both near at one time
    if not (s_i[0] < occ[0][0] and s_j[0] < occ[1][0]):
        return None
    a0, a1 = _near_window(ti, s_i, params.near_m)
    b0, b1 = _near_window(tj, s_j, params.near_m)
    if max(a0, b0) > min(a1, b1) + 1e-9:
        return None
    # labels: when each reaches its conflict point, enters and leaves its occupancy interval
    # and the conflict area (one search per vehicle)
    area = conflict_area(rc.kind, angle, (size_i[0], size_j[0]), (size_i[1], size_j[1]))
    at_i = _times_at(ti, s_i, (0.0, *occ[0], *area[0]))
    at_j = _times_at(tj, s_j, (0.0, *occ[1], *area[1]))
    t_pass = (at_i[0], at_j[0])
    first = _first(*t_pass)
    ends = (float(ti[-1]), float(tj[-1]))
    pet = _pet_of_times((at_i[1], at_j[1]), (at_i[2], at_j[2]), ends)
    pet_area = _pet_of_times((at_i[3], at_j[3]), (at_i[4], at_j[4]), ends)
    second = {"1": 1, "2": 0}.get(first)
    if second is None:
        slowed, drop = None, math.nan
    else:
        rows = (ri, rj)[second]
        t_k, s_k = (ti, tj)[second], (s_i, s_j)[second]
        drop = _speed_drop(t_k, s_k, tracks.v[rows], params.near_m)
        slowed = bool(drop >= params.slow_drop_mps)
    # the steps both are present
    t_lo, t_hi = max(ti[0], tj[0]), min(ti[-1], tj[-1])
    n = int(round((t_hi - t_lo) / STEP_S)) + 1
    ki = int(round((t_lo - ti[0]) / STEP_S)) + np.arange(n)
    kj = int(round((t_lo - tj[0]) / STEP_S)) + np.arange(n)
    gi, gj = ri.start + ki, rj.start + kj
    xy = pi_.at(cp_i - off_i)
    return Pair(
        pair=-1, recording=str(tracks.recording[i]), kind=rc.kind,
        angle_deg=float(angle), tracks=(int(tracks.track[i]), int(tracks.track[j])),
        classes=(str(tracks.agent_class[i]), str(tracks.agent_class[j])),
        lengths_m=(size_i[0], size_j[0]), widths_m=(size_i[1], size_j[1]), occupancy=occ,
        conflict_xy=(float(xy[0]), float(xy[1])), first=first, pet_s=pet,
        pet_area_s=pet_area, t_pass_s=t_pass, second_slowed=slowed,
        second_speed_drop_mps=float(drop),
        t=np.round(ti[ki], 1), s=np.stack([s_i[ki], s_j[kj]]),
        v=np.stack([tracks.v[gi], tracks.v[gj]]), a=np.stack([tracks.a[gi], tracks.a[gj]]),
        x=np.stack([tracks.x[gi], tracks.x[gj]]), y=np.stack([tracks.y[gi], tracks.y[gj]]),
        heading=np.stack([tracks.heading[gi], tracks.heading[gj]]), index=(i, j),
        track_k0=(int(ki[0]), int(kj[0])), track_n=(int(ti.size), int(tj.size)))


def _first(t1: float, t2: float) -> str:
    if math.isnan(t1) and math.isnan(t2):
        return "neither"
    if math.isnan(t2) or t1 < t2:
        return "1"
    if math.isnan(t1) or t2 < t1:
        return "2"
    return "same time"


def conflict_area(kind: str, angle_deg: float, lengths_m: tuple[float, float],
                  widths_m: tuple[float, float]) -> tuple[tuple[float, float],
                                                          tuple[float, float]]:
    """Per vehicle, the centre positions ``(enter, leave)`` [m] (relative to its conflict
    point, along its path) at which its footprint starts and stops overlapping the conflict
    area (module docstring, ``pet_area_s``): ``(-a_k - L_k / 2, a_k + L_k / 2)``.

    ``kind``: :data:`CROSSING` or :data:`MERGE`; ``angle_deg``: the crossing angle in [0, 180]
    (0 the same direction, 90 right angles, 180 head on); ``lengths_m``, ``widths_m``: ``(L_1,
    L_2)``, ``(w_1, w_2)`` [m], at least 0. A crossing's area is the intersection of the two
    strips ``|lateral| <= w_k / 2`` about two straight paths crossing at ``theta``: along path
    ``k`` it reaches ``a_k = (w_o / 2 + |cos theta| w_k / 2) / sin theta`` either side of the
    point (its far corner, where ``k``'s outer edge meets the other strip's far edge). A
    merge's is the merge point, ``a_k = 0``. At ``sin theta = 0`` (within 1e-12) the strips are
    parallel and the area unbounded: ``(-inf, inf)``, which no vehicle ever enters or leaves.
    :class:`RecordingError` (one line) for another kind or a value out of range."""
    if kind not in (CROSSING, MERGE):
        raise RecordingError(f"kind = {kind!r} is not allowed; allowed: {CROSSING}, {MERGE}")
    for name, values in (("lengths_m", lengths_m), ("widths_m", widths_m)):
        if not all(math.isfinite(v) and v >= 0.0 for v in values):
            raise RecordingError(f"{name} = {tuple(values)!r} is out of range; allowed: two "
                                 "finite numbers >= 0 m")
    if kind == MERGE:
        return tuple((-0.5 * length, 0.5 * length) for length in lengths_m)
    if not 0.0 <= angle_deg <= 180.0:
        raise RecordingError(f"angle_deg = {angle_deg!r} is out of range; allowed: [0, 180] "
                             "degrees")
    theta = math.radians(angle_deg)
    sin, cos = math.sin(theta), abs(math.cos(theta))
    out = []
    for k in (0, 1):
        w_own, w_other = widths_m[k], widths_m[1 - k]
        # sin(pi) is 1.2e-16, not 0: parallel to the rounding of the angle
        a = (0.5 * w_other + cos * 0.5 * w_own) / sin if sin > 1e-12 else math.inf
        out.append((-a - 0.5 * lengths_m[k], a + 0.5 * lengths_m[k]))
    return tuple(out)


def post_encroachment(t1: np.ndarray, s1: np.ndarray, span1: tuple[float, float],
                      t2: np.ndarray, s2: np.ndarray, span2: tuple[float, float]) -> float:
    """Post-encroachment time [s] of two vehicles over a region each enters when its centre
    ``s`` [m] (non-decreasing, at times ``t`` [s]) reaches ``span[0]`` and leaves when it
    reaches ``span[1]`` (the occupancy intervals for ``pet_s``, :func:`conflict_area` for
    ``pet_area_s``): from the first to enter leaving to the other entering, times interpolated
    linearly between samples; 0 when both were in at once; NaN when one never enters while
    recorded (or is in at its first sample), or the first never leaves and its track ends
    before the other enters."""
    in1, out1 = _times_at(t1, s1, span1)
    in2, out2 = _times_at(t2, s2, span2)
    return _pet_of_times((in1, in2), (out1, out2), (float(t1[-1]), float(t2[-1])))


def _pet_of_times(enter: tuple[float, float], leave: tuple[float, float],
                  end: tuple[float, float]) -> float:
    """:func:`post_encroachment` from each vehicle's times [s] of entering and leaving the
    region (NaN: not seen) and the end of its track."""
    (in1, in2), (out1, out2) = enter, leave
    if math.isnan(in1) or math.isnan(in2):
        return math.nan
    if in1 <= in2:
        first_out, first_end, second_in = out1, end[0], in2
    else:
        first_out, first_end, second_in = out2, end[1], in1
    if math.isnan(first_out):
        # still inside when its track ends: inside when the other came in, if it was seen
        return 0.0 if first_end >= second_in else math.nan
    return max(second_in - first_out, 0.0)


def _speed_drop(t: np.ndarray, s: np.ndarray, v: np.ndarray, near: float) -> float:
    """The largest fall of speed below an earlier speed [m/s] over the approach: from when
    ``s >= -near`` to when ``s`` reaches 0 (or the track ends)."""
    a = int(np.searchsorted(s, -near, side="left"))
    b = min(int(np.searchsorted(s, 0.0, side="left")) + 1, s.shape[0])
    seg = v[a:b]
    if seg.size == 0:
        return 0.0
    return float(np.max(np.maximum.accumulate(seg) - seg))


# -- the projection of every candidate at once (compiled) ------------------------------------
#
# Each function below is the compiled twin of the plain function it names, on the rows
# lo:hi of the track arrays, with numpy's own arithmetic written out (searchsorted's sides,
# linspace's k * step + start, interp's slope * (x - x_j) + y_j on the last segment whose
# start is <= x, hypot from the C library as numpy's), so that the twins give the same bits;
# tests/test_recordings_pairs_speed.py pins each against the plain path.

#: What :func:`project_candidates` made of a candidate (``out[p, P_STATUS]``): not an
#: approaching pair, a pair, or left to :func:`_project` (a merge where route_conflict finds
#: no sample beside the merge point and raises).
NOT_A_PAIR, A_PAIR, PLAIN = 0.0, 1.0, 2.0
#: Columns of :func:`project_candidates`' output per candidate: the status, each vehicle's
#: conflict point on its track's path [m] (arc from its first sample), the occupancy
#: intervals [m], the conflict point ``(x, y)`` [m], when each reached it [s], ``first`` (an
#: index into :data:`FIRST_LABELS`), ``pet_s``, ``pet_area_s`` [s], the second passer (0:
#: vehicle 1, 1: vehicle 2, -1: none) and its speed drop [m/s] (NaN: none).
(P_STATUS, P_CP_1, P_CP_2, P_OCC_1_LO, P_OCC_1_HI, P_OCC_2_LO, P_OCC_2_HI, P_X, P_Y,
 P_PASS_1, P_PASS_2, P_FIRST, P_PET, P_PET_AREA, P_SECOND, P_DROP) = range(16)
N_PROJECTION = 16
#: Samples of the other path per bounding box in :func:`_route_conflict_nb`.
_BLOCK = 16


@njit(cache=True)
def _rank_nb(S, lo, hi, shift, value, inclusive):
    """``np.searchsorted(S[lo:hi] - shift, value, side)`` (``S`` non-decreasing): how many
    of ``S[k] - shift`` are below ``value`` (side ``"left"``), or at most ``value``
    (``inclusive``, side ``"right"``)."""
    a, b = lo, hi
    while a < b:
        m = (a + b) >> 1
        v = S[m] - shift
        if v < value or (inclusive and v == value):
            a = m + 1
        else:
            b = m
    return a - lo


@njit(cache=True)
def _near_window_nb(T, S, lo, hi, shift, near):
    """:func:`_near_window` of times ``T[lo:hi]`` and positions ``S[lo:hi] - shift``."""
    a = _rank_nb(S, lo, hi, shift, -near, False)
    b = _rank_nb(S, lo, hi, shift, near, True) - 1
    if a > b:
        return math.inf, -math.inf
    return T[lo + a], T[lo + b]


@njit(cache=True)
def _interp_nb(x, xp, fp, j):
    """``np.interp(x, xp, fp)`` at one point ``x`` (``xp`` non-decreasing, at least 2 long)
    and the segment it used: numpy's is the last ``j`` with ``xp[j] <= x``, however ``xp``
    repeats; the search starts from the guess ``j`` (walks on from it when ``x`` lies
    further along, as consecutive samples do; searches afresh when before it)."""
    n = xp.shape[0]
    if x < xp[0]:
        return fp[0], j
    if x > xp[n - 1]:
        return fp[n - 1], j
    if xp[j] > x:
        j = np.searchsorted(xp, x, side="right") - 1
    while j + 1 < n and xp[j + 1] <= x:
        j += 1
    if j == n - 1 or xp[j] == x:
        return fp[j], j
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    r = slope * (x - xp[j]) + fp[j]
    if np.isnan(r):  # numpy's retry from the other end of the segment
        r = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(r) and fp[j] == fp[j + 1]:
            r = fp[j]
    return r, j


@njit(cache=True)
def _samples_nb(X, Y, arc, lo, hi, step):
    """``Polyline(xy, arc).samples(lo, hi, step)``: the arcs ``np.linspace(lo, hi, n)`` and
    their points ``(s, x, y)``, each coordinate :func:`_interp_nb`'s (its arithmetic written
    out here, once per sample for both coordinates)."""
    lo, hi = max(lo, 0.0), min(hi, arc[arc.shape[0] - 1])
    n = max(2, int(math.ceil((hi - lo) / step)) + 1)
    div = n - 1
    delta = hi - lo
    dstep = delta / div
    s = np.empty(n)
    px = np.empty(n)
    py = np.empty(n)
    m = arc.shape[0]
    j = 0
    for k in range(n):
        if k == n - 1:
            v = hi
        elif dstep == 0.0:
            v = (k / div) * delta + lo
        else:
            v = k * dstep + lo
        s[k] = v
        if v < arc[0] or v > arc[m - 1] or arc[j] > v:  # off the line, or before the guess
            px[k], j = _interp_nb(v, arc, X, j)
            py[k], j = _interp_nb(v, arc, Y, j)
            continue
        while j + 1 < m and arc[j + 1] <= v:
            j += 1
        if j == m - 1 or arc[j] == v:
            px[k], py[k] = X[j], Y[j]
            continue
        ds = arc[j + 1] - arc[j]
        sx, sy = (X[j + 1] - X[j]) / ds, (Y[j + 1] - Y[j]) / ds
        rx, ry = sx * (v - arc[j]) + X[j], sy * (v - arc[j]) + Y[j]
        if rx != rx or ry != ry:  # a NaN: numpy's retry, in _interp_nb
            rx, j = _interp_nb(v, arc, X, j)
            ry, j = _interp_nb(v, arc, Y, j)
        px[k], py[k] = rx, ry
    return s, px, py


@njit(cache=True)
def _cut_nb(X, Y, S, lo, hi, s_at, reach):
    """:func:`_cut` of the track of rows ``lo:hi``: its vertices ``x``, ``y`` from ``s_at -
    reach`` to ``s_at + reach`` without repeated consecutive ones (``Polyline.of``), their
    arc from the first (the Polyline's ``arc``), and the whole track's arc at the first."""
    n = hi - lo
    a = max(_rank_nb(S, lo, hi, 0.0, s_at - reach, True) - 1, 0)
    b = min(_rank_nb(S, lo, hi, 0.0, s_at + reach, False) + 1, n)
    cx = np.empty(max(b - a, 0))
    cy = np.empty(max(b - a, 0))
    m = 0
    for k in range(lo + a, lo + b):
        if m == 0 or X[k] != cx[m - 1] or Y[k] != cy[m - 1]:
            cx[m], cy[m] = X[k], Y[k]
            m += 1
    arc = np.empty(m)
    if m:
        arc[0] = 0.0
    for k in range(1, m):
        arc[k] = arc[k - 1] + math.hypot(cx[k] - cx[k - 1], cy[k] - cy[k - 1])
    return cx[:m], cy[:m], arc, S[lo + a]


@njit(cache=True)
def _route_conflict_nb(xe, ye, arc_e, xo, yo, arc_o, l_e, w_e, l_o, w_o, lateral, longit,
                       step, merge, a0, b0, res):
    """``persuasive.envs.external.route_conflict`` of the ego's path ``(xe, ye, arc_e)`` and
    the other's, sizes ``(l, w)`` [m], margins and step [m], a merge at arcs ``(a0, b0)``
    where ``merge``: 0 for no conflict (None), else 1 with ``res`` = ``(ego_at_m,
    other_at_m, ego_occupancy, other_occupancy)``, or 2 where route_conflict raises (no
    sample of the ego beside the merge point). The pairs of samples within reach are taken
    ego sample by ego sample, the other's in order, as route_conflict takes them (its
    closest pair is the first of the closest)."""
    reach = 0.5 * (w_e + w_o) + lateral + step
    widen_e = 0.5 * l_e + 0.5 * step + longit
    widen_o = 0.5 * l_o + 0.5 * step + longit
    if merge:
        s_e, pxe, pye = _samples_nb(xe, ye, arc_e, 0.0, a0 + 0.5 * l_e + step, step)
        s_o, pxo, pyo = _samples_nb(xo, yo, arc_o, 0.0, b0 + 0.5 * l_e + reach + step, step)
    else:
        s_e, pxe, pye = _samples_nb(xe, ye, arc_e, 0.0, arc_e[arc_e.shape[0] - 1], step)
        s_o, pxo, pyo = _samples_nb(xo, yo, arc_o, 0.0, arc_o[arc_o.shape[0] - 1], step)
    r2 = reach * reach
    side_at = a0 + 0.5 * l_e + 0.5 * step
    n_o = s_o.shape[0]
    # the other's samples in blocks with bounding boxes: a box's gap to a point is never more
    # than the distance of any of its samples, rounded too, so a box out of reach holds none
    nb = (n_o + _BLOCK - 1) // _BLOCK
    box = np.empty((nb, 4))
    for c in range(nb):
        k0 = c * _BLOCK
        box[c, 0], box[c, 1], box[c, 2], box[c, 3] = pxo[k0], pyo[k0], pxo[k0], pyo[k0]
        for k in range(k0 + 1, min(k0 + _BLOCK, n_o)):
            box[c, 0] = min(box[c, 0], pxo[k])
            box[c, 1] = min(box[c, 1], pyo[k])
            box[c, 2] = max(box[c, 2], pxo[k])
            box[c, 3] = max(box[c, 3], pyo[k])
    # and all of them in one box: most ego samples of a crossing are out of its reach
    bx0, by0, bx1, by1 = box[0, 0], box[0, 1], box[0, 2], box[0, 3]
    for c in range(1, nb):
        bx0, by0 = min(bx0, box[c, 0]), min(by0, box[c, 1])
        bx1, by1 = max(bx1, box[c, 2]), max(by1, box[c, 3])
    found = False
    a_min, a_max, b_min, b_max = math.inf, -math.inf, math.inf, -math.inf
    best, best_a, best_b = math.inf, 0.0, 0.0
    lo_e, any_before = math.inf, False
    side_lo, side_hi, any_side = math.inf, -math.inf, False
    for i in range(s_e.shape[0]):
        px, py, a = pxe[i], pye[i], s_e[i]
        gx = max(max(bx0 - px, px - bx1), 0.0)
        gy = max(max(by0 - py, py - by1), 0.0)
        if gx * gx + gy * gy > r2:
            continue
        for c in range(nb):
            gx = max(max(box[c, 0] - px, px - box[c, 2]), 0.0)
            gy = max(max(box[c, 1] - py, py - box[c, 3]), 0.0)
            if gx * gx + gy * gy > r2:
                continue
            for j in range(c * _BLOCK, min(c * _BLOCK + _BLOCK, n_o)):
                dx, dy = pxo[j] - px, pyo[j] - py
                if not dx * dx + dy * dy <= r2:  # the k-d tree's test, as route_conflict's
                    continue
                b = s_o[j]
                found = True
                if merge:
                    if a <= a0:
                        any_before = True
                        lo_e = min(lo_e, a)
                    if a <= side_at:
                        any_side = True
                        side_lo, side_hi = min(side_lo, b), max(side_hi, b)
                else:
                    a_min, a_max = min(a_min, a), max(a_max, a)
                    b_min, b_max = min(b_min, b), max(b_max, b)
                    d = math.hypot(px - pxo[j], py - pyo[j])
                    if d < best:
                        best, best_a, best_b = d, a, b
    if not found:
        return 0
    if merge:
        if not any_side:
            return 2
        if not any_before:
            lo_e = a0
        res[0], res[1] = a0, b0
        res[2], res[3] = lo_e - widen_e - a0, 0.0
        res[4], res[5] = side_lo - widen_o - b0, side_hi + widen_o - b0
        return 1
    res[0], res[1] = best_a, best_b
    res[2], res[3] = a_min - widen_e - best_a, a_max + widen_e - best_a
    res[4], res[5] = b_min - widen_o - best_b, b_max + widen_o - best_b
    return 1


@njit(cache=True)
def _time_at_nb(T, S, lo, hi, shift, target):
    """:func:`_times_at` of one ``target`` [m] on times ``T[lo:hi]`` and positions
    ``S[lo:hi] - shift``."""
    n = hi - lo
    k = _rank_nb(S, lo, hi, shift, target, False)
    if k == 0 or k == n:
        return math.nan
    s1, s0 = S[lo + k] - shift, S[lo + k - 1] - shift
    ds = s1 - s0
    f = (target - s0) / ds if ds > 0 else 1.0
    return T[lo + k - 1] + f * (T[lo + k] - T[lo + k - 1])


@njit(cache=True)
def _pet_of_times_nb(in1, in2, out1, out2, end1, end2):
    """:func:`_pet_of_times` of ``((in1, in2), (out1, out2), (end1, end2))``."""
    if math.isnan(in1) or math.isnan(in2):
        return math.nan
    if in1 <= in2:
        first_out, first_end, second_in = out1, end1, in2
    else:
        first_out, first_end, second_in = out2, end2, in1
    if math.isnan(first_out):
        return 0.0 if first_end >= second_in else math.nan
    return max(second_in - first_out, 0.0)


@njit(cache=True)
def _speed_drop_nb(S, V, lo, hi, shift, near):
    """:func:`_speed_drop` of speeds ``V[lo:hi]`` on positions ``S[lo:hi] - shift`` (a NaN
    speed propagates, as through ``np.maximum.accumulate`` and ``np.max``)."""
    n = hi - lo
    a = _rank_nb(S, lo, hi, shift, -near, False)
    b = min(_rank_nb(S, lo, hi, shift, 0.0, False) + 1, n)
    if b <= a:
        return 0.0
    top = V[lo + a]
    drop = top - top
    for k in range(lo + a, lo + b):
        v = V[k]
        if not top >= v and not math.isnan(top):  # np.maximum(top, v): v if larger or NaN
            top = v
        d = top - v
        if not drop >= d and not math.isnan(drop):
            drop = d
    return drop


@njit(cache=True, parallel=True)
def project_candidates(T, X, Y, S, V, starts, length, width, vi, vj, merge, si, sj, area,
                       near, lateral, longit, step, out):
    """:func:`_project` of every candidate ``p``, into ``out`` ``(n, N_PROJECTION)``
    (:data:`P_STATUS` ...): vehicle 1 is track ``vi[p]``, vehicle 2 track ``vj[p]``, a merge
    where ``merge[p]``, their paths meeting at arcs ``si[p]``, ``sj[p]`` [m]; ``area[p]``:
    :func:`conflict_area`'s ``(enter_1, leave_1, enter_2, leave_2)`` [m]. The tracks: times
    ``T``, centres ``X``, ``Y``, arcs ``S``, speeds ``V`` per sample, ``starts``, ``length``,
    ``width`` per track (:class:`Tracks`); ``near``, ``lateral``, ``longit``, ``step``:
    :class:`PairParams`' ``near_m``, ``lateral_margin_m``, ``long_margin_m``, ``step_m``."""
    for p in prange(vi.shape[0]):
        for c in range(N_PROJECTION):
            out[p, c] = math.nan
        out[p, P_STATUS] = NOT_A_PAIR
        i, j = vi[p], vj[p]
        lo_i, hi_i, lo_j, hi_j = starts[i], starts[i + 1], starts[j], starts[j + 1]
        s_i, s_j = si[p], sj[p]
        # cheap tests first, on the kernel's meeting point: both within near_m at one time
        a0, a1 = _near_window_nb(T, S, lo_i, hi_i, s_i, near)
        b0, b1 = _near_window_nb(T, S, lo_j, hi_j, s_j, near)
        if max(a0, b0) > min(a1, b1) + 1e-9:
            continue
        xi, yi, arc_i, off_i = _cut_nb(X, Y, S, lo_i, hi_i, s_i, CUT_M)
        xj, yj, arc_j, off_j = _cut_nb(X, Y, S, lo_j, hi_j, s_j, CUT_M)
        if xi.shape[0] < 2 or xj.shape[0] < 2:
            continue
        res = np.empty(6)
        got = _route_conflict_nb(xi, yi, arc_i, xj, yj, arc_j, length[i], width[i],
                                 length[j], width[j], lateral, longit, step, merge[p],
                                 s_i - off_i, s_j - off_j, res)
        if got == 0:
            continue
        if got == 2:
            out[p, P_STATUS] = PLAIN
            continue
        cp_i, cp_j = off_i + res[0], off_j + res[1]
        o1_lo, o1_hi, o2_lo, o2_hi = res[2], res[3], res[4], res[5]
        if not merge[p] and abs(s_i - cp_i) <= step and abs(s_j - cp_j) <= step:
            # the exact crossing of the two centre lines (_project says why)
            o1_lo, o1_hi = o1_lo + cp_i - s_i, o1_hi + cp_i - s_i
            o2_lo, o2_hi = o2_lo + cp_j - s_j, o2_hi + cp_j - s_j
            cp_i, cp_j = s_i, s_j
        # approaching: each observed before its occupancy interval, both near at one time
        if not (S[lo_i] - cp_i < o1_lo and S[lo_j] - cp_j < o2_lo):
            continue
        a0, a1 = _near_window_nb(T, S, lo_i, hi_i, cp_i, near)
        b0, b1 = _near_window_nb(T, S, lo_j, hi_j, cp_j, near)
        if max(a0, b0) > min(a1, b1) + 1e-9:
            continue
        # the labels
        pass_i = _time_at_nb(T, S, lo_i, hi_i, cp_i, 0.0)
        pass_j = _time_at_nb(T, S, lo_j, hi_j, cp_j, 0.0)
        end_i, end_j = T[hi_i - 1], T[hi_j - 1]
        pet = _pet_of_times_nb(_time_at_nb(T, S, lo_i, hi_i, cp_i, o1_lo),
                               _time_at_nb(T, S, lo_j, hi_j, cp_j, o2_lo),
                               _time_at_nb(T, S, lo_i, hi_i, cp_i, o1_hi),
                               _time_at_nb(T, S, lo_j, hi_j, cp_j, o2_hi), end_i, end_j)
        pet_area = _pet_of_times_nb(_time_at_nb(T, S, lo_i, hi_i, cp_i, area[p, 0]),
                                    _time_at_nb(T, S, lo_j, hi_j, cp_j, area[p, 2]),
                                    _time_at_nb(T, S, lo_i, hi_i, cp_i, area[p, 1]),
                                    _time_at_nb(T, S, lo_j, hi_j, cp_j, area[p, 3]),
                                    end_i, end_j)
        if math.isnan(pass_i) and math.isnan(pass_j):  # _first
            first = 3
        elif math.isnan(pass_j) or pass_i < pass_j:
            first = 0
        elif math.isnan(pass_i) or pass_j < pass_i:
            first = 1
        else:
            first = 2
        out[p, P_SECOND] = -1.0
        if first == 0:  # vehicle 1 first: vehicle 2 is the second passer
            out[p, P_SECOND] = 1.0
            out[p, P_DROP] = _speed_drop_nb(S, V, lo_j, hi_j, cp_j, near)
        elif first == 1:
            out[p, P_SECOND] = 0.0
            out[p, P_DROP] = _speed_drop_nb(S, V, lo_i, hi_i, cp_i, near)
        out[p, P_STATUS] = A_PAIR
        out[p, P_CP_1], out[p, P_CP_2] = cp_i, cp_j
        out[p, P_OCC_1_LO], out[p, P_OCC_1_HI] = o1_lo, o1_hi
        out[p, P_OCC_2_LO], out[p, P_OCC_2_HI] = o2_lo, o2_hi
        out[p, P_X] = _interp_nb(cp_i - off_i, arc_i, xi, 0)[0]
        out[p, P_Y] = _interp_nb(cp_i - off_i, arc_i, yi, 0)[0]
        out[p, P_PASS_1], out[p, P_PASS_2] = pass_i, pass_j
        out[p, P_FIRST] = first
        out[p, P_PET], out[p, P_PET_AREA] = pet, pet_area


# -- the pairs file --------------------------------------------------------------------------

#: The pair-level columns of the pairs file (repeated on each of the pair's rows).
PAIR_COLUMNS = ("pair", "recording", "kind", "angle_deg", "track_1", "track_2", "class_1",
                "class_2", "length_1_m", "width_1_m", "length_2_m", "width_2_m",
                "occupancy_1_lo_m", "occupancy_1_hi_m", "occupancy_2_lo_m", "occupancy_2_hi_m",
                "conflict_x_m", "conflict_y_m", "first", "pet_s", "pet_area_s", "t_pass_1_s",
                "t_pass_2_s", "second_slowed", "second_speed_drop_mps")
#: Pair columns that files written before them lack; :func:`read_pairs` reads them as NaN
#: (``pet_area_s``: write the pairs again to have it).
LATER_PAIR_COLUMNS = ("pet_area_s",)
#: Where the steps lie in each vehicle's track (per pair; optional when read: pairs files
#: written before them have none, and their fit filters every step as an interior one).
TRACK_COLUMNS = ("track_k0_1", "track_n_1", "track_k0_2", "track_n_2")
#: The junction's rule from a map (per pair; optional when read: files written before them
#: read as "unknown", no map).
MAP_COLUMNS = ("control", "priority", "stop_1_m", "stop_2_m")
#: The step columns (one row per pair and step).
STEP_COLUMNS = ("step", "t_s", "s_1_m", "v_1_mps", "a_1_mps2", "x_1_m", "y_1_m",
                "heading_1_rad", "s_2_m", "v_2_mps", "a_2_mps2", "x_2_m", "y_2_m",
                "heading_2_rad")


def pairs_frame(pairs: Sequence[Pair]):
    """One row per pair and step: :data:`PAIR_COLUMNS`, :data:`TRACK_COLUMNS`,
    :data:`MAP_COLUMNS`, then :data:`STEP_COLUMNS`."""
    import pandas as pd

    def text(name, values, rows):
        # typed as pandas types a column of Python strings (pandas 3: its string type), once
        # per pair, then repeated by a take: the same column, without a string per row
        return pd.Series(np.asarray(values, dtype=object)).array.take(rows)

    def flags(values, rows):
        return pd.array(np.array(values, dtype=object), dtype="boolean").take(rows)

    return pd.DataFrame(_columns(pairs, text, flags),
                        columns=[*PAIR_COLUMNS, *TRACK_COLUMNS, *MAP_COLUMNS, *STEP_COLUMNS])


def pairs_table(pairs: Sequence[Pair]):
    """``pa.Table.from_pandas(pairs_frame(pairs), preserve_index=False)`` (the table the
    pairs file holds: the same schema, pandas' metadata included, and the same arrays) built
    from the pairs' arrays without the frame: the text and flag columns as Arrow arrays per
    pair repeated by a take, the numbers as they are."""
    import pyarrow as pa

    if not pairs:
        return pa.Table.from_pandas(pairs_frame(pairs), preserve_index=False)
    # the schema pandas gives these columns (their types depend on pandas' version only)
    schema = pa.Table.from_pandas(pairs_frame(pairs[:1]), preserve_index=False).schema

    def text(name, values, rows):
        return pa.array(values, type=schema.field(name).type).take(rows)

    def flags(values, rows):
        return pa.array(values, type=pa.bool_()).take(rows)

    cols = _columns(pairs, text, flags)
    # a NaN is a null, as in pandas' table (from_pandas=True); integers are taken as they are
    return pa.Table.from_arrays([
        cols[f.name] if not isinstance(cols[f.name], np.ndarray)
        else pa.array(cols[f.name], from_pandas=cols[f.name].dtype.kind == "f")
        for f in schema], schema=schema)


def _columns(pairs: Sequence[Pair], text, flags) -> dict:
    """The columns of :func:`pairs_frame` by name: numbers as arrays; the text columns
    (``recording``, ``first``...) as ``text(name, values, rows)`` and the flags
    (``second_slowed``) as ``flags(values, rows)`` make them from one value per pair and each
    row's pair."""
    n = np.array([p.n_steps for p in pairs], np.int64)
    of_row = np.repeat(np.arange(len(pairs)), n)

    def rep(values, dtype=None):
        return np.repeat(np.asarray(values, dtype=dtype), n)

    def per_pair(name, values):
        return text(name, values, of_row)

    def cat(get):
        return np.concatenate([get(p) for p in pairs]) if pairs else np.zeros(0)

    cols = {
        "pair": rep([p.pair for p in pairs], np.int64),
        "recording": per_pair("recording", [p.recording for p in pairs]),
        "kind": per_pair("kind", [p.kind for p in pairs]),
        "angle_deg": rep([p.angle_deg for p in pairs], float),
        "track_1": rep([p.tracks[0] for p in pairs], np.int64),
        "track_2": rep([p.tracks[1] for p in pairs], np.int64),
        "class_1": per_pair("class_1", [p.classes[0] for p in pairs]),
        "class_2": per_pair("class_2", [p.classes[1] for p in pairs]),
        "length_1_m": rep([p.lengths_m[0] for p in pairs], float),
        "width_1_m": rep([p.widths_m[0] for p in pairs], float),
        "length_2_m": rep([p.lengths_m[1] for p in pairs], float),
        "width_2_m": rep([p.widths_m[1] for p in pairs], float),
        "occupancy_1_lo_m": rep([p.occupancy[0][0] for p in pairs], float),
        "occupancy_1_hi_m": rep([p.occupancy[0][1] for p in pairs], float),
        "occupancy_2_lo_m": rep([p.occupancy[1][0] for p in pairs], float),
        "occupancy_2_hi_m": rep([p.occupancy[1][1] for p in pairs], float),
        "conflict_x_m": rep([p.conflict_xy[0] for p in pairs], float),
        "conflict_y_m": rep([p.conflict_xy[1] for p in pairs], float),
        "first": per_pair("first", [p.first for p in pairs]),
        "pet_s": rep([p.pet_s for p in pairs], float),
        "pet_area_s": rep([p.pet_area_s for p in pairs], float),
        "t_pass_1_s": rep([p.t_pass_s[0] for p in pairs], float),
        "t_pass_2_s": rep([p.t_pass_s[1] for p in pairs], float),
        "second_slowed": flags([p.second_slowed for p in pairs], of_row),
        "second_speed_drop_mps": rep([p.second_speed_drop_mps for p in pairs], float),
        **{f"track_{what}_{k + 1}": rep([getattr(p, f"track_{what}")[k] for p in pairs],
                                        np.int64)
           for k in (0, 1) for what in ("k0", "n")},
        "control": per_pair("control", [p.control for p in pairs]),
        "priority": rep([p.priority for p in pairs], np.int64),
        "stop_1_m": rep([p.stop_s[0] for p in pairs], float),
        "stop_2_m": rep([p.stop_s[1] for p in pairs], float),
        "step": np.arange(of_row.shape[0], dtype=np.int64) - np.repeat(np.cumsum(n) - n, n),
        "t_s": cat(lambda p: p.t),
    }
    for k in (0, 1):
        tag = k + 1
        cols[f"s_{tag}_m"] = cat(lambda p: p.s[k])
        cols[f"v_{tag}_mps"] = cat(lambda p: p.v[k])
        cols[f"a_{tag}_mps2"] = cat(lambda p: p.a[k])
        cols[f"x_{tag}_m"] = cat(lambda p: p.x[k])
        cols[f"y_{tag}_m"] = cat(lambda p: p.y[k])
        cols[f"heading_{tag}_rad"] = cat(lambda p: p.heading[k])
    return cols


def write_pairs(path, result: PairsResult, sources: Sequence[str]) -> None:
    """Write the pairs file (Parquet, atomically): :func:`pairs_frame` with the parameters,
    the smoothing and the source files in its metadata (:data:`PAIRS_METADATA`)."""
    import json
    from dataclasses import asdict

    import pyarrow as pa
    import pyarrow.parquet as pq

    from .._files import atomic_write
    from .._version import __version__

    table = pa.Table.from_pandas(pairs_frame(result.pairs), preserve_index=False)
    meta = {"params": asdict(result.params), "sources": [str(s) for s in sources],
            "n_pairs": len(result.pairs), "candidates": result.candidates,
            "vehicle_tracks": result.tracks.n_tracks, "version": __version__,
            "step_s": STEP_S, "smoothing": asdict(result.tracks.params),
            "map": result.road_map}
    table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                           PAIRS_METADATA: json.dumps(meta)})
    atomic_write(path, lambda p: pq.write_table(table, p))


def read_pairs(path, columns=None):
    """The pairs file ``path`` as ``(frame, metadata)``; :class:`RecordingError` (one line
    naming it) when it is not one. Columns of :data:`LATER_PAIR_COLUMNS` a file lacks are
    NaN. ``frame.attrs["smoothing"]``: the tracks' filter
    (:class:`~persuasive.recordings.tracks.SmoothingParams` as a dict; None for a file written
    before it was recorded), which the fit's measurement model needs.

    ``columns``: read only these (those the file has, and of :data:`LATER_PAIR_COLUMNS` the
    ones asked for, NaN where missing), text columns as categories and each column freed as it
    is converted: a site's file, 5.6 million step rows, read whole, takes 5.5 GB."""
    import json
    from pathlib import Path

    import pyarrow as pa
    import pyarrow.parquet as pq

    from .formats import file_head

    name = str(path)
    if file_head(path, 4, "pairs file") != b"PAR1":
        raise RecordingError(f"pairs file {name!r} is not a Parquet file (write it with "
                             "'persuasive recordings pairs PATHS... --out FILE.parquet')")
    try:
        pf = pq.ParquetFile(Path(path))
        schema = pf.schema_arrow
        # a file written part by part (persuasive.recordings.streaming) holds its final
        # metadata among the file's key-value metadata, the schema's being the one it
        # started with
        raw = (pf.metadata.metadata or {}).get(PAIRS_METADATA) or \
            (schema.metadata or {}).get(PAIRS_METADATA)
        missing = [c for c in (*PAIR_COLUMNS, *STEP_COLUMNS)
                   if c not in schema.names and c not in LATER_PAIR_COLUMNS]
        if raw is None or missing:
            raise RecordingError(f"pairs file {name!r} is not a pairs file (write it with "
                                 "'persuasive recordings pairs PATHS... --out FILE.parquet')")
        if columns is None:
            frame = pq.read_table(Path(path)).to_pandas()
        else:
            cols = [c for c in columns if c in schema.names]
            text = [c for c in cols if pa.types.is_string(schema.field(c).type)
                    or pa.types.is_large_string(schema.field(c).type)]
            table = pq.read_table(Path(path), columns=cols, read_dictionary=text)
            frame = table.to_pandas(split_blocks=True, self_destruct=True)
            del table
    except RecordingError:
        raise
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several kinds for a bad file
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RecordingError(f"pairs file {name!r} cannot be read: {text}") from None
    if frame.empty:
        raise RecordingError(f"pairs file {name!r} holds no pair")
    for col in LATER_PAIR_COLUMNS:
        if col not in frame and (columns is None or col in columns):
            # a file written before the column: NaN, in its place
            before = PAIR_COLUMNS[PAIR_COLUMNS.index(col) - 1]
            at = frame.columns.get_loc(before) + 1 if before in frame else len(frame.columns)
            frame.insert(at, col, math.nan)
    meta = json.loads(raw)
    # the filter its accelerations went through (files of before it was kept: unknown)
    frame.attrs["smoothing"] = meta.get("smoothing")
    return frame, meta


@dataclass(frozen=True)
class PairLabels:
    """What :func:`summary_of` reads of a pair (a pair without its steps)."""

    kind: str
    angle_deg: float
    pet_s: float
    pet_area_s: float
    first: str
    second_slowed: bool | None
    control: str

    @classmethod
    def of(cls, pair: Pair) -> PairLabels:
        return cls(pair.kind, pair.angle_deg, pair.pet_s, pair.pet_area_s, pair.first,
                   pair.second_slowed, pair.control)


def summary(result: PairsResult) -> dict:
    """Counts and distributions of a set of pairs (what ``recordings pairs`` prints). The
    PETs' quantiles [s] over the pairs that define them: ``pet_area_quantiles_s`` of
    ``pet_area_s`` (at the conflict area), ``pet_quantiles_s`` of ``pet_s`` (on the
    occupancy intervals); ``pet_area_defined``, ``pet_defined``: how many pairs define
    each."""
    return summary_of(result.pairs, result.tracks.n_tracks,
                      int(np.unique(result.tracks.recording).size), result.candidates)


def summary_of(pairs: Sequence, vehicle_tracks: int, recordings: int, candidates: int) -> dict:
    """:func:`summary` from the pairs' labels alone (objects with ``kind``, ``angle_deg``,
    ``pet_s``, ``pet_area_s``, ``first``, ``second_slowed`` and ``control``, such as
    :class:`Pair` or :class:`PairLabels`) and the counts of tracks, recordings and candidate
    pairs they came from."""
    kinds = [p.kind for p in pairs]
    angles = np.array([p.angle_deg for p in pairs if p.kind == CROSSING])
    merge_angles = np.array([p.angle_deg for p in pairs if p.kind == MERGE])

    def defined(values):
        values = np.array(values, float)
        return values[np.isfinite(values)]

    def quantiles(values):
        return {f"{q}%": float(np.percentile(values, q)) for q in (5, 25, 50, 75, 95)} \
            if values.size else {}

    pet = defined([p.pet_s for p in pairs])
    pet_area = defined([p.pet_area_s for p in pairs])
    edges = np.arange(0.0, 181.0, 20.0)
    hist = np.histogram(angles, edges)[0] if angles.size else np.zeros(edges.size - 1, int)
    slowed = [p.second_slowed for p in pairs if p.second_slowed is not None]
    return {
        "vehicle_tracks": int(vehicle_tracks),
        "recordings": int(recordings),
        "candidates": int(candidates),
        "pairs": len(pairs),
        "crossing": kinds.count(CROSSING),
        "merge": kinds.count(MERGE),
        "angle_histogram": {f"{int(a)}-{int(b)}": int(c) for a, b, c in
                            zip(edges[:-1], edges[1:], hist) if c},
        "merge_angle_median_deg": float(np.median(merge_angles)) if merge_angles.size
        else None,
        "pet_area_defined": int(pet_area.size),
        "pet_area_quantiles_s": quantiles(pet_area),
        "pet_defined": int(pet.size),
        "pet_quantiles_s": quantiles(pet),
        "first": {label: sum(p.first == label for p in pairs) for label in FIRST_LABELS},
        "second_slowed": int(sum(slowed)),
        "second_known": len(slowed),
        "control": {c: n for c in ("right_of_way", "all_way_stop", "none", "unknown")
                    if (n := sum(p.control == c for p in pairs))},
    }


def pair_of(result: PairsResult, pair_id: int) -> Pair:
    """Pair ``pair_id`` of ``result``; :class:`RecordingError` when there is none."""
    for p in result.pairs:
        if p.pair == pair_id:
            return p
    raise RecordingError(f"--pair = {pair_id} is out of range; allowed: a pair ID in "
                         f"[0, {len(result.pairs) - 1}]")


__all__ = ["CROSSING", "FIRST_LABELS", "LATER_PAIR_COLUMNS", "MAP_COLUMNS", "MERGE",
           "PAIRS_METADATA", "PAIR_COLUMNS", "Pair", "PairLabels", "PairParams", "PairsResult",
           "STEP_COLUMNS", "TRACK_COLUMNS", "candidates", "conflict_area", "find_pairs",
           "meetings", "pair_of", "pairs_frame", "pairs_table", "post_encroachment",
           "project_candidates", "read_pairs", "summary", "summary_of", "write_pairs"]
