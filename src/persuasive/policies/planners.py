"""The AV's model-based planners (docs/method.md §6, §11): ``persuasive``, ``passive``, ``cv``.

- ``persuasive``: the paper's branch MPC (``persuasive.mpc.decide``) with interactive
  prediction and role persuasion; parameter ``p_a_hat``, fixed or, with
  ``mpc.p_a_hat = "online"``, the mean of a posterior over ``p_a`` updated every step
  (:mod:`persuasive.online`, docs/method.md §13.9; its block follows the MPC's state slots, and
  the replay of the model human's plausible role runs for it whether or not the shield is on).
- ``passive``: the same MPC, the same belief ``q`` and the same re-solves at T1, but the AV
  assumes its plan does not change the human's role (``Pi_hat`` is the identity, as with
  ``p_a_hat = 0``): it predicts, it does not persuade (``"online"`` changes nothing for it).
- ``cv``: the same candidates and chance constraint against a human holding its current speed
  (``persuasive.mpc.decide_cv``); it keeps no belief.

The persuasive and passive planners hold the belief ``q`` on the human's role and the stored
one-step prediction of the human per role (§6 step 6).

**Knowing the shield** (docs/method.md §12.3), two settings of the planner, not of the shield (a
planner whose proposals another loop filters is the same planner): with ``mpc.shield_aware`` and a
shield on (``av.shield``), a candidate whose first acceleration the shield would reject is not
feasible, so the planner does not persuade itself into a corner the shield then brakes it out of.
With ``mpc.confidence_filter`` (unset: on exactly when a shield is) the persuasive and passive
planners track their confidence in the human model (``persuasive.safety.confidence``); below
``mpc.confidence_threshold`` they stop trying to persuade: only candidates that stand before the
conflict at their end (yield smoothly) or that the worst-case shield certifies to cross whatever
the human does remain (when none does, the shield-admitted ones, or all without a shield). With the
``responsive`` shield, which trusts the human to brake in time, this is what protects the AV from a
human the model does not explain.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import packing as slot
from ..game import EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER
from ..library import Lib, as_lib
from ..mpc import (D_BELIEF_L, D_EXPECTED, D_MAX_SAFE, D_MIN_SAFE, D_P_LL, D_PLAUSIBLE_L,
                   decide, decide_cv)
from ..online import online_init, online_step
from ..roles import FOLLOWER, LEADER, bayes_update
from ..safety.confidence import confidence_update, plausible_of, role_prediction
from ..safety.shield import (C_KIND, C_R_LINE, C_R_NOISE, C_R_UMAX, C_R_UMIN, N_CONFLICT,
                             admissible, conflict_vector, go_certified, human_window, line_binds,
                             line_brake, yields_before)

#: Slots of the MPC's state: belief q = (P(HV = L), P(HV = F)), the stored prediction of the
#: HV's next state per HV role, whether it has been initialised; then the confidence filter
#: (persuasion.safety.confidence): the confidence in the human model, the model's predicted
#: P(HV = L) for the human's pending action, the model human's belief about the AV, its
#: stored prediction of the AV per AV role, and its plausible role at the last step.
(BELIEF_L, BELIEF_F, PRED_L_S, PRED_L_V, PRED_F_S, PRED_F_V, READY, CONFIDENCE, ROLE_PRED_L,
 HB_L, HB_F, HP_L_S, HP_L_V, HP_F_S, HP_F_V, PLAUSIBLE_PREV) = range(16)
#: Slots of its parameter vector: the AV's estimate of p_a; quirk Q3 (belief ties read a given
#: human role); whether that role is the simulated human's own (p_a_hat == p_a); the human's
#: initial role (the Q3 fallback); the online posterior's grid size (0: p_a_hat is fixed),
#: followed by the rest of the online block (``persuasive.online``) when it is not 0.
PRM_P_A_HAT, PRM_TIE_GIVEN, PRM_MODEL_IS_HUMAN, PRM_HUMAN_ROLE, PRM_ONLINE = range(5)
#: Length of the parameter vector without the online block.
PRM_SIZE = 5
#: The online posterior's state block (``persuasive.online``) starts after the MPC's slots.
ONLINE_STATE = 16

# Log columns (``persuasive.policies.kinds.MPC_LOG``; the cv planner's are its own).
(COL_TRAJ, COL_FEASIBLE, COL_N_FEASIBLE, COL_PSAFE_MIN, COL_PSAFE_MAX, COL_EXPECTED,
 COL_BELIEF_USED, COL_BELIEF_L, COL_BELIEF_F, COL_TIE, COL_HUMAN_BELIEF_L, COL_HUMAN_PLAUSIBLE,
 COL_P_LL, COL_P_LF, COL_P_FL, COL_P_FF, COL_CONFIDENCE, COL_N_ALLOWED, COL_P_A_HAT) = range(19)
(CV_COL_TRAJ, CV_COL_FEASIBLE, CV_COL_N_FEASIBLE, CV_COL_PSAFE_MIN, CV_COL_EXPECTED,
 CV_COL_N_ALLOWED) = range(6)


@njit(cache=True)
def mpc_init(st: np.ndarray, prm: np.ndarray, prior_l: float) -> None:
    """A fresh MPC state in ``st``: belief ``(prior_l, 1 - prior_l)``, no prediction yet, full
    confidence in the model; with an online posterior over ``p_a`` (``prm[PRM_ONLINE] > 0``),
    its rows from their initial roles and the prior mean as ``p_a_hat``."""
    st[:] = 0.0
    st[BELIEF_L] = prior_l
    st[BELIEF_F] = 1.0 - prior_l
    st[CONFIDENCE] = 1.0
    st[ROLE_PRED_L] = prior_l
    st[HB_L] = prior_l
    st[HB_F] = 1.0 - prior_l
    if prm.shape[0] > PRM_ONLINE and prm[PRM_ONLINE] > 0.0:
        online_init(st, ONLINE_STATE, prm, PRM_ONLINE, prior_l)


@njit(cache=True)
def shield_allowed(s_R: float, v_R: float, s_H: float, v_H: float, lib_r: Lib,
                   P_av: np.ndarray, P_hv: np.ndarray, robust: bool,
                   allowed: np.ndarray) -> int:
    """Which candidates may count as feasible, into ``allowed`` (docs/method.md §12.3); returns
    how many. ``robust`` (the confidence filter, ``mpc.confidence_filter``: the model does not
    explain the human): only those that stand before the conflict at their end or that the
    worst-case shield certifies to cross now, or, once the human is past its interval, that
    the worst-case shield admits (following it in a shared lane), whatever the shield's own
    kind, on or off (if none, as if not robust). Otherwise, with a shield on and ``mpc.shield_aware``, those whose
    first acceleration the shield admits (the AV held to its yield line while the line binds,
    §12.8); without, all of them."""
    n_traj = allowed.shape[0]
    aware = P_av[slot.SHIELD] != slot.SHIELD_OFF and P_av[slot.SHIELD_AWARE] != 0.0
    if not aware and not robust:
        allowed[:] = True
        return n_traj
    C = np.empty(N_CONFLICT)
    conflict_vector(P_av, P_hv, C)
    dt = P_av[slot.SAMPLE_DT]
    n = lib_r.S.shape[0]
    count = 0
    if robust:  # a human the model does not explain is planned for as the worst case
        kind = C[C_KIND]
        C[C_KIND] = slot.SHIELD_WORST_CASE
        t_in, t_out, past = human_window(s_H, v_H, C)
        for c in range(n_traj):
            a = lib_r.A[0, c]
            # once the human is past its interval (in a merge: ahead in the lane) there is
            # nothing left to persuade it of: what the worst-case shield admits, following
            # it included, is allowed (else a human merged ahead kept the AV at its line)
            allowed[c] = (yields_before(lib_r.S[n - 1, c], lib_r.V[n - 1, c], C)
                          or go_certified(s_R, v_R, a, dt, s_H, v_H, C, t_in, t_out, past)
                          or (past and admissible(s_R, v_R, a, dt, s_H, v_H, C, t_in, t_out,
                                                  past)))
            count += allowed[c]
        C[C_KIND] = kind
        if count > 0:
            return count
    if not aware:
        allowed[:] = True
        return n_traj
    t_in, t_out, past = human_window(s_H, v_H, C)
    for c in range(n_traj):
        allowed[c] = admissible(s_R, v_R, lib_r.A[0, c], dt, s_H, v_H, C, t_in, t_out, past)
        count += allowed[c]
    return count


@njit(cache=True)
def yield_at_line(s_R: float, v_R: float, P_av: np.ndarray, P_hv: np.ndarray) -> float:
    """With a shield on and its yield line still binding (docs/method.md §12.8): the gentlest
    acceleration that stands the AV before its line (``persuasive.safety.shield.line_brake``),
    for a shield-aware planner none of whose candidates the shield allows (its library may
    hold none that stops exactly there); NaN otherwise (the planner's own choice stands)."""
    if P_av[slot.SHIELD] == slot.SHIELD_OFF or P_av[slot.SHIELD_AWARE] == 0.0:
        return np.nan
    C = np.empty(N_CONFLICT)
    conflict_vector(P_av, P_hv, C)
    if not line_binds(s_R, v_R, C):
        return np.nan
    w = C[C_R_NOISE]  # the stop fits the fastest of the noisy realisations
    return line_brake(s_R, v_R, P_av[slot.SAMPLE_DT], C[C_R_LINE], C[C_R_UMIN] + w,
                      C[C_R_UMAX]) - w


@njit(cache=True)
def allowed_of(s_R: float, v_R: float, s_H: float, v_H: float, buf: np.ndarray,
               win: np.ndarray, P_av: np.ndarray, P_hv: np.ndarray, robust: bool,
               allowed: np.ndarray) -> int:
    """:func:`shield_allowed` of the AV's library stored as
    :func:`persuasive.library.lib_buffers` (``persuasive.planner.Planner.allowed_now``)."""
    return shield_allowed(s_R, v_R, s_H, v_H, as_lib(buf, win), P_av, P_hv, robust, allowed)


@njit(cache=True)
def _n_feasible(diag: np.ndarray, threshold: float) -> int:
    count = 0
    for c in range(diag.shape[0]):
        if diag[c, D_MIN_SAFE] > threshold:
            count += 1
    return count


@njit(cache=True)
def mpc_step(st: np.ndarray, prm: np.ndarray, persuade: bool, s_R: float, v_R: float,
             s_H: float, v_H: float, human_role: int, lib_h: Lib, lib_r: Lib,
             idx: np.ndarray, P_av: np.ndarray, P_hv: np.ndarray, disc: np.ndarray,
             diag: np.ndarray, log: np.ndarray, lib_h1a: Lib, lib_h1b: Lib,
             ahead: np.ndarray, work: np.ndarray) -> float:
    """One step of the persuasive (or, ``persuade=False``, passive) MPC; returns the
    acceleration.

    ``lib_h, lib_r, idx``: the full prediction of ``z = (x_H, x_R)`` from the human's view. The
    human model's own role (for belief ties) is, with quirk Q3, ``human_role`` (the simulated
    human's current role, -1 when it has none) when the model is the human, else the human's
    initial role; without Q3, the most likely HV role under ``q`` (ties: L). ``diag``, ``log``,
    ``lib_h1a``, ``lib_h1b``, ``ahead``: see :func:`persuasive.mpc.decide`.
    """
    tracking = P_av[slot.CONF_THRESHOLD] > 0.0  # the confidence filter (mpc.confidence_filter)
    online = persuade and prm[PRM_ONLINE] > 0.0  # a posterior over p_a (persuasive.online)
    p_hat = prm[PRM_P_A_HAT]
    if st[READY] == 0.0:
        st[PRED_L_S], st[PRED_L_V] = s_H, v_H
        st[PRED_F_S], st[PRED_F_V] = s_H, v_H
        st[HP_L_S], st[HP_L_V] = s_R, v_R
        st[HP_F_S], st[HP_F_V] = s_R, v_R
        st[READY] = 1.0
    elif tracking or online:  # the human's last action against the model's prediction of it
        dt = P_av[slot.SAMPLE_DT]
        e_l, e_f = (v_H - st[PRED_L_V]) / dt, (v_H - st[PRED_F_V]) / dt
        if online:
            online_step(st, ONLINE_STATE, prm, PRM_ONLINE, e_l, e_f, P_av[slot.CONF_STD],
                        st[PLAUSIBLE_PREV], P_av[slot.PRIOR_L])
        if tracking:
            conf, alpha_l = confidence_update(
                st[CONFIDENCE], st[ROLE_PRED_L], e_l, e_f, P_av[slot.CONF_STD],
                P_av[slot.CONF_SWITCH], P_hv[slot.U_MAX] - P_hv[slot.U_MIN])
            st[CONFIDENCE] = conf
            p_model = (st[ONLINE_STATE] if online else p_hat) if persuade else 0.0
            st[ROLE_PRED_L] = role_prediction(alpha_l, st[PLAUSIBLE_PREV], p_model)
    if online:
        p_hat = st[ONLINE_STATE]
    q_l, q_f = st[BELIEF_L], st[BELIEF_F]
    if prm[PRM_TIE_GIVEN] != 0.0:  # Q3
        tie = human_role if (prm[PRM_MODEL_IS_HUMAN] != 0.0 and human_role >= 0) \
            else int(prm[PRM_HUMAN_ROLE])
    else:
        tie = LEADER if q_l >= q_f else FOLLOWER
    allowed = np.empty(lib_r.S.shape[1], np.bool_)
    robust = tracking and st[CONFIDENCE] < P_av[slot.CONF_THRESHOLD]
    n_allowed = shield_allowed(s_R, v_R, s_H, v_H, lib_r, P_av, P_hv, robust, allowed)
    c, feasible = decide(s_R, v_R, s_H, v_H, lib_h, lib_r, idx, q_l, q_f, tie == LEADER,
                         p_hat, persuade, P_av, P_hv, disc, diag, lib_h1a, lib_h1b,
                         ahead, work, allowed)
    if tracking or online:  # the model human's step: plausible role, then its belief of the AV
        st[PLAUSIBLE_PREV] = plausible_of(st[HB_L], st[HB_F])
        st[HB_L], st[HB_F] = bayes_update(
            st[HB_L], st[HB_F],
            abs(s_R - st[HP_L_S]), abs(v_R - st[HP_L_V]),
            abs(s_R - st[HP_F_S]), abs(v_R - st[HP_F_V]),
            P_av[slot.W_S], P_av[slot.W_V])
        a_l, a_f = idx[OTHER_LEADER], idx[OTHER_FOLLOWER]
        st[HP_L_S], st[HP_L_V] = lib_r.S[0, a_l], lib_r.V[0, a_l]
        st[HP_F_S], st[HP_F_V] = lib_r.S[0, a_f], lib_r.V[0, a_f]
    # 6. update q against the stored prediction, then store the new one
    b_l, b_f = bayes_update(
        q_l, q_f,
        abs(s_H - st[PRED_L_S]), abs(v_H - st[PRED_L_V]),
        abs(s_H - st[PRED_F_S]), abs(v_H - st[PRED_F_V]),
        P_av[slot.W_S], P_av[slot.W_V],
    )
    h_l, h_f = idx[EGO_LEADER], idx[EGO_FOLLOWER]
    st[BELIEF_L], st[BELIEF_F] = b_l, b_f
    st[PRED_L_S], st[PRED_L_V] = lib_h.S[0, h_l], lib_h.V[0, h_l]
    st[PRED_F_S], st[PRED_F_V] = lib_h.S[0, h_f], lib_h.V[0, h_f]
    log[COL_TRAJ] = c
    log[COL_FEASIBLE] = 1.0 if feasible else 0.0
    log[COL_N_FEASIBLE] = _n_feasible(diag, 1.0 - P_av[slot.EPSILON])
    log[COL_PSAFE_MIN] = diag[c, D_MIN_SAFE]
    log[COL_PSAFE_MAX] = diag[c, D_MAX_SAFE]
    log[COL_EXPECTED] = diag[c, D_EXPECTED]
    log[COL_BELIEF_USED] = q_l
    log[COL_BELIEF_L], log[COL_BELIEF_F] = b_l, b_f
    log[COL_TIE] = tie
    log[COL_HUMAN_BELIEF_L] = diag[c, D_BELIEF_L]
    log[COL_HUMAN_PLAUSIBLE] = diag[c, D_PLAUSIBLE_L]
    for b in range(4):
        log[COL_P_LL + b] = diag[c, D_P_LL + b]
    log[COL_CONFIDENCE] = st[CONFIDENCE] if tracking else np.nan
    log[COL_N_ALLOWED] = n_allowed
    log[COL_P_A_HAT] = p_hat if persuade else np.nan
    if n_allowed == 0:
        a_line = yield_at_line(s_R, v_R, P_av, P_hv)
        if not math.isnan(a_line):
            return a_line
    return lib_r.A[0, c]


@njit(cache=True)
def cv_step(s_R: float, v_R: float, s_H: float, v_H: float, lib_r: Lib, P_av: np.ndarray,
            P_hv: np.ndarray, diag: np.ndarray, log: np.ndarray, work: np.ndarray) -> float:
    """One step of the constant-velocity planner; returns the acceleration."""
    allowed = np.empty(lib_r.S.shape[1], np.bool_)
    n_allowed = shield_allowed(s_R, v_R, s_H, v_H, lib_r, P_av, P_hv, False, allowed)
    c, feasible = decide_cv(s_H, v_H, lib_r, P_av, P_hv, diag, work, allowed)
    log[CV_COL_TRAJ] = c
    log[CV_COL_FEASIBLE] = 1.0 if feasible else 0.0
    log[CV_COL_N_FEASIBLE] = _n_feasible(diag, 1.0 - P_av[slot.EPSILON])
    log[CV_COL_PSAFE_MIN] = diag[c, D_MIN_SAFE]
    log[CV_COL_EXPECTED] = diag[c, D_EXPECTED]
    log[CV_COL_N_ALLOWED] = n_allowed
    return lib_r.A[0, c]
