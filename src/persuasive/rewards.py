"""Rewards of a player along its trajectories (docs/method.md §3).

Step reward at sample ``k = 1..n`` of a player with own state ``(s_k, v_k)``, own acceleration
``u_k`` and the other's position ``s'_k``:

    r_k = (s_k - s_0) - w_c c_k - w_u |u_k|,   c_k = [d_k < min_dist] (1 + v_k),

with ``d_k`` the distance between the two vehicles (``sqrt(s_k^2 + s'_k^2)`` at the paper's
intersection; between the centres ``xy(s)`` on the paths otherwise, ``persuasive.geometry``),
and the cumulative reward ``R = sum_k lambda^(k-1) r_k``. It is computed as a per-trajectory
part and a collision part, each summed in sample order:

    R = B - w_c C,   B = sum_k lambda^(k-1) ((s_k - s_0) - w_u |u_k|),
                     C = sum_k [d_k < min_dist] (lambda^(k-1) (1 + v_k)).

``B`` depends on the own trajectory only. A safe sample adds exactly ``0.0`` to ``C``, so ``C``
sums only the samples inside both vehicles' conflict windows, which skips most of the
``n_traj x n_traj x n`` work exactly. A window holds every sample that can be unsafe: at the
intersection the samples with ``s^2 < min_dist^2`` (``d < min_dist`` needs ``|s| < min_dist``
for both, since ``sqrt(fl(s^2) + x) >= |s|``); elsewhere the samples inside the vehicle's
conflict zone ``ZONE_LO < s < ZONE_HI``. The distance test compares squared distances with the
threshold of :func:`persuasive.packing.sqrt_threshold`, which agrees exactly with
``sqrt(.) < min_dist``.

Arrays are sample-major: ``S[k, m]`` is sample ``k`` of trajectory ``m``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import packing as slot
from .geometry import pair_unsafe_along, pair_unsafe_xy, path_point


@njit(cache=True, _nrt=False)
def reward_terms(S: np.ndarray, V: np.ndarray, A: np.ndarray, s0: float, disc: np.ndarray,
                 P: np.ndarray, base: np.ndarray, coll: np.ndarray, pos: np.ndarray,
                 win: np.ndarray) -> None:
    """Per-trajectory reward parts of a library of the vehicle whose parameters are ``P``.

    ``S, V, A``: ``(n, n_traj)``. Writes ``base`` ``(n_traj,)`` the collision-free reward
    ``B``; ``coll`` ``(n, n_traj)`` the discounted collision weights ``lambda^(k-1) (1 + v_k)``;
    ``win`` ``(n_traj, 2)`` each trajectory's conflict window (first and one-past-last sample;
    empty when ``lo >= hi``); ``pos`` ``(2, n, n_traj)``: for a along_paths conflict
    ``pos[0] = S * S``, for a euclidean one the positions ``x, y`` of the samples inside the
    window.
    """
    n, n_traj = S.shape
    w_u = P[slot.W_U]
    along_paths = P[slot.CONFLICT] == slot.CONFLICT_ALONG_PATHS
    sq = pos[0]
    for m in range(n_traj):
        base[m] = 0.0
    for k in range(n):
        for m in range(n_traj):
            base[m] += disc[k] * ((S[k, m] - s0) - w_u * abs(A[k, m]))
            coll[k, m] = disc[k] * (1.0 + V[k, m])
            if along_paths:
                sq[k, m] = S[k, m] * S[k, m]
    if along_paths:
        zone_windows(pos, P[slot.MIN_DIST_SQ], win)
    else:
        zone_positions(S, P, win, pos)


@njit(cache=True, inline="always")
def zone_positions(S: np.ndarray, P: np.ndarray, win: np.ndarray, pos: np.ndarray) -> None:
    """Euclidean conflicts: each trajectory's window of samples inside the vehicle's zone
    ``ZONE_LO < s < ZONE_HI``, and the positions ``x, y`` of those samples into ``pos``."""
    zone_windows_s(S, P[slot.ZONE_LO], P[slot.ZONE_HI], win)
    for m in range(S.shape[1]):
        for k in range(win[m, 0], win[m, 1]):
            pos[0, k, m], pos[1, k, m] = path_point(P, slot.PATH_B1, S[k, m])


@njit(cache=True, inline="always", _nrt=False)
def zone_windows(pos: np.ndarray, min_dist_sq: float, win: np.ndarray) -> None:
    """First and one-past-last sample of each trajectory with ``s^2 = pos[0] < min_dist_sq``.

    Scans from both ends, so the window covers every such sample whatever their pattern.
    """
    n, n_traj = pos.shape[1], pos.shape[2]
    for m in range(n_traj):
        lo = 0
        while lo < n and not pos[0, lo, m] < min_dist_sq:
            lo += 1
        hi = n
        while hi > lo and not pos[0, hi - 1, m] < min_dist_sq:
            hi -= 1
        win[m, 0] = lo
        win[m, 1] = hi


@njit(cache=True, inline="always", _nrt=False)
def zone_windows_s(S: np.ndarray, lo_s: float, hi_s: float, win: np.ndarray) -> None:
    """First and one-past-last sample of each trajectory with ``lo_s < s < hi_s``."""
    n, n_traj = S.shape
    for m in range(n_traj):
        lo = 0
        while lo < n and not (lo_s < S[lo, m] < hi_s):
            lo += 1
        hi = n
        while hi > lo and not (lo_s < S[hi - 1, m] < hi_s):
            hi -= 1
        win[m, 0] = lo
        win[m, 1] = hi


@njit(cache=True, _nrt=False)
def reward_matrix(base: np.ndarray, coll: np.ndarray, pos: np.ndarray, win: np.ndarray,
                  pos_other: np.ndarray, win_other: np.ndarray, w_c: float, thr: float,
                  along_paths: bool, C: np.ndarray, out: np.ndarray) -> int:
    """A player's cumulative rewards ``out[m, b] = base[m] - w_c C[m, b]``; returns the
    number of pair tests made.

    ``base, coll, pos, win`` from :func:`reward_terms` for the own library; ``pos_other,
    win_other`` for the other's; ``thr`` the squared safety distance
    (``packing.MIN_DIST_SQ``); ``along_paths``: the conflict's kind. ``C``
    ``(n_own, n_other)`` receives the collision sums. (Scalars rather than the parameter
    vector, and the counter returned rather than written: every array handed to a compiled
    call costs reference-count updates, and this runs for every game.)
    """
    n_own = win.shape[0]
    n_other = win_other.shape[0]
    sq, sq_other = pos[0], pos_other[0]  # s^2 along the paths (2-D: cheaper to index)
    tests = 0
    lo_o, hi_o = pos.shape[1], 0
    for b in range(n_other):
        lo_o = min(lo_o, win_other[b, 0])
        hi_o = max(hi_o, win_other[b, 1])
    for m in range(n_own):
        for b in range(n_other):
            C[m, b] = 0.0
        # every unsafe sample of m lies in its own window and in some other's window
        lo, hi = max(win[m, 0], lo_o), min(win[m, 1], hi_o)
        if along_paths:
            tests += max(hi - lo, 0) * n_other
            for k in range(lo, hi):
                own, weight = sq[k, m], coll[k, m]
                for b in range(n_other):
                    C[m, b] += weight if pair_unsafe_along(own, sq_other[k, b], thr) else 0.0
        else:
            tests += collision_sums_xy(m, lo, hi, coll, pos, win_other, pos_other, thr, C)
        for b in range(n_other):
            out[m, b] = base[m] - w_c * C[m, b]
    return tests


@njit(cache=True, inline="always")
def collision_sums_xy(m: int, lo: int, hi: int, coll: np.ndarray, pos: np.ndarray,
                      win_other: np.ndarray, pos_other: np.ndarray, thr: float,
                      C: np.ndarray) -> int:
    """Euclidean conflicts: add own trajectory ``m``'s collision weights over samples
    ``lo..hi-1`` to ``C[m]``; returns the number of pair tests."""
    tests = 0
    for k in range(lo, hi):
        x, y, weight = pos[0, k, m], pos[1, k, m], coll[k, m]
        for b in range(win_other.shape[0]):
            if win_other[b, 0] <= k < win_other[b, 1]:
                tests += 1
                C[m, b] += weight if pair_unsafe_xy(x, y, pos_other[0, k, b], pos_other[1, k, b],
                                                    thr) else 0.0
    return tests


def reward_matrix_of(own, other, disc: np.ndarray, P_own: np.ndarray,
                     P_other: np.ndarray) -> np.ndarray:
    """Rewards ``R[m, b]`` of the player owning library ``own`` against library ``other``.

    ``own``, ``other``: :class:`persuasive.library.Library`; ``P_own``, ``P_other`` their
    vehicles' parameter vectors. Returns ``(n_own, n_other)``.
    """
    parts = []
    for lib, P in ((own, P_own), (other, P_other)):
        n_traj, n = lib.s.shape
        base, win = np.empty(n_traj), np.empty((n_traj, 2), np.int64)
        coll, pos = np.empty((n, n_traj)), np.empty((2, n, n_traj))
        reward_terms(np.ascontiguousarray(lib.s.T), np.ascontiguousarray(lib.v.T),
                     np.ascontiguousarray(lib.a.T), lib.s0, disc, P, base, coll, pos, win)
        parts.append((base, coll, pos, win))
    (base, coll, pos, win), (_, _, pos_o, win_o) = parts
    out = np.empty((own.s.shape[0], other.s.shape[0]))
    reward_matrix(base, coll, pos, win, pos_o, win_o, P_own[slot.W_C], P_own[slot.MIN_DIST_SQ],
                  P_own[slot.CONFLICT] == slot.CONFLICT_ALONG_PATHS, np.empty_like(out), out)
    return out
