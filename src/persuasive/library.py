"""The candidate trajectories, the action set U (docs/method.md §2).

Every trajectory follows an optimal-velocity (OVM) car-following law behind a virtual leader:

    a = alpha (kappa (h_c - h_st) - v) + beta (v1_c - v),  clipped to [u_min, u_max],

with ``h_c`` the headway clipped to ``[h_st, h_go]`` (``h_go = h_st + v_max / kappa``) and
``v1_c`` the leader's speed clipped to ``[0, v_max]``. Regulating to a target speed ``v_t`` puts
the leader ``v_t / kappa + h_st + l`` ahead of the vehicle at every sample, moving at ``v_t``;
regulating to ``v_t`` and a stop position ``s_t`` puts it at ``s_t + h_st + l``, standing.

The library of a vehicle at ``(s0, v0)`` holds ``n_mesh + 1`` trajectories in this order (the
order decides ties):

0. keep the current speed (``v_t = v0``);
1. ``v_t = v_mesh[0]``, with the stop position ``s_yield`` when one is offered;
2. .. n_mesh: ``v_t = v_mesh[1:]``;

with ``v_mesh = linspace(v_lo, v_hi, n_mesh)``, ``v_hi = min(v_max, v0 + u_max T)`` and
``v_lo = max(v_min, v0 + u_min T)``. The stop position is the vehicle's yield line
(``-stop_distance`` at the paper's intersection). The stop is offered when ``v_lo <= 0`` and
``s0 + v0 / |u_min| < s_yield`` (quirk Q6; with Q6 off the test uses the stopping distance
``v0^2 / (2 |u_min|)``). Every parameter comes from the vehicle's own vector
(``persuasive.packing``): each vehicle has its own limits and yield line.

Arrays: the kernels store ``S, V, A`` sample-major, shape ``(n_samples, n_traj)``: position
[m], speed [m/s] and the acceleration [m/s^2] used to reach each sample; sample ``k`` is at time
``t + (k + 1) dt`` (the initial state is not stored). Sample-major lets the trajectories advance
side by side in vector registers. :class:`Library` shows them trajectory-major.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from . import packing as slot
from .kinematics import saturated_step


@njit(cache=True, inline="always")
def ovm(h: float, v: float, v1: float, alpha: float, beta: float, kappa: float, h_st: float,
        h_go: float, v_max: float, u_min: float, u_max: float) -> float:
    """OVM acceleration [m/s^2] for headway ``h`` [m], own speed ``v`` and leader speed ``v1``."""
    h_c = min(max(h, h_st), h_go)
    v1_c = min(max(v1, 0.0), v_max)
    a = alpha * (kappa * (h_c - h_st) - v) + beta * (v1_c - v)
    return min(max(a, u_min), u_max)


@njit(cache=True, _nrt=False)
def offers_stop(s0: float, v0: float, P: np.ndarray) -> bool:
    """Whether the library of ``(s0, v0)`` holds the stop-at-the-line trajectory."""
    v_lo = max(P[slot.V_MIN], v0 + P[slot.U_MIN] * P[slot.HORIZON])
    if v_lo > 0.0:
        return False
    if P[slot.QUIRK_TIME_LIKE_STOP_TEST] != 0.0:  # Q6
        return s0 + v0 / abs(P[slot.U_MIN]) < P[slot.YIELD_S]
    return s0 + v0 * v0 / (2.0 * abs(P[slot.U_MIN])) < P[slot.YIELD_S]


@njit(cache=True, inline="always")
def mesh_speed(v_lo: float, v_hi: float, i: int, n_mesh: int) -> float:
    """``numpy.linspace(v_lo, v_hi, n_mesh)[i]``, computed as numpy does."""
    if i == n_mesh - 1:
        return v_hi
    step = (v_hi - v_lo) / (n_mesh - 1)
    if step == 0.0:  # numpy scales first when the step underflows
        return i / (n_mesh - 1) * (v_hi - v_lo) + v_lo
    return i * step + v_lo


@njit(cache=True)
def fill_library(
    s0: float, v0: float, P: np.ndarray, S: np.ndarray, V: np.ndarray, A: np.ndarray
) -> None:
    """Write the library of a vehicle at ``(s0 [m], v0 [m/s])`` into ``S, V, A``.

    ``S, V, A``: ``(n_samples, n_mesh + 1)`` float64 arrays (sample-major), overwritten.
    """
    n = int(P[slot.N_SAMPLES])
    n_traj = int(P[slot.N_MESH]) + 1
    dt = P[slot.SAMPLE_DT]
    v_min, v_max = P[slot.V_MIN], P[slot.V_MAX]
    u_min, u_max = P[slot.U_MIN], P[slot.U_MAX]
    alpha, beta, kappa = P[slot.ALPHA], P[slot.BETA], P[slot.KAPPA]
    h_st, h_go = P[slot.H_ST], P[slot.H_GO]
    length = P[slot.LENGTH]
    v_hi = min(v_max, v0 + u_max * P[slot.HORIZON])
    v_lo = max(v_min, v0 + u_min * P[slot.HORIZON])
    stop_leader = P[slot.YIELD_S] + h_st + length
    v_t = np.empty(n_traj)
    gap = np.empty(n_traj)
    standing = np.zeros(n_traj, np.bool_)
    standing[1] = offers_stop(s0, v0, P)
    s = np.empty(n_traj)
    v = np.empty(n_traj)
    for m in range(n_traj):
        v_t[m] = v0 if m == 0 else mesh_speed(v_lo, v_hi, m - 1, n_traj - 1)
        gap[m] = v_t[m] / kappa + h_st + length
        s[m] = s0
        v[m] = v0
    for k in range(n):
        for m in range(n_traj):
            sm = s[m]
            h = (stop_leader - sm - length) if standing[m] else ((sm + gap[m]) - sm - length)
            a = ovm(h, v[m], v_t[m], alpha, beta, kappa, h_st, h_go, v_max, u_min, u_max)
            sm, vm = saturated_step(sm, v[m], a, dt, v_min, v_max)
            s[m] = sm
            v[m] = vm
            S[k, m] = sm
            V[k, m] = vm
            A[k, m] = a


class Lib(NamedTuple):
    """A library in kernel form, with its reward parts (filled by ``persuasive.game.build``).

    Sample-major trajectories ``S, V, A`` ``(n, n_traj)``; reward parts of
    ``persuasive.rewards``: ``base`` ``(n_traj,)``, ``coll`` ``(n, n_traj)``, ``pos``
    ``(2, n, n_traj)``: ``pos[0] = s^2`` for a conflict along the paths, the positions ``x, y``
    [m] of the samples inside the window for a euclidean one; ``win`` ``(n_traj, 2)`` int64.
    (Two coordinates in one array keep the tuple small: every field is passed on each call.)
    """

    S: np.ndarray
    V: np.ndarray
    A: np.ndarray
    base: np.ndarray
    coll: np.ndarray
    pos: np.ndarray
    win: np.ndarray


#: Rows of a library's float storage per sample: S, V, A, coll, pos[0], pos[1] (then base).
_ROWS = 6


def lib_buffers(n: int, n_traj: int) -> tuple[np.ndarray, np.ndarray]:
    """Storage of one :class:`Lib`: a float ``(6 n + 1, n_traj)`` and an int ``(n_traj, 2)``.

    Python code passes these two plain arrays to the compiled entry points (a tuple of arrays
    costs several microseconds per call to type-check); :func:`as_lib` views them as a
    :class:`Lib` inside compiled code.
    """
    return np.empty((_ROWS * n + 1, n_traj)), np.empty((n_traj, 2), np.int64)


@njit(cache=True)
def as_lib(buf: np.ndarray, win: np.ndarray) -> Lib:
    """The :class:`Lib` stored in ``buf``/``win`` (rows: S, V, A, coll, pos, then base)."""
    n = (buf.shape[0] - 1) // _ROWS
    return Lib(buf[0:n], buf[n:2 * n], buf[2 * n:3 * n], buf[_ROWS * n], buf[3 * n:4 * n],
               buf[4 * n:6 * n].reshape((2, n, buf.shape[1])), win)


@njit(cache=True)
def new_lib(n: int, n_traj: int) -> Lib:
    """Uninitialised kernel arrays for a library of ``n_traj`` trajectories of ``n`` samples."""
    return as_lib(np.empty((_ROWS * n + 1, n_traj)), np.empty((n_traj, 2), np.int64))


@dataclass(frozen=True)
class Library:
    """The candidate trajectories of one vehicle; arrays ``(n_traj, n_samples)``.

    ``s, v, a`` are trajectory-major views of the kernels' sample-major arrays.
    """

    s: np.ndarray  #: positions [m]
    v: np.ndarray  #: speeds [m/s]
    a: np.ndarray  #: accelerations used to reach each sample [m/s^2]
    s0: float  #: initial position [m]
    v0: float  #: initial speed [m/s]
    has_stop: bool  #: whether trajectory 1 stops at the crossing line

    @property
    def n_traj(self) -> int:
        return self.s.shape[0]


def trajectory_library(s0: float, v0: float, P: np.ndarray) -> Library:
    """The library of a vehicle at ``(s0 [m], v0 [m/s])``; ``P`` its parameter vector
    (:func:`persuasive.packing.pack`)."""
    n_traj, n = int(P[slot.N_MESH]) + 1, int(P[slot.N_SAMPLES])
    S, V, A = np.empty((n, n_traj)), np.empty((n, n_traj)), np.empty((n, n_traj))
    fill_library(float(s0), float(v0), P, S, V, A)
    return Library(S.T, V.T, A.T, float(s0), float(v0),
                   bool(offers_stop(float(s0), float(v0), P)))
