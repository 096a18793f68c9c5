"""Agents: thin stateful players on top of the numerical core (spec sections 5 and 6).

An agent holds what persists between steps (role, belief, stored prediction) and calls the pure
kernels of ``persuasive.game``, ``persuasive.roles`` and ``persuasive.mpc`` for everything else.
Agents never move vehicles: :meth:`decide` returns an acceleration and the simulation advances
the world.

- :class:`LFGAgent` is the adaptive-role leader-follower player: the human model, and the AV in
  the 2-LFG case.
- :class:`PersuasiveMPCAgent` is the AV's branch MPC with interactive prediction.

Both share a :class:`GameCache`: the HV's own game at a step and the MPC's prediction of the
human at that step are the same game, solved once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _packed as K
from .game import EGO_FOLLOWER, EGO_LEADER, OTHER_FOLLOWER, OTHER_LEADER, predict_into, work_shape
from .mpc import N_DIAG, decide
from .roles import FOLLOWER, LEADER, bayes_update, next_role, plausible_leader, transition_into

State = tuple[float, float]  # (s [m], v [m/s])

_SWAP = np.array([OTHER_LEADER, OTHER_FOLLOWER, EGO_LEADER, EGO_FOLLOWER])


class GameView:
    """The raw arrays of one full prediction, seen by an ego player.

    ``Se, Ve, Ae`` and ``So, Vo, Ao``: the ego's and the other's libraries ``(n_traj, n)``;
    ``idx``: trajectory indices (ego-L, ego-F, other-L, other-F).
    """

    __slots__ = ("Se", "Ve", "Ae", "So", "Vo", "Ao", "idx")

    def __init__(self, Se, Ve, Ae, So, Vo, Ao, idx):
        self.Se, self.Ve, self.Ae, self.So, self.Vo, self.Ao, self.idx = Se, Ve, Ae, So, Vo, Ao, idx

    def swapped(self) -> GameView:
        """The same game seen by the other player (it is the same pair of solves)."""
        return GameView(self.So, self.Vo, self.Ao, self.Se, self.Ve, self.Ae, self.idx[_SWAP])

    def ego_traj(self, role: int) -> int:
        return int(self.idx[EGO_LEADER if role == LEADER else EGO_FOLLOWER])

    def other_next(self, role: int) -> State:
        """The other's predicted state one sample ahead when it holds ``role``."""
        i = self.idx[OTHER_LEADER if role == LEADER else OTHER_FOLLOWER]
        return float(self.So[i, 0]), float(self.Vo[i, 0])


class GameCache:
    """Full predictions (spec section 4) with a memo of the last joint state.

    A query for the same joint state, or for the same state seen from the other player, returns
    the stored solve (exact float equality of the four numbers).
    """

    def __init__(self, P: np.ndarray, disc: np.ndarray):
        self.P, self.disc = P, disc
        n_traj, n = int(P[K.N_MESH]) + 1, int(P[K.N_SAMPLES])
        self._shape = (n_traj, n)
        self._work = np.empty(work_shape(n_traj))
        self._iwork = np.empty((2, n_traj, 2), np.int64)
        self._key: tuple[float, float, float, float] | None = None
        self._view: GameView | None = None
        self.solves = 0  #: number of games actually solved

    def __call__(self, x_ego: State, x_other: State) -> GameView:
        key = (x_ego[0], x_ego[1], x_other[0], x_other[1])
        if key == self._key:
            return self._view
        if (key[2], key[3], key[0], key[1]) == self._key:
            return self._view.swapped()
        shape = self._shape
        Se, Ve, Ae = np.empty(shape), np.empty(shape), np.empty(shape)
        So, Vo, Ao = np.empty(shape), np.empty(shape), np.empty(shape)
        idx = np.empty(4, np.int64)
        predict_into(key[0], key[1], key[2], key[3], self.P, self.disc, True, True,
                     Se, Ve, Ae, So, Vo, Ao, self._work, self._iwork, idx)
        self.solves += 1
        self._key, self._view = key, GameView(Se, Ve, Ae, So, Vo, Ao, idx)
        return self._view


@dataclass
class LFGStep:
    """What an LFG player did at one step."""

    accel_mps2: float  #: applied acceleration
    role: int  #: the role it acted in (0 = L, 1 = F)
    next_role: int  #: its role after adaptation
    plausible_leader: float  #: P(plausible role = L) from the belief held before the step
    transition: np.ndarray  #: Pi (2, 2)
    draw: float  #: the uniform drawn for adaptation
    trajectory: int  #: index of the trajectory it follows
    belief_leader: float  #: P(other = L) after this step's update
    belief_follower: float  #: P(other = F) after this step's update


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
        self.role = LEADER if role == "leader" else FOLLOWER
        self.initial_role = self.role
        self.p_a = float(p_a)
        self.adapt_role = adapt_role
        self.games = games
        prior = float(games.P[K.PRIOR_L])
        self.belief = (prior, 1.0 - prior)  # (P(other = L), P(other = F))
        self.prediction: tuple[State, State] | None = None  # the other's next state per role

    def decide(self, x_self: State, x_other: State, rng: np.random.RandomState) -> LFGStep:
        """One step: act on the current role, then adapt role, belief and prediction."""
        if self.prediction is None:
            self.prediction = (x_other, x_other)
        b_l, b_f = self.belief
        pl = plausible_leader(b_l, b_f, self.role)
        Pi = np.empty((2, 2))
        transition_into(pl, self.p_a, Pi)
        game = self.games(x_self, x_other)
        traj = game.ego_traj(self.role)
        accel = float(game.Ae[traj, 0])
        r = rng.random_sample()
        acted = self.role
        if self.adapt_role:
            self.role = next_role(self.role, r, Pi)
        (ls, lv), (fs, fv) = self.prediction
        P = self.games.P
        self.belief = bayes_update(
            b_l, b_f,
            abs(x_other[0] - ls), abs(x_other[1] - lv),
            abs(x_other[0] - fs), abs(x_other[1] - fv),
            P[K.W_S], P[K.W_V],
        )
        self.prediction = (game.other_next(LEADER), game.other_next(FOLLOWER))
        return LFGStep(accel, acted, self.role, pl, Pi, r, traj, *self.belief)


@dataclass
class MPCStep:
    """What the branch MPC did at one step."""

    accel_mps2: float  #: applied acceleration
    trajectory: int  #: chosen candidate
    feasible: bool  #: a candidate met the chance constraint
    tie_role: int  #: the human model's own role used for belief ties (0 = L, 1 = F)
    q_used: tuple[float, float]  #: belief on the HV's role used in the decision
    belief_leader: float  #: P(HV = L) after this step's update
    belief_follower: float  #: P(HV = F) after this step's update
    diagnostics: np.ndarray  #: per-candidate diagnostics (``persuasive.mpc`` columns)


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
        passed to :meth:`decide` (quirk Q3: the simulation passes the HV's true or initial
        role).
    """

    def __init__(self, p_a_hat: float, games: GameCache, tie_rule: str = "belief"):
        if tie_rule not in ("belief", "given"):
            raise ValueError(f"tie_rule = {tie_rule!r} is out of range; allowed: belief | given")
        self.p_a_hat = float(p_a_hat)
        self.games = games
        self.tie_rule = tie_rule
        prior = float(games.P[K.PRIOR_L])
        self.belief = (prior, 1.0 - prior)  # q = (P(HV = L), P(HV = F))
        self.prediction: tuple[State, State] | None = None  # the HV's next state per role
        self.n_traj = int(games.P[K.N_MESH]) + 1

    def decide(self, x_R: State, x_H: State, human_role: int | None = None) -> MPCStep:
        """One decision of the AV at ``x_R`` with the HV at ``x_H``."""
        if self.prediction is None:
            self.prediction = (x_H, x_H)
        q_l, q_f = self.belief
        if self.tie_rule == "given":
            if human_role is None:
                raise ValueError("human_role is required when tie_rule = 'given'")
            tie = human_role
        else:
            tie = LEADER if q_l >= q_f else FOLLOWER
        game = self.games(x_H, x_R)  # the human's view z = (x_H, x_R)
        diag = np.empty((self.n_traj, N_DIAG))
        P = self.games.P
        k, feasible = decide(
            x_R[0], x_R[1], x_H[0], x_H[1],
            game.Se, game.Ve, game.Ae, game.So, game.Vo, game.Ao, game.idx,
            q_l, q_f, tie == LEADER, self.p_a_hat, P, self.games.disc, diag,
        )
        (ls, lv), (fs, fv) = self.prediction
        self.belief = bayes_update(
            q_l, q_f,
            abs(x_H[0] - ls), abs(x_H[1] - lv),
            abs(x_H[0] - fs), abs(x_H[1] - fv),
            P[K.W_S], P[K.W_V],
        )
        hv_l, hv_f = game.idx[EGO_LEADER], game.idx[EGO_FOLLOWER]
        self.prediction = (
            (float(game.Se[hv_l, 0]), float(game.Ve[hv_l, 0])),
            (float(game.Se[hv_f, 0]), float(game.Ve[hv_f, 0])),
        )
        return MPCStep(float(game.Ao[k, 0]), int(k), bool(feasible), tie,
                       (q_l, q_f), *self.belief, diag)
