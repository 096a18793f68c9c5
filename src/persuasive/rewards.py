"""Rewards of a player along its trajectories (spec section 3).

Step reward at sample ``k = 1..n`` of a player with own state ``(s_k, v_k)``, own acceleration
``u_k`` and the other's position ``s'_k``:

    r_k = (s_k - s_0) - w_c c_k - w_u |u_k|,   c_k = [d_k < min_dist] (1 + v_k),
    d_k = sqrt(s_k^2 + s'_k^2),

and the cumulative reward ``R = sum_k lambda^(k-1) r_k``. It is computed as a per-trajectory
part and a collision part, each summed in sample order:

    R = B - w_c C,   B = sum_k lambda^(k-1) ((s_k - s_0) - w_u |u_k|),
                     C = sum_k [d_k < min_dist] (lambda^(k-1) (1 + v_k)).

``B`` depends on the own trajectory only. A safe sample adds exactly ``0.0`` to ``C``, so ``C``
sums only the samples where both vehicles are inside the ``min_dist`` zone (``d < min_dist``
needs ``|s| < min_dist`` for both, since ``sqrt(fl(s^2) + x) >= |s|``), which skips most of the
``n_traj x n_traj x n`` work exactly. The distance test compares ``s_k^2 + s'_k^2`` with the
threshold of :func:`persuasive._packed.sqrt_threshold`, which agrees exactly with
``sqrt(.) < min_dist``.

Arrays are sample-major: ``S[k, m]`` is sample ``k`` of trajectory ``m``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _packed as K


@njit(cache=True)
def reward_terms(S: np.ndarray, V: np.ndarray, A: np.ndarray, s0: float, disc: np.ndarray,
                 w_u: float, min_dist_sq: float, base: np.ndarray, coll: np.ndarray,
                 sq: np.ndarray, win: np.ndarray) -> None:
    """Per-trajectory reward parts of a library.

    ``S, V, A``: ``(n, n_traj)``. Writes ``base`` ``(n_traj,)`` the collision-free reward
    ``B``; ``coll`` ``(n, n_traj)`` the discounted collision weights ``lambda^(k-1) (1 + v_k)``;
    ``sq = S * S``; ``win`` ``(n_traj, 2)`` the first and one-past-last sample with
    ``s^2 < min_dist_sq`` (empty when ``lo >= hi``).
    """
    n, n_traj = S.shape
    for m in range(n_traj):
        base[m] = 0.0
    for k in range(n):
        for m in range(n_traj):
            base[m] += disc[k] * ((S[k, m] - s0) - w_u * abs(A[k, m]))
            coll[k, m] = disc[k] * (1.0 + V[k, m])
            sq[k, m] = S[k, m] * S[k, m]
    zone_windows(sq, min_dist_sq, win)


@njit(cache=True)
def zone_windows(sq: np.ndarray, min_dist_sq: float, win: np.ndarray) -> None:
    """First and one-past-last sample of each trajectory with ``s^2 < min_dist_sq``.

    Scans from both ends, so the window covers every such sample whatever their pattern.
    """
    n, n_traj = sq.shape
    for m in range(n_traj):
        lo = 0
        while lo < n and not sq[lo, m] < min_dist_sq:
            lo += 1
        hi = n
        while hi > lo and not sq[hi - 1, m] < min_dist_sq:
            hi -= 1
        win[m, 0] = lo
        win[m, 1] = hi


@njit(cache=True)
def reward_matrix(base: np.ndarray, coll: np.ndarray, sq: np.ndarray, win: np.ndarray,
                  sq_other: np.ndarray, win_other: np.ndarray, w_c: float, min_dist_sq: float,
                  C: np.ndarray, out: np.ndarray) -> None:
    """A player's cumulative rewards ``out[m, b] = base[m] - w_c C[m, b]``.

    ``base, coll, sq, win`` from :func:`reward_terms` for the own library; ``sq_other,
    win_other`` for the other's. ``C`` ``(n_own, n_other)`` receives the collision sums.
    """
    n_own = sq.shape[1]
    n_other = sq_other.shape[1]
    lo_o, hi_o = sq.shape[0], 0
    for b in range(n_other):
        lo_o = min(lo_o, win_other[b, 0])
        hi_o = max(hi_o, win_other[b, 1])
    for m in range(n_own):
        for b in range(n_other):
            C[m, b] = 0.0
        # every unsafe sample of m lies in its own window and in some other's window
        for k in range(max(win[m, 0], lo_o), min(win[m, 1], hi_o)):
            own, weight = sq[k, m], coll[k, m]
            for b in range(n_other):
                C[m, b] += weight if own + sq_other[k, b] < min_dist_sq else 0.0
        for b in range(n_other):
            out[m, b] = base[m] - w_c * C[m, b]


def reward_matrix_of(own, other, disc: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Rewards ``R[m, b]`` of the player owning library ``own`` against library ``other``.

    ``own``, ``other``: :class:`persuasive.library.Library`. Returns ``(n_own, n_other)``.
    """
    parts = []
    for lib in (own, other):
        n_traj, n = lib.s.shape
        base, win = np.empty(n_traj), np.empty((n_traj, 2), np.int64)
        coll, sq = np.empty((n, n_traj)), np.empty((n, n_traj))
        reward_terms(np.ascontiguousarray(lib.s.T), np.ascontiguousarray(lib.v.T),
                     np.ascontiguousarray(lib.a.T), lib.s0, disc, P[K.W_U], P[K.MIN_DIST_SQ],
                     base, coll, sq, win)
        parts.append((base, coll, sq, win))
    (base, coll, sq, win), (_, _, sq_o, win_o) = parts
    out = np.empty((own.s.shape[0], other.s.shape[0]))
    reward_matrix(base, coll, sq, win, sq_o, win_o, P[K.W_C], P[K.MIN_DIST_SQ],
                  np.empty_like(out), out)
    return out
