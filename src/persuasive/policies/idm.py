"""The IDM driver with gap acceptance at the conflict (``idm``, docs/method.md §11).

Car following (Treiber's Intelligent Driver Model): for speed ``v``, desired speed ``v0``,
gap ``g`` to a leader and approach rate ``dv`` (own speed minus the leader's),

    a = a_max (1 - (v / v0)^delta - (s*(v, dv) / g)^2),   s* = s0 + v T + v dv / (2 sqrt(a_max b)),

with ``T`` the time gap (1.5 s), ``b`` the comfortable deceleration, ``s0`` the jam distance,
clipped to the vehicle's limits; without a leader only the free-road term.

Gap acceptance at the conflict (as a minor-road driver in SUMO's junction model): with the
times to reach the conflict point ``t = -s / max(v, 0.1 m/s)`` (0 once past it), the driver
goes when the AV has cleared the conflict, or when the AV is not in the conflict and reaches it
at least ``critical_gap_s`` (SUMO's ``jmTimegapMinor``, 1 s) after the driver itself. The gap
shrinks with waiting (speed below 0.1 m/s) by ``impatience_per_s`` per second (0: patient).
Otherwise the driver yields: its yield line is a standing leader, placed so that the driver
stops exactly at the line (``g = s_yield - s + s0``). Once it cannot stop at the line with its
comfortable deceleration, or is past it, it commits and goes. When the paths share a lane
past the conflict point (a merge), a vehicle ahead on it is followed as a leader.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import packing as slot

WAITING_S, COMMITTED = 0, 1  #: state slots
(PRM_V0, PRM_T, PRM_A, PRM_B, PRM_DELTA, PRM_S0, PRM_GAP, PRM_IMPATIENCE) = range(8)
COL_GO, COL_COMMITTED, COL_WAITING, COL_GAP, COL_T_OWN, COL_T_OTHER = range(6)

_SLOW_MPS = 0.1  #: below this speed the driver is waiting; the floor of time-to-conflict


@njit(cache=True, inline="always")
def idm_accel(v: float, v0: float, gap: float, dv: float, T: float, a_max: float, b: float,
              delta: float, s0: float) -> float:
    """The IDM acceleration toward a leader ``gap`` [m] ahead approached at ``dv`` [m/s]."""
    s_star = s0 + max(0.0, v * T + v * dv / (2.0 * math.sqrt(a_max * b)))
    return a_max * (1.0 - (v / v0) ** delta - (s_star / max(gap, 1e-3)) ** 2)


@njit(cache=True, inline="always")
def idm_times(s: float, v: float, s_o: float, v_o: float,
              P_other: np.ndarray) -> tuple[float, float, bool]:
    """``(t_own, t_other, other_clear)``: the times both vehicles need to reach the conflict
    point (0 once in or past it; the other's ``inf`` once it has cleared the conflict)."""
    t_own = 0.0 if s >= 0.0 else -s / max(v, _SLOW_MPS)
    other_clear = s_o >= P_other[slot.CLEAR_S]
    if other_clear:
        t_other = math.inf
    elif s_o >= 0.0:
        t_other = 0.0  # the other is in the conflict now
    else:
        t_other = -s_o / max(v_o, _SLOW_MPS)
    return t_own, t_other, other_clear


@njit(cache=True, inline="always")
def idm_commits(s: float, v: float, b: float, line: float) -> bool:
    """Past the yield line ``line``, or unable to stop at it with the comfortable
    deceleration ``b``: the driver commits (for good)."""
    return s >= line or v * v / (2.0 * b) > line - s


@njit(cache=True, inline="always")
def idm_branches(prm: np.ndarray, s: float, v: float, s_o: float, v_o: float,
                 P_self: np.ndarray, P_other: np.ndarray) -> tuple[float, float]:
    """``(a_go, a_yield)``: the accelerations of the two decisions at the conflict, each
    clipped to the vehicle's limits (the gap acceptance picks one of them; the fit evaluates
    both once for every gap parameter, ``persuasive.fitting.models.idm_sse``)."""
    v0, T, a_max, b = prm[PRM_V0], prm[PRM_T], prm[PRM_A], prm[PRM_B]
    delta, s0 = prm[PRM_DELTA], prm[PRM_S0]
    a_go = a_max * (1.0 - (v / v0) ** delta)
    a_yield = min(a_go, idm_accel(v, v0, P_self[slot.YIELD_S] - s + s0, v, T, a_max, b,
                                  delta, s0))
    if P_self[slot.LANE_SHARED] != 0.0 and s_o >= 0.0 and s_o > s:
        lead = idm_accel(v, v0, s_o - s - 0.5 * (P_self[slot.LENGTH] + P_other[slot.LENGTH]),
                         v - v_o, T, a_max, b, delta, s0)
        a_go, a_yield = min(a_go, lead), min(a_yield, lead)
    lo, hi = P_self[slot.U_MIN], P_self[slot.U_MAX]
    return min(max(a_go, lo), hi), min(max(a_yield, lo), hi)


@njit(cache=True, _nrt=False)
def idm_step(st: np.ndarray, prm: np.ndarray, s: float, v: float, s_o: float, v_o: float,
             dt: float, P_self: np.ndarray, P_other: np.ndarray, log: np.ndarray) -> float:
    """One step of the IDM driver at ``(s, v)`` with the other vehicle at ``(s_o, v_o)``."""
    t_own, t_other, other_clear = idm_times(s, v, s_o, v_o, P_other)
    gap = prm[PRM_GAP] * max(0.0, 1.0 - prm[PRM_IMPATIENCE] * st[WAITING_S])
    if idm_commits(s, v, prm[PRM_B], P_self[slot.YIELD_S]):
        st[COMMITTED] = 1.0  # past the line, or it cannot stop at it comfortably
    go = st[COMMITTED] != 0.0 or other_clear or (t_other - t_own > gap)
    a_go, a_yield = idm_branches(prm, s, v, s_o, v_o, P_self, P_other)
    if v < _SLOW_MPS:
        st[WAITING_S] += dt
    log[COL_GO] = 1.0 if go else 0.0
    log[COL_COMMITTED] = st[COMMITTED]
    log[COL_WAITING] = st[WAITING_S]
    log[COL_GAP] = gap
    log[COL_T_OWN] = t_own
    log[COL_T_OTHER] = t_other
    return a_go if go else a_yield
