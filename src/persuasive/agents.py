"""Agents: the stateful players on top of the numerical core (spec sections 5 and 6).

An agent's state is a small float vector (role, belief, stored prediction); one compiled step
function per agent kind reads it, calls the pure kernels of ``persuasive.game``,
``persuasive.roles`` and ``persuasive.mpc``, and writes the new state and a log row. The same
step functions serve the compiled closed loop (``persuasive.simulation``) and the Python
classes below, which a user drives from their own loop.

- :class:`LFGAgent`: the adaptive-role leader-follower player, "act first, then adapt"; the
  human model, and the AV in the 2-LFG case.
- :class:`PersuasiveMPCAgent`: the AV's branch MPC with interactive prediction.

Agents never move vehicles: a step returns an acceleration and the caller advances the world.
Both classes share a :class:`GameCache`: the HV's own game at a step and the MPC's prediction of
the human at that step are the same game, solved once.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import _packed as K
from .game import EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER, predict_buffers
from .library import Lib, as_lib, lib_buffers, new_lib
from .mpc import (D_BELIEF_L, D_EXPECTED, D_MAX_SAFE, D_MIN_SAFE, D_P_LL, D_PLAUSIBLE_L, N_DIAG,
                  decide)
from .roles import FOLLOWER, LEADER, bayes_update, next_role, plausible_leader, transition_into

State = tuple[float, float]  # (s [m], v [m/s])

#: Index permutation that turns a full prediction into the other player's view of it.
SWAP = np.array([OTHER_LEADER, OTHER_FOLLOWER, EGO_LEADER, EGO_FOLLOWER], np.int64)

# -- LFG player ---------------------------------------------------------------------------------

#: Slots of an LFG player's state vector: role (0 = L, 1 = F), belief (P(other = L),
#: P(other = F)), the stored prediction of the other's next state per role of the other, and
#: whether that prediction has been initialised.
ROLE, BEL_L, BEL_F, PRED_LS, PRED_LV, PRED_FS, PRED_FV, READY = range(8)
N_LFG_STATE = 8

#: Columns of an LFG player's log row.
LFG_LOG = ("role", "next_role", "trajectory", "plausible_leader", "pi_ll", "pi_lf", "pi_fl",
           "pi_ff", "draw", "belief_other_leader", "belief_other_follower")
(L_ROLE, L_NEXT_ROLE, L_TRAJ, L_PLAUSIBLE, L_PI_LL, L_PI_LF, L_PI_FL, L_PI_FF, L_DRAW,
 L_BEL_L, L_BEL_F) = range(len(LFG_LOG))


@njit(cache=True)
def lfg_init(role: int, prior_l: float) -> np.ndarray:
    """A fresh LFG state: ``role``, belief ``(prior_l, 1 - prior_l)``, no prediction yet."""
    st = np.zeros(N_LFG_STATE)
    st[ROLE] = role
    st[BEL_L] = prior_l
    st[BEL_F] = 1.0 - prior_l
    return st


@njit(cache=True)
def lfg_step(st: np.ndarray, s_other: float, v_other: float, r: float, p_a: float,
             adapt: bool, L_self: Lib, L_other: Lib, idx: np.ndarray, w_s: float, w_v: float,
             log: np.ndarray) -> float:
    """One step of an LFG player (spec section 5); returns its acceleration [m/s^2].

    ``L_self``, ``L_other``: the two libraries of the full prediction of the current joint
    state seen by this player, whose indices are ``idx`` (ego-L, ego-F, other-L, other-F).
    ``r`` is the uniform drawn for this step. Updates ``st`` in place and fills ``log``
    (``LFG_LOG`` columns).
    """
    if st[READY] == 0.0:  # the stored prediction starts at the other's current state
        st[PRED_LS], st[PRED_LV] = s_other, v_other
        st[PRED_FS], st[PRED_FV] = s_other, v_other
        st[READY] = 1.0
    role = int(st[ROLE])
    b_l, b_f = st[BEL_L], st[BEL_F]
    # 1-2. plausible role from the belief held before this step, and Pi(p_a)
    pl = plausible_leader(b_l, b_f, role)
    Pi = np.empty((2, 2))
    transition_into(pl, p_a, Pi)
    # 3. act on the current role
    traj = idx[EGO_LEADER] if role == LEADER else idx[EGO_FOLLOWER]
    accel = L_self.A[0, traj]
    # 4. adapt the role (the draw is made whether or not roles adapt)
    new_role = next_role(role, r, Pi) if adapt else role
    # 5. Bayes update of the belief against the prediction stored at the previous step
    b_l, b_f = bayes_update(
        b_l, b_f,
        abs(s_other - st[PRED_LS]), abs(v_other - st[PRED_LV]),
        abs(s_other - st[PRED_FS]), abs(v_other - st[PRED_FV]),
        w_s, w_v,
    )
    # 6. predict the other's next state per role of the other
    o_l, o_f = idx[OTHER_LEADER], idx[OTHER_FOLLOWER]
    st[ROLE] = new_role
    st[BEL_L], st[BEL_F] = b_l, b_f
    st[PRED_LS], st[PRED_LV] = L_other.S[0, o_l], L_other.V[0, o_l]
    st[PRED_FS], st[PRED_FV] = L_other.S[0, o_f], L_other.V[0, o_f]
    log[L_ROLE] = role
    log[L_NEXT_ROLE] = new_role
    log[L_TRAJ] = traj
    log[L_PLAUSIBLE] = pl
    log[L_PI_LL], log[L_PI_LF], log[L_PI_FL], log[L_PI_FF] = Pi[0, 0], Pi[0, 1], Pi[1, 0], Pi[1, 1]
    log[L_DRAW] = r
    log[L_BEL_L], log[L_BEL_F] = b_l, b_f
    return accel


# -- persuasive branch MPC ----------------------------------------------------------------------

#: Slots of the MPC's state vector: belief q = (P(HV = L), P(HV = F)), the stored prediction of
#: the HV's next state per HV role, and whether it has been initialised.
Q_L, Q_F, MPRED_LS, MPRED_LV, MPRED_FS, MPRED_FV, MREADY = range(7)
N_MPC_STATE = 7

#: Columns of the MPC's log row (those of the chosen candidate where per-candidate).
MPC_LOG = ("trajectory", "feasible", "n_feasible", "p_safe_min", "p_safe_max",
           "expected_reward", "belief_hv_leader_used", "belief_hv_leader",
           "belief_hv_follower", "tie_role", "human_belief_av_leader",
           "human_plausible_leader", "branch_p_ll", "branch_p_lf", "branch_p_fl", "branch_p_ff")
(M_TRAJ, M_FEASIBLE, M_N_FEASIBLE, M_PSAFE_MIN, M_PSAFE_MAX, M_EXPECTED, M_Q_USED, M_BEL_L,
 M_BEL_F, M_TIE, M_H_BEL_L, M_H_PLAUSIBLE, M_P_LL, M_P_LF, M_P_FL, M_P_FF) = range(len(MPC_LOG))


@njit(cache=True)
def mpc_init(prior_l: float) -> np.ndarray:
    """A fresh MPC state: belief ``(prior_l, 1 - prior_l)``, no prediction yet."""
    st = np.zeros(N_MPC_STATE)
    st[Q_L] = prior_l
    st[Q_F] = 1.0 - prior_l
    return st


@njit(cache=True)
def mpc_step(st: np.ndarray, s_R: float, v_R: float, s_H: float, v_H: float,
             tie_given: bool, given_role: int, p_a_hat: float, LH: Lib, LR: Lib,
             idx: np.ndarray, P: np.ndarray, disc: np.ndarray, diag: np.ndarray,
             log: np.ndarray, LH1a: Lib, LH1b: Lib) -> float:
    """One step of the persuasive MPC (spec section 6); returns the AV's acceleration.

    ``LH, LR, idx``: the full prediction of ``z = (x_H, x_R)`` from the human's view. The human
    model's own role (for belief ties) is ``given_role`` when ``tie_given`` (quirk Q3), else the
    most likely HV role under ``q`` (ties: L). ``diag`` receives the per-candidate diagnostics
    of :func:`persuasive.mpc.decide`; ``log`` the ``MPC_LOG`` columns; ``LH1a``, ``LH1b``
    the HV's libraries one sample ahead (scratch, see :func:`persuasive.mpc.decide`).
    """
    if st[MREADY] == 0.0:
        st[MPRED_LS], st[MPRED_LV] = s_H, v_H
        st[MPRED_FS], st[MPRED_FV] = s_H, v_H
        st[MREADY] = 1.0
    q_l, q_f = st[Q_L], st[Q_F]
    if tie_given:
        tie = given_role
    else:
        tie = LEADER if q_l >= q_f else FOLLOWER
    c, feasible = decide(s_R, v_R, s_H, v_H, LH, LR, idx, q_l, q_f, tie == LEADER, p_a_hat,
                         P, disc, diag, LH1a, LH1b)
    # 6. update q against the stored prediction, then store the new one
    b_l, b_f = bayes_update(
        q_l, q_f,
        abs(s_H - st[MPRED_LS]), abs(v_H - st[MPRED_LV]),
        abs(s_H - st[MPRED_FS]), abs(v_H - st[MPRED_FV]),
        P[K.W_S], P[K.W_V],
    )
    h_l, h_f = idx[EGO_LEADER], idx[EGO_FOLLOWER]
    st[Q_L], st[Q_F] = b_l, b_f
    st[MPRED_LS], st[MPRED_LV] = LH.S[0, h_l], LH.V[0, h_l]
    st[MPRED_FS], st[MPRED_FV] = LH.S[0, h_f], LH.V[0, h_f]
    threshold = 1.0 - P[K.EPSILON]
    n_feasible = 0
    for k in range(diag.shape[0]):
        if diag[k, D_MIN_SAFE] > threshold:
            n_feasible += 1
    log[M_TRAJ] = c
    log[M_FEASIBLE] = 1.0 if feasible else 0.0
    log[M_N_FEASIBLE] = n_feasible
    log[M_PSAFE_MIN] = diag[c, D_MIN_SAFE]
    log[M_PSAFE_MAX] = diag[c, D_MAX_SAFE]
    log[M_EXPECTED] = diag[c, D_EXPECTED]
    log[M_Q_USED] = q_l
    log[M_BEL_L], log[M_BEL_F] = b_l, b_f
    log[M_TIE] = tie
    log[M_H_BEL_L] = diag[c, D_BELIEF_L]
    log[M_H_PLAUSIBLE] = diag[c, D_PLAUSIBLE_L]
    for b in range(4):
        log[M_P_LL + b] = diag[c, D_P_LL + b]
    return LR.A[0, c]


@njit(cache=True)
def lfg_step_buffers(st, s_other, v_other, r, p_a, adapt, buf_self, win_self, buf_other,
                     win_other, idx, w_s, w_v, log) -> float:
    """:func:`lfg_step` on libraries stored as :func:`persuasive.library.lib_buffers`."""
    return lfg_step(st, s_other, v_other, r, p_a, adapt, as_lib(buf_self, win_self),
                    as_lib(buf_other, win_other), idx, w_s, w_v, log)


@njit(cache=True)
def mpc_step_buffers(st, s_R, v_R, s_H, v_H, tie_given, given_role, p_a_hat, buf_H, win_H,
                     buf_R, win_R, idx, P, disc, diag, log) -> float:
    """:func:`mpc_step` on libraries stored as :func:`persuasive.library.lib_buffers`."""
    n, n_traj = (buf_H.shape[0] - 1) // 5, win_H.shape[0]
    return mpc_step(st, s_R, v_R, s_H, v_H, tie_given, given_role, p_a_hat,
                    as_lib(buf_H, win_H), as_lib(buf_R, win_R), idx, P, disc, diag, log,
                    new_lib(n, n_traj), new_lib(n, n_traj))


# -- Python classes -----------------------------------------------------------------------------


class GameView:
    """One full prediction seen by an ego player.

    ``ego`` and ``other``: each library as its ``(buf, win)`` storage
    (:func:`persuasive.library.lib_buffers`); ``idx``: (ego-L, ego-F, other-L, other-F).
    """

    __slots__ = ("ego", "other", "idx")

    def __init__(self, ego: tuple[np.ndarray, np.ndarray], other: tuple[np.ndarray, np.ndarray],
                 idx: np.ndarray):
        self.ego, self.other, self.idx = ego, other, idx

    def swapped(self) -> GameView:
        """The same game seen by the other player (it is the same pair of solves)."""
        return GameView(self.other, self.ego, self.idx[SWAP])

    def ego_lib(self) -> Lib:
        """The ego's library as a :class:`persuasive.library.Lib` of views."""
        return as_lib(*self.ego)

    def other_lib(self) -> Lib:
        """The other's library as a :class:`persuasive.library.Lib` of views."""
        return as_lib(*self.other)


class GameCache:
    """Full predictions (spec section 4) with a memo of the last joint state.

    A query for the same joint state, or for the same state seen from the other player, returns
    the stored solve (exact float equality of the four numbers).
    """

    def __init__(self, P: np.ndarray, disc: np.ndarray):
        self.P, self.disc = P, disc
        self._shape = (int(P[K.N_SAMPLES]), int(P[K.N_MESH]) + 1)
        self._key: tuple[float, float, float, float] | None = None
        self._view: GameView | None = None
        self.solves = 0  #: number of games actually solved

    def __call__(self, x_ego: State, x_other: State) -> GameView:
        key = (float(x_ego[0]), float(x_ego[1]), float(x_other[0]), float(x_other[1]))
        if key == self._key:
            return self._view
        if (key[2], key[3], key[0], key[1]) == self._key:
            return self._view.swapped()
        ego, other = lib_buffers(*self._shape), lib_buffers(*self._shape)
        idx = np.empty(4, np.int64)
        predict_buffers(*key, self.P, self.disc, *ego, *other, idx)
        self.solves += 1
        self._key, self._view = key, GameView(ego, other, idx)
        return self._view


class LFGAgent:
    """An adaptive-role leader-follower player (spec section 5), "act first, then adapt".

    Parameters
    ----------
    role : "leader" | "follower"
        Initial role.
    p_a : float
        Willingness to change role, in [0, 1].
    adapt_role : bool
        False fixes the role (the uniform is still drawn).
    games : GameCache
        Shared full predictions.
    """

    def __init__(self, role: str, p_a: float, adapt_role: bool, games: GameCache):
        self.initial_role = LEADER if role == "leader" else FOLLOWER
        self.p_a = float(p_a)
        self.adapt_role = bool(adapt_role)
        self.games = games
        self.state = lfg_init(self.initial_role, float(games.P[K.PRIOR_L]))
        self.last = np.zeros(len(LFG_LOG))  #: the last step's log row (``LFG_LOG`` columns)

    @property
    def role(self) -> int:
        """Current role: 0 = leader, 1 = follower."""
        return int(self.state[ROLE])

    @property
    def belief(self) -> tuple[float, float]:
        """``(P(other = L), P(other = F))``."""
        return float(self.state[BEL_L]), float(self.state[BEL_F])

    def decide(self, x_self: State, x_other: State, rng: np.random.RandomState) -> float:
        """One step: act on the current role, then adapt; returns the acceleration [m/s^2]."""
        game = self.games(x_self, x_other)
        P = self.games.P
        return float(lfg_step_buffers(
            self.state, float(x_other[0]), float(x_other[1]), rng.random_sample(), self.p_a,
            self.adapt_role, *game.ego, *game.other, game.idx, P[K.W_S], P[K.W_V], self.last))


class PersuasiveMPCAgent:
    """The AV's persuasive branch MPC (spec section 6).

    Parameters
    ----------
    p_a_hat : float
        The AV's estimate of the human's ``p_a``.
    games : GameCache
        Shared full predictions.
    tie_rule : "belief" | "given"
        Which role the human model holds when its belief on the AV is a tie: ``"belief"`` the
        AV's most likely HV role under ``q`` (ties: L; corrected mode); ``"given"`` the role
        passed to :meth:`decide` (quirk Q3).
    """

    def __init__(self, p_a_hat: float, games: GameCache, tie_rule: str = "belief"):
        if tie_rule not in ("belief", "given"):
            raise ValueError(f"tie_rule = {tie_rule!r} is out of range; allowed: belief | given")
        self.p_a_hat = float(p_a_hat)
        self.games = games
        self.tie_rule = tie_rule
        self.state = mpc_init(float(games.P[K.PRIOR_L]))
        n_traj = int(games.P[K.N_MESH]) + 1
        self.diagnostics = np.zeros((n_traj, N_DIAG))  #: the last decision, per candidate
        self.last = np.zeros(len(MPC_LOG))  #: the last step's log row (``MPC_LOG`` columns)
        self.last_game: GameView | None = None  #: the human-view prediction of the last step

    @property
    def belief(self) -> tuple[float, float]:
        """``q = (P(HV = L), P(HV = F))``."""
        return float(self.state[Q_L]), float(self.state[Q_F])

    def decide(self, x_R: State, x_H: State, human_role: int | None = None) -> float:
        """One decision of the AV at ``x_R`` with the HV at ``x_H``; returns the acceleration."""
        given = self.tie_rule == "given"
        if given and human_role is None:
            raise ValueError("human_role is required when tie_rule = 'given'")
        game = self.games(x_H, x_R)  # the human's view z = (x_H, x_R)
        self.last_game = game
        return float(mpc_step_buffers(
            self.state, float(x_R[0]), float(x_R[1]), float(x_H[0]), float(x_H[1]),
            given, int(human_role or 0), self.p_a_hat, *game.ego, *game.other, game.idx,
            self.games.P, self.games.disc, self.diagnostics, self.last,
        ))
