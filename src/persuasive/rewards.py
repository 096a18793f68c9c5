"""Rewards of a player along its trajectories (spec section 3).

Step reward at sample ``k = 1..n`` of a player with own state ``(s_k, v_k)``, own acceleration
``u_k`` and the other's position ``s'_k``:

    r_k = (s_k - s_0) - w_c c_k - w_u |u_k|,   c_k = [d_k < min_dist] (1 + v_k),
    d_k = sqrt(s_k^2 + s'_k^2),

and the cumulative reward ``R = sum_k lambda^(k-1) r_k``, summed in sample order.

The collision term couples the two players only where both are inside the ``min_dist`` zone
at the same sample. The kernels therefore compute, once per trajectory, the reward without
collision (``base``) and the window of samples where ``|s| < min_dist``; a pair whose windows
hold no unsafe sample gets ``base`` exactly, and only the other pairs are summed again in full.
The result is bit-identical to summing every pair (``d < min_dist`` needs ``|s| < min_dist``
for both, since ``sqrt(fl(s^2) + x) >= |s|`` in IEEE arithmetic).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _packed as K


@njit(cache=True)
def base_rewards(S: np.ndarray, A: np.ndarray, s0: float, disc: np.ndarray, P: np.ndarray,
                 out: np.ndarray) -> None:
    """Collision-free cumulative reward of every trajectory: ``out[m]``, shape ``(n_traj,)``.

    Equal, bit for bit, to the full sum of the module docstring with every ``c_k = 0``.
    """
    w_u = P[K.W_U]
    for m in range(S.shape[0]):
        acc = 0.0
        for k in range(S.shape[1]):
            acc += disc[k] * ((S[m, k] - s0) - w_u * abs(A[m, k]))
        out[m] = acc


@njit(cache=True)
def zone_windows(S: np.ndarray, min_dist: float, out: np.ndarray) -> None:
    """First and one-past-last sample with ``|s| < min_dist`` per trajectory: ``out[m] = (lo, hi)``.

    An empty window has ``lo >= hi``.
    """
    for m in range(S.shape[0]):
        lo, hi = S.shape[1], 0
        for k in range(S.shape[1]):
            if abs(S[m, k]) < min_dist:
                if k < lo:
                    lo = k
                hi = k + 1
        out[m, 0] = lo
        out[m, 1] = hi


@njit(cache=True)
def full_reward(S: np.ndarray, V: np.ndarray, A: np.ndarray, m: int, s0: float,
                S_other: np.ndarray, b: int, disc: np.ndarray, P: np.ndarray) -> float:
    """Cumulative reward of own trajectory ``m`` against the other's trajectory ``b``."""
    w_c, w_u, min_dist = P[K.W_C], P[K.W_U], P[K.MIN_DIST]
    acc = 0.0
    for k in range(S.shape[1]):
        s, so = S[m, k], S_other[b, k]
        c = (1.0 + V[m, k]) if math.sqrt(s * s + so * so) < min_dist else 0.0
        acc += disc[k] * (((s - s0) - w_c * c) - w_u * abs(A[m, k]))
    return acc


@njit(cache=True)
def reward_matrix(S: np.ndarray, V: np.ndarray, A: np.ndarray, s0: float, base: np.ndarray,
                  win: np.ndarray, S_other: np.ndarray, win_other: np.ndarray,
                  disc: np.ndarray, P: np.ndarray, out: np.ndarray) -> None:
    """A player's cumulative rewards ``out[m, b]``: own trajectory ``m``, the other's ``b``.

    ``base`` and ``win`` come from :func:`base_rewards` and :func:`zone_windows` for the own
    trajectories, ``win_other`` for the other's.
    """
    min_dist = P[K.MIN_DIST]
    for m in range(S.shape[0]):
        for b in range(S_other.shape[0]):
            lo = max(win[m, 0], win_other[b, 0])
            hi = min(win[m, 1], win_other[b, 1])
            unsafe = False
            for k in range(lo, hi):
                s, so = S[m, k], S_other[b, k]
                if math.sqrt(s * s + so * so) < min_dist:
                    unsafe = True
                    break
            out[m, b] = full_reward(S, V, A, m, s0, S_other, b, disc, P) if unsafe else base[m]


def reward_matrix_of(own, other, disc: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Rewards ``R[m, b]`` of the player owning library ``own`` against library ``other``.

    ``own``, ``other``: :class:`persuasive.library.Library`. Returns ``(n_own, n_other)``.
    """
    n_own, n_other = own.s.shape[0], other.s.shape[0]
    base = np.empty(n_own)
    win, win_o = np.empty((n_own, 2), np.int64), np.empty((n_other, 2), np.int64)
    base_rewards(own.s, own.a, own.s0, disc, P, base)
    zone_windows(own.s, P[K.MIN_DIST], win)
    zone_windows(other.s, P[K.MIN_DIST], win_o)
    out = np.empty((n_own, n_other))
    reward_matrix(own.s, own.v, own.a, own.s0, base, win, other.s, win_o, disc, P, out)
    return out
