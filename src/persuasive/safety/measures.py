"""Surrogate safety measures of a run (docs/method.md §12.6), from its states.

The conflict is described by each vehicle's occupancy interval (``Path.occupancy``: outside
it the vehicle's footprint cannot touch the other's; in a merge, the side zone up to the merge
point, after which the lane is shared).

- **PET** (post-encroachment time) [s]: the time from the moment the first vehicle leaves its
  occupancy interval to the moment the second enters its own (crossing times interpolated
  linearly between the loop's states); 0 when both were inside at once; undefined (NaN) when
  one never enters or the first never leaves.
- **minimum TTC** (time to collision along the paths) [s]: at every state, both vehicles
  extrapolated at constant speed; on a crossing, the time at which both would be inside their
  occupancy intervals together (if their time windows meet); in a shared lane past the merge
  point, the gap over the closing speed of the follower. The minimum over the run; NaN if the
  two were never on a collision course.
- **minimum footprint gap** [m]: the smallest distance between the two oriented rectangles
  over the run (0 when they overlap): physical, in every scenario.
- **standoff** (deadlock): a window of ``STANDOFF_WINDOW_S`` (3 s) in which neither vehicle
  advances more than ``STANDOFF_PROGRESS_M`` (0.5 m) and neither has cleared the conflict by
  its end; a run has one when any window of its states does (runs shorter than the window
  have none). Reported with the time its first window starts.
- **waiting time** [s]: how long a vehicle stood (speed below ``WAIT_SPEED_MPS``, 0.1 m/s, as
  SUMO's ``waitingTime``) before it cleared the conflict (the whole run if it never did).
- **override cost**: the share of the AV's steps the shield overrode and the mean change it
  made to the proposal (:func:`override_cost`).
- **collisions by fault**: a collision (a run of overlapping states) is a *rear-end by the
  human* when it starts with the lane shared, the AV past the merge point and ahead of the
  human; every other collision is *caused by the AV* (the shield's target is none of those).
  Where it starts is judged in continuous time, at the first contact inside the step that
  led to the collision's first overlapping state (:func:`contact_rear_mask`): with a coarse
  step or a fast human, the human can go from behind the AV to ahead of it and overlapping
  between two states, and the first overlapping state then shows it ahead although it drove
  into the AV from behind.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..tables import STAND_V_MPS


#: A standoff: neither vehicle advances more than this [m] ...
STANDOFF_PROGRESS_M = 0.5
#: ... within this window [s], neither having cleared.
STANDOFF_WINDOW_S = 3.0
#: Below this speed a vehicle is waiting [m/s] (SUMO's ``waitingTime`` threshold).
WAIT_SPEED_MPS = STAND_V_MPS


def standoff(s_av: np.ndarray, s_hv: np.ndarray, cleared_av: np.ndarray,
             cleared_hv: np.ndarray, dt: float) -> float:
    """When the run's first standoff window starts [s] (module docstring); NaN if none.

    ``s_*``: positions at states ``0..N`` (``k dt``); ``cleared_*``: per state, the vehicle is
    past its conflict."""
    w = int(round(STANDOFF_WINDOW_S / dt))
    s_av, s_hv = np.asarray(s_av, float), np.asarray(s_hv, float)
    if s_av.shape[0] <= w:
        return math.nan
    still = ((s_av[w:] - s_av[:-w] <= STANDOFF_PROGRESS_M)
             & (s_hv[w:] - s_hv[:-w] <= STANDOFF_PROGRESS_M)
             & ~np.asarray(cleared_av, bool)[w:] & ~np.asarray(cleared_hv, bool)[w:])
    k = np.flatnonzero(still)
    return float(k[0] * dt) if k.size else math.nan


def waiting_time(v: np.ndarray, cleared: np.ndarray, dt: float) -> float:
    """Time [s] a vehicle stood (speed below ``WAIT_SPEED_MPS``) before it cleared: the steps
    ``k`` (from state ``k`` to ``k + 1``) that start below the speed, before the first cleared
    state. ``v``, ``cleared``: per state ``0..N``."""
    v, cleared = np.asarray(v, float), np.asarray(cleared, bool)
    done = np.flatnonzero(cleared)
    end = int(done[0]) if done.size else v.shape[0] - 1
    return float(np.count_nonzero(v[:end] < WAIT_SPEED_MPS) * dt)


def restricted_mean(times, horizon) -> float | None:
    """The restricted mean of times to clear (or cross) ``times``: the mean of
    ``min(t, horizon)`` over all runs, a run that never did it (``None``, NaN or an infinity)
    counted at its ``horizon`` (a number, or one per run), so that failing the hard runs is not
    rewarded, as a mean over the runs that did it would; None without runs (issue 25 item 6)."""
    t = np.array([np.nan if x is None else x for x in times], float)
    if t.size == 0:
        return None
    h = np.broadcast_to(np.asarray(horizon, float), t.shape)
    return float(np.mean(np.where(np.isfinite(t), np.minimum(t, h), h)))


def override_cost(verdicts: np.ndarray | None, proposed: np.ndarray | None,
                  applied: np.ndarray) -> dict[str, float]:
    """What the shield's overrides cost a run (issue 25 item 6, after SHARP's comparison of a
    shield-aware planner with a shield-agnostic one, Hu, Nakamura, Fisac, RA-L 2022):
    ``override_share``, the share of the AV's steps the shield overrode (verdict other than
    admitted), and ``override_mps2``, the mean over the AV's steps of ``|applied - proposed|``
    [m/s^2] (0 where it admitted the proposal; a non-finite proposal, always overridden,
    adds nothing). Both 0 without a shield (``verdicts`` None or empty, or every verdict
    ``OFF``)."""
    if verdicts is None or proposed is None or len(verdicts) == 0:
        return {"override_share": 0.0, "override_mps2": 0.0}
    verdicts = np.asarray(verdicts)
    over = verdicts > 0
    diff = np.abs(np.asarray(applied, float) - np.asarray(proposed, float))
    diff = np.where(over & np.isfinite(diff), diff, 0.0)
    return {"override_share": float(np.count_nonzero(over) / verdicts.size),
            "override_mps2": float(diff.mean())}


def crossing_times(s: np.ndarray, target: float, dt: float) -> float:
    """First time [s] at which the positions ``s`` (states ``0..N`` at ``k dt``, non-
    decreasing) reach ``target``, interpolated linearly between states; 0 if the first does,
    NaN if none does."""
    if not math.isfinite(target):
        return 0.0 if target < 0 else math.nan
    hit = np.flatnonzero(s >= target)
    if hit.size == 0:
        return math.nan
    k = int(hit[0])
    if k == 0:
        return 0.0
    ds = float(s[k] - s[k - 1])
    frac = (target - float(s[k - 1])) / ds if ds > 0 else 1.0
    return (k - 1 + frac) * dt


def pet(s_av: np.ndarray, s_hv: np.ndarray, occ_av: tuple[float, float],
        occ_hv: tuple[float, float], dt: float) -> float:
    """Post-encroachment time [s] (module docstring)."""
    in_a, out_a = crossing_times(s_av, occ_av[0], dt), crossing_times(s_av, occ_av[1], dt)
    in_h, out_h = crossing_times(s_hv, occ_hv[0], dt), crossing_times(s_hv, occ_hv[1], dt)
    if math.isnan(in_a) or math.isnan(in_h):
        return math.nan  # one never came
    if in_a <= in_h:
        first_out, second_in = out_a, in_h
    else:
        first_out, second_in = out_h, in_a
    if math.isnan(first_out):
        return 0.0  # the first was still inside when the second came in
    return max(second_in - first_out, 0.0)


@njit(cache=True)
def min_ttc(s_av: np.ndarray, v_av: np.ndarray, s_hv: np.ndarray, v_hv: np.ndarray,
            r_lo: float, r_hi: float, h_lo: float, h_hi: float, shared: bool,
            gap_m: float) -> float:
    """Minimum time to collision along the paths [s] (module docstring); NaN if never on a
    collision course."""
    best = math.inf
    for k in range(s_av.shape[0]):
        sr, vr, sh, vh = s_av[k], v_av[k], s_hv[k], v_hv[k]
        if shared and sr >= r_hi:  # in the lane: the follower closing on the leader
            if sh > sr:
                gap, closing = sh - sr - gap_m, vr - vh
            else:
                gap, closing = sr - sh - gap_m, vh - vr
            ttc = 0.0 if gap <= 0.0 else (gap / closing if closing > 0.0 else math.inf)
        else:
            ttc = math.inf
            a_in, a_out = _window(sr, vr, r_lo, r_hi)
            h_in, h_out = _window(sh, vh, h_lo, h_hi)
            if a_in < math.inf and h_in < math.inf:
                lo, hi = max(a_in, h_in), min(a_out, h_out)
                if lo <= hi:
                    ttc = lo
        if ttc < best:
            best = ttc
    return best if best < math.inf else math.nan


@njit(cache=True, inline="always")
def _window(s: float, v: float, lo: float, hi: float) -> tuple[float, float]:
    """The time window a vehicle at constant speed spends in ``[lo, hi]``."""
    if s > hi:
        return math.inf, math.inf
    if s >= lo:
        t_in = 0.0
    elif v > 0.0:
        t_in = (lo - s) / v
    else:
        return math.inf, math.inf
    t_out = (hi - s) / v if v > 0.0 else math.inf
    return t_in, t_out


@njit(cache=True)
def footprint_gaps(xa, ya, uax, uay, la, wa, xb, yb, ubx, uby, lb, wb, out) -> None:
    """Distance [m] between two oriented rectangles (0 when they overlap), elementwise:
    rectangle A centred at ``(xa, ya)``, length ``la`` along the unit ``(uax, uay)``, width
    ``wa``; likewise B. Outside each other, the distance of two convex polygons is the
    smallest distance from a corner of one to an edge of the other."""
    ca = np.empty((4, 2))
    cb = np.empty((4, 2))
    for i in range(out.size):
        _corners(xa[i], ya[i], uax[i], uay[i], la, wa, ca)
        _corners(xb[i], yb[i], ubx[i], uby[i], lb, wb, cb)
        if _overlap(ca, cb):
            out[i] = 0.0
            continue
        d = math.inf
        for p in range(4):
            for e in range(4):
                d = min(d, _point_segment(ca[p], cb[e], cb[(e + 1) % 4]))
                d = min(d, _point_segment(cb[p], ca[e], ca[(e + 1) % 4]))
        out[i] = d


@njit(cache=True, inline="always")
def _corners(x, y, ux, uy, length, width, out) -> None:
    hl, hw = length / 2, width / 2
    nx, ny = -uy, ux
    out[0, 0], out[0, 1] = x + hl * ux + hw * nx, y + hl * uy + hw * ny
    out[1, 0], out[1, 1] = x - hl * ux + hw * nx, y - hl * uy + hw * ny
    out[2, 0], out[2, 1] = x - hl * ux - hw * nx, y - hl * uy - hw * ny
    out[3, 0], out[3, 1] = x + hl * ux - hw * nx, y + hl * uy - hw * ny


@njit(cache=True, inline="always")
def _overlap(ca, cb) -> bool:
    """Separating-axis test of two rectangles given by their corners (touching overlaps)."""
    for poly in (ca, cb):
        for e in range(2):
            ax = poly[e + 1, 1] - poly[e, 1]
            ay = poly[e, 0] - poly[e + 1, 0]
            lo_a, hi_a, lo_b, hi_b = math.inf, -math.inf, math.inf, -math.inf
            for p in range(4):
                pa = ca[p, 0] * ax + ca[p, 1] * ay
                pb = cb[p, 0] * ax + cb[p, 1] * ay
                lo_a, hi_a = min(lo_a, pa), max(hi_a, pa)
                lo_b, hi_b = min(lo_b, pb), max(hi_b, pb)
            if hi_a < lo_b or hi_b < lo_a:
                return False
    return True


@njit(cache=True, inline="always")
def _point_segment(p, a, b) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    den = dx * dx + dy * dy
    t = 0.0 if den == 0.0 else min(max(((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / den, 0.0),
                                   1.0)
    ex, ey = p[0] - (a[0] + t * dx), p[1] - (a[1] + t * dy)
    return math.sqrt(ex * ex + ey * ey)


def min_gap(scenario, s_av: np.ndarray, s_hv: np.ndarray) -> np.ndarray:
    """The footprint gap [m] at every pair of positions (module docstring)."""
    s_av, s_hv = np.ascontiguousarray(s_av, float), np.ascontiguousarray(s_hv, float)
    xa, ya = scenario.av.xy(s_av)
    xb, yb = scenario.hv.xy(s_hv)
    (uax, uay), (ubx, uby) = scenario.av.direction(s_av), scenario.hv.direction(s_hv)
    va, vb = scenario.av.vehicle, scenario.hv.vehicle
    out = np.empty(s_av.shape)
    footprint_gaps(xa, ya, np.ascontiguousarray(uax), np.ascontiguousarray(uay), va.length_m,
                   va.width_m, xb, yb, np.ascontiguousarray(ubx), np.ascontiguousarray(uby),
                   vb.length_m, vb.width_m, out)
    return out


def caused_by_av(overlap: np.ndarray, rear: np.ndarray) -> np.ndarray:
    """Per state: the overlap there belongs to a collision the AV caused. A collision is a run of
    consecutive overlapping states, and its cause is its first state: a rear-end by the human
    stays one while the vehicles go on overlapping (the simulation has no contact forces: a
    human that drives into the AV from behind passes through it, and its later overlaps ahead
    of the AV are the same collision)."""
    overlap, rear = np.asarray(overlap, bool), np.asarray(rear, bool)
    start = overlap & ~np.r_[False, overlap[:-1]]
    cause = np.cumsum(start)  # the collision each state belongs to (0: none yet)
    first_rear = np.r_[False, rear[start]]  # per collision number: did it start as a rear-end
    return overlap & ~first_rear[cause]


def rear_end_mask(scenario, s_av: np.ndarray, s_hv: np.ndarray) -> np.ndarray:
    """Per state: an overlap there would be a rear-end by the human (the lane is shared, the AV
    is past the merge point and ahead of the human)."""
    if not scenario.lane_shared:
        return np.zeros(np.shape(s_av), dtype=bool)
    return (np.asarray(s_av) >= scenario.av.occupancy[1]) & (np.asarray(s_av) > np.asarray(s_hv))


#: Sub-steps of a step searched for the first contact, before bisection (:func:`first_contact`).
CONTACT_SAMPLES = 64
#: Bisection of the first contact down to this [s].
CONTACT_TOL_S = 1e-9


def first_contact(scenario, x0: np.ndarray, a_av: float, a_hv: float, dt: float
                  ) -> tuple[float, float, float]:
    """The first instant of a step at which the footprints overlap, both vehicles moving as
    the loop moves them (the saturated step from ``x0 = (s_av, v_av, s_hv, v_hv)`` with
    their realised accelerations): ``(t [s] in (0, dt], s_av, s_hv)`` there; ``dt`` and the
    step's end positions when no sub-step before the end overlaps. The step is sampled at
    :data:`CONTACT_SAMPLES` instants, then the first overlapping interval bisected to
    :data:`CONTACT_TOL_S` (a contact shorter than a sample's span between two samples is not
    seen: it would not decide who was behind either)."""
    from ..kinematics import saturated_step

    av, hv = scenario.av.vehicle, scenario.hv.vehicle

    def at(t: float) -> tuple[float, float]:
        return (saturated_step(x0[0], x0[1], a_av, t, av.v_min_mps, av.v_max_mps)[0],
                saturated_step(x0[2], x0[3], a_hv, t, hv.v_min_mps, hv.v_max_mps)[0])

    times = dt * np.arange(1, CONTACT_SAMPLES + 1) / CONTACT_SAMPLES
    pos = np.array([at(float(t)) for t in times])
    hit = np.flatnonzero(scenario.collides(pos[:, 0], pos[:, 1]))
    if hit.size == 0:
        return dt, float(pos[-1, 0]), float(pos[-1, 1])
    i = int(hit[0])
    lo, hi = (0.0 if i == 0 else float(times[i - 1])), float(times[i])
    while hi - lo > CONTACT_TOL_S:
        mid = 0.5 * (lo + hi)
        s_a, s_h = at(mid)
        if scenario.collides(np.array([s_a]), np.array([s_h]))[0]:
            hi = mid
        else:
            lo = mid
    s_a, s_h = at(hi)
    return hi, float(s_a), float(s_h)


def contact_rear_mask(scenario, states: np.ndarray, accel_av: np.ndarray,
                      accel_hv: np.ndarray, dt: float) -> np.ndarray:
    """Per state after each step (``states[1:]``): an overlap there would be a rear-end by
    the human (:func:`rear_end_mask`), judged for the first state of each collision at the
    first contact inside the step that led to it (:func:`first_contact`), for the others at
    the state itself (a collision's cause is its first state: :func:`caused_by_av`)."""
    after = states[1:]
    rear = rear_end_mask(scenario, after[:, 0], after[:, 2])
    if not scenario.lane_shared:
        return rear
    overlap = scenario.collides(after[:, 0], after[:, 2])
    start = np.flatnonzero(overlap & ~np.r_[False, overlap[:-1]])
    for k in start:
        _, s_a, s_h = first_contact(scenario, states[k], float(accel_av[k]),
                                    float(accel_hv[k]), dt)
        rear[k] = bool(rear_end_mask(scenario, np.array([s_a]), np.array([s_h]))[0])
    return rear


def human_at_fault(scenario, states: np.ndarray, accel_av: np.ndarray, dt: float,
                   accel_hv: np.ndarray) -> np.ndarray:
    """Per state after each step (``states[1:]``): an overlap there is a rear-end for which the
    human is at fault under the cut-in rule (docs/method.md §12.10). That needs all of: a
    rear-end by geometry (:func:`rear_end_mask`); the AV entered the lane (passed the shield's
    merge point) on a fair cut-in, judged as the shield judges it
    (``persuasive.safety.shield.cut_in_fair``) from the state before its entry step, with its
    realised acceleration over that step, against every human the model allows (an AV that
    starts in the lane is judged at its first state); and it has braked no harder than the
    rule's in-lane limit since (its realised accelerations, to 1e-9 m/s^2). Anything else is
    the AV's.

    ``states`` ``(n + 1, 4)``: the true states ``s_av, v_av, s_hv, v_hv``; ``accel_av``
    ``(n,)`` [m/s^2]: the AV's realised acceleration of each step (noise included);
    ``accel_hv`` the human's (a collision's rear-end is judged at its first contact inside
    the step, :func:`contact_rear_mask`)."""
    after = states[1:]
    rear = contact_rear_mask(scenario, states, accel_av, accel_hv, dt)
    if not rear.any():
        return rear
    from ..packing import pack
    from . import shield as sh

    P_av, P_hv = pack(scenario.config, scenario)
    C = np.empty(sh.N_CONFLICT)
    sh.conflict_vector(P_av, P_hv, C)
    C[sh.C_R_NOISE] = 0.0  # the realised accelerations are known
    r_hi = C[sh.C_R_HI]
    inside = np.flatnonzero(states[:, 0] >= r_hi)
    if inside.size == 0:
        return np.zeros_like(rear)
    e = int(inside[0])
    k = max(e - 1, 0)  # the entry step (or the first one, for an AV that starts in the lane)
    s_R, v_R, s_H, v_H = (float(x) for x in states[k])
    a = float(accel_av[k]) if e > 0 else 0.0
    t_0 = 0.0 if e == 0 else sh.profile_reach(s_R, v_R, a, dt, a, r_hi, C[sh.C_R_VMIN],
                                              C[sh.C_R_VMAX])
    fair = math.isfinite(t_0) and sh.cut_in_fair(s_R, v_R, a, dt, a, math.inf, a, t_0, s_H,
                                                 v_H, C)
    out = np.zeros_like(rear)
    if fair:
        gentle = np.asarray(accel_av, float)[k:] >= -C[sh.C_RESP_FRONT] - 1e-9
        out[k:] = np.logical_and.accumulate(gentle)
    return rear & out


__all__ = ["CONTACT_SAMPLES", "CONTACT_TOL_S", "STANDOFF_PROGRESS_M", "STANDOFF_WINDOW_S",
           "WAIT_SPEED_MPS", "caused_by_av", "contact_rear_mask", "first_contact",
           "footprint_gaps", "human_at_fault", "min_gap", "min_ttc", "override_cost", "pet",
           "rear_end_mask",
           "restricted_mean", "standoff",
           "waiting_time"]
