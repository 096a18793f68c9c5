"""The leader-follower game: one solve and the full prediction (docs/method.md §4).

Notation. The "ego" player solves the game at the joint state ``x = (s_e, v_e, s_o, v_o)``.
Both players' libraries are built (``persuasive.library``), each with its own vehicle's
parameter vector, and each player's reward matrix is ``R_own[own trajectory, other's
trajectory]`` (``persuasive.rewards``). In the notation of §4, ``R_e[i, j] = R_ego[j, i]`` and
``R_o[i, j] = R_other[i, j]`` (row ``i`` the other's trajectory, column ``j`` the ego's).

One leader-follower solve, with ``R_lead`` the leader's and ``R_fol`` the follower's matrix:

- the follower maximises its worst case: ``Qf[f] = min_l R_fol[f, l]``, ``F* = argmax-set Qf``
  (every tie, exact floating-point equality);
- the leader evaluates each of its trajectories against the follower's optimal set:
  ``Ql[l] = agg_{f in F*} R_lead[l, f]`` (``agg`` is ``min`` as in the paper, or ``max``, quirk
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

from . import packing as slot
from .library import Lib, Library, as_lib, fill_library, trajectory_library
from .rewards import reward_matrix, reward_matrix_of, reward_terms

# Indices into the 4-vector returned by a full prediction.
EGO_LEADER, EGO_FOLLOWER, OTHER_LEADER, OTHER_FOLLOWER = 0, 1, 2, 3
# Rows of the Q-values of a full prediction ``(4, n_traj)``: the leader's and the follower's
# values of "ego leads", then of "ego follows".
Q_EGO_LEADS_LEADER, Q_EGO_LEADS_FOLLOWER, Q_EGO_FOLLOWS_LEADER, Q_EGO_FOLLOWS_FOLLOWER = 0, 1, 2, 3


@njit(cache=True, _nrt=False)
def leader_follower(R_lead: np.ndarray, R_fol: np.ndarray, agg_max: bool,
                    Ql: np.ndarray, Qf: np.ndarray) -> tuple[int, int]:
    """Solve one leader-follower game; return ``(leader pick, follower pick)``.

    ``R_lead``: ``(n_lead, n_fol)``, ``R_fol``: ``(n_fol, n_lead)``. ``Ql`` and ``Qf`` receive
    the leader's and follower's Q-values. Ties go to the lowest index.
    """
    n_lead, n_fol = R_lead.shape
    best_f = -np.inf
    for f in range(n_fol):
        q = R_fol[f, 0]
        for l in range(1, n_lead):
            if R_fol[f, l] < q:
                q = R_fol[f, l]
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
        q = R_lead[l, first_f]
        for f in range(first_f + 1, n_fol):
            if Qf[f] == best_f:
                x = R_lead[l, f]
                if (x > q) if agg_max else (x < q):
                    q = x
        Ql[l] = q
        if q > best_l or l == 0:
            best_l, pick_l = q, l
    return pick_l, first_f


@njit(cache=True, _nrt=False)
def solve_both(R_ego: np.ndarray, R_other: np.ndarray, agg_max: bool, out: np.ndarray,
               q_values: np.ndarray) -> None:
    """Both role assignments: ``out = (ego-L, ego-F, other-L, other-F)`` trajectory indices.

    ``q_values`` ``(4, n)``: rows Ql and Qf of "ego leads", then Ql and Qf of "ego follows"
    (``Q_EGO_LEADS_LEADER`` ...).
    """
    out[EGO_LEADER], out[OTHER_FOLLOWER] = leader_follower(R_ego, R_other, agg_max,
                                                           q_values[0], q_values[1])
    out[OTHER_LEADER], out[EGO_FOLLOWER] = leader_follower(R_other, R_ego, agg_max,
                                                           q_values[2], q_values[3])


@njit(cache=True)
def build(s0: float, v0: float, P: np.ndarray, disc: np.ndarray, lib: Lib) -> None:
    """Fill ``lib`` with the library of the vehicle of ``P`` at ``(s0, v0)`` and its reward
    parts."""
    fill_library(s0, v0, P, lib.S, lib.V, lib.A)
    reward_terms(lib.S, lib.V, lib.A, s0, disc, P, lib.base, lib.coll, lib.pos, lib.win)


@njit(cache=True)
def solve_libs(lib_ego: Lib, lib_other: Lib, P: np.ndarray, R_ego: np.ndarray,
               R_other: np.ndarray, C: np.ndarray, q_values: np.ndarray, out: np.ndarray,
               work: np.ndarray) -> None:
    """Both reward matrices of two built libraries (ego, other), then both solves into ``out``.

    ``R_ego, R_other, C``: ``(n_traj, n_traj)`` scratch; ``q_values``: ``(4, n_traj)`` (see
    :func:`solve_both`). ``P``: either vehicle's parameters (only shared slots are read).
    ``work``: the counters of ``persuasive.packing`` (``WORK_*``).
    """
    e, o = lib_ego, lib_other
    w_c, thr = P[slot.W_C], P[slot.MIN_DIST_SQ]
    along_paths = P[slot.CONFLICT] == slot.CONFLICT_ALONG_PATHS
    tests = reward_matrix(e.base, e.coll, e.pos, e.win, o.pos, o.win, w_c, thr, along_paths,
                          C, R_ego)
    tests += reward_matrix(o.base, o.coll, o.pos, o.win, e.pos, e.win, w_c, thr, along_paths,
                           C, R_other)
    work[slot.WORK_PAIRS_GAME] += tests
    solve_both(R_ego, R_other, P[slot.QUIRK_LEADER_AGG_MAX] != 0.0, out, q_values)


@njit(cache=True)
def predict_into(s_e: float, v_e: float, s_o: float, v_o: float, P_ego: np.ndarray,
                 P_other: np.ndarray, disc: np.ndarray, lib_ego: Lib, lib_other: Lib,
                 out: np.ndarray, q_values: np.ndarray, work: np.ndarray,
                 ego_built: bool = False) -> None:
    """Full prediction at the joint state: both libraries built into ``lib_ego, lib_other``,
    indices (ego-L, ego-F, other-L, other-F) into ``out``, Q-values into ``q_values``
    ``(4, n_traj)``. ``ego_built``: ``lib_ego`` already holds the ego's library at
    ``(s_e, v_e)``."""
    n_traj = lib_ego.S.shape[1]
    if not ego_built:
        build(s_e, v_e, P_ego, disc, lib_ego)
        work[slot.WORK_LIBRARIES] += 1
    else:
        work[slot.WORK_LIBRARIES_REUSED] += 1
    build(s_o, v_o, P_other, disc, lib_other)
    work[slot.WORK_LIBRARIES] += 1
    solve_libs(lib_ego, lib_other, P_ego, np.empty((n_traj, n_traj)),
               np.empty((n_traj, n_traj)), np.empty((n_traj, n_traj)), q_values, out, work)


@njit(cache=True)
def predict_buffers(s_e: float, v_e: float, s_o: float, v_o: float, P_ego: np.ndarray,
                    P_other: np.ndarray, disc: np.ndarray, buf_e: np.ndarray,
                    win_e: np.ndarray, buf_o: np.ndarray, win_o: np.ndarray, out: np.ndarray,
                    q_values: np.ndarray, work: np.ndarray) -> None:
    """:func:`predict_into` on libraries stored as :func:`persuasive.library.lib_buffers`
    (the cheap entry point from Python)."""
    predict_into(s_e, v_e, s_o, v_o, P_ego, P_other, disc, as_lib(buf_e, win_e),
                 as_lib(buf_o, win_o), out, q_values, work)


@njit(cache=True)
def build_buffers(s0: float, v0: float, P: np.ndarray, disc: np.ndarray, buf: np.ndarray,
                  win: np.ndarray) -> None:
    """:func:`build` into a library stored as :func:`persuasive.library.lib_buffers`."""
    build(s0, v0, P, disc, as_lib(buf, win))


@njit(cache=True)
def shifted_into(S: np.ndarray, V: np.ndarray, A: np.ndarray, shift: float, s0: float,
                 P: np.ndarray, disc: np.ndarray, buf: np.ndarray, win: np.ndarray) -> None:
    """Another frame's trajectories ``S + shift``, ``V``, ``A`` (sample-major, from a state
    at ``s0 - shift`` there, ``s0`` here) with their reward parts, into a library stored as
    :func:`persuasive.library.lib_buffers` (``buf`` must not hold ``S``, ``V`` or ``A``)."""
    lib = as_lib(buf, win)
    n, n_traj = S.shape
    for k in range(n):
        for m in range(n_traj):
            lib.S[k, m] = S[k, m] + shift
            lib.V[k, m] = V[k, m]
            lib.A[k, m] = A[k, m]
    reward_terms(lib.S, lib.V, lib.A, s0, disc, P, lib.base, lib.coll, lib.pos, lib.win)


@njit(cache=True)
def solve_buffers(buf_e: np.ndarray, win_e: np.ndarray, buf_o: np.ndarray, win_o: np.ndarray,
                  P: np.ndarray, out: np.ndarray, q_values: np.ndarray,
                  work: np.ndarray) -> None:
    """:func:`solve_libs` of two built libraries stored as buffers (ego, other)."""
    n_traj = win_e.shape[0]
    solve_libs(as_lib(buf_e, win_e), as_lib(buf_o, win_o), P, np.empty((n_traj, n_traj)),
               np.empty((n_traj, n_traj)), np.empty((n_traj, n_traj)), q_values, out, work)


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
    R_l = np.ascontiguousarray(rewards_leader, dtype=np.float64)
    R_f = np.ascontiguousarray(rewards_follower, dtype=np.float64)
    if R_l.ndim != 2 or R_f.shape != R_l.shape[::-1] or 0 in R_l.shape:
        raise ValueError(
            f"reward shapes {R_l.shape} and {R_f.shape} must be (n_lead, n_fol) and (n_fol, n_lead)"
        )
    Ql, Qf = np.empty(R_l.shape[0]), np.empty(R_l.shape[1])
    lead, fol = leader_follower(R_l, R_f, agg == "max", Ql, Qf)
    return GameSolution(int(lead), int(fol), np.flatnonzero(Qf == Qf.max()), Ql, Qf)


@dataclass(frozen=True)
class Prediction:
    """A full prediction at a joint state seen by an ego player (docs/method.md §4.3)."""

    ego: Library  #: the ego's candidate trajectories
    other: Library  #: the other's candidate trajectories
    ego_leader: int  #: the ego's trajectory when it leads
    ego_follower: int  #: the ego's trajectory when it follows
    other_leader: int  #: the other's trajectory when it leads
    other_follower: int  #: the other's trajectory when it follows
    rewards_ego: np.ndarray  #: ``R_ego[ego trajectory, other's trajectory]``
    rewards_other: np.ndarray  #: ``R_other[other's trajectory, ego trajectory]``

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
                    P_ego: np.ndarray, P_other: np.ndarray, disc: np.ndarray) -> Prediction:
    """Full prediction of the joint state ``(x_ego, x_other)``, each ``(s [m], v [m/s])``.

    ``P_ego``, ``P_other``: the two vehicles' parameter vectors; ``disc`` the discounts
    (:func:`persuasive.packing.pack`, :func:`persuasive.packing.discounts`).
    """
    ego = trajectory_library(x_ego[0], x_ego[1], P_ego)
    other = trajectory_library(x_other[0], x_other[1], P_other)
    R_ego = reward_matrix_of(ego, other, disc, P_ego, P_other)
    R_other = reward_matrix_of(other, ego, disc, P_other, P_ego)
    idx = np.empty(4, np.int64)
    solve_both(R_ego, R_other, P_ego[slot.QUIRK_LEADER_AGG_MAX] != 0.0, idx,
               np.empty((4, R_ego.shape[0])))
    return Prediction(ego, other, int(idx[0]), int(idx[1]), int(idx[2]), int(idx[3]), R_ego,
                      R_other)


__all__ = [
    "GameSolution",
    "Prediction",
    "full_prediction",
    "leader_follower",
    "predict_buffers",
    "predict_into",
    "solve_game",
    "build",
    "build_buffers",
    "shifted_into",
    "solve_buffers",
    "solve_libs",
]
