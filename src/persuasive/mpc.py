"""The persuasive branch MPC: one decision of the AV (docs/method.md §6).

Notation: ``x_R = (s_R, v_R)`` the AV, ``x_H`` the HV, ``q = (P(HV = L), P(HV = F))`` the AV's
belief. The human's view of the joint state is ``z = (x_H, x_R)`` (ego = HV, other = AV); its
full prediction (``persuasive.game``) gives the HV's trajectory per HV role and the AV's
trajectory the human expects per AV role. The AV's candidates are its own library at ``x_R``,
which is also the "other" library of that prediction.

Per candidate ``k``:

a. the human's belief on the AV at ``T1``: from ``(0.5, 0.5)``, Bayes with the mean absolute
   residuals over two samples between candidate ``k`` and the expected AV trajectories
   (corrected: samples at ``t, t+0.1`` against the same times; quirk Q2: candidate samples
   ``t+0.1, t+0.2`` against expected ``t, t+0.1``);
b. the human's plausible role and ``Pi_hat`` (with ``p_a_hat``; belief ties go to the human
   model's own role, supplied by the caller: quirk Q3 decides what that is);
c. four branches ``(i, j)``, HV role ``i`` until ``T1`` and ``j`` after, probability
   ``P(i, j) = Pi_hat[j, i] q[i]``, in the order LL, LF, FL, FF. The HV's path until ``T1`` is
   its role-``i`` prediction; at ``T1`` the game is solved again from the human's view and the
   HV follows its role-``j`` answer (corrected: re-solve from both states at ``t+0.1``, HV
   sample 1 = role-``i`` state, samples 2.. = the re-solve's first samples; quirk Q1: re-solve
   from the candidate's state at ``t+0.2``, HV sample 1 = the HV's current state, sample 2 =
   role-``i`` state, samples 3.. = the re-solve's first samples);
d. safety ``d >= min_dist`` per branch and sample, step reward
   ``lambda^(k-1) ((s_k - s_0) - w_u |u_k|) - w_c [unsafe] (1 + v_k)`` (quirk Q4; with Q4 off
   the collision term is discounted too), summed as ``R_b = B - w_c C_b`` with ``B`` the
   candidate's collision-free reward and ``C_b`` the sum of its collision weights over the
   branch's unsafe samples (``persuasive.rewards``);
e. expected reward ``sum_b P_b R_b`` and chance constraint ``sum_b P_b [safe] > 1 - epsilon``
   at every sample.

The feasible candidate with the highest expected reward is chosen (first on ties); if none is
feasible, the best of all, flagged infeasible.

Two baselines share this machinery (docs/method.md §11): the **passive** planner predicts the
human with the same belief ``q`` and the same re-solves but assumes its plan does not change
the human's role (``Pi_hat`` is the identity, i.e. ``p_a_hat = 0``); the **constant-velocity**
planner (:func:`decide_cv`) evaluates the same candidates and chance constraint against the
human holding its current speed.

Distances follow the scenario's conflict (``persuasive.geometry``): at the paper's intersection
``s_R^2 + s_H^2``, otherwise between the centres ``xy(s)``; each vehicle's libraries are built
with its own parameter vector.

Re-solves are batched: the HV's state at ``T1`` takes at most two values and the AV's re-solve
start at most ``n_traj``; identical states (exact equality) share one library and one solve.
A re-solve is skipped when no trajectory of the HV's library at ``T1`` comes within
``min_dist`` of the candidates sharing it: every branch after ``T1`` is then safe whatever the
answer, so the decision and its diagnostics are exactly those of the full computation
(``persuasive.reference.mpc`` solves all 22 and the tests compare the two bit for bit).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import packing as slot
from .game import EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER, build, solve_libs
from .geometry import pair_unsafe_along, pair_unsafe_xy, path_point
from .kinematics import saturated_step
from .library import Lib, new_lib
from .roles import bayes_update, plausible_leader, transition_into

# Columns of the per-candidate diagnostics written by :func:`decide`.
(D_EXPECTED, D_MIN_SAFE, D_MAX_SAFE, D_BELIEF_L, D_BELIEF_F, D_PLAUSIBLE_L,
 D_P_LL, D_P_LF, D_P_FL, D_P_FF) = range(10)
N_DIAG = 10

# Rows of the look-ahead record ``ahead`` (2, 3): which HV states the scratch libraries hold.
AHEAD_VALID, AHEAD_S, AHEAD_V = 0, 1, 2


@njit(cache=True, _nrt=False)
def any_unsafe(pos_r: np.ndarray, win_r: np.ndarray, c: int, pos_h: np.ndarray,
               win_h: np.ndarray, off: int, thr: float,
               along_paths: bool) -> tuple[bool, int]:
    """Whether candidate ``c`` (``pos_r``, ``win_r`` of the AV's library) is unsafe at some
    sample ``m >= off`` against some trajectory of the HV library (``pos_h``, ``win_h``) at its
    sample ``m - off``; and the number of pair tests made.

    It takes the few arrays it reads, not the libraries, and returns its counter instead of
    writing it: it runs ~22 times per decision, and every array handed to a compiled call
    costs a reference-count update on the way in and out."""
    n_traj = win_h.shape[0]
    lo_h, hi_h = pos_h.shape[1], 0
    for h in range(n_traj):
        lo_h = min(lo_h, win_h[h, 0])
        hi_h = max(hi_h, win_h[h, 1])
    lo, hi = max(win_r[c, 0], off + lo_h), min(win_r[c, 1], off + hi_h)
    if along_paths:
        sq_r, sq_h = pos_r[0], pos_h[0]
        for m in range(lo, hi):
            own = sq_r[m, c]
            for h in range(n_traj):
                if pair_unsafe_along(own, sq_h[m - off, h], thr):
                    return True, (m - lo) * n_traj + h + 1
        return False, max(hi - lo, 0) * n_traj
    for m in range(lo, hi):
        x, y = pos_r[0, m, c], pos_r[1, m, c]
        for h in range(n_traj):
            if win_h[h, 0] <= m - off < win_h[h, 1] and pair_unsafe_xy(
                    x, y, pos_h[0, m - off, h], pos_h[1, m - off, h], thr):
                return True, (m - lo) * n_traj + h + 1
    return False, max(hi - lo, 0) * n_traj


@njit(cache=True, _nrt=False)
def branch_unsafe_xy(lib_r: Lib, c: int, m: int, lib_h: Lib, h: int, k: int,
                     thr: float) -> bool:
    """Euclidean conflicts: candidate ``c`` at its sample ``m`` against HV trajectory ``h`` of
    ``lib_h`` at its sample ``k`` (safe outside the trajectory's window)."""
    return (lib_h.win[h, 0] <= k < lib_h.win[h, 1]
            and pair_unsafe_xy(lib_r.pos[0, m, c], lib_r.pos[1, m, c], lib_h.pos[0, k, h],
                               lib_h.pos[1, k, h], thr))


@njit(cache=True)
def decide(s_R: float, v_R: float, s_H: float, v_H: float, lib_h: Lib, lib_r: Lib,
           idx: np.ndarray, q_l: float, q_f: float, tie_leader: bool, p_a_hat: float,
           persuade: bool, P_av: np.ndarray, P_hv: np.ndarray, disc: np.ndarray,
           diag: np.ndarray, lib_h1a: Lib, lib_h1b: Lib, ahead: np.ndarray,
           work: np.ndarray, allowed: np.ndarray) -> tuple[int, bool]:
    """One branch-MPC decision; returns ``(chosen candidate, feasible)``.

    ``lib_h`` / ``lib_r``: the HV's and AV's libraries at ``x_H`` / ``x_R`` with their reward
    parts, and ``idx`` (HV-L, HV-F, AV-L, AV-F): the full prediction of ``z`` from the human's
    view (``persuasive.game.predict_into``). ``tie_leader``: the human model's own role is L.
    ``persuade``: False for the passive planner (no role transition at T1). ``diag``
    ``(n_traj, N_DIAG)`` receives per-candidate diagnostics (expected reward, min and max of
    P(safe) over the samples, the human's belief on the AV, P(plausible = L), the four branch
    probabilities). ``lib_h1a``, ``lib_h1b``: scratch that receives the HV's libraries at its
    role-L and role-F states one sample ahead (``lib_h1b`` only when the two states differ);
    ``ahead`` ``(2, 3)`` records which states they hold (``AHEAD_*``), so that the closed loop
    reuses them for the next step's prediction. ``work``: the counters of
    ``persuasive.packing``. ``allowed`` ``(n_traj,)`` bool: candidates that may count as
    feasible (the safety shield's verdict, docs/method.md §12.3; all True without it). Index
    names: ``c`` candidate, ``m`` sample, ``b`` branch.
    """
    SR, VR = lib_r.S, lib_r.V
    SH, VH = lib_h.S, lib_h.V
    n, n_traj = SR.shape
    paper_q1 = P_av[slot.QUIRK_BRANCH_OFFSET] != 0.0
    paper_q2 = P_av[slot.QUIRK_BELIEF_OFFSET] != 0.0
    undiscounted = P_av[slot.QUIRK_UNDISCOUNTED_COLLISION] != 0.0
    w_s, w_v = P_av[slot.W_S], P_av[slot.W_V]
    w_c, thr = P_av[slot.W_C], P_av[slot.MIN_DIST_SQ]
    along_paths = P_av[slot.CONFLICT] == slot.CONFLICT_ALONG_PATHS
    prior_l = P_av[slot.PRIOR_L]
    threshold = 1.0 - P_av[slot.EPSILON]

    # a-b. The human's belief on the AV at T1, its plausible role and the branch probabilities.
    Pi = np.empty((2, 2))
    probs = np.empty((n_traj, 4))
    exp_idx = (idx[OTHER_LEADER], idx[OTHER_FOLLOWER])
    e = np.empty((2, 2))  # residuals: (role of the AV, component)
    for c in range(n_traj):
        if not persuade:  # passive: the human keeps its role after T1
            probs[c, 0], probs[c, 1], probs[c, 2], probs[c, 3] = q_l, 0.0, 0.0, q_f
            diag[c, D_BELIEF_L] = np.nan
            diag[c, D_BELIEF_F] = np.nan
            diag[c, D_PLAUSIBLE_L] = np.nan
            for b in range(4):
                diag[c, D_P_LL + b] = probs[c, b]
            continue
        for r in range(2):
            x = exp_idx[r]
            if paper_q2:
                # Q2: candidate (t+0.1, t+0.2) against expected (t, t+0.1).
                e[r, 0] = (abs(SR[0, c] - s_R) + abs(SR[1, c] - SR[0, x])) / 2.0
                e[r, 1] = (abs(VR[0, c] - v_R) + abs(VR[1, c] - VR[0, x])) / 2.0
            else:
                e[r, 0] = (abs(s_R - s_R) + abs(SR[0, c] - SR[0, x])) / 2.0
                e[r, 1] = (abs(v_R - v_R) + abs(VR[0, c] - VR[0, x])) / 2.0
        b_l, b_f = bayes_update(prior_l, 1.0 - prior_l, e[0, 0], e[0, 1], e[1, 0], e[1, 1],
                                w_s, w_v)
        pl = plausible_leader(b_l, b_f, 0 if tie_leader else 1)
        transition_into(pl, p_a_hat, Pi)
        probs[c, 0] = Pi[0, 0] * q_l  # (i, j) = (L, L)
        probs[c, 1] = Pi[1, 0] * q_l  # (L, F)
        probs[c, 2] = Pi[0, 1] * q_f  # (F, L)
        probs[c, 3] = Pi[1, 1] * q_f  # (F, F)
        diag[c, D_BELIEF_L] = b_l
        diag[c, D_BELIEF_F] = b_f
        diag[c, D_PLAUSIBLE_L] = pl
        for b in range(4):
            diag[c, D_P_LL + b] = probs[c, b]

    # c. Re-solves at T1, deduplicated by exact state.
    hv_traj = (idx[EGO_LEADER], idx[EGO_FOLLOWER])
    hv_src = np.empty(2, np.int64)  # which HV library serves HV role i
    hv_src[0] = 0
    hv_src[1] = 0 if (SH[0, hv_traj[1]] == SH[0, hv_traj[0]]
                      and VH[0, hv_traj[1]] == VH[0, hv_traj[0]]) else 1
    start = 1 if paper_q1 else 0  # the AV candidate sample the re-solve starts from
    av_src = np.empty(n_traj, np.int64)
    for c in range(n_traj):
        av_src[c] = c
        for c2 in range(c):
            if SR[start, c2] == SR[start, c] and VR[start, c2] == VR[start, c]:
                av_src[c] = av_src[c2]
                break
    # The HV's libraries at T1.
    lib_h1 = (lib_h1a, lib_h1b)
    # work counters, kept in locals and written once at the end
    n_libraries, n_pairs, n_resolves, n_skipped = 0, 0, 0, 0
    for i in range(2):
        ahead[i, AHEAD_VALID] = 0.0
        if hv_src[i] == i:
            build(SH[0, hv_traj[i]], VH[0, hv_traj[i]], P_hv, disc, lib_h1[i])
            n_libraries += 1
            ahead[i, AHEAD_VALID] = 1.0
            ahead[i, AHEAD_S] = SH[0, hv_traj[i]]
            ahead[i, AHEAD_V] = VH[0, hv_traj[i]]
    # A re-solve only matters if some HV trajectory it could return is unsafe against a
    # candidate sharing its start: otherwise every branch is safe after T1 whatever the
    # answer, and skipping the solve changes nothing (exactly).
    off = 2 if paper_q1 else 1  # branch sample m holds the re-solve's sample m - off
    need = np.zeros((2, n_traj), np.bool_)  # per (HV source, AV source)
    for c in range(n_traj):
        for i in range(2):
            if hv_src[i] == i and not need[i, av_src[c]]:
                lib = lib_h1a if i == 0 else lib_h1b
                unsafe, tests = any_unsafe(lib_r.pos, lib_r.win, c, lib.pos, lib.win, off, thr,
                                           along_paths)
                need[i, av_src[c]] = unsafe
                n_pairs += tests
    # The AV's library from each distinct start that matters, and the solves.
    lib_r1 = new_lib(n, n_traj)
    R_hv, R_av = np.empty((n_traj, n_traj)), np.empty((n_traj, n_traj))
    C = np.empty((n_traj, n_traj))
    q_values = np.empty((4, n_traj))
    sol = np.empty(4, np.int64)
    answer = np.zeros((2, n_traj, 2), np.int64)  # HV role-j trajectory, per (i, AV source)
    for c in range(n_traj):
        for i in range(2):
            # the full computation solves every (HV role, candidate) pair: 2 n_traj re-solves
            if not need[hv_src[i], av_src[c]]:
                n_skipped += 1
        if av_src[c] != c or not (need[0, c] or need[1, c]):
            continue
        build(SR[start, c], VR[start, c], P_av, disc, lib_r1)
        n_libraries += 1
        for i in range(2):
            if need[i, c]:
                n_resolves += 1
                solve_libs(lib_h1[i], lib_r1, P_hv, R_hv, R_av, C, q_values, sol, work)
                answer[i, c, 0] = sol[EGO_LEADER]
                answer[i, c, 1] = sol[EGO_FOLLOWER]
    # The HV's positions before the re-solve (its current state, and its role-i state at T1).
    early_x = np.empty((2, 2))  # (i, sample m < off): x ...
    early_y = np.empty((2, 2))
    early_sq = np.empty((2, 2))
    for i in range(2):
        for m in range(off):
            x = SH[0, hv_traj[i]] if m == off - 1 else s_H
            early_sq[i, m] = x * x
            if not along_paths:
                early_x[i, m], early_y[i, m] = path_point(P_hv, slot.PATH_B1, x)

    # d-e. Branch safety, rewards R_b = B - w_c C_b, expectation and the chance constraint.
    # Outside the candidate's zone window every branch is safe, so only its window is scanned.
    # Branch by branch, so that each branch's HV trajectory is looked up once; P(safe) of a
    # sample still sums the branches in order (LL, LF, FL, FF), as the reference does.
    Cb = np.empty(4)
    p_safe = np.empty(n)
    sq_r, sq_h1a, sq_h1b = lib_r.pos[0], lib_h1a.pos[0], lib_h1b.pos[0]  # s^2 (along paths)
    best_feasible, best_any = -1, -1
    for c in range(n_traj):
        all_safe = 0.0
        for b in range(4):
            all_safe += probs[c, b] * 1.0
        lo_c, hi_c = lib_r.win[c, 0], lib_r.win[c, 1]
        covered = lo_c <= 0 and hi_c >= n
        lo = math.inf if covered else all_safe
        hi = -math.inf if covered else all_safe
        n_pairs += 4 * max(hi_c - lo_c, 0)
        for m in range(lo_c, hi_c):
            p_safe[m] = 0.0
        for b in range(4):
            i, j = b // 2, b % 2
            src = hv_src[i]
            # single arrays, not the library tuple: selecting a whole library per branch costs
            sq_h = sq_h1a if src == 0 else sq_h1b
            h = answer[src, av_src[c], j]
            p = probs[c, b]
            cb = 0.0
            for m in range(lo_c, hi_c):
                if m < off:  # samples before the re-solve: the HV's own states
                    if along_paths:
                        ok = not pair_unsafe_along(sq_r[m, c], early_sq[i, m], thr)
                    else:
                        ok = not pair_unsafe_xy(lib_r.pos[0, m, c], lib_r.pos[1, m, c],
                                                early_x[i, m], early_y[i, m], thr)
                elif along_paths:
                    ok = not pair_unsafe_along(sq_r[m, c], sq_h[m - off, h], thr)
                else:
                    ok = not branch_unsafe_xy(lib_r, c, m, lib_h1a if src == 0 else lib_h1b,
                                              h, m - off, thr)
                if not ok:
                    cb += (1.0 + VR[m, c]) if undiscounted else lib_r.coll[m, c]  # Q4
                p_safe[m] += p * (1.0 if ok else 0.0)
            Cb[b] = cb
        for m in range(lo_c, hi_c):
            lo = min(lo, p_safe[m])
            hi = max(hi, p_safe[m])
        expected = 0.0
        for b in range(4):
            expected += probs[c, b] * (lib_r.base[c] - w_c * Cb[b])
        diag[c, D_EXPECTED] = expected
        diag[c, D_MIN_SAFE] = lo
        diag[c, D_MAX_SAFE] = hi
        if best_any < 0 or expected > diag[best_any, D_EXPECTED]:
            best_any = c
        if lo > threshold and allowed[c] and (
                best_feasible < 0 or expected > diag[best_feasible, D_EXPECTED]):
            best_feasible = c
    work[slot.WORK_LIBRARIES] += n_libraries
    work[slot.WORK_PAIRS_MPC] += n_pairs
    work[slot.WORK_RESOLVES] += n_resolves
    work[slot.WORK_RESOLVES_SKIPPED] += n_skipped
    if best_feasible >= 0:
        return best_feasible, True
    return best_any, False


@njit(cache=True)
def decide_cv(s_H: float, v_H: float, lib_r: Lib, P_av: np.ndarray, P_hv: np.ndarray,
              diag: np.ndarray, work: np.ndarray, allowed: np.ndarray) -> tuple[int, bool]:
    """One decision of the constant-velocity planner; returns ``(chosen, feasible)``.

    The human is predicted to hold its current speed (one branch, probability 1): its sample
    ``m`` is ``m + 1`` saturated steps at zero acceleration from ``(s_H, v_H)``. Each candidate
    of ``lib_r`` (the AV's library with its reward parts) is scored ``B - w_c C`` (collision
    term as the MPC's, quirk Q4) and is feasible when every sample is safe (the chance
    constraint with one branch). ``diag`` and ``allowed`` as :func:`decide` (beliefs NaN,
    P(LL) = 1).
    """
    SR, VR = lib_r.S, lib_r.V
    n, n_traj = SR.shape
    dt, v_min, v_max = P_hv[slot.SAMPLE_DT], P_hv[slot.V_MIN], P_hv[slot.V_MAX]
    undiscounted = P_av[slot.QUIRK_UNDISCOUNTED_COLLISION] != 0.0
    w_c, thr = P_av[slot.W_C], P_av[slot.MIN_DIST_SQ]
    along_paths = P_av[slot.CONFLICT] == slot.CONFLICT_ALONG_PATHS
    threshold = 1.0 - P_av[slot.EPSILON]
    hx, hy, hsq = np.empty(n), np.empty(n), np.empty(n)
    s, v = s_H, v_H
    for m in range(n):
        s, v = saturated_step(s, v, 0.0, dt, v_min, v_max)
        hsq[m] = s * s
        if not along_paths:
            hx[m], hy[m] = path_point(P_hv, slot.PATH_B1, s)
    best_feasible, best_any = -1, -1
    n_pairs = 0
    for c in range(n_traj):
        C = 0.0
        safe = True
        any_safe = lib_r.win[c, 0] > 0 or lib_r.win[c, 1] < n  # samples outside are safe
        n_pairs += max(lib_r.win[c, 1] - lib_r.win[c, 0], 0)
        for m in range(lib_r.win[c, 0], lib_r.win[c, 1]):
            if along_paths:
                unsafe = pair_unsafe_along(lib_r.pos[0, m, c], hsq[m], thr)
            else:
                unsafe = pair_unsafe_xy(lib_r.pos[0, m, c], lib_r.pos[1, m, c], hx[m], hy[m],
                                        thr)
            if unsafe:
                safe = False
                C += (1.0 + VR[m, c]) if undiscounted else lib_r.coll[m, c]  # Q4
            else:
                any_safe = True
        expected = lib_r.base[c] - w_c * C
        p = 1.0 if safe else 0.0
        diag[c, D_EXPECTED] = expected
        diag[c, D_MIN_SAFE] = p
        diag[c, D_MAX_SAFE] = 1.0 if any_safe else 0.0
        diag[c, D_BELIEF_L] = np.nan
        diag[c, D_BELIEF_F] = np.nan
        diag[c, D_PLAUSIBLE_L] = np.nan
        diag[c, D_P_LL] = 1.0
        diag[c, D_P_LF] = 0.0
        diag[c, D_P_FL] = 0.0
        diag[c, D_P_FF] = 0.0
        if best_any < 0 or expected > diag[best_any, D_EXPECTED]:
            best_any = c
        if p > threshold and allowed[c] and (
                best_feasible < 0 or expected > diag[best_feasible, D_EXPECTED]):
            best_feasible = c
    work[slot.WORK_PAIRS_MPC] += n_pairs
    if best_feasible >= 0:
        return best_feasible, True
    return best_any, False
