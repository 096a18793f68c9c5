"""The leader-follower game: one solve and the full prediction (spec section 4).

Notation. The "ego" player solves the game at the joint state ``x = (s_e, v_e, s_o, v_o)``.
Both players' libraries are built (``persuasive.library``) and each player's reward matrix is
``M[own trajectory, other's trajectory]`` (``persuasive.rewards``). In the spec's notation
``R_e[i, j] = M_e[j, i]`` and ``R_o[i, j] = M_o[i, j]`` (row ``i`` the other's trajectory,
column ``j`` the ego's).

One leader-follower solve, with ``M_lead`` the leader's and ``M_fol`` the follower's matrix:

- the follower maximises its worst case: ``Qf[f] = min_l M_fol[f, l]``, ``F* = argmax-set Qf``
  (every tie, exact floating-point equality);
- the leader evaluates each of its trajectories against the follower's optimal set:
  ``Ql[l] = agg_{f in F*} M_lead[l, f]`` (``agg`` is ``min`` as in the paper, or ``max``, quirk
  Q5), and picks the first (lowest-index) maximiser;
- the predicted follower trajectory is the first element of ``F*``.

"Ego leads" is the solve with the ego as leader, "ego follows" the one with the other as leader.
A **full prediction** gives each player's trajectory in each role: ego-L and other-F from the
first solve, other-L and ego-F from the second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from . import _packed as K
from .library import Lib, Library, as_lib, fill_library, trajectory_library
from .rewards import reward_matrix, reward_matrix_of, reward_terms

# Indices into the 4-vector returned by a full prediction.
EGO_LEADER, EGO_FOLLOWER, OTHER_LEADER, OTHER_FOLLOWER = 0, 1, 2, 3


@njit(cache=True)
def leader_follower(M_lead: np.ndarray, M_fol: np.ndarray, agg_max: bool,
                    Ql: np.ndarray, Qf: np.ndarray) -> tuple[int, int]:
    """Solve one leader-follower game; return ``(leader pick, follower pick)``.

    ``M_lead``: ``(n_lead, n_fol)``, ``M_fol``: ``(n_fol, n_lead)``. ``Ql`` and ``Qf`` receive
    the leader's and follower's Q-values. Ties go to the lowest index.
    """
    n_lead, n_fol = M_lead.shape
    best_f = -np.inf
    for f in range(n_fol):
        q = M_fol[f, 0]
        for l in range(1, n_lead):
            if M_fol[f, l] < q:
                q = M_fol[f, l]
        Qf[f] = q
        if q > best_f:
            best_f = q
    first_f = -1
    for f in range(n_fol):
        if Qf[f] == best_f:
            first_f = f
            break
    best_l, pick_l = -np.inf, 0
    for l in range(n_lead):
        q = M_lead[l, first_f]
        for f in range(first_f + 1, n_fol):
            if Qf[f] == best_f:
                x = M_lead[l, f]
                if (x > q) if agg_max else (x < q):
                    q = x
        Ql[l] = q
        if q > best_l or l == 0:
            best_l, pick_l = q, l
    return pick_l, first_f


@njit(cache=True)
def solve_both(M_e: np.ndarray, M_o: np.ndarray, agg_max: bool, out: np.ndarray,
               Q: np.ndarray) -> None:
    """Both role assignments: ``out = (ego-L, ego-F, other-L, other-F)`` trajectory indices.

    ``Q`` ``(4, n)``: rows Ql and Qf of "ego leads", then Ql and Qf of "ego follows".
    """
    out[EGO_LEADER], out[OTHER_FOLLOWER] = leader_follower(M_e, M_o, agg_max, Q[0], Q[1])
    out[OTHER_LEADER], out[EGO_FOLLOWER] = leader_follower(M_o, M_e, agg_max, Q[2], Q[3])


@njit(cache=True)
def build(s0: float, v0: float, P: np.ndarray, disc: np.ndarray, L: Lib) -> None:
    """Fill ``L`` with the library of a vehicle at ``(s0, v0)`` and its reward parts."""
    fill_library(s0, v0, P, L.S, L.V, L.A)
    reward_terms(L.S, L.V, L.A, s0, disc, P[K.W_U], P[K.MIN_DIST_SQ], L.base, L.coll, L.sq,
                 L.win)


@njit(cache=True)
def solve_libs(Le: Lib, Lo: Lib, w_c: float, min_dist_sq: float, agg_max: bool,
               M_e: np.ndarray, M_o: np.ndarray, C: np.ndarray, Q: np.ndarray,
               out: np.ndarray) -> None:
    """Both reward matrices of two built libraries (ego, other), then both solves into ``out``.

    ``M_e, M_o, C``: ``(n_traj, n_traj)`` scratch; ``Q``: ``(4, n_traj)`` (see
    :func:`solve_both`).
    """
    reward_matrix(Le.base, Le.coll, Le.sq, Le.win, Lo.sq, Lo.win, w_c, min_dist_sq, C, M_e)
    reward_matrix(Lo.base, Lo.coll, Lo.sq, Lo.win, Le.sq, Le.win, w_c, min_dist_sq, C, M_o)
    solve_both(M_e, M_o, agg_max, out, Q)


@njit(cache=True)
def predict_into(s_e: float, v_e: float, s_o: float, v_o: float, P: np.ndarray,
                 disc: np.ndarray, Le: Lib, Lo: Lib, out: np.ndarray,
                 ego_built: bool = False) -> None:
    """Full prediction at the joint state: both libraries built into ``Le, Lo``, indices
    (ego-L, ego-F, other-L, other-F) into ``out``. ``ego_built``: ``Le`` already holds the
    ego's library at ``(s_e, v_e)``."""
    n_traj = Le.S.shape[1]
    if not ego_built:
        build(s_e, v_e, P, disc, Le)
    build(s_o, v_o, P, disc, Lo)
    M_e, M_o, C = np.empty((n_traj, n_traj)), np.empty((n_traj, n_traj)), np.empty((n_traj, n_traj))
    solve_libs(Le, Lo, P[K.W_C], P[K.MIN_DIST_SQ], P[K.Q5] != 0.0, M_e, M_o, C,
               np.empty((4, n_traj)), out)


@njit(cache=True)
def predict_buffers(s_e: float, v_e: float, s_o: float, v_o: float, P: np.ndarray,
                    disc: np.ndarray, buf_e: np.ndarray, win_e: np.ndarray, buf_o: np.ndarray,
                    win_o: np.ndarray, out: np.ndarray) -> None:
    """:func:`predict_into` on libraries stored as :func:`persuasive.library.lib_buffers`
    (the cheap entry point from Python)."""
    predict_into(s_e, v_e, s_o, v_o, P, disc, as_lib(buf_e, win_e), as_lib(buf_o, win_o), out)


@dataclass(frozen=True)
class GameSolution:
    """One leader-follower solve (:func:`solve_game`)."""

    leader: int  #: the leader's chosen trajectory
    follower: int  #: the predicted follower trajectory, first of the optimal set
    follower_set: np.ndarray  #: every follower trajectory maximising Qf (ascending)
    q_leader: np.ndarray  #: Ql, one value per leader trajectory
    q_follower: np.ndarray  #: Qf, one value per follower trajectory


def solve_game(rewards_leader: np.ndarray, rewards_follower: np.ndarray,
               agg: str = "min") -> GameSolution:
    """Solve one leader-follower game from the two players' reward matrices.

    Parameters
    ----------
    rewards_leader : (n_lead, n_fol) array
        The leader's cumulative reward for (its trajectory, the follower's trajectory).
    rewards_follower : (n_fol, n_lead) array
        The follower's cumulative reward for (its trajectory, the leader's trajectory).
    agg : {"min", "max"}
        How the leader aggregates over the follower's tied optimal choices ("max" is quirk Q5).
    """
    if agg not in ("min", "max"):
        raise ValueError(f"agg = {agg!r} is out of range; allowed: min | max")
    M_l = np.ascontiguousarray(rewards_leader, dtype=np.float64)
    M_f = np.ascontiguousarray(rewards_follower, dtype=np.float64)
    if M_l.ndim != 2 or M_f.shape != M_l.shape[::-1] or 0 in M_l.shape:
        raise ValueError(
            f"reward shapes {M_l.shape} and {M_f.shape} must be (n_lead, n_fol) and (n_fol, n_lead)"
        )
    Ql, Qf = np.empty(M_l.shape[0]), np.empty(M_l.shape[1])
    lead, fol = leader_follower(M_l, M_f, agg == "max", Ql, Qf)
    return GameSolution(int(lead), int(fol), np.flatnonzero(Qf == Qf.max()), Ql, Qf)


@dataclass(frozen=True)
class Prediction:
    """A full prediction at a joint state seen by an ego player (spec section 4)."""

    ego: Library  #: the ego's candidate trajectories
    other: Library  #: the other's candidate trajectories
    ego_leader: int  #: the ego's trajectory when it leads
    ego_follower: int  #: the ego's trajectory when it follows
    other_leader: int  #: the other's trajectory when it leads
    other_follower: int  #: the other's trajectory when it follows
    rewards_ego: np.ndarray  #: ``M_e[ego trajectory, other's trajectory]``
    rewards_other: np.ndarray  #: ``M_o[other's trajectory, ego trajectory]``

    def ego_state(self, role: str, k: int) -> tuple[float, float]:
        """The ego's predicted ``(s, v)`` in ``role`` at sample ``k`` (0 = now)."""
        return _state_at(self.ego, self.ego_leader if role == "leader" else self.ego_follower, k)

    def other_state(self, role: str, k: int) -> tuple[float, float]:
        """The other's predicted ``(s, v)`` in ``role`` at sample ``k`` (0 = now)."""
        idx = self.other_leader if role == "leader" else self.other_follower
        return _state_at(self.other, idx, k)


def _state_at(lib: Library, idx: int, k: int) -> tuple[float, float]:
    """State of trajectory ``idx`` of ``lib`` at sample ``k`` (0 = the initial state)."""
    if k == 0:
        return lib.s0, lib.v0
    return float(lib.s[idx, k - 1]), float(lib.v[idx, k - 1])


def full_prediction(x_ego: tuple[float, float], x_other: tuple[float, float],
                    P: np.ndarray, disc: np.ndarray) -> Prediction:
    """Full prediction of the joint state ``(x_ego, x_other)``, each ``(s [m], v [m/s])``.

    ``P`` and ``disc`` from :func:`persuasive.pack` and :func:`persuasive.discounts`.
    """
    ego = trajectory_library(x_ego[0], x_ego[1], P)
    other = trajectory_library(x_other[0], x_other[1], P)
    M_e = reward_matrix_of(ego, other, disc, P)
    M_o = reward_matrix_of(other, ego, disc, P)
    idx = np.empty(4, np.int64)
    solve_both(M_e, M_o, P[K.Q5] != 0.0, idx, np.empty((4, M_e.shape[0])))
    return Prediction(ego, other, int(idx[0]), int(idx[1]), int(idx[2]), int(idx[3]), M_e, M_o)


__all__ = [
    "GameSolution",
    "Prediction",
    "full_prediction",
    "leader_follower",
    "predict_buffers",
    "predict_into",
    "solve_game",
    "build",
    "solve_libs",
]
