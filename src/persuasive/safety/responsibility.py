"""Who broke the responsibility rule: the duties of the ``responsibility`` shield kind, watched
step by step for every other vehicle, and the fault of a collision (docs/method.md §12.13).

The rule (after RSS's intersection rule, Shalev-Shwartz et al. 2017, Definitions 16-18, as
``ad-rss`` implements it): an instant is **safe** for the pair (ego, vehicle ``j``) when the
ego's answer is certified against every responsible ``j`` granted its fresh response; the
next instant that is not is ``j``'s first **dangerous** instant ``t_d``, and its response
time ``rho`` runs from there. The shield writes, after each decision, what is left of that
response at the next step's start (``persuasive.safety.shield.C_RESP_LEFT``: ``rho`` after
a safe instant) and whether ``j`` owes one (``C_RESP_OWED``: it does unless it has the right
of way and the ego could still stand before its interval at the last safe instant). The
duties over the step ``[t, t + dt]`` are:

- **the other vehicle**: it accelerates at most at the rule's ``C_RESP_ACCEL`` (always, the
  bound of a responsible driver); at a crossing (a shared lane's rule is the cut-in rule,
  which the shield takes at the worst case), when it owes a response, from the instant its
  response time runs out (``t_d + rho``, in continuous time, also inside a step) it brakes at
  least at ``C_RESP_BRAKE`` until it stands, then stands, until it is past its interval.
  This is exactly the human the shield certifies against (``shield.responsible_arrival``:
  ``C_RESP_ACCEL`` for what is left of the response, then ``C_RESP_BRAKE``), judged on what
  a step shows: over the step ``[t, t + dt]`` the vehicle's speed at its end may not exceed
  that of the responsible envelope from its state at ``t`` (the rule's acceleration until the
  response runs out at ``t + tau``, then its braking), and where the envelope stands within
  the step, neither may its position (a vehicle holding one acceleration over the step, as
  the loops move them, then stays behind the envelope at every instant of the step: its
  speed is a chord under the envelope's concave speed, or it ends standing behind the
  envelope's stop). A step in which the response runs out is thus held against a vehicle
  that keeps accelerating through it (the shield assumed braking from ``t + tau``);
- **the ego**: its step is certified under the rule (the shield's verdict is not
  ``uncertified``; for a driver the shield only judges, the step it drove is admitted). An
  uncertified step also makes the instant dangerous for every vehicle (the response runs on).

A collision is the **other's fault** when some other vehicle broke a duty (since its last safe
instant with the ego) before the ego broke one of its own: an ego step left uncertified while
such a breach is open is the breach's consequence, not the ego's (the vehicle the ego then
collides with need not be the one that broke the rule: the breach took away the assumption
every answer rested on). Otherwise it is the ego's, also where neither broke one (the rule
promises that cannot happen, so a modelling error is the ego's).
:class:`DutyWatch` keeps these flags per vehicle from the shield's inputs and state.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence

import numpy as np

from . import shield as sh

#: Tolerance on an observed acceleration against a duty [m/s^2] (the simulators' speeds are
#: rounded to float, the rule's bounds are exact).
ACCEL_TOL_MPS2 = 1e-6
#: A vehicle below this speed stands [m/s].
STAND_MPS = 1e-3
#: Tolerance on a position against the responsible envelope's stop [m] (rounding of the
#: exact step).
POS_TOL_M = 1e-6


def duty_kept(s0: float, v0: float, s1: float, v1: float, dt: float, left: float, rho: float,
              accel: float, brake: float, owes: bool, v_min: float = 0.0,
              v_max: float = math.inf, slack_m: float = POS_TOL_M) -> bool:
    """Whether a vehicle that went from ``(s0, v0)`` to ``(s1, v1)`` over a step of ``dt``
    kept its duty (module docstring). ``left``: what is left of its response at the step's
    *end* (``C_RESP_LEFT`` written after the decision at the step's start), so it runs out
    ``tau = left + dt`` into the step; ``owes``: it owes a response at a crossing and is not
    past its interval; the response has started (``left < rho``) only after a dangerous
    instant. Before its response runs out it may accelerate at up to ``accel``; from then on
    it brakes at ``brake`` (positive) or more until it stands."""
    tau = left + dt
    if not (owes and left < rho - 1e-9 and tau < dt - 1e-12):
        return (v1 - v0) / dt <= accel + ACCEL_TOL_MPS2
    # the responsible envelope over the step: accel until tau, then braking to a stand
    # (a speed read above the limits the shield knows is not held against the envelope)
    s_e, v_e = sh._profile_state(s0, v0, accel, max(tau, 0.0), -brake, math.inf, -brake, dt,
                                 min(v_min, v0), max(v_max, v0))
    if v_e <= STAND_MPS:  # the envelope stands by the step's end: so must it, behind it
        return v1 <= STAND_MPS and s1 <= s_e + slack_m
    return v1 <= v_e + ACCEL_TOL_MPS2 * dt


class DutyWatch:
    """The duties of the ego and of every other vehicle under the responsibility rule (module
    docstring), from one step's shield inputs to the next's.

    Call :meth:`step` after every decision with the step's conflicts (their keys), the
    shield's inputs ``(s_H, v_H, C)`` with the state it wrote, and whether the ego's step
    was certified; :meth:`fault` names who broke the rule first."""

    def __init__(self, dt_s: float, slack_m: float = POS_TOL_M):
        self.dt_s = float(dt_s)
        #: how far past the responsible envelope's stop a vehicle's position may read [m]
        #: (rounding; a simulator whose integration lets a braking vehicle roll further than
        #: the exact step hands in its own slack)
        self.slack_m = float(slack_m)
        self._last: dict[Hashable, tuple] = {}
        #: per vehicle, since their last safe instant: when the ego first broke a duty and
        #: when the other did (in decisions; None: not)
        self.broken: dict[Hashable, tuple[float | None, float | None]] = {}
        self._k = 0  # decisions recorded
        self.other_breaches = 0  #: vehicle-steps in which another vehicle broke its duty
        #: steps in which the ego's step was not certified (whether or not a breach by
        #: another vehicle excused it)
        self.ego_breaches = 0
        self._undo: tuple | None = None

    def left_of(self, key: Hashable) -> float:
        """What is left of vehicle ``key``'s response at the next step [s] (``inf``: not
        seen)."""
        prev = self._last.get(key)
        return math.inf if prev is None else prev[3]

    def restore(self, keys: Sequence[Hashable], C: np.ndarray) -> None:
        """Write into ``C`` (one row per key) the shield's state kept for these vehicles:
        what is left of each one's response (``inf``: first seen) and whether it owes one."""
        for j, k in enumerate(keys):
            prev = self._last.get(k)
            C[j, sh.C_RESP_LEFT] = math.inf if prev is None else prev[3]
            C[j, sh.C_RESP_OWED] = 1.0 if prev is None else prev[7]

    def undo(self) -> None:
        """Forget the last :meth:`step`: a caller that asks the shield again for the same
        step (SUMO's re-anchored ego at rest) records the second answer instead."""
        if self._undo is not None:
            (self._last, self.broken, self.other_breaches, self.ego_breaches,
             self._k) = self._undo
            self._undo = None

    def step(self, keys: Sequence[Hashable], s_H: np.ndarray, v_H: np.ndarray, C: np.ndarray,
             ego_certified: bool, judged: Sequence[bool] | None = None) -> None:
        """Record one decision: ``keys[j]`` the vehicle of conflict ``j``, ``s_H, v_H`` its
        state at the step's start and ``C[j]`` its conflict vector after the filter (its
        state written). Checks each vehicle seen at the previous decision against the duty
        it had over the step since (from its state then and now). ``judged[j]`` False: a
        stand-in for vehicles not in the simulator yet, which has no duty and whose response
        is always fresh (whatever appears there is a vehicle first seen)."""
        dt = self.dt_s
        self._undo = (self._last, dict(self.broken), self.other_breaches, self.ego_breaches,
                      self._k)
        self._k += 1
        k = float(self._k)
        if not ego_certified:
            self.ego_breaches += 1
        last, self._last = self._last, {}
        # the other vehicles' duties over the step just driven, first: a breach there leaves
        # the ego's answers of this decision without the assumption they rest on (excused)
        rows = []
        for j, key in enumerate(keys):
            if judged is not None and not judged[j]:
                continue
            ego_broke, other_broke = self.broken.get(key, (None, None))
            prev = last.get(key)
            if prev is not None:
                s0, v0, hi, left0, rho, accel, brake, owed0, shared0, v_min, v_max = prev
                if not duty_kept(s0, v0, float(s_H[j]), float(v_H[j]), dt, left0, rho, accel,
                                 brake, bool(owed0) and not shared0 and s0 <= hi, v_min,
                                 v_max, self.slack_m):
                    if other_broke is None:  # in the step before this decision
                        other_broke = k - 0.5
                    self.other_breaches += 1
            rows.append((j, key, ego_broke, other_broke))
        excused = any(o is not None for _, _, _, o in rows)
        for j, key, ego_broke, other_broke in rows:
            c = C[j]
            left = float(c[sh.C_RESP_LEFT])
            if not ego_certified:  # the instant is dangerous whatever the shield found
                if ego_broke is None and not excused:
                    ego_broke = k
                before = last[key][3] if key in last else math.inf
                if math.isfinite(before):
                    left = before - dt
                    c[sh.C_RESP_LEFT] = left
            elif left >= float(c[sh.C_RESP_RHO]) - 1e-9:  # a safe instant: afresh
                ego_broke, other_broke = None, None
            self.broken[key] = (ego_broke, other_broke)
            self._last[key] = (float(s_H[j]), float(v_H[j]), float(c[sh.C_H_HI]), left,
                               float(c[sh.C_RESP_RHO]), float(c[sh.C_RESP_ACCEL]),
                               float(c[sh.C_RESP_BRAKE]), float(c[sh.C_RESP_OWED]),
                               bool(c[sh.C_SHARED]), float(c[sh.C_H_VMIN]),
                               float(c[sh.C_H_VMAX]))
        for key in list(self.broken):  # vehicles gone from view close their record
            if key not in self._last:
                del self.broken[key]

    def fault(self) -> str:
        """Who is at fault for a collision now: ``"other"`` when another vehicle broke a
        duty, since its last safe instant with the ego, before the ego broke one of its own
        (an ego step left uncertified while such a breach is open is not the ego's), else
        ``"ego"``."""
        ego = [e for e, _ in self.broken.values() if e is not None]
        other = [o for _, o in self.broken.values() if o is not None]
        if other and (not ego or min(other) < min(ego)):
            return "other"
        return "ego"


__all__ = ["ACCEL_TOL_MPS2", "POS_TOL_M", "STAND_MPS", "DutyWatch", "duty_kept"]
