"""The adaptive-role leader-follower player (docs/method.md §5): the paper's human, the AV in
the 2-LFG case, and the human variants ``stubborn`` and ``noisy`` (§11).

"Act first, then adapt": from the belief held before this step, the plausible role and
``Pi(p_a)``; act on the current role (the game's trajectory for that role); draw ``r`` and
adapt the role; update the belief against the prediction stored at the previous step; store
the prediction of the other's next state per role of the other.

- ``lfg``: parameters ``p_a`` (``roles.p_a``) and ``adapt_role``; one uniform per step.
- ``stubborn``: the LFG with ``p_a = 0``: ``Pi`` is the identity and the role never changes.
- ``noisy``: a Boltzmann-rational LFG: it picks trajectory ``c`` with probability proportional
  to ``exp(beta (Q_c - max Q))`` over its game's values for its current role (the leader's
  ``Ql`` of "ego leads", or the follower's ``Qf`` of "ego follows"); exact ties at the maximum
  collapse onto the lowest index, the game's own tie rule, so ``beta -> inf`` is the LFG bit
  for bit. A second uniform per step makes the choice (inverse CDF in index order).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..game import (EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER,
                    Q_EGO_FOLLOWS_FOLLOWER, Q_EGO_LEADS_LEADER)
from ..library import Lib
from ..roles import LEADER, bayes_update, next_role, plausible_leader, transition_into

#: Slots of an LFG player's state: role (0 = L, 1 = F), belief (P(other = L), P(other = F)),
#: the stored prediction of the other's next state per role of the other, and whether that
#: prediction has been initialised.
ROLE, BELIEF_L, BELIEF_F, PRED_L_S, PRED_L_V, PRED_F_S, PRED_F_V, READY = range(8)
#: Slots of its parameter vector.
PRM_P_A, PRM_ADAPT, PRM_BETA, PRM_ROLE = range(4)

# Log columns (``persuasive.policies.kinds.NOISY_LOG``; the LFG's are the first 11).
(COL_ROLE, COL_NEXT_ROLE, COL_TRAJ, COL_PLAUSIBLE, COL_PI_LL, COL_PI_LF, COL_PI_FL, COL_PI_FF,
 COL_DRAW, COL_BELIEF_L, COL_BELIEF_F, COL_CHOICE_DRAW, COL_CHOICE_P) = range(13)


@njit(cache=True)
def lfg_init(st: np.ndarray, role: int, prior_l: float) -> None:
    """A fresh LFG state in ``st``: ``role``, belief ``(prior_l, 1 - prior_l)``, no
    prediction yet."""
    st[:] = 0.0
    st[ROLE] = role
    st[BELIEF_L] = prior_l
    st[BELIEF_F] = 1.0 - prior_l


@njit(cache=True)
def boltzmann_choice(q: np.ndarray, beta: float, r: float) -> tuple[int, float]:
    """A trajectory drawn with ``P(c) ~ exp(beta (q_c - max q))``, ties at the maximum on the
    lowest index; ``r`` in [0, 1). Returns ``(c, P(c))``."""
    n = q.shape[0]
    q_max = q[0]
    first = 0
    for c in range(1, n):
        if q[c] > q_max:
            q_max, first = q[c], c
    w = np.empty(n)
    total = 0.0
    for c in range(n):
        if q[c] == q_max:
            w[c] = 1.0 if c == first else 0.0
        else:
            w[c] = math.exp(beta * (q[c] - q_max))
        total += w[c]
    target = r * total
    acc = 0.0
    for c in range(n):
        acc += w[c]
        if w[c] > 0.0 and target < acc:
            return c, w[c] / total
    return first, w[first] / total


@njit(cache=True)
def lfg_step(st: np.ndarray, prm: np.ndarray, noisy: bool, s_other: float, v_other: float,
             r: float, r_choice: float, lib_self: Lib, lib_other: Lib, idx: np.ndarray,
             q_values: np.ndarray, w_s: float, w_v: float, log: np.ndarray) -> float:
    """One step of an LFG player; returns its acceleration [m/s^2].

    ``lib_self``, ``lib_other``, ``idx``, ``q_values``: the full prediction of the current
    joint state seen by this player (ego = this player). ``r`` is the role uniform of this
    step, ``r_choice`` the choice uniform of a ``noisy`` player. Updates ``st`` in place and
    fills ``log``.
    """
    if st[READY] == 0.0:  # the stored prediction starts at the other's current state
        st[PRED_L_S], st[PRED_L_V] = s_other, v_other
        st[PRED_F_S], st[PRED_F_V] = s_other, v_other
        st[READY] = 1.0
    role = int(st[ROLE])
    b_l, b_f = st[BELIEF_L], st[BELIEF_F]
    # 1-2. plausible role from the belief held before this step, and Pi(p_a)
    pl = plausible_leader(b_l, b_f, role)
    Pi = np.empty((2, 2))
    transition_into(pl, prm[PRM_P_A], Pi)
    # 3. act on the current role
    traj = idx[EGO_LEADER] if role == LEADER else idx[EGO_FOLLOWER]
    if noisy:
        row = Q_EGO_LEADS_LEADER if role == LEADER else Q_EGO_FOLLOWS_FOLLOWER
        traj, p_choice = boltzmann_choice(q_values[row], prm[PRM_BETA], r_choice)
        log[COL_CHOICE_DRAW] = r_choice
        log[COL_CHOICE_P] = p_choice
    accel = lib_self.A[0, traj]
    # 4. adapt the role (the draw is made whether or not roles adapt)
    new_role = next_role(role, r, Pi) if prm[PRM_ADAPT] != 0.0 else role
    # 5. Bayes update of the belief against the prediction stored at the previous step
    b_l, b_f = bayes_update(
        b_l, b_f,
        abs(s_other - st[PRED_L_S]), abs(v_other - st[PRED_L_V]),
        abs(s_other - st[PRED_F_S]), abs(v_other - st[PRED_F_V]),
        w_s, w_v,
    )
    # 6. predict the other's next state per role of the other
    o_l, o_f = idx[OTHER_LEADER], idx[OTHER_FOLLOWER]
    st[ROLE] = new_role
    st[BELIEF_L], st[BELIEF_F] = b_l, b_f
    st[PRED_L_S], st[PRED_L_V] = lib_other.S[0, o_l], lib_other.V[0, o_l]
    st[PRED_F_S], st[PRED_F_V] = lib_other.S[0, o_f], lib_other.V[0, o_f]
    log[COL_ROLE] = role
    log[COL_NEXT_ROLE] = new_role
    log[COL_TRAJ] = traj
    log[COL_PLAUSIBLE] = pl
    log[COL_PI_LL], log[COL_PI_LF] = Pi[0, 0], Pi[0, 1]
    log[COL_PI_FL], log[COL_PI_FF] = Pi[1, 0], Pi[1, 1]
    log[COL_DRAW] = r
    log[COL_BELIEF_L], log[COL_BELIEF_F] = b_l, b_f
    return accel
