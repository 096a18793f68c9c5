"""Where two recorded paths meet: the compiled search for crossings and merges between the
smoothed tracks of :mod:`persuasive.recordings.tracks` (docs/guide/recordings.md).

Each track is its own path: the polyline through its smoothed 10 Hz centres, parameterised by
its arc length ``s``. For a candidate pair ``(i, j)`` (same recording, overlapping times,
overlapping bounding boxes) :func:`pair_geometry` finds, with no Python per pair:

- **a crossing**: the first proper intersection of the two polylines, in ``i``'s order, whose
  crossing angle lies in ``[angle_lo, angle_hi]`` degrees. The angle is the one between the
  two directions of travel, each taken over ``+-DIRECTION_M`` of arc around the point (0:
  same direction, 90: at right angles, 180: head on);
- **a merge of ``j`` into ``i``'s path** (and of ``i`` into ``j``'s): ``j`` is first *beside*
  ``i``'s path (a vertex between ``apart`` and ``3 apart`` from it whose nearest point lies
  inside ``i``'s path, not at its ends: ``i``'s path exists alongside), then *on* it (within
  ``gap``) for at least ``run`` metres of ``j``'s arc without leaving it. The merge point is
  ``j``'s first vertex of that run and its nearest point on ``i``; the merge angle is the one
  between ``j``'s direction over the ``MERGE_APPROACH_M`` before its merge point and ``i``'s
  direction at its own.

Both polylines are cut into chunks of :data:`CHUNK` segments with bounding boxes, so only
chunks that come near each other are compared segment by segment.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: Segments per chunk of a polyline (the unit of the bounding-box pruning).
CHUNK = 8
#: Half the arc over which a direction of travel is taken at a crossing [m].
DIRECTION_M = 5.0
#: The arc before a merge point over which the merging vehicle's approach direction is
#: taken [m].
MERGE_APPROACH_M = 10.0
#: Outputs of :func:`pair_geometry`, per pair (columns of ``out``).
(G_CROSS, G_CROSS_SI, G_CROSS_SJ, G_CROSS_ANGLE, G_MERGE_JI, G_MERGE_JI_SJ, G_MERGE_JI_SI,
 G_MERGE_JI_ANGLE, G_MERGE_IJ, G_MERGE_IJ_SI, G_MERGE_IJ_SJ, G_MERGE_IJ_ANGLE) = range(12)
N_GEOMETRY = 12


@njit(cache=True)
def chunk_boxes(X, Y, starts, chunk):
    """Chunks of ``chunk`` segments per track: ``cstart`` ``(n_tracks + 1,)`` (track ``i``'s
    chunks are ``cstart[i]:cstart[i + 1]``), ``v0``, ``v1`` ``(n_chunks,)`` (a chunk's first
    and last vertex) and ``box`` ``(n_chunks, 4)`` (x0, y0, x1, y1) [m]."""
    n_tracks = starts.shape[0] - 1
    cstart = np.zeros(n_tracks + 1, np.int64)
    for i in range(n_tracks):
        n_seg = starts[i + 1] - starts[i] - 1
        cstart[i + 1] = cstart[i] + max(1, (n_seg + chunk - 1) // chunk)
    n = cstart[-1]
    v0 = np.empty(n, np.int64)
    v1 = np.empty(n, np.int64)
    box = np.empty((n, 4))
    for i in range(n_tracks):
        end = starts[i + 1] - 1
        for c in range(cstart[i], cstart[i + 1]):
            a = starts[i] + (c - cstart[i]) * chunk
            b = min(a + chunk, end)
            v0[c], v1[c] = a, b
            box[c, 0], box[c, 1] = X[a], Y[a]
            box[c, 2], box[c, 3] = X[a], Y[a]
            for k in range(a + 1, b + 1):
                box[c, 0] = min(box[c, 0], X[k])
                box[c, 1] = min(box[c, 1], Y[k])
                box[c, 2] = max(box[c, 2], X[k])
                box[c, 3] = max(box[c, 3], Y[k])
    return cstart, v0, v1, box


@njit(cache=True)
def _box_gap(box, a, b):
    """Distance between the boxes of chunks ``a`` and ``b`` (0 when they overlap) [m]."""
    dx = max(0.0, max(box[a, 0], box[b, 0]) - min(box[a, 2], box[b, 2]))
    dy = max(0.0, max(box[a, 1], box[b, 1]) - min(box[a, 3], box[b, 3]))
    return math.sqrt(dx * dx + dy * dy)


@njit(cache=True)
def _point_at(X, Y, S, lo, hi, s):
    """The point at arc ``s`` of the polyline of vertices ``lo..hi-1`` (clamped)."""
    if s <= S[lo]:
        return X[lo], Y[lo]
    if s >= S[hi - 1]:
        return X[hi - 1], Y[hi - 1]
    k = lo + np.searchsorted(S[lo:hi], s)
    ds = S[k] - S[k - 1]
    f = (s - S[k - 1]) / ds if ds > 0.0 else 1.0
    return X[k - 1] + f * (X[k] - X[k - 1]), Y[k - 1] + f * (Y[k] - Y[k - 1])


@njit(cache=True)
def _direction(X, Y, S, lo, hi, s0, s1):
    """Unit vector from the point at arc ``s0`` to that at ``s1`` ((0, 0) if they meet)."""
    x0, y0 = _point_at(X, Y, S, lo, hi, s0)
    x1, y1 = _point_at(X, Y, S, lo, hi, s1)
    d = math.hypot(x1 - x0, y1 - y0)
    if d == 0.0:
        return 0.0, 0.0
    return (x1 - x0) / d, (y1 - y0) / d


@njit(cache=True)
def _angle_deg(ux, uy, wx, wy):
    c = max(-1.0, min(1.0, ux * wx + uy * wy))
    return math.degrees(math.acos(c))


@njit(cache=True)
def _nearest(X, Y, S, px, py, cs, ce, v0, v1, box, reach, first, last):
    """The nearest point to ``(px, py)`` on the chunks ``cs..ce-1`` within ``reach``:
    ``(distance, arc there, interior)``; ``interior``: it is not the polyline's first or last
    vertex (``first``, ``last``). Distance ``inf`` when no chunk is in reach."""
    best, best_s, best_k, best_f = math.inf, 0.0, -1, 0.0
    for c in range(cs, ce):
        dx = max(0.0, max(box[c, 0] - px, px - box[c, 2]))
        dy = max(0.0, max(box[c, 1] - py, py - box[c, 3]))
        if dx * dx + dy * dy >= best * best or math.sqrt(dx * dx + dy * dy) > reach:
            continue
        for k in range(v0[c], v1[c]):
            ax, ay = X[k + 1] - X[k], Y[k + 1] - Y[k]
            L2 = ax * ax + ay * ay
            f = 0.0 if L2 == 0.0 else ((px - X[k]) * ax + (py - Y[k]) * ay) / L2
            f = min(1.0, max(0.0, f))
            qx, qy = X[k] + f * ax, Y[k] + f * ay
            d = math.hypot(px - qx, py - qy)
            if d < best:
                best, best_k, best_f = d, k, f
                best_s = S[k] + f * (S[k + 1] - S[k])
    interior = best_k >= 0 and not ((best_k == first and best_f == 0.0)
                                    or (best_k == last - 1 and best_f == 1.0))
    return best, best_s, interior


@njit(cache=True)
def _merge_into(X, Y, S, starts, cstart, v0, v1, box, i, j, gap, apart, run):
    """Does ``j`` merge into ``i``'s path (module docstring)? ``(found, s_j, s_i, angle)``.

    ``j``'s vertices are taken in order and the search stops at the first stretch of ``run``
    metres on ``i``'s path: a merge if ``j`` was beside the path before it, else ``j`` was on
    it from its first contact (a follower, not a merge)."""
    lo_i, hi_i = starts[i], starts[i + 1]
    lo_j, hi_j = starts[j], starts[j + 1]
    reach = 3.0 * apart
    seen_apart = False
    run_start, run_proj = -1, 0.0
    for cb in range(cstart[j], cstart[j + 1]):
        close = False
        for ca in range(cstart[i], cstart[i + 1]):
            if _box_gap(box, ca, cb) <= reach:
                close = True
                break
        first_m = v0[cb] if cb == cstart[j] else v0[cb] + 1  # chunks share their end vertex
        for m in range(first_m, v1[cb] + 1):
            if close:
                d, s_at, interior = _nearest(X, Y, S, X[m], Y[m], cstart[i], cstart[i + 1],
                                             v0, v1, box, reach, lo_i, hi_i - 1)
            else:
                d, s_at, interior = math.inf, 0.0, False
            if d <= gap:
                if run_start < 0:
                    run_start, run_proj = m, s_at
                if S[m] - S[run_start] >= run:
                    if not seen_apart:
                        return False, 0.0, 0.0, 0.0
                    s_j, s_i = S[run_start], run_proj
                    ux, uy = _direction(X, Y, S, lo_j, hi_j, s_j - MERGE_APPROACH_M, s_j)
                    wx, wy = _direction(X, Y, S, lo_i, hi_i, s_i - DIRECTION_M,
                                        s_i + DIRECTION_M)
                    return True, s_j, s_i, _angle_deg(ux, uy, wx, wy)
            else:
                run_start = -1
                if apart <= d <= reach and interior:
                    seen_apart = True
    return False, 0.0, 0.0, 0.0


@njit(cache=True, parallel=True)
def pair_geometry(X, Y, S, starts, cstart, v0, v1, box, pi, pj, angle_lo, angle_hi, gap,
                  apart, run, out):
    """The crossing and merges of each candidate pair ``(pi[p], pj[p])`` (module
    docstring), into ``out`` ``(n_pairs, N_GEOMETRY)``: flags 1.0 / 0.0, arcs [m] on each
    track's own path from its first sample, angles [deg]."""
    for p in prange(pi.shape[0]):
        i, j = pi[p], pj[p]
        for c in range(N_GEOMETRY):
            out[p, c] = 0.0
        lo_i, hi_i, lo_j, hi_j = starts[i], starts[i + 1], starts[j], starts[j + 1]
        any_close = False
        best = math.inf
        for ca in range(cstart[i], cstart[i + 1]):
            for cb in range(cstart[j], cstart[j + 1]):
                if _box_gap(box, ca, cb) > gap:
                    continue
                any_close = True
                for k in range(v0[ca], v1[ca]):
                    if k >= best:
                        break
                    rx, ry = X[k + 1] - X[k], Y[k + 1] - Y[k]
                    for m in range(v0[cb], v1[cb]):
                        sx, sy = X[m + 1] - X[m], Y[m + 1] - Y[m]
                        den = rx * sy - ry * sx
                        if den == 0.0:
                            continue
                        qx, qy = X[m] - X[k], Y[m] - Y[k]
                        t = (qx * sy - qy * sx) / den
                        u = (qx * ry - qy * rx) / den
                        if not (0.0 <= t < 1.0 and 0.0 <= u < 1.0) or k + t >= best:
                            continue
                        si = S[k] + t * (S[k + 1] - S[k])
                        sj = S[m] + u * (S[m + 1] - S[m])
                        ux, uy = _direction(X, Y, S, lo_i, hi_i, si - DIRECTION_M,
                                            si + DIRECTION_M)
                        wx, wy = _direction(X, Y, S, lo_j, hi_j, sj - DIRECTION_M,
                                            sj + DIRECTION_M)
                        angle = _angle_deg(ux, uy, wx, wy)
                        if angle_lo <= angle <= angle_hi:
                            best = k + t
                            out[p, G_CROSS] = 1.0
                            out[p, G_CROSS_SI], out[p, G_CROSS_SJ] = si, sj
                            out[p, G_CROSS_ANGLE] = angle
        if not any_close or out[p, G_CROSS] > 0.0:
            continue  # a crossing is what the pair is (find_pairs prefers it)
        found, s_j, s_i, angle = _merge_into(X, Y, S, starts, cstart, v0, v1, box, i, j, gap,
                                             apart, run)
        if found:
            out[p, G_MERGE_JI], out[p, G_MERGE_JI_SJ] = 1.0, s_j
            out[p, G_MERGE_JI_SI], out[p, G_MERGE_JI_ANGLE] = s_i, angle
        found, s_i, s_j, angle = _merge_into(X, Y, S, starts, cstart, v0, v1, box, j, i, gap,
                                             apart, run)
        if found:
            out[p, G_MERGE_IJ], out[p, G_MERGE_IJ_SI] = 1.0, s_i
            out[p, G_MERGE_IJ_SJ], out[p, G_MERGE_IJ_ANGLE] = s_j, angle


__all__ = ["CHUNK", "DIRECTION_M", "MERGE_APPROACH_M", "N_GEOMETRY", "chunk_boxes",
           "pair_geometry"]
