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
   the collision term is discounted too);
e. expected reward ``sum_b P_b R_b`` and chance constraint ``sum_b P_b [safe] > 1 - epsilon``
   at every sample.

The feasible candidate with the highest expected reward is chosen (first on ties); if none is
feasible, the best of all, flagged infeasible.

Re-solves are batched: the HV's state at ``T1`` takes at most two values and the AV's re-solve
start at most ``n_traj``; identical states (exact equality) share one library and one solve.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _packed as K
from .game import EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER, solve_both
from .library import fill_library
from .rewards import base_rewards, reward_matrix, zone_windows
from .roles import bayes_update, plausible_leader, transition_into

# Columns of the per-candidate diagnostics written by :func:`decide`.
(D_EXPECTED, D_MIN_SAFE, D_MAX_SAFE, D_BELIEF_L, D_BELIEF_F, D_PLAUSIBLE_L,
 D_P_LL, D_P_LF, D_P_FL, D_P_FF) = range(10)
N_DIAG = 10


@njit(cache=True)
def decide(s_R: float, v_R: float, s_H: float, v_H: float,
           SH: np.ndarray, VH: np.ndarray, AH: np.ndarray,
           SR: np.ndarray, VR: np.ndarray, AR: np.ndarray, idx: np.ndarray,
           q_l: float, q_f: float, tie_leader: bool, p_a_hat: float,
           P: np.ndarray, disc: np.ndarray, diag: np.ndarray) -> tuple[int, bool]:
    """One branch-MPC decision; returns ``(chosen candidate, feasible)``.

    ``SH, VH, AH`` / ``SR, VR, AR``: the HV's and AV's libraries at ``x_H`` / ``x_R``
    ``(n_traj, n)``; ``idx``: the human-view full prediction at ``z`` (``persuasive.game``
    order: HV-L, HV-F, AV-L, AV-F). ``tie_leader``: the human model's own role is L.
    ``diag`` ``(n_traj, N_DIAG)`` receives per-candidate diagnostics (expected reward, min and
    max of P(safe) over the samples, the human's belief on the AV, P(plausible = L), the four
    branch probabilities).
    """
    n_traj, n = SR.shape
    paper_q1 = P[K.Q1] != 0.0
    paper_q2 = P[K.Q2] != 0.0
    undiscounted = P[K.Q4] != 0.0
    agg_max = P[K.Q5] != 0.0
    w_s, w_v = P[K.W_S], P[K.W_V]
    w_c, w_u, min_dist = P[K.W_C], P[K.W_U], P[K.MIN_DIST]
    prior_l = P[K.PRIOR_L]
    threshold = 1.0 - P[K.EPSILON]

    # a-b. The human's belief on the AV at T1, its plausible role and the branch probabilities.
    Pi = np.empty((2, 2))
    probs = np.empty((n_traj, 4))
    exp_idx = (idx[OTHER_LEADER], idx[OTHER_FOLLOWER])
    e = np.empty((2, 2))  # residuals: (role of the AV, component)
    for k in range(n_traj):
        for r in range(2):
            x = exp_idx[r]
            if paper_q2:
                # Q2: candidate (t+0.1, t+0.2) against expected (t, t+0.1).
                e[r, 0] = (abs(SR[k, 0] - s_R) + abs(SR[k, 1] - SR[x, 0])) / 2.0
                e[r, 1] = (abs(VR[k, 0] - v_R) + abs(VR[k, 1] - VR[x, 0])) / 2.0
            else:
                e[r, 0] = (abs(s_R - s_R) + abs(SR[k, 0] - SR[x, 0])) / 2.0
                e[r, 1] = (abs(v_R - v_R) + abs(VR[k, 0] - VR[x, 0])) / 2.0
        b_l, b_f = bayes_update(prior_l, 1.0 - prior_l, e[0, 0], e[0, 1], e[1, 0], e[1, 1],
                                w_s, w_v)
        pl = plausible_leader(b_l, b_f, 0 if tie_leader else 1)
        transition_into(pl, p_a_hat, Pi)
        probs[k, 0] = Pi[0, 0] * q_l  # (i, j) = (L, L)
        probs[k, 1] = Pi[1, 0] * q_l  # (L, F)
        probs[k, 2] = Pi[0, 1] * q_f  # (F, L)
        probs[k, 3] = Pi[1, 1] * q_f  # (F, F)
        diag[k, D_BELIEF_L] = b_l
        diag[k, D_BELIEF_F] = b_f
        diag[k, D_PLAUSIBLE_L] = pl
        for b in range(4):
            diag[k, D_P_LL + b] = probs[k, b]

    # c. Re-solves at T1, deduplicated by exact state.
    hv_traj = (idx[EGO_LEADER], idx[EGO_FOLLOWER])
    hv_src = np.empty(2, np.int64)  # which HV library serves HV role i
    hv_src[0] = 0
    hv_src[1] = 0 if (SH[hv_traj[1], 0] == SH[hv_traj[0], 0]
                      and VH[hv_traj[1], 0] == VH[hv_traj[0], 0]) else 1
    start = 1 if paper_q1 else 0  # the AV candidate sample the re-solve starts from
    av_src = np.empty(n_traj, np.int64)
    for k in range(n_traj):
        av_src[k] = k
        for k2 in range(k):
            if SR[k2, start] == SR[k, start] and VR[k2, start] == VR[k, start]:
                av_src[k] = av_src[k2]
                break

    LS = np.empty((2, n_traj, n))
    LV = np.empty((2, n_traj, n))
    LA = np.empty((2, n_traj, n))
    hb = np.empty((2, n_traj))
    hw = np.empty((2, n_traj, 2), np.int64)
    for i in range(2):
        if hv_src[i] == i:
            s0, v0 = SH[hv_traj[i], 0], VH[hv_traj[i], 0]
            fill_library(s0, v0, P, LS[i], LV[i], LA[i])
            base_rewards(LS[i], LA[i], s0, disc, P, hb[i])
            zone_windows(LS[i], min_dist, hw[i])
    RS = np.empty((n_traj, n_traj, n))
    RV = np.empty((n_traj, n_traj, n))
    RA = np.empty((n_traj, n_traj, n))
    rb = np.empty((n_traj, n_traj))
    rw = np.empty((n_traj, n_traj, 2), np.int64)
    M_e = np.empty((n_traj, n_traj))
    M_o = np.empty((n_traj, n_traj))
    Q = np.empty((4, n_traj))
    sol = np.empty(4, np.int64)
    answer = np.empty((2, n_traj, 2), np.int64)  # HV role-j trajectory, per (i, AV source)
    for k in range(n_traj):
        if av_src[k] != k:
            continue
        s0, v0 = SR[k, start], VR[k, start]
        fill_library(s0, v0, P, RS[k], RV[k], RA[k])
        base_rewards(RS[k], RA[k], s0, disc, P, rb[k])
        zone_windows(RS[k], min_dist, rw[k])
        for i in range(2):
            if hv_src[i] != i:
                continue
            hs0 = SH[hv_traj[i], 0]
            reward_matrix(LS[i], LV[i], LA[i], hs0, hb[i], hw[i], RS[k], rw[k], disc, P, M_e)
            reward_matrix(RS[k], RV[k], RA[k], s0, rb[k], rw[k], LS[i], hw[i], disc, P, M_o)
            solve_both(M_e, M_o, agg_max, sol, Q)
            answer[i, k, 0] = sol[EGO_LEADER]
            answer[i, k, 1] = sol[EGO_FOLLOWER]

    # d-e. Branch safety, rewards, expectation and the chance constraint.
    base_R = np.empty(n_traj)
    base_rewards(SR, AR, s_R, disc, P, base_R)
    hv_s = np.empty((4, n))
    safe = np.empty((4, n))
    best_feasible, best_any = -1, -1
    for k in range(n_traj):
        for i in range(2):
            src_i = hv_src[i]
            s_i1 = SH[hv_traj[i], 0]
            for j in range(2):
                b = 2 * i + j
                path = answer[src_i, av_src[k], j]
                if paper_q1:
                    hv_s[b, 0] = s_H
                    hv_s[b, 1] = s_i1
                    for m in range(2, n):
                        hv_s[b, m] = LS[src_i, path, m - 2]
                else:
                    hv_s[b, 0] = s_i1
                    for m in range(1, n):
                        hv_s[b, m] = LS[src_i, path, m - 1]
        expected = 0.0
        for b in range(4):
            any_unsafe = False
            for m in range(n):
                s, sh = SR[k, m], hv_s[b, m]
                ok = math.sqrt(s * s + sh * sh) >= min_dist
                safe[b, m] = 1.0 if ok else 0.0
                any_unsafe = any_unsafe or not ok
            if not any_unsafe:
                R_b = base_R[k]
            elif undiscounted:
                R_b = 0.0
                for m in range(n):
                    c = (1.0 + VR[k, m]) if safe[b, m] == 0.0 else 0.0
                    R_b += disc[m] * ((SR[k, m] - s_R) - w_u * abs(AR[k, m])) - w_c * c
            else:
                R_b = 0.0
                for m in range(n):
                    c = (1.0 + VR[k, m]) if safe[b, m] == 0.0 else 0.0
                    R_b += disc[m] * (((SR[k, m] - s_R) - w_c * c) - w_u * abs(AR[k, m]))
            expected += probs[k, b] * R_b
        lo, hi = math.inf, -math.inf
        for m in range(n):
            p_safe = 0.0
            for b in range(4):
                p_safe += probs[k, b] * safe[b, m]
            lo = min(lo, p_safe)
            hi = max(hi, p_safe)
        diag[k, D_EXPECTED] = expected
        diag[k, D_MIN_SAFE] = lo
        diag[k, D_MAX_SAFE] = hi
        if best_any < 0 or expected > diag[best_any, D_EXPECTED]:
            best_any = k
        if lo > threshold and (best_feasible < 0 or expected > diag[best_feasible, D_EXPECTED]):
            best_feasible = k
    if best_feasible >= 0:
        return best_feasible, True
    return best_any, False
