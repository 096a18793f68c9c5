"""Humans that test the safety shield: ``adversary``, ``deceptive``, ``random``
(docs/method.md §12.4). Each stays within its vehicle's limits (accelerations clipped to
``u_min..u_max``; the loop keeps the speed in ``v_min..v_max``) and knows the conflict
geometry: each vehicle's occupancy interval ``[OCC_LO, OCC_HI]`` (where its footprint can touch
the other's) and its yield line.

- ``adversary`` tries to collide: it aims to be at its conflict point (``s = 0``) when the AV
  is at its own, taking the AV's arrival time at its current speed and choosing the constant
  acceleration that arrives then (re-aimed every step). While the AV does not come (stopped
  before its interval), it lurks: it stops one metre before its own occupancy interval, ready
  to pounce. In a shared lane, once the AV is in the lane ahead of it, it drives into it.
- ``deceptive`` yields until the AV commits, then accelerates fully: it brakes comfortably to
  stand at its yield line (the IDM law toward a standing leader on the line,
  ``persuasive.policies.idm``) until the AV can no longer stop before its occupancy interval
  at full braking (or is inside it), and from then on drives at ``u_max``.
- ``random`` draws an acceleration uniformly in ``[u_min, u_max]`` and holds it for a uniform
  time in ``[hold_min_s, hold_max_s]`` (``hv.random``), then draws again; two uniforms of its
  stream per step (used when a hold ends).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import packing as slot
from .idm import idm_accel

#: State slots: the deceptive human's latch; the random human's hold left [s] and acceleration.
COMMITTED = 0
HOLD_LEFT, HOLD_ACCEL = 0, 1
#: Parameter slots of the random human.
PRM_HOLD_MIN, PRM_HOLD_MAX = 0, 1
#: Log columns (``persuasive.policies.kinds``).
COL_TARGET_TIME, COL_LURKING = 0, 1
COL_COMMITTED = 0
COL_HOLD_LEFT = 0

_SLOW_MPS = 0.1  #: below this the AV is taken as not coming
_LURK_M = 1.0  #: the adversary lurks this far before its occupancy interval
_LURK_DECEL = 1.0  #: ... approaching it at this comfortable deceleration [m/s^2]


@njit(cache=True, _nrt=False)
def adversary_step(s: float, v: float, s_o: float, v_o: float, dt: float, P_self: np.ndarray,
                   P_other: np.ndarray, log: np.ndarray) -> float:
    """One step of the adversary at ``(s, v)``, the AV at ``(s_o, v_o)``."""
    u_min, u_max = P_self[slot.U_MIN], P_self[slot.U_MAX]
    shared = P_self[slot.LANE_SHARED] != 0.0
    lurking = False
    if s_o > P_other[slot.OCC_HI]:
        # the AV is past its interval: in a shared lane ahead of the human, ram it; else go
        t_target = 0.0
        a = u_max
    else:
        t_target = 0.0 if s_o >= 0.0 else (-s_o / v_o if v_o > _SLOW_MPS else math.inf)
        if t_target == math.inf:  # the AV is not coming: stop before the interval and wait
            lurking = True
            gap = P_self[slot.OCC_LO] - _LURK_M - s
            v_want = math.sqrt(2.0 * _LURK_DECEL * gap) if gap > 0.0 else 0.0
            a = (v_want - v) / dt
        elif t_target < dt:
            a = u_max if s < 0.0 else (u_min if not shared else u_max)
        else:  # the constant acceleration that puts it at s = 0 at the AV's arrival
            a = 2.0 * (-s - v * t_target) / (t_target * t_target)
    log[COL_TARGET_TIME] = t_target
    log[COL_LURKING] = 1.0 if lurking else 0.0
    return min(max(a, u_min), u_max)


@njit(cache=True, _nrt=False)
def deceptive_step(st: np.ndarray, s: float, v: float, s_o: float, v_o: float, dt: float,
                   P_self: np.ndarray, P_other: np.ndarray, log: np.ndarray) -> float:
    """One step of the deceptive human at ``(s, v)``, the AV at ``(s_o, v_o)``."""
    u_min, u_max, v_max = P_self[slot.U_MIN], P_self[slot.U_MAX], P_self[slot.V_MAX]
    room = P_other[slot.OCC_LO] - s_o
    if room <= 0.0 or v_o * v_o / (2.0 * abs(P_other[slot.U_MIN])) >= room:
        st[COMMITTED] = 1.0  # the AV can no longer stand before its interval
    if st[COMMITTED] != 0.0:
        a = u_max
    else:  # yield: the IDM law (SUMO-like defaults) toward a standing leader on its line
        s0 = 2.0
        a = idm_accel(v, v_max, P_self[slot.YIELD_S] - s + s0, v, 1.5, u_max, 1.5, 4.0, s0)
    log[COL_COMMITTED] = st[COMMITTED]
    return min(max(a, u_min), u_max)


@njit(cache=True, _nrt=False)
def random_step(st: np.ndarray, prm: np.ndarray, draws: np.ndarray, dt: float,
                P_self: np.ndarray, log: np.ndarray) -> float:
    """One step of the random human: a new uniform acceleration and hold when the last hold
    has run out (``draws[0]``, ``draws[1]``)."""
    u_min, u_max = P_self[slot.U_MIN], P_self[slot.U_MAX]
    if st[HOLD_LEFT] <= 1e-9:
        st[HOLD_ACCEL] = u_min + (u_max - u_min) * draws[0]
        st[HOLD_LEFT] = prm[PRM_HOLD_MIN] + (prm[PRM_HOLD_MAX] - prm[PRM_HOLD_MIN]) * draws[1]
    st[HOLD_LEFT] -= dt
    log[COL_HOLD_LEFT] = max(st[HOLD_LEFT], 0.0)
    return st[HOLD_ACCEL]


__all__ = ["adversary_step", "deceptive_step", "random_step"]
