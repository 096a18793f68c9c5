"""The persuasive branch MPC: one decision of the AV (spec section 6).

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

from . import _packed as K
from .game import EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER, build, solve_libs
from .library import Lib, new_lib
from .roles import bayes_update, plausible_leader, transition_into

# Columns of the per-candidate diagnostics written by :func:`decide`.
(D_EXPECTED, D_MIN_SAFE, D_MAX_SAFE, D_BELIEF_L, D_BELIEF_F, D_PLAUSIBLE_L,
 D_P_LL, D_P_LF, D_P_FL, D_P_FF) = range(10)
N_DIAG = 10


@njit(cache=True)
def any_unsafe(LR: Lib, c: int, LH: Lib, off: int, thr: float) -> bool:
    """Whether candidate ``c`` of ``LR`` is unsafe at some sample ``m >= off`` against some
    trajectory of the HV library ``LH`` at its sample ``m - off``."""
    n, n_traj = LH.sq.shape
    lo_h, hi_h = n, 0
    for h in range(n_traj):
        lo_h = min(lo_h, LH.win[h, 0])
        hi_h = max(hi_h, LH.win[h, 1])
    for m in range(max(LR.win[c, 0], off + lo_h), min(LR.win[c, 1], off + hi_h)):
        own = LR.sq[m, c]
        for h in range(n_traj):
            if own + LH.sq[m - off, h] < thr:
                return True
    return False


@njit(cache=True)
def decide(s_R: float, v_R: float, s_H: float, v_H: float, LH: Lib, LR: Lib, idx: np.ndarray,
           q_l: float, q_f: float, tie_leader: bool, p_a_hat: float,
           P: np.ndarray, disc: np.ndarray, diag: np.ndarray, LH1a: Lib,
           LH1b: Lib) -> tuple[int, bool]:
    """One branch-MPC decision; returns ``(chosen candidate, feasible)``.

    ``LH`` / ``LR``: the HV's and AV's libraries at ``x_H`` / ``x_R`` with their reward parts,
    and ``idx`` (HV-L, HV-F, AV-L, AV-F): the full prediction of ``z`` from the human's view
    (``persuasive.game.predict_into``). ``tie_leader``: the human model's own role is L.
    ``diag`` ``(n_traj, N_DIAG)`` receives per-candidate diagnostics (expected reward, min and
    max of P(safe) over the samples, the human's belief on the AV, P(plausible = L), the four
    branch probabilities). ``LH1a``, ``LH1b``: scratch that receives the HV's libraries at
    its role-L and role-F states one sample ahead (``LH1b`` only when the two states differ);
    the closed loop reuses them for the next step's prediction. Index names: ``c`` candidate,
    ``m`` sample, ``b`` branch.
    """
    SR, VR = LR.S, LR.V
    SH, VH = LH.S, LH.V
    n, n_traj = SR.shape
    paper_q1 = P[K.Q1] != 0.0
    paper_q2 = P[K.Q2] != 0.0
    undiscounted = P[K.Q4] != 0.0
    agg_max = P[K.Q5] != 0.0
    w_s, w_v = P[K.W_S], P[K.W_V]
    w_c, thr = P[K.W_C], P[K.MIN_DIST_SQ]
    prior_l = P[K.PRIOR_L]
    threshold = 1.0 - P[K.EPSILON]

    # a-b. The human's belief on the AV at T1, its plausible role and the branch probabilities.
    Pi = np.empty((2, 2))
    probs = np.empty((n_traj, 4))
    exp_idx = (idx[OTHER_LEADER], idx[OTHER_FOLLOWER])
    e = np.empty((2, 2))  # residuals: (role of the AV, component)
    for c in range(n_traj):
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
    LH1 = (LH1a, LH1b)
    for i in range(2):
        if hv_src[i] == i:
            build(SH[0, hv_traj[i]], VH[0, hv_traj[i]], P, disc, LH1[i])
    # A re-solve only matters if some HV trajectory it could return is unsafe against a
    # candidate sharing its start: otherwise every branch is safe after T1 whatever the
    # answer, and skipping the solve changes nothing (exactly).
    off = 2 if paper_q1 else 1  # branch sample m holds the re-solve's sample m - off
    need = np.zeros((2, n_traj), np.bool_)  # per (HV source, AV source)
    for c in range(n_traj):
        for i in range(2):
            if hv_src[i] == i and not need[i, av_src[c]]:
                need[i, av_src[c]] = any_unsafe(LR, c, LH1[i], off, thr)
    # The AV's library from each distinct start that matters, and the solves.
    L1 = new_lib(n, n_traj)
    M_e, M_o = np.empty((n_traj, n_traj)), np.empty((n_traj, n_traj))
    Cm = np.empty((n_traj, n_traj))
    Q = np.empty((4, n_traj))
    sol = np.empty(4, np.int64)
    answer = np.zeros((2, n_traj, 2), np.int64)  # HV role-j trajectory, per (i, AV source)
    for c in range(n_traj):
        if av_src[c] != c or not (need[0, c] or need[1, c]):
            continue
        build(SR[start, c], VR[start, c], P, disc, L1)
        for i in range(2):
            if need[i, c]:
                solve_libs(LH1[i], L1, w_c, thr, agg_max, M_e, M_o, Cm, Q, sol)
                answer[i, c, 0] = sol[EGO_LEADER]
                answer[i, c, 1] = sol[EGO_FOLLOWER]

    # d-e. Branch safety, rewards R_b = B - w_c C_b, expectation and the chance constraint.
    # Outside the candidate's zone window every branch is safe, so only its window is scanned.
    Cb = np.empty(4)
    best_feasible, best_any = -1, -1
    for c in range(n_traj):
        all_safe = 0.0
        for b in range(4):
            all_safe += probs[c, b] * 1.0
        lo_c, hi_c = LR.win[c, 0], LR.win[c, 1]
        covered = lo_c <= 0 and hi_c >= n
        lo = math.inf if covered else all_safe
        hi = -math.inf if covered else all_safe
        for b in range(4):
            Cb[b] = 0.0
        for m in range(lo_c, hi_c):
            own = LR.sq[m, c]
            weight = (1.0 + VR[m, c]) if undiscounted else LR.coll[m, c]  # Q4
            p_safe = 0.0
            for b in range(4):
                i, j = b // 2, b % 2
                src = hv_src[i]
                if m < off:  # samples before the re-solve: the HV's own states
                    x = SH[0, hv_traj[i]] if m == off - 1 else s_H
                    hv2 = x * x
                else:
                    hv2 = LH1[src].sq[m - off, answer[src, av_src[c], j]]
                ok = own + hv2 >= thr
                if not ok:
                    Cb[b] += weight
                p_safe += probs[c, b] * (1.0 if ok else 0.0)
            lo = min(lo, p_safe)
            hi = max(hi, p_safe)
        expected = 0.0
        for b in range(4):
            expected += probs[c, b] * (LR.base[c] - w_c * Cb[b])
        diag[c, D_EXPECTED] = expected
        diag[c, D_MIN_SAFE] = lo
        diag[c, D_MAX_SAFE] = hi
        if best_any < 0 or expected > diag[best_any, D_EXPECTED]:
            best_any = c
        if lo > threshold and (best_feasible < 0 or expected > diag[best_feasible, D_EXPECTED]):
            best_feasible = c
    if best_feasible >= 0:
        return best_feasible, True
    return best_any, False
