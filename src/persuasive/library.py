"""The candidate trajectories, the action set U (spec section 2).

Every trajectory follows an optimal-velocity (OVM) car-following law behind a virtual leader:

    a = alpha (kappa (h_c - h_st) - v) + beta (v1_c - v),  clipped to [u_min, u_max],

with ``h_c`` the headway clipped to ``[h_st, h_go]`` (``h_go = h_st + v_max / kappa``) and
``v1_c`` the leader's speed clipped to ``[0, v_max]``. Regulating to a target speed ``v_t`` puts
the leader ``v_t / kappa + h_st + l`` ahead of the vehicle at every sample, moving at ``v_t``;
regulating to ``v_t`` and a stop position ``s_t`` puts it at ``s_t + h_st + l``, standing.

The library of a vehicle at ``(s0, v0)`` holds ``n_mesh + 1`` trajectories in this order (the
order decides ties):

0. keep the current speed (``v_t = v0``);
1. ``v_t = v_mesh[0]``, with the stop position ``-stop_distance`` when one is offered;
2. .. n_mesh: ``v_t = v_mesh[1:]``;

with ``v_mesh = linspace(v_lo, v_hi, n_mesh)``, ``v_hi = min(v_max, v0 + u_max T)`` and
``v_lo = max(v_min, v0 + u_min T)``. The stop is offered when ``v_lo <= 0`` and
``s0 + v0 / |u_min| < -stop_distance`` (quirk Q6; with Q6 off the test uses the stopping
distance ``v0^2 / (2 |u_min|)``).

Arrays: ``S, V, A`` of shape ``(n_traj, n_samples)`` hold position [m], speed [m/s] and the
acceleration [m/s^2] used to reach each sample; sample ``k`` is at time ``t + (k + 1) dt``
(the initial state is not stored).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from . import _packed as K
from .kinematics import saturated_step


@njit(cache=True, inline="always")
def ovm_acceleration(h: float, v: float, v1: float, P: np.ndarray) -> float:
    """OVM acceleration [m/s^2] for headway ``h`` [m], own speed ``v`` and leader speed ``v1``."""
    h_c = min(max(h, P[K.H_ST]), P[K.H_GO])
    v1_c = min(max(v1, 0.0), P[K.V_MAX])
    a = P[K.ALPHA] * (P[K.KAPPA] * (h_c - P[K.H_ST]) - v) + P[K.BETA] * (v1_c - v)
    return min(max(a, P[K.U_MIN]), P[K.U_MAX])


@njit(cache=True)
def offers_stop(s0: float, v0: float, P: np.ndarray) -> bool:
    """Whether the library of ``(s0, v0)`` holds the stop-at-the-line trajectory."""
    v_lo = max(P[K.V_MIN], v0 + P[K.U_MIN] * P[K.HORIZON])
    if v_lo > 0.0:
        return False
    if P[K.Q6] != 0.0:
        return s0 + v0 / abs(P[K.U_MIN]) < -P[K.STOP_DIST]
    return s0 + v0 * v0 / (2.0 * abs(P[K.U_MIN])) < -P[K.STOP_DIST]


@njit(cache=True, inline="always")
def mesh_speed(v_lo: float, v_hi: float, i: int, n_mesh: int) -> float:
    """``numpy.linspace(v_lo, v_hi, n_mesh)[i]``, computed as numpy does."""
    if i == n_mesh - 1:
        return v_hi
    return i * ((v_hi - v_lo) / (n_mesh - 1)) + v_lo


@njit(cache=True)
def fill_library(
    s0: float, v0: float, P: np.ndarray, S: np.ndarray, V: np.ndarray, A: np.ndarray
) -> None:
    """Write the library of a vehicle at ``(s0 [m], v0 [m/s])`` into ``S, V, A``.

    ``S, V, A``: ``(n_mesh + 1, n_samples)`` float64 arrays, overwritten.
    """
    n = int(P[K.N_SAMPLES])
    n_mesh = int(P[K.N_MESH])
    dt = P[K.SAMPLE_DT]
    v_min, v_max = P[K.V_MIN], P[K.V_MAX]
    length = P[K.LENGTH]
    v_hi = min(v_max, v0 + P[K.U_MAX] * P[K.HORIZON])
    v_lo = max(v_min, v0 + P[K.U_MIN] * P[K.HORIZON])
    stop = offers_stop(s0, v0, P)
    stop_leader = -P[K.STOP_DIST] + P[K.H_ST] + length
    for m in range(n_mesh + 1):
        v_t = v0 if m == 0 else mesh_speed(v_lo, v_hi, m - 1, n_mesh)
        standing = m == 1 and stop
        gap = v_t / P[K.KAPPA] + P[K.H_ST] + length
        s, v = s0, v0
        for k in range(n):
            if standing:
                h = stop_leader - s - length
            else:
                h = (s + gap) - s - length
            a = ovm_acceleration(h, v, v_t, P)
            s, v = saturated_step(s, v, a, dt, v_min, v_max)
            S[m, k] = s
            V[m, k] = v
            A[m, k] = a


@dataclass(frozen=True)
class Library:
    """The candidate trajectories of one vehicle; arrays ``(n_traj, n_samples)``."""

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
    """The library of a vehicle at ``(s0 [m], v0 [m/s])``; ``P`` from :func:`persuasive.pack`."""
    n_traj, n = int(P[K.N_MESH]) + 1, int(P[K.N_SAMPLES])
    S, V, A = np.empty((n_traj, n)), np.empty((n_traj, n)), np.empty((n_traj, n))
    fill_library(float(s0), float(v0), P, S, V, A)
    return Library(S, V, A, float(s0), float(v0), bool(offers_stop(float(s0), float(v0), P)))
