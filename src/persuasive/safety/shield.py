"""The safety shield: a filter around any AV policy that no bounded human can defeat
(docs/method.md §12.2).

Notation: the AV at ``(s_R, v_R)`` on its path, the human at ``(s_H, v_H)`` on its own; each
vehicle's **occupancy interval** ``[R_lo, R_hi]`` / ``[H_lo, H_hi]`` is the set of positions where
its footprint can touch the other's (``persuasive.geometry.occupancy_interval``; outside it,
no overlap is possible wherever the other is). A **human** is any acceleration sequence within
its vehicle's limits ``u_min..u_max`` whose speed stays in ``v_min..v_max`` (the closed loop
holds each acceleration for a step; the argument below allows any measurable sequence, so it
covers those). Two **fallbacks** of the AV, each a constant acceleration held from some time
on: ``BRAKE`` (``u_min``: stand before the human's path) and ``GO`` (``u_max``: clear it).

**Propose, check, override.** At every step the policy proposes ``a``. The shield *admits*
``a`` if the AV trajectory "``a`` for one step, then a fallback ``F`` for ever" is certified
for ``F = BRAKE`` or ``F = GO``; otherwise it applies ``BRAKE`` if "``BRAKE`` for ever" is
certified, else ``GO`` (``certify_*`` below). A trajectory is **certified** when no human
makes an AV-caused overlap along it:

- *crossings* (two paths meeting once): the AV occupies its interval during the time window
  ``[t_in_R, t_out_R]`` (its position is monotone, so this is one window; ``t_in_R = inf`` when
  it stops before ``R_lo``); every human together occupies ``[t_in_H, t_out_H)``, where
  ``t_in_H`` is the earliest arrival at ``H_lo`` (full throttle) and ``t_out_H`` the time after
  which even the slowest human (full braking) is past ``H_hi`` (``inf`` when it can stop before
  it). Certified iff the AV never enters, or the windows are disjoint
  (``t_out_R < t_in_H`` or ``t_out_H < t_in_R``). Every position between the slowest and the
  fastest human is reachable at every time, so the test is exact for the human; the
  occupancy rectangle ``[R_lo, R_hi] x [H_lo, H_hi]`` contains every overlapping pair of
  positions (exactly the overlaps at the paper's intersection), so it is conservative there
  and only there.
- *shared lanes* (a merge; ``R_hi`` is the merge point, ``[H_lo, H_hi]`` the human's side
  zone, ``L`` the mean length): before the merge point as a crossing, except that the AV may
  end in the lane ahead of the human (merge ahead: it reaches the merge point before any human
  reaches its side zone; a human that then drives into it from behind is a rear-end by the
  human, not the AV's collision), or behind it (the human has surely passed its side zone
  before the AV enters its own, and the AV then follows it); in the lane behind a human the
  AV keeps the gap of a follower that brakes at ``u_min`` after the step against a leader
  braking at its ``u_min`` from now: ``s_H(t) - s_R(t) > L`` for all ``t`` (checked on the
  breakpoints and the stationary points of the piecewise-quadratic gap, exactly).

**Invariant.** Let ``S`` be the joint states from which ``BRAKE`` or ``GO`` for ever is certified.
If the state is in ``S``, the shield's output keeps it in ``S`` and no AV-caused overlap happens
during the step. *Proof.* An admitted ``a`` comes with a fallback ``F`` such that "``a``, then
``F``" is certified from ``(x_R, x_H)``; after the step the AV is at the second piece's start and
the human at some state it reached within its limits, and the humans from there are a subset of
those from ``x_H``, so "``F`` for ever" is certified from the new state. An override applies the
first step of a certified fallback, and the same argument holds with ``a = F``. Certification
covers the step itself (the windows are in continuous time from now), so no overlap happens within
it either. By induction, from an initial state in ``S`` no AV-caused overlap ever happens. The
closed loop's initial states let each vehicle stop before its conflict zone and the AV stand
before its occupancy interval (``Scenario.av_stands_before_occupancy``, this module's own test),
so they are in ``S``. From states outside it the shield still answers (``UNCERTIFIED``: the
fallback whose possible overlap starts latest, or is shortest), e.g. with measurement noise on, or
when a vehicle appears out of nowhere in an outside simulator, where the guarantee does not hold.

**Acceleration noise** (``simulation.accel_noise_mps2 = w``, uniform, on both vehicles) is
certified against: the human's limits widen by ``w`` (:func:`conflict_vector`) and the AV's
trajectory is any between the slowest and the fastest realisation (:func:`certified`).
**Uniform measurement noise** is certified against as state sets: a measured state stands for
the box of true states within the noise's half-widths, bounded by its furthest-and-fastest and
nearest-and-slowest corners (:func:`_fast`, :func:`_slow`); a step certified on the box is safe
for every true state in it, but a fresh measurement can leave ``S`` (docs/method.md §12.2).

**The yield line** (docs/method.md §12.8). Each conflict carries the AV's yield line
``C_R_LINE <= R_lo``: where it stands when it yields. While the line *binds* (the AV is before
it and can still stand before it, :func:`line_binds`), "``a``, then ``BRAKE``" is certified with
the AV's interval taken to start at the line (:func:`brake_certified`), and an override first
tries the gentlest stop at the line (:func:`line_brake`); once committed, an override prefers
``GO`` to ``BRAKE``, and while the AV is committed before a crossing's interval or inside it, a
braking proposal (or standing) is admitted only when no way through is certified: it drives
through rather than stand where it blocks the others (every kind; standing there stays
certified, but is the last resort). Moving ``R_lo`` back only enlarges the AV's claimed occupancy, so every
answer is still certified from the current state and ``S`` is unchanged: the line chooses among
certified answers, never adds one. A line at ``R_lo`` (the default) never binds.

**Enter, then follow** (docs/method.md §12.11). A merge between two cars of the main road is
certified by neither fallback (``GO`` for ever reaches the car ahead, ``BRAKE`` stops in the
side zone where the car behind arrives), so a third family joins them: ``FOLLOW(m)``, ``u_max``
for ``m`` whole steps after the step (until the AV is past every merge point and crossing
interval in view, :func:`follow_steps`), then the in-lane braking for ever, certified exactly on the three-piece
motion (:func:`certified3`). Its switch falls on a step boundary, so a step that carries it out
lands on its remainder, ``FOLLOW(m - 1)``: the invariant above holds for ``S`` the states from
which ``BRAKE``, ``GO`` or some ``FOLLOW(m)`` is certified, which contains the old ``S``. It is
tried only with the exact kinematics (no noise, no simulator lead), where that holds.

**Conservative, never optimistic.** Every time compared carries a margin of
:data:`TIME_MARGIN_S` against the AV and every interval is widened by rounding margins when it
is built (``persuasive.packing``), so floating-point rounding cannot turn an unsafe verdict into
a safe one. The ``responsive`` kind is *not* a guarantee against every human: it assumes the
human does anything for ``rho`` seconds and then brakes at its ``u_min`` (the frontier between
safety and persuasion, docs/method.md §12.5). Nor is the ``responsibility`` kind
(docs/method.md §12.13): it certifies against the humans RSS's intersection rule obliges to
respond (:func:`responsible_arrival`), keeping in each conflict vector what is left of each
one's response and whether it owes one (``C_RESP_LEFT``, ``C_RESP_OWED``, written by
:func:`shield_filter` after each decision), and its guarantee holds only while they keep the
rule (``persuasive.safety.responsibility`` watches that).

**One filter in one place.** :func:`shield_filter` is the only entry point that applies the
shield: every loop and adapter (the compiled closed loop, the Python loop, ``Planner``, the
adapter for outside simulators) first lets its policy propose, then calls it (through
:class:`persuasive.safety.filter.ShieldFilter` from Python). It takes one **conflict vector**
``C`` (``N_CONFLICT`` floats, :func:`conflict_vector`) per other vehicle: the closed loop has
one, from the scenario; an outside simulator one per vehicle (``persuasive.envs.external``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import packing as slot
from ..kinematics import saturated_step

# Conflict vector slots: the AV's and the human's occupancy intervals [m]; 1.0 for a shared
# lane (``R_HI`` is then the merge point, ``H_LO..H_HI`` the human's side zone); the mean
# length of the pair [m] (the gap of a follower); the shield kind and the responsive
# human's response time [s]; the AV's and the human's limits; the AV's yield line (where it
# stands when it yields, at or before ``R_LO``; ``R_LO`` itself: none before the interval).
# Then the half-width of the uniform error on the AV's applied acceleration [m/s^2]
# (``simulation.accel_noise_mps2``; the human's limits are widened by it already). Last, the
# cut-in rule of a shared lane (``[responsibility]``, docs/method.md §12.10): the follower's
# reaction time [s], its acceleration during it, its braking after it and the AV's hardest
# braking in the lane ahead of it [m/s^2, brakings positive]. Then the
# half-widths of a uniform error on every measured position [m] and speed [m/s]
# (``simulation.measurement_noise = "uniform"``; 0 otherwise): each measured state stands for
# the box of true states around it (:func:`_fast`, :func:`_slow`). Then the AV's braking
# command in the lane ahead of this vehicle (its ``C_R_UMIN`` held to the cut-in rule's in-lane
# limit in a shared lane, :func:`lane_braking`; ``C_R_UMIN`` elsewhere): the filter's BRAKE
# while the AV is there (:func:`braking`). Last, for the ``responsibility`` kind
# (docs/method.md §12.13): who has the right of way (1 the AV, -1 the other, 0 neither); and
# the filter's own state, which it writes after each decision and a caller keeps per vehicle
# from one step to the next: the **response left** [s], what is left of this vehicle's
# response time at the next step's start should that instant be dangerous (``rho`` after a
# safe instant; ``inf``: not seen yet, its response starts with its first dangerous instant),
# and 1.0 when the vehicle owes a response in a danger that began there (0.0: it has the
# right of way and the AV could still stop at its last safe instant).
(C_R_LO, C_R_HI, C_H_LO, C_H_HI, C_SHARED, C_GAP, C_KIND, C_RHO, C_R_UMIN, C_R_UMAX, C_R_VMIN,
 C_R_VMAX, C_H_UMIN, C_H_UMAX, C_H_VMIN, C_H_VMAX, C_R_LINE, C_R_NOISE, C_RESP_RHO,
 C_RESP_ACCEL, C_RESP_BRAKE, C_RESP_FRONT, C_MEAS_S, C_MEAS_V, C_R_ULANE, C_PRIORITY,
 C_RESP_LEFT, C_RESP_OWED) = range(28)
N_CONFLICT = 28

#: Verdicts of :func:`shield_filter` (the world logs them per step); ``OFF``: no shield.
ADMITTED, BRAKE, GO, UNCERTIFIED, OFF = 0, 1, 2, 3, -1
VERDICTS = ("admitted", "brake", "go", "uncertified")

#: Margin on every compared time, against the AV [s]: far below anything physical, far above
#: the rounding of the closed forms.
TIME_MARGIN_S = 1e-6
#: Margin on a follower's gap, against the AV [m] (same reason).
GAP_MARGIN_M = 1e-6
#: How far before its yield line the AV aims to stand when it yields there [m]: standing on
#: the line itself would count as past it (committed).
LINE_MARGIN_M = 0.01

_INF = math.inf


@njit(cache=True, _nrt=False, inline="always")
def lane_braking(u_min: float, front_brake: float, w: float) -> float:
    """The AV's braking command in a shared lane [m/s^2]: its own ``u_min``, held to the
    cut-in rule's in-lane limit ``front_brake`` (positive) less the acceleration noise ``w``,
    so that no realisation brakes harder than the rule allows (docs/method.md §12.10)."""
    return max(u_min, -front_brake + w)


@njit(cache=True, _nrt=False)
def conflict_vector(P_av: np.ndarray, P_hv: np.ndarray, out: np.ndarray) -> None:
    """The closed loop's conflict vector (``N_CONFLICT``,) from the two parameter vectors."""
    out[C_R_LO], out[C_R_HI] = P_av[slot.SHIELD_OCC_LO], P_av[slot.SHIELD_OCC_HI]
    out[C_H_LO], out[C_H_HI] = P_hv[slot.SHIELD_OCC_LO], P_hv[slot.SHIELD_OCC_HI]
    out[C_SHARED] = P_av[slot.LANE_SHARED]
    out[C_GAP] = 0.5 * (P_av[slot.LENGTH] + P_hv[slot.LENGTH]) + P_av[slot.SHIELD_MARGIN]
    out[C_KIND], out[C_RHO] = P_av[slot.SHIELD], P_av[slot.SHIELD_RESPONSE]
    out[C_R_UMIN], out[C_R_UMAX] = P_av[slot.U_MIN], P_av[slot.U_MAX]
    out[C_R_VMIN], out[C_R_VMAX] = P_av[slot.V_MIN], P_av[slot.V_MAX]
    # the acceleration noise both vehicles' accelerations carry (uniform, half-width w): the
    # human's limits widen by it, the AV's trajectories become the set between its slowest and
    # fastest (docs/method.md §12.2)
    w = P_av[slot.ACCEL_NOISE]
    out[C_H_UMIN], out[C_H_UMAX] = P_hv[slot.U_MIN] - w, P_hv[slot.U_MAX] + w
    out[C_R_NOISE] = w
    out[C_H_VMIN], out[C_H_VMAX] = P_hv[slot.V_MIN], P_hv[slot.V_MAX]
    out[C_R_LINE] = min(P_av[slot.SHIELD_LINE], P_av[slot.SHIELD_OCC_LO])
    out[C_RESP_RHO], out[C_RESP_ACCEL] = P_av[slot.RESP_RHO], P_av[slot.RESP_ACCEL]
    out[C_RESP_BRAKE], out[C_RESP_FRONT] = P_av[slot.RESP_BRAKE], P_av[slot.RESP_FRONT_BRAKE]
    out[C_R_ULANE] = (lane_braking(P_av[slot.U_MIN], P_av[slot.RESP_FRONT_BRAKE], w)
                      if out[C_SHARED] != 0.0 else out[C_R_UMIN])
    out[C_MEAS_S], out[C_MEAS_V] = P_av[slot.MEAS_S], P_av[slot.MEAS_V]
    out[C_PRIORITY] = P_av[slot.RIGHT_OF_WAY]
    out[C_RESP_LEFT], out[C_RESP_OWED] = _INF, 1.0


@njit(cache=True, _nrt=False, inline="always")
def _fast(s: float, v: float, v_min: float, v_max: float, C: np.ndarray
          ) -> tuple[float, float]:
    """The furthest and fastest true state behind a measured ``(s, v)``: ``s + ds`` and
    ``v + dv`` (at most ``v_max``), ``ds, dv`` the uniform measurement error's
    half-widths (0: the state itself, exactly). Reach times are monotone in both, so it
    arrives first of every state in the box."""
    dv = C[C_MEAS_V]
    return s + C[C_MEAS_S], (min(v + dv, v_max) if dv > 0.0 else v)


@njit(cache=True, _nrt=False, inline="always")
def _slow(s: float, v: float, v_min: float, v_max: float, C: np.ndarray
          ) -> tuple[float, float]:
    """The nearest and slowest true state behind a measured ``(s, v)`` (:func:`_fast`)."""
    dv = C[C_MEAS_V]
    return s - C[C_MEAS_S], (max(v - dv, v_min) if dv > 0.0 else v)



# -- one vehicle under constant acceleration -----------------------------------------------


@njit(cache=True, _nrt=False, inline="always")
def reach_time(s: float, v: float, a: float, target: float, v_min: float,
               v_max: float) -> float:
    """First time [s] at which a vehicle at ``(s, v)`` holding acceleration ``a`` (its speed
    saturating at ``v_min``/``v_max``, as :func:`persuasive.kinematics.saturated_step`) is at
    or past ``target``; 0 if it already is, ``inf`` if never."""
    d = target - s
    if d <= 0.0:
        return 0.0
    if a > 0.0:
        v_lim = v_max
        t_sat = (v_max - v) / a
        d_sat = (v_max * v_max - v * v) / (2.0 * a)
    elif a < 0.0:
        v_lim = v_min
        t_sat = (v_min - v) / a
        d_sat = (v_min * v_min - v * v) / (2.0 * a)
    else:  # constant speed (not the root below: v * v underflows for a speed of 1e-160)
        return d / v if v > 0.0 else _INF
    if d <= d_sat:  # reached before the speed saturates
        # t = 2 d / (v + sqrt(v^2 + 2 a d))
        if v >= 1e-150 or abs(a) * d >= 1e-300:  # neither square underflows
            disc = max(v * v + 2.0 * a * d, 0.0)
            den = v + math.sqrt(disc)
            return 2.0 * d / den if den > 0.0 else _INF
        # tiny numbers (v = a = d = 6e-236 underflow v^2 + 2 a d to 0, giving 2 s for
        # 0.73 s, a late arrival): the same root with everything scaled by
        # m = max(v, sqrt(|a| d)) first
        m = max(v, math.sqrt(abs(a)) * math.sqrt(d))
        if m <= 0.0:
            return _INF
        r = math.sqrt(abs(a)) * math.sqrt(d) / m
        disc = max((v / m) * (v / m) + (2.0 if a > 0.0 else -2.0) * r * r, 0.0)
        den = v / m + math.sqrt(disc)
        return 2.0 * (d / m) / den if den > 0.0 else _INF
    if v_lim <= 0.0:
        return _INF
    return t_sat + (d - d_sat) / v_lim


@njit(cache=True, _nrt=False, inline="always")
def profile3_reach(s: float, v: float, a1: float, d1: float, a2: float, d2: float, a3: float,
                   target: float, v_min: float, v_max: float) -> float:
    """:func:`reach_time` of the profile "``a1`` for ``d1`` seconds, then ``a2`` for ``d2``,
    then ``a3`` for ever" (``d2 = inf``: two pieces)."""
    t = reach_time(s, v, a1, target, v_min, v_max)
    if t <= d1:
        return t
    s1, v1 = saturated_step(s, v, a1, d1, v_min, v_max)
    t = reach_time(s1, v1, a2, target, v_min, v_max)
    if t <= d2:
        return d1 + t
    s2, v2 = saturated_step(s1, v1, a2, d2, v_min, v_max)
    return d1 + d2 + reach_time(s2, v2, a3, target, v_min, v_max)


@njit(cache=True, _nrt=False, inline="always")
def profile_reach(s: float, v: float, a1: float, d1: float, a2: float, target: float,
                  v_min: float, v_max: float) -> float:
    """:func:`reach_time` of the profile "``a1`` for ``d1`` seconds, then ``a2`` for ever"."""
    return profile3_reach(s, v, a1, d1, a2, _INF, a2, target, v_min, v_max)


@njit(cache=True, _nrt=False, inline="always")
def _profile_state(s: float, v: float, a1: float, d1: float, a2: float, d2: float, a3: float,
                   t: float, v_min: float, v_max: float) -> tuple[float, float]:
    """The state at time ``t`` of "``a1`` for ``d1``, then ``a2`` for ``d2``, then ``a3``"."""
    if t <= d1:
        return saturated_step(s, v, a1, t, v_min, v_max)
    s1, v1 = saturated_step(s, v, a1, d1, v_min, v_max)
    if t - d1 <= d2:
        return saturated_step(s1, v1, a2, t - d1, v_min, v_max)
    s2, v2 = saturated_step(s1, v1, a2, d2, v_min, v_max)
    return saturated_step(s2, v2, a3, t - d1 - d2, v_min, v_max)


@njit(cache=True, _nrt=False, inline="always")
def _saturation_time(v: float, a: float, v_min: float, v_max: float) -> float:
    if a > 0.0:
        return (v_max - v) / a
    if a < 0.0:
        return (v_min - v) / a
    return _INF


# -- the human's occupancy window ------------------------------------------------------------


@njit(cache=True, _nrt=False)
def human_window(s_H: float, v_H: float, C: np.ndarray) -> tuple[float, float, bool]:
    """When any human in the shield's model may be inside ``[H_lo, H_hi]``: ``(t_in, t_out,
    past)``. ``t_in``: earliest arrival at ``H_lo`` (``inf``: never; the ``responsive`` human
    arrives only if it cannot stop before ``H_lo`` after its response time); ``t_out``: the
    time after which every human is past ``H_hi`` (``inf`` if one can stop before it); ``past``:
    the human is already past ``H_hi`` (it never occupies again)."""
    lo, hi = C[C_H_LO], C[C_H_HI]
    u_min, u_max, v_min, v_max = C[C_H_UMIN], C[C_H_UMAX], C[C_H_VMIN], C[C_H_VMAX]
    sl, vl = _slow(s_H, v_H, v_min, v_max, C)  # every true state behind the measured one
    if sl > hi:
        return _INF, _INF, True
    sf, vf = _fast(s_H, v_H, v_min, v_max, C)
    kind = C[C_KIND]
    if kind == slot.SHIELD_RESPONSIVE:  # the furthest it gets: u_max for rho, then brake
        t_in = profile_reach(sf, vf, u_max, C[C_RHO], u_min, lo, v_min, v_max)
    elif kind == slot.SHIELD_RESPONSIBILITY and C[C_RESP_OWED] != 0.0 and C[C_SHARED] == 0.0:
        # what is left of the response it owes (not seen yet: the whole of it)
        left = C[C_RESP_LEFT]
        t_in = responsible_arrival(s_H, v_H, C, C[C_RESP_RHO] if left == _INF else left)
    else:
        t_in = reach_time(sf, vf, u_max, lo, v_min, v_max)
    t_out = reach_time(sl, vl, u_min, hi, v_min, v_max)
    return t_in, t_out, False


@njit(cache=True, _nrt=False, inline="always")
def owes_response(s_R: float, v_R: float, C: np.ndarray) -> float:
    """1.0 when the other vehicle owes its response in a danger that begins now (the
    ``responsibility`` kind, docs/method.md §12.13, after ``ad-rss``'s proper response): it
    does unless it has the right of way and the AV can still stand before the intersection
    (:func:`can_yield`; then the AV alone must yield)."""
    if C[C_PRIORITY] < 0.0 and can_yield(s_R, v_R, C):
        return 0.0
    return 1.0


@njit(cache=True, _nrt=False, inline="always")
def can_yield(s_R: float, v_R: float, C: np.ndarray) -> bool:
    """The AV can still stand before the intersection as the responsibility rule reads it:
    before its yield line where it has one (the junction's entry in SUMO and highway-env,
    :func:`line_binds`), else before its occupancy interval (:func:`yields_before`)."""
    if C[C_R_LINE] < C[C_R_LO]:
        return line_binds(s_R, v_R, C)
    return yields_before(s_R, v_R, C)


@njit(cache=True, _nrt=False, inline="always")
def fresh_response(s_R: float, v_R: float, dt: float, C: np.ndarray) -> float:
    """The response time [s] a vehicle is granted from a safe instant: the coming step, in
    which it cannot know that the next instant will be dangerous, and then the whole ``rho``
    from that first dangerous instant; one step more when it has the right of way and the AV
    can still stand before the intersection (:func:`can_yield`: it owes nothing before the AV
    has passed that point, which takes at least the step)."""
    fresh = C[C_RESP_RHO] + dt
    if C[C_PRIORITY] < 0.0 and can_yield(s_R, v_R, C):
        return fresh + dt
    return fresh


@njit(cache=True, _nrt=False, inline="always")
def responsible_arrival(s_H: float, v_H: float, C: np.ndarray, left: float) -> float:
    """The earliest arrival [s] at ``H_lo`` of a **responsible** human (the
    ``responsibility`` kind, docs/method.md §12.13, after RSS's intersection rule as
    ``ad-rss`` computes a vehicle's time to reach an intersection): it accelerates at most
    at the rule's ``C_RESP_ACCEL`` for the ``left`` seconds of its response time still to
    run, then brakes at least at ``C_RESP_BRAKE`` until it stands (``inf``: it stands before
    ``H_lo``). Under acceleration noise of half-width ``w`` its realised accelerations are
    taken ``w`` worse, and never beyond its physical limits."""
    v_min, v_max = C[C_H_VMIN], C[C_H_VMAX]
    sf, vf = _fast(s_H, v_H, v_min, v_max, C)
    w = C[C_R_NOISE]
    acc = min(C[C_RESP_ACCEL] + w, C[C_H_UMAX])
    brake = max(-C[C_RESP_BRAKE] + w, C[C_H_UMIN])
    return profile_reach(sf, vf, acc, max(left, 0.0), brake, C[C_H_LO], v_min, v_max)


# -- certification of one AV trajectory --------------------------------------------------------


@njit(cache=True, _nrt=False, inline="always")
def _held(a: float, v: float, v_min: float, v_max: float) -> float:
    """The acceleration a vehicle at speed ``v`` commanded ``a`` actually has from now on."""
    if (a > 0.0 and v >= v_max) or (a < 0.0 and v <= v_min):
        return 0.0
    return a


@njit(cache=True, _nrt=False, inline="always")
def _next_after(t: float, b0: float, b1: float, b2: float, b3: float) -> float:
    """The smallest of the breakpoints ``b*`` after ``t`` (``inf`` if none)."""
    out = _INF
    if t < b0 < out:
        out = b0
    if t < b1 < out:
        out = b1
    if t < b2 < out:
        out = b2
    if t < b3 < out:
        out = b3
    return out


@njit(cache=True, _nrt=False)
def _gap_ok(s_L: float, v_L: float, la1: float, ld1: float, la2: float, lv_min: float,
            lv_max: float, s_F: float, v_F: float, fa1: float, fd1: float, fa2: float,
            fd2: float, fa3: float, fv_min: float, fv_max: float, L: float) -> bool:
    """A follower ("``fa1`` for ``fd1`` seconds, then ``fa2`` for ``fd2``, then ``fa3``",
    speeds in ``fv_min..fv_max``; ``fd2 = inf``: two pieces) stays more than ``L`` behind a
    leader ("``la1`` for ``ld1``, then ``la2``"): ``s_L(t) - s_F(t) > L`` for all ``t >= 0``,
    exactly.

    Both positions are piecewise quadratic in ``t``; the gap's minimum lies at a breakpoint
    (a change of acceleration or a saturation) or where the speeds are equal inside a piece,
    and after the last breakpoint both speeds are constant."""
    # breakpoints: each vehicle's saturation in each piece and its switches
    b0 = _saturation_time(v_F, fa1, fv_min, fv_max)
    b0 = b0 if b0 < fd1 else _INF
    _, v1 = saturated_step(s_F, v_F, fa1, fd1, fv_min, fv_max)
    b2 = fd1 + _saturation_time(v1, fa2, fv_min, fv_max)
    sw2, b4 = _INF, _INF
    if fd2 < _INF:  # a third piece
        sw2 = fd1 + fd2
        b2 = b2 if b2 < sw2 else _INF
        _, v2 = saturated_step(0.0, v1, fa2, fd2, fv_min, fv_max)
        b4 = sw2 + _saturation_time(v2, fa3, fv_min, fv_max)
    c0 = _saturation_time(v_L, la1, lv_min, lv_max)
    c0 = c0 if c0 < ld1 else _INF
    _, w1 = saturated_step(s_L, v_L, la1, ld1, lv_min, lv_max)
    c2 = ld1 + _saturation_time(w1, la2, lv_min, lv_max)
    t = 0.0
    while True:
        sr, vr = _profile_state(s_F, v_F, fa1, fd1, fa2, fd2, fa3, t, fv_min, fv_max)
        sh, vh = _profile_state(s_L, v_L, la1, ld1, la2, _INF, la2, t, lv_min, lv_max)
        if not sh - sr > L:
            return False
        t_next = min(_next_after(t, b0, fd1, b2, sw2), _next_after(t, b4, c0, ld1, c2))
        # constant accelerations until t_next (0 once a speed limit is reached)
        ar = _held(fa1 if t < fd1 else (fa2 if t < sw2 else fa3), vr, fv_min, fv_max)
        ah = _held(la1 if t < ld1 else la2, vh, lv_min, lv_max)
        if ah != ar:  # the gap's stationary point inside the piece
            t_star = t + (vr - vh) / (ah - ar)
            if t < t_star < t_next:
                srs, _ = _profile_state(s_F, v_F, fa1, fd1, fa2, fd2, fa3, t_star, fv_min,
                                        fv_max)
                shs, _ = _profile_state(s_L, v_L, la1, ld1, la2, _INF, la2, t_star, lv_min,
                                        lv_max)
                if not shs - srs > L:
                    return False
        if t_next == _INF:
            # the speeds the two keep for ever: a speed a rounding error short of its limit
            # may leave no breakpoint of its own, so the limit is read off the acceleration
            vr_end = fv_max if ar > 0.0 else (fv_min if ar < 0.0 else vr)
            vh_end = lv_max if ah > 0.0 else (lv_min if ah < 0.0 else vh)
            return not vh_end < vr_end
        t = t_next


@njit(cache=True, _nrt=False, inline="always")
def _gap_holds(s_R: float, v_R: float, a1: float, d1: float, a2: float, d2: float, a3: float,
               s_H: float, v_H: float, C: np.ndarray) -> bool:
    """The AV following ("``a1`` for ``d1``, then ``a2`` for ``d2``, then ``a3``") never closes
    to within ``L`` of a human leader braking at its ``u_min`` from now (:func:`_gap_ok`)."""
    hu = C[C_H_UMIN]
    return _gap_ok(s_H, v_H, hu, 0.0, hu, C[C_H_VMIN], C[C_H_VMAX], s_R, v_R, a1, d1, a2, d2,
                   a3, C[C_R_VMIN], C[C_R_VMAX], C[C_GAP] + GAP_MARGIN_M)


@njit(cache=True, _nrt=False)
def cut_in_fair(s_R: float, v_R: float, a1: float, d1: float, a2: float, d2: float, a3: float,
                t_0: float, s_H: float, v_H: float, C: np.ndarray) -> bool:
    """The cut-in rule (docs/method.md §12.10) for the AV trajectory "``a1`` for ``d1``, then
    ``a2`` for ``d2``, then ``a3``" (its slowest realisation under acceleration noise) that
    reaches the merge point at ``t_0``: against the furthest and fastest human at ``t_0``
    (full throttle from now: every human is behind it and slower), a follower that holds
    ``C_RESP_ACCEL`` for ``C_RESP_RHO`` and then brakes at ``C_RESP_BRAKE`` stays more than
    the gap behind the AV braking at ``C_RESP_FRONT`` from ``t_0`` (RSS's safe longitudinal
    distance, computed exactly on the piecewise-quadratic motions rather than by the closed
    form, so that it also holds when the follower brakes harder than the AV, or reaches a
    speed limit)."""
    w = C[C_R_NOISE]
    rv_min, rv_max, hv_min, hv_max = C[C_R_VMIN], C[C_R_VMAX], C[C_H_VMIN], C[C_H_VMAX]
    s_e, v_e = _profile_state(s_R, v_R, a1 - w, d1, a2 - w, d2, a3 - w, t_0, rv_min, rv_max)
    s_h, v_h = saturated_step(s_H, v_H, C[C_H_UMAX], t_0, hv_min, hv_max)
    front = -C[C_RESP_FRONT]
    return _gap_ok(s_e, v_e, front, 0.0, front, rv_min, rv_max, s_h, v_h, C[C_RESP_ACCEL],
                   C[C_RESP_RHO], -C[C_RESP_BRAKE], _INF, -C[C_RESP_BRAKE], hv_min, hv_max,
                   C[C_GAP] + GAP_MARGIN_M)


@njit(cache=True, _nrt=False)
def certified3(s_R: float, v_R: float, a1: float, d1: float, a2: float, d2: float, a3: float,
               s_H: float, v_H: float, C: np.ndarray, t_in_H: float, t_out_H: float,
               past: bool) -> bool:
    """Whether the AV trajectory "``a1`` for ``d1`` seconds, then ``a2`` for ``d2``, then
    ``a3`` for ever" is certified against every human of the model (module docstring);
    ``t_in_H, t_out_H, past``: the human's :func:`human_window`. ``d2 = inf`` is the
    two-piece trajectory of :func:`certified`; a finite ``d2`` is the enter-then-follow
    fallback (:func:`follow_steps`). With acceleration noise of half-width
    ``w = C[C_R_NOISE]`` the AV's actual trajectory lies between the slowest ("``a1 - w``,
    then ``a2 - w``, ...") and the fastest (``+ w``), position being monotone in every step's
    acceleration: it enters no earlier than the fastest, leaves no later than the slowest,
    stands before a line if the fastest does, and follows no closer than the fastest."""
    m = TIME_MARGIN_S
    rv_min, rv_max = C[C_R_VMIN], C[C_R_VMAX]
    r_lo, r_hi = C[C_R_LO], C[C_R_HI]
    w = C[C_R_NOISE]
    # fastest, slowest (w = 0: a1, a2, a3)
    f1, f2, f3, l1, l2, l3 = a1 + w, a2 + w, a3 + w, a1 - w, a2 - w, a3 - w
    # the box of true states behind the measured ones: its furthest and fastest corner enters
    # first, its nearest and slowest leaves last (no measurement error: the state itself)
    sf, vf = _fast(s_R, v_R, rv_min, rv_max, C)
    sl, vl = _slow(s_R, v_R, rv_min, rv_max, C)
    if C[C_SHARED] == 0.0:  # a crossing
        if sl > r_hi:
            return True
        t_in_R = profile3_reach(sf, vf, f1, d1, f2, d2, f3, r_lo, rv_min, rv_max)
        if t_in_R == _INF or t_in_H == _INF:
            return True  # it stands before the human's path, or no human gets to its own
        t_out_R = profile3_reach(sl, vl, l1, d1, l2, d2, l3, r_hi, rv_min, rv_max)
        return t_out_R + m < t_in_H - m or t_out_H + m < t_in_R - m
    # a shared lane past r_hi (the merge point)
    hv_min, hv_max = C[C_H_VMIN], C[C_H_VMAX]
    hf, hvf = _fast(s_H, v_H, hv_min, hv_max, C)
    hl, hvl = _slow(s_H, v_H, hv_min, hv_max, C)
    u_lane = C[C_R_ULANE]  # the AV's braking command held to the cut-in rule's in-lane limit
    if sl >= r_hi:
        if hf < sl:  # the human is behind: the AV brakes no harder than the rule allows
            return a1 >= u_lane and a2 >= u_lane and a3 >= u_lane
        return _gap_holds(sf, vf, f1, d1, f2, d2, f3, hl, hvl, C)
    t_in_R = profile3_reach(sf, vf, f1, d1, f2, d2, f3, r_lo, rv_min, rv_max)
    if t_in_R == _INF:
        return True  # it stands before the side zone
    t_0 = profile3_reach(sl, vl, l1, d1, l2, d2, l3, r_hi, rv_min, rv_max)
    if not past and (t_in_H == _INF or t_0 + m < t_in_H - m):
        # in the lane (or standing in its side zone) before any human gets near: ahead of
        # it by the cut-in rule, and from its entry on braking no harder than the rule allows
        if t_0 == _INF:
            return True
        t_enter = profile3_reach(sf, vf, f1, d1, f2, d2, f3, r_hi, rv_min, rv_max)
        return (a3 >= u_lane and (t_enter >= d1 + d2 or a2 >= u_lane)
                and (t_enter >= d1 or a1 >= u_lane)
                and cut_in_fair(sl, vl, a1, d1, a2, d2, a3, t_0, hf, hvf, C))
    if past or t_out_H + m < t_in_R - m:  # the human is surely ahead: follow it
        return _gap_holds(sf, vf, f1, d1, f2, d2, f3, hl, hvl, C)
    return False


@njit(cache=True, _nrt=False)
def certified(s_R: float, v_R: float, a1: float, d1: float, a2: float, s_H: float,
              v_H: float, C: np.ndarray, t_in_H: float, t_out_H: float, past: bool) -> bool:
    """Whether the AV trajectory "``a1`` for ``d1`` seconds, then ``a2`` for ever" is
    certified against every human of the model (:func:`certified3` with two pieces)."""
    return certified3(s_R, v_R, a1, d1, a2, _INF, a2, s_H, v_H, C, t_in_H, t_out_H, past)


@njit(cache=True, _nrt=False)
def threat(s_R: float, v_R: float, a1: float, d1: float, a2: float, s_H: float, v_H: float,
           C: np.ndarray, t_in_H: float, t_out_H: float, past: bool) -> tuple[float, float]:
    """How soon and for how long some human of the model could overlap the AV along "``a1``
    for ``d1``, then ``a2``": ``(start, length)`` [s] of the first window in which both may be
    inside their intervals (``(inf, 0)`` when certified; ``(0, inf)`` when the AV could not
    follow a leader). Only used to pick the less bad fallback outside the invariant set."""
    if certified(s_R, v_R, a1, d1, a2, s_H, v_H, C, t_in_H, t_out_H, past):
        return _INF, 0.0
    rv_min, rv_max = C[C_R_VMIN], C[C_R_VMAX]
    sf, vf = _fast(s_R, v_R, rv_min, rv_max, C)
    sl, vl = _slow(s_R, v_R, rv_min, rv_max, C)
    if C[C_SHARED] != 0.0 and (sl >= C[C_R_HI] or past):
        return 0.0, _INF
    w = C[C_R_NOISE]
    t_in_R = profile_reach(sf, vf, a1 + w, d1, a2 + w, C[C_R_LO], rv_min, rv_max)
    t_out_R = profile_reach(sl, vl, a1 - w, d1, a2 - w, C[C_R_HI], rv_min, rv_max)
    start = max(t_in_R, t_in_H)
    return start, max(min(t_out_R, t_out_H) - start, 0.0)


@njit(cache=True, _nrt=False, inline="always")
def _worse(start_a: float, len_a: float, start_b: float, len_b: float) -> bool:
    """Threat ``a`` is worse than ``b``: it starts sooner, or as soon and lasts longer."""
    return start_a < start_b or (start_a == start_b and len_a > len_b)


# -- the filter ---------------------------------------------------------------------------------


@njit(cache=True, _nrt=False, inline="always")
def line_binds(s: float, v: float, C: np.ndarray) -> bool:
    """The AV at ``(s, v)`` has a yield line before its occupancy interval and can still
    stand before it by braking now: it has not committed (docs/method.md §12.8)."""
    line = C[C_R_LINE]
    sf, vf = _fast(s, v, C[C_R_VMIN], C[C_R_VMAX], C)  # every true state behind the measured
    if not (line < C[C_R_LO] and sf < line):
        return False
    # where :func:`brake_certified` then wants it to stand: before its stop target
    # (LINE_MARGIN_M before the line), or, already past the target, before the line itself;
    # an AV that could stand before the line but not before its target has committed (with
    # acceleration noise a braking harder than the weakest can bring it back into reach of
    # the line, and the line must not bind where it cannot be kept: docs/method.md §12.8)
    target = line - LINE_MARGIN_M
    return reach_time(sf, vf, C[C_R_UMIN] + C[C_R_NOISE], target if sf < target else line,
                      C[C_R_VMIN], C[C_R_VMAX]) == _INF


@njit(cache=True, _nrt=False)
def brake_certified(s_R: float, v_R: float, a: float, dt: float, s_H: float, v_H: float,
                    C: np.ndarray, t_in_H: float, t_out_H: float, past: bool,
                    binds: bool, u_brake: float) -> bool:
    """"``a``, then ``BRAKE``" is certified, ``BRAKE`` being ``u_brake`` (the filter's, the
    weakest of its conflicts'; one conflict: its ``C_R_UMIN``); ``binds`` (:func:`line_binds`
    at the step's start): certified with the AV's interval starting at its stop target,
    :data:`LINE_MARGIN_M` before its yield line, so that it yields there, not at the interval
    (more conservative: the interval only grows). An AV already past its target (within the
    margin before the line: a stop at the target that rolled on by rounding or a simulator's
    integration) may not creep on: it moves forward only when ``GO`` is certified, and
    standing there is certified against the line itself."""
    u_min = u_brake
    if not binds:
        return certified(s_R, v_R, a, dt, u_min, s_H, v_H, C, t_in_H, t_out_H, past)
    line = C[C_R_LINE]
    target = line - LINE_MARGIN_M
    if a == C[C_R_UMIN] and u_min == C[C_R_UMIN]:
        # full braking from now: :func:`line_binds` (from the same position) found that its
        # weakest realisation stands before the stop target (the line itself within the
        # margin), so the interval moved back there is never entered; not computed again,
        # because two roundings of the same stop must not disagree
        return True
    if s_R + C[C_MEAS_S] >= target:
        if a > 0.0:
            return False
        target = line
    lo = C[C_R_LO]
    C[C_R_LO] = target
    ok = certified(s_R, v_R, a, dt, u_min, s_H, v_H, C, t_in_H, t_out_H, past)
    C[C_R_LO] = lo
    return ok


@njit(cache=True, _nrt=False, inline="always")
def in_lane_ahead(s_R: float, v_R: float, s_H: float, v_H: float, C: np.ndarray) -> bool:
    """The AV is surely in the shared lane (past the merge point) and the human surely behind
    it: the cut-in rule's in-lane braking limit holds (docs/method.md §12.10)."""
    if C[C_SHARED] == 0.0:
        return False
    sl, _ = _slow(s_R, v_R, C[C_R_VMIN], C[C_R_VMAX], C)
    hf, _ = _fast(s_H, v_H, C[C_H_VMIN], C[C_H_VMAX], C)
    return sl >= C[C_R_HI] and hf < sl


@njit(cache=True, _nrt=False, inline="always")
def braking(s_R: float, v_R: float, s_H: float, v_H: float, C: np.ndarray) -> float:
    """The BRAKE fallback's command against this conflict [m/s^2]: the AV's ``u_min``, or
    the in-lane limit while it is in the lane ahead of the human (:func:`in_lane_ahead`).
    Held to the limit only there, not before the merge point: the limit of a merge conflict
    does not weaken the AV's braking against the others until it has entered the lane (a
    merge conflict appearing while the AV approaches a crossing leaves its certificate for
    that crossing as it was)."""
    if in_lane_ahead(s_R, v_R, s_H, v_H, C):
        return C[C_R_ULANE]
    return C[C_R_UMIN]


@njit(cache=True, _nrt=False, inline="always")
def follow_steps(v: float, first: float, dt: float, dist: float, u_max: float, v_min: float,
                 v_max: float) -> int:
    """How many whole steps of ``u_max`` after a first step of ``first`` (from speed ``v``)
    carry the AV ``dist`` metres or more: the GO part of the enter-then-follow fallback
    (docs/method.md §12.11); -1 if none does. Whole steps, so that the fallback's switch
    falls on a step boundary and the step that carries it out lands exactly on its remainder
    (the next step's fallback has one step less); a relative 1e-6 of a step is forgiven so
    that rounding cannot add a step, and the filter also tries one more."""
    x1, v1 = saturated_step(0.0, v, first, dt, v_min, v_max)
    t = reach_time(x1, v1, u_max, dist, v_min, v_max)
    if t == _INF:
        return -1
    return max(0, int(math.ceil(t / dt - 1e-6)))


@njit(cache=True, _nrt=False)
def admissible(s_R: float, v_R: float, a: float, dt: float, s_H: float, v_H: float,
               C: np.ndarray, t_in_H: float, t_out_H: float, past: bool) -> bool:
    """The shield admits ``a`` for one step: "``a``, then ``GO``" is certified, or "``a``,
    then ``BRAKE``" (with the yield line while it binds, :func:`brake_certified`), or, in a
    shared lane with the exact kinematics, "``a``, then enter-then-follow" (the filter's
    ``FOLLOW(m)`` and ``FOLLOW(m + 1)``, docs/method.md §12.11): some fallback certifies it.
    The filter tries them in its own order, so a proposal admitted here on ``BRAKE`` alone
    may still be overridden by ``GO`` while the AV is committed before an interval
    (:func:`shield_filter`)."""
    u_brake = braking(s_R, v_R, s_H, v_H, C)
    if (certified(s_R, v_R, a, dt, C[C_R_UMAX], s_H, v_H, C, t_in_H, t_out_H, past)
            or brake_certified(s_R, v_R, a, dt, s_H, v_H, C, t_in_H, t_out_H, past,
                               line_binds(s_R, v_R, C), u_brake)):
        return True
    if C[C_SHARED] == 0.0 or C[C_R_NOISE] != 0.0 or C[C_MEAS_S] != 0.0 \
            or C[C_MEAS_V] != 0.0 or not math.isfinite(a):
        return False
    u_max = C[C_R_UMAX]
    m = follow_steps(v_R, a, dt, C[C_R_HI] - s_R, u_max, C[C_R_VMIN], C[C_R_VMAX])
    if m < 0:
        return False
    a_f = max(u_brake, C[C_R_ULANE])
    return (certified3(s_R, v_R, a, dt, u_max, m * dt, a_f, s_H, v_H, C, t_in_H, t_out_H, past)
            or certified3(s_R, v_R, a, dt, u_max, (m + 1) * dt, a_f, s_H, v_H, C, t_in_H,
                          t_out_H, past))


@njit(cache=True, _nrt=False, inline="always")
def line_brake(s: float, v: float, dt: float, line: float, u_min: float, u_max: float
               ) -> float:
    """The gentlest acceleration that, held for ``dt`` and followed by ``u_min``, stands the
    AV at ``(s, v)`` :data:`LINE_MARGIN_M` before ``line`` (within ``[u_min, 0]``: a yield
    never speeds up; ``u_min`` when none does): the yield that stops at the line instead of
    as early as full braking would, and leaves the AV standing where the line still binds.
    ``u_max`` is unused (kept for the callers' symmetry). Closed form
    of ``(v + w) dt / 2 + w^2 / (2 |u_min|) = line - s`` for the speed ``w`` after the step,
    less a relative margin; the caller certifies the result."""
    d = line - LINE_MARGIN_M - s
    if not (d > 0.0) or u_min >= 0.0:
        return u_min
    b = -u_min
    half = 0.5 * dt
    c = v * half - d
    disc = half * half - 2.0 * c / b
    if not disc >= 0.0:  # not even a stop within the step reaches only the line
        return u_min
    w = b * (-half + math.sqrt(disc))
    if w <= 0.0:
        return u_min
    a = (w - v) / dt
    a -= 1e-9 * (1.0 + abs(a))
    return min(max(a, u_min), 0.0)


@njit(cache=True, _nrt=False)
def go_certified(s_R: float, v_R: float, a: float, dt: float, s_H: float, v_H: float,
                 C: np.ndarray, t_in_H: float, t_out_H: float, past: bool) -> bool:
    """"``a``, then ``GO``" is certified: the AV can cross now whatever the human does."""
    return certified(s_R, v_R, a, dt, C[C_R_UMAX], s_H, v_H, C, t_in_H, t_out_H, past)


@njit(cache=True, _nrt=False)
def yields_before(s: float, v: float, C: np.ndarray) -> bool:
    """The AV at ``(s, v)`` can still stand before its occupancy interval by braking now
    (with its weakest braking under acceleration noise)."""
    sf, vf = _fast(s, v, C[C_R_VMIN], C[C_R_VMAX], C)
    return reach_time(sf, vf, C[C_R_UMIN] + C[C_R_NOISE], C[C_R_LO], C[C_R_VMIN],
                      C[C_R_VMAX]) == _INF


@njit(cache=True, _nrt=False, inline="always")
def _good(j: int, first: float, fb: float, shift: float, steps: int, dt: float, u_min: float,
          u_max: float, v_R: float, s_R: np.ndarray, s_H: np.ndarray, v_H: np.ndarray,
          C: np.ndarray, window: np.ndarray) -> bool:
    """Whether the candidate "``first`` for a step, then ``fb``" (``steps >= 0``: ``u_max``
    for that many steps first, the enter-then-follow fallback) is certified against vehicle
    ``j`` (its window in ``window[j]``), the AV taken ``shift`` further along."""
    past = window[j, 2] % 2.0 != 0.0
    if steps >= 0:
        return certified3(s_R[j] + shift, v_R, first, dt, u_max, steps * dt, fb, s_H[j],
                          v_H[j], C[j], window[j, 0], window[j, 1], past)
    if fb == u_min:
        return brake_certified(s_R[j] + shift, v_R, first, dt, s_H[j], v_H[j], C[j],
                               window[j, 0], window[j, 1], past, window[j, 2] >= 2.0, u_min)
    return certified(s_R[j] + shift, v_R, first, dt, fb, s_H[j], v_H[j], C[j], window[j, 0],
                     window[j, 1], past)


@njit(cache=True, _nrt=False)
def _pick(order, proposal_ok: bool, a: float, v_R: float, dt: float, s_R: np.ndarray,
          s_H: np.ndarray, v_H: np.ndarray, C: np.ndarray, lead: np.ndarray,
          window: np.ndarray, u_min: float, u_max: float, a_f: float, a_line: float,
          m_a: int, m_g: int, yielding: bool, follow: bool):
    """The first candidate of :func:`shield_filter`'s ``order`` certified against every
    vehicle (their windows in ``window``): ``(found, first step, verdict, fallback, shift,
    GO steps, candidate)``; a candidate above 9 in ``order`` is left out."""
    n = s_R.shape[0]
    for p in range(10):
        c = order[p]
        if c > 9 or (c < 4 and not proposal_ok):  # (c > 9: left out)
            continue
        steps = -1
        if c < 2:
            first, fb, shift, verdict = a, (u_min if c == 0 else u_max), lead[0], ADMITTED
        elif c < 4:
            if m_a < 0:
                continue
            first, fb, shift, verdict, steps = a, a_f, lead[0], ADMITTED, m_a + c - 2
        elif c == 4:
            if not yielding:
                continue
            first, fb, shift, verdict = a_line, u_min, lead[1], BRAKE
        elif c == 5:
            first, fb, shift, verdict = u_min, u_min, lead[1], BRAKE
        elif c == 6:
            first, fb, shift, verdict = u_max, u_max, lead[2], GO
        elif c < 9:
            if m_g < 0:
                continue
            first, fb, shift, verdict, steps = u_max, a_f, lead[2], GO, m_g + c - 7
        else:
            if not follow or a_f == u_min:
                continue
            first, fb, shift, verdict = a_f, a_f, lead[1], BRAKE
        ok = True
        for j in range(n):
            if not _good(j, first, fb, shift, steps, dt, u_min, u_max, v_R, s_R, s_H, v_H, C,
                         window):
                ok = False
                break
        if ok:
            return True, first, verdict, fb, shift, steps, c
    return False, 0.0, UNCERTIFIED, 0.0, 0.0, -1, -1


@njit(cache=True)
def shield_filter(kind: float, a: float, v_R: float, dt: float, u_brake: float,
                  s_R: np.ndarray, s_H: np.ndarray, v_H: np.ndarray, C: np.ndarray,
                  lead: np.ndarray, window: np.ndarray) -> tuple[float, int]:
    """**The** filter: every loop and adapter applies the shield through this one entry point
    (the closed loop with one conflict, an outside simulator with one per other vehicle),
    after its policy has proposed ``a``; returns ``(applied acceleration, verdict)``.

    ``kind``: the shield's kind (``persuasive.packing.SHIELD_*``; ``SHIELD_OFF``: ``a`` is
    applied as proposed, verdict :data:`OFF`). A **non-finite proposal** (NaN, an infinity) is
    never admitted: one of the fallbacks below applies (its verdict; the caller's log keeps the
    proposal), and with no conflict at all the AV's braking fallback ``u_brake`` [m/s^2]
    (``BRAKE``). Conflict ``j`` (of ``n = len(s_R)``; none at all: a finite proposal is
    admitted): ``s_R[j]`` the AV's position in its coordinates, ``s_H[j], v_H[j]`` the
    other vehicle's state, ``C[j]`` its conflict vector (:func:`conflict_vector`). A
    trajectory is certified only with one fallback against all of them: ``a`` is admitted if
    "``a``, then ``F``" is certified against every vehicle for ``F = BRAKE`` (held to the
    yield line of every conflict whose line binds) or for ``F = GO``; otherwise, while some
    line binds, the gentlest stop before every binding line (verdict ``BRAKE``), then
    ``BRAKE``, then ``GO``; once none binds, ``GO`` before ``BRAKE``, unless the proposal
    brakes harder than ``BRAKE`` (each if certified against all); with a shared lane in view
    and the exact kinematics the enter-then-follow fallbacks join both lists (after ``GO``:
    docs/method.md §12.11; verdict ``GO``). ``BRAKE`` is the AV's
    ``u_min``, held to the cut-in rule's in-lane limit while it is in the lane ahead of a
    vehicle (:func:`braking`, docs/method.md §12.10). Otherwise (``UNCERTIFIED``) the fallback whose first possible overlap, over
    all the vehicles, starts latest, or whose overlaps are shortest in all (ties: brake).

    ``lead`` ``(3,)`` [m]: how much further along its path the AV is taken when its first
    step is ``a``, ``u_min`` or ``u_max`` (zeros: the exact kinematics). A simulator that
    integrates differently from the exact step (highway-env's Euler step,
    :func:`persuasive.envs.highway.euler_shift`) hands in how much further its vehicle rolls
    to a stop after that first step than the exact kinematics say (the stop at a yield line,
    a braking step, takes ``u_min``'s). ``window``: scratch for the
    humans' windows, ``(n, 3)`` or larger (the caller keeps it, so that a step allocates
    nothing; a smaller one is replaced by a new one)."""
    if kind == slot.SHIELD_OFF:
        return a, OFF
    proposal_ok = math.isfinite(a)  # a non-finite proposal is never admitted: a fallback
    n = s_R.shape[0]
    if n == 0:
        return (a, ADMITTED) if proposal_ok else (u_brake, BRAKE)
    if window.shape[0] < n:
        window = np.empty((n, 3))
    for j in range(n):
        t_in, t_out, past = human_window(s_H[j], v_H[j], C[j])
        if kind == slot.SHIELD_RESPONSIBILITY and not past and C[j, C_SHARED] == 0.0:
            # first with a fresh response (a shared lane keeps the worst case: its rule is
            # the cut-in rule, docs/method.md §12.10)
            t_in = responsible_arrival(s_H[j], v_H[j], C[j], fresh_response(
                s_R[j] + lead[1], v_R, dt, C[j]))
        window[j, 0], window[j, 1], window[j, 2] = t_in, t_out, 1.0 if past else 0.0
    # BRAKE: the AV's u_min, held to the cut-in rule's in-lane limit while it is in the lane
    # ahead of some vehicle (the weakest such command, allowed against every conflict)
    u_min, u_max = C[0, C_R_UMIN], C[0, C_R_UMAX]
    for j in range(n):
        u_min = max(u_min, braking(s_R[j], v_R, s_H[j], v_H[j], C[j]))
    # the yield lines that still bind (the AV can stand before them: docs/method.md §12.8),
    # and the gentlest braking that stands before every one of them
    # and whether the AV is committed: past a line (or unable to stop before it) but still
    # before that conflict's interval, where standing would block the others (§12.8)
    yielding, committed, a_line = False, False, u_max
    for j in range(n):
        binds = line_binds(s_R[j] + lead[1], v_R, C[j])
        window[j, 2] += 2.0 if binds else 0.0
        if not binds and C[j, C_R_LINE] < C[j, C_R_LO] and s_R[j] + lead[1] < C[j, C_R_LO]:
            committed = True
        if binds:
            yielding = True
            sf, vf = _fast(s_R[j] + lead[1], v_R, C[j, C_R_VMIN], C[j, C_R_VMAX], C[j])
            a_line = min(a_line, line_brake(sf, vf, dt, C[j, C_R_LINE],
                                            u_min + C[j, C_R_NOISE], u_max) - C[j, C_R_NOISE])
    # the enter-then-follow fallbacks (docs/method.md §12.11), while a shared lane is in
    # view: GO for whole steps until the AV is past every merge point and crossing in view,
    # then the in-lane braking a_f; only with the exact kinematics (no noise, no lead), where
    # the step lands where it was certified to
    follow, dist, a_f = False, 0.0, u_min
    for j in range(n):
        if C[j, C_SHARED] != 0.0:
            follow = True
            a_f = max(a_f, C[j, C_R_ULANE])
    for j in range(n):
        if not follow:
            break
        # past every merge point and every crossing in view before it brakes
        dist = max(dist, C[j, C_R_HI] - s_R[j])
        if C[j, C_R_NOISE] != 0.0 or C[j, C_MEAS_S] != 0.0 or C[j, C_MEAS_V] != 0.0:
            follow = False
    if follow and (lead[0] != 0.0 or lead[1] != 0.0 or lead[2] != 0.0):
        follow = False
    m_a = follow_steps(v_R, a, dt, dist, u_max, C[0, C_R_VMIN], C[0, C_R_VMAX]) \
        if follow and proposal_ok else -1
    m_g = follow_steps(v_R, u_max, dt, dist, u_max, C[0, C_R_VMIN], C[0, C_R_VMAX]) \
        if follow else -1
    # candidates (the first step, the fallback after it, the fallback's GO steps): 0, 1 the
    # proposal with BRAKE or GO, 2, 3 with enter-then-follow; then, while a line binds, 4 the
    # yield at the line, 5 BRAKE, 6 GO, 7, 8 enter-then-follow; once no line binds, GO,
    # enter-then-follow, then BRAKE: drive through rather than stand where it blocks others;
    # but a proposal that brakes harder than BRAKE (the in-lane limit of a shared lane) gets
    # BRAKE first, the nearest to what it asked; last 9, the in-lane braking a_f alone (where
    # an enter-then-follow fallback ends). Committed between a line and its interval, the
    # proposal is admitted with BRAKE only after every way through has failed (it would
    # stand there)
    through = False
    asked = proposal_ok
    if not yielding:
        # an AV between a line and its interval or inside a crossing's interval that brakes
        # (or stays at rest) would be admitted wherever "a, then GO" stays certified, and
        # could stand there, where it blocks the others, for as long as GO does (issue 39: 13
        # of 2,286 random worst-case runs ended at rest inside the interval); under the
        # responsibility rule others stop for an AV in their way, and standing there would
        # even count as safe (docs/method.md §12.13). So, whatever the kind, it drives
        # through instead: a braking proposal there is admitted only when no way through is
        # certified (the second pass below); for the responsibility kind standing is then
        # its last resort and a safe instant only for the vehicles that do not block its
        # way through (below)
        for j in range(n):
            s = s_R[j] + lead[1]
            if C[j, C_SHARED] == 0.0 and (C[j, C_R_LO] <= s <= C[j, C_R_HI] or (
                    C[j, C_R_LINE] < C[j, C_R_LO] and s < C[j, C_R_LO]
                    and window[j, 2] < 2.0)):  # inside, or past its line (committed)
                through = True
        if through:
            committed = True
            if proposal_ok and (a < 0.0 or (a <= 0.0 and v_R <= 0.0)):
                proposal_ok = False
    brake_first = yielding or (proposal_ok and a < u_min)
    if brake_first:
        order = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9)
    elif committed:
        order = (1, 2, 3, 6, 7, 8, 0, 5, 9, 4)
    else:
        order = (0, 1, 2, 3, 4, 6, 7, 8, 5, 9)
    # (the responsibility rule's first pass: only the ways through where the AV drives
    # through, candidates 10 left out)
    found, first, verdict, fb, shift, steps, c = _pick(
        (1, 2, 3, 6, 7, 8, 10, 10, 10, 10) if through else order, proposal_ok, a, v_R, dt,
        s_R, s_H, v_H, C, lead, window, u_min, u_max, a_f, a_line, m_a, m_g, yielding, follow)
    if through and not found and kind != slot.SHIELD_RESPONSIBILITY:
        # no way through is certified: the proposal as asked, then the fallbacks in order
        found, first, verdict, fb, shift, steps, c = _pick(
            order, asked, a, v_R, dt, s_R, s_H, v_H, C, lead, window, u_min, u_max, a_f,
            a_line, m_a, m_g, yielding, follow)
    if kind == slot.SHIELD_RESPONSIBILITY:
        # the response (docs/method.md §12.13): an answer certified against every
        # responsible human granted its fresh response makes this a safe instant for every
        # vehicle (each has its whole rho from the next dangerous instant on); otherwise
        # each vehicle keeps what is left of the response it owes since its own first
        # dangerous instant (a vehicle with the right of way that owes none: the worst
        # case), and after the answer a vehicle whose fresh window also certifies it has
        # its safe instant now
        if found:
            for j in range(n):
                C[j, C_RESP_LEFT] = C[j, C_RESP_RHO]
                C[j, C_RESP_OWED] = owes_response(s_R[j] + lead[1], v_R, C[j])
            return first, verdict
        for j in range(n):
            if C[j, C_RESP_LEFT] == _INF:  # first seen: its last safe instant is now
                C[j, C_RESP_LEFT] = fresh_response(s_R[j] + lead[1], v_R, dt, C[j])
                C[j, C_RESP_OWED] = owes_response(s_R[j] + lead[1], v_R, C[j])
            if window[j, 2] % 2.0 == 0.0:
                window[j, 0] = human_window(s_H[j], v_H[j], C[j])[0]
        found, first, verdict, fb, shift, steps, c = _pick(
            order, proposal_ok, a, v_R, dt, s_R, s_H, v_H, C, lead, window, u_min, u_max,
            a_f, a_line, m_a, m_g, yielding, follow)
        # a braking answer where the AV should drive through: a vehicle's instant is safe
        # only if GO would be certified against its fresh response (one that stopped for the
        # AV, and blocks its way through, keeps its response running until it must stand)
        stands = through and (c == 0 or c == 4 or c == 5 or c == 9)
        for j in range(n):
            safe = False
            if found and window[j, 2] % 2.0 == 0.0:
                held = window[j, 0]
                if C[j, C_SHARED] == 0.0:
                    window[j, 0] = responsible_arrival(s_H[j], v_H[j], C[j], fresh_response(
                        s_R[j] + lead[1], v_R, dt, C[j]))
                if stands:
                    safe = _good(j, u_max, u_max, lead[2], -1, dt, u_min, u_max, v_R, s_R,
                                 s_H, v_H, C, window)
                else:
                    safe = _good(j, first, fb, shift, steps, dt, u_min, u_max, v_R, s_R, s_H,
                                 v_H, C, window)
                window[j, 0] = held
            elif found:
                safe = True  # past its interval: it never occupies again
            if safe:
                C[j, C_RESP_LEFT] = C[j, C_RESP_RHO]
                C[j, C_RESP_OWED] = owes_response(s_R[j] + lead[1], v_R, C[j])
            else:
                C[j, C_RESP_LEFT] -= dt
        if found:
            return first, verdict
    elif found:
        return first, verdict
    sb, lb, sg, lg = _INF, 0.0, _INF, 0.0
    for j in range(n):
        past = window[j, 2] % 2.0 != 0.0
        s, length = threat(s_R[j] + lead[1], v_R, u_min, dt, u_min, s_H[j], v_H[j], C[j],
                           window[j, 0], window[j, 1], past)
        sb, lb = min(sb, s), lb + length
        s, length = threat(s_R[j] + lead[2], v_R, u_max, dt, u_max, s_H[j], v_H[j], C[j],
                           window[j, 0], window[j, 1], past)
        sg, lg = min(sg, s), lg + length
    return (u_max if _worse(sb, lb, sg, lg) else u_min), UNCERTIFIED


#: Size of the one buffer of :func:`shield_filter_one`: the conflict vector, then the three
#: positions it fills (``s_R, s_H, v_H``), the three leads (zeros) and the window's scratch.
ONE_BUFFER = N_CONFLICT + 9


def one_buffer(C: np.ndarray) -> np.ndarray:
    """A buffer for :func:`shield_filter_one` around conflict vector ``C``."""
    buf = np.zeros(ONE_BUFFER)
    buf[:N_CONFLICT] = C
    return buf


@njit(cache=True)
def shield_filter_one(kind: float, a: float, s_R: float, v_R: float, dt: float,
                      u_brake: float, s_H: float, v_H: float, buf: np.ndarray
                      ) -> tuple[float, int]:
    """:func:`shield_filter` against the closed loop's one other vehicle, the AV at ``(s_R,
    v_R)`` and the other at ``(s_H, v_H)``, everything else in one buffer
    (:func:`one_buffer`): the two-vehicle loops' way in, one array to hand over, so that a
    check from Python costs about what a scalar one would (no logic of its own)."""
    if kind == slot.SHIELD_OFF:  # (shield_filter's own first test, before any copying)
        return a, OFF
    n = N_CONFLICT
    buf[n], buf[n + 1], buf[n + 2] = s_R, s_H, v_H
    return shield_filter(kind, a, v_R, dt, u_brake, buf[n:n + 1], buf[n + 1:n + 2],
                         buf[n + 2:n + 3], buf[:n].reshape(1, n), buf[n + 3:n + 6],
                         buf[n + 6:n + 9].reshape(1, 3))


@njit(cache=True)
def shield_step(s_R: float, v_R: float, a: float, dt: float, s_H: float, v_H: float,
                C: np.ndarray) -> tuple[float, int]:
    """:func:`shield_filter` against one other vehicle at ``(s_H, v_H)``, the AV at
    ``(s_R, v_R)``, conflict vector ``C`` (its kind from ``C``): ``(applied acceleration,
    verdict)``. A convenience for one-off questions (it allocates); the loops keep their
    buffers."""
    buf = np.zeros(ONE_BUFFER)
    buf[:N_CONFLICT] = C
    return shield_filter_one(C[C_KIND], a, s_R, v_R, dt, C[C_R_UMIN], s_H, v_H, buf)


def verdict_name(code: int) -> str | None:
    """The name of verdict ``code`` (:data:`VERDICTS`); None for :data:`OFF` (no shield)."""
    return None if code == OFF else VERDICTS[code]


__all__ = ["ADMITTED", "BRAKE", "GO", "LINE_MARGIN_M", "N_CONFLICT", "OFF", "TIME_MARGIN_S",
           "UNCERTIFIED", "VERDICTS", "admissible", "brake_certified", "certified",
           "braking", "certified3", "conflict_vector", "cut_in_fair", "follow_steps",
           "go_certified", "human_window",
           "in_lane_ahead", "lane_braking",
           "line_binds", "line_brake",
           "one_buffer", "profile3_reach", "profile_reach", "reach_time", "shield_filter",
           "shield_filter_one", "shield_step",
           "verdict_name", "yields_before"]
