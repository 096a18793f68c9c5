"""The level-k AV (``level1``, ``level2``, docs/method.md §11): iterated best responses.

Level-k reasoning (Stahl & Wilson, Games Econ. Behav. 1995; for driving, Li et al., "Game
theoretic modeling of driver and vehicle interactions", IEEE TCST 2018) on the game's own
players: each vehicle chooses among its trajectory library at its measured state, scored with
the reward matrices of the leader-follower game (docs/method.md §3-4, ``persuasive.game``):
``R_av[i, j]`` the AV's and ``R_hv[j, i]`` the human's cumulative reward for AV trajectory
``i`` and human trajectory ``j``, progress, effort and the collision term
``w_c [d < min_dist] (1 + v)`` included, exactly as the game computes them
(``persuasive.rewards.reward_matrix`` on the libraries the loop built for it, each vehicle's
with its own parameters; the collision term discounted as in the game, whatever quirk Q4 says
of the MPC's branches).

- **Level 0** is non-strategic: it keeps its current speed, i.e. trajectory 0 of its library
  (the OVM regulated to the target speed ``v0``, ``persuasive.library``: zero acceleration up
  to rounding). Not "the candidate nearest to zero acceleration": that one depends on how the
  mesh falls, trajectory 0 is the constant-speed one by construction, and it is what the
  ``cv`` planner's human does (there integrated at exactly zero acceleration; here the library
  trajectory, since the rewards are over library pairs).
- **Level k >= 1** plays the best response to the other's level-(k-1) trajectory: the highest
  own reward in that column, the lowest index on ties (exact floating-point equality, the
  game's rule).

So ``level1`` is the AV's best response to the human holding its speed, and ``level2`` its best
response to the human's level-1 trajectory, itself the human's best response to the AV holding
its speed. The AV applies the first acceleration of its choice and decides again at the next
step (receding horizon); it keeps no state, no belief and no prediction between steps.

**Two kinds, one kernel.** The level is a kind (``av.kind = "level1"`` or ``"level2"``) rather
than a parameter of one ``levelk`` kind so that ``compare --av persuasive,level1,level2`` puts
both levels side by side on its one planner axis, ``simulate --av level2`` reads as it runs, and
an unknown level is refused as any unknown kind (``av.kind = 'level3' is out of range; allowed:
...``); both kinds run :func:`levelk_step`, which reads the level from its parameter vector
(``PRM_LEVEL``, set from the kind by ``persuasive.policies.policy_params``) and takes any
``k >= 1``.

**The shield.** As the ``cv`` planner (``persuasive.policies.planners``, docs/method.md §12.3):
with a shield on and ``mpc.shield_aware``, the AV's own best response is taken among the
candidates whose first acceleration the shield admits (``shield_allowed``; all of them when
it admits none, and the shield then overrides), and the loop's shield filters the proposal
after the policy, as for every AV kind. The levels the AV attributes to the human (and, for
``k >= 3``, to itself inside the human's reasoning) are the plain ones: the human knows nothing
of the AV's shield. The shield's clearance ``av.shield_margin_m`` lives in the shield only; the
rewards keep the game's safety distance ``min_dist``, as every planner's do.

**Its inputs.** The kind reads the game cache's two libraries (its ``KindSpec`` sets
``needs_game``: the loops, ``Planner`` and the Python side build both libraries with their
reward parts, and solve the human's game, which this kind does not read); it computes the two
reward matrices itself, with the game's kernel, every step.

Log columns (``persuasive.policies.kinds.LEVELK_LOG``): the chosen trajectory, the human's
level-(k-1) trajectory it answers (``predicted_hv_trajectory``), the AV's reward of that pair
(``expected_reward``) and how many candidates the shield allowed (``n_allowed``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import packing as slot
from ..library import Lib
from ..rewards import reward_matrix
from .planners import shield_allowed

#: Slot of its parameter vector: the level k >= 1.
PRM_LEVEL = 0
#: Log columns (``persuasive.policies.kinds.LEVELK_LOG``).
COL_TRAJ, COL_HV_TRAJ, COL_REWARD, COL_N_ALLOWED = range(4)
#: The level-0 trajectory of every library: keep the current speed (``persuasive.library``).
LEVEL0 = 0


@njit(cache=True, _nrt=False)
def best_response(R: np.ndarray, other: int, allowed: np.ndarray) -> int:
    """The row of ``R`` (own trajectory) with the highest reward against the other's
    trajectory ``other`` (a column), among ``allowed`` rows; lowest index on ties; -1 when
    none is allowed."""
    best = -1
    for i in range(R.shape[0]):
        if allowed[i] and (best < 0 or R[i, other] > R[best, other]):
            best = i
    return best


@njit(cache=True)
def level_choice(R_me: np.ndarray, R_you: np.ndarray, k: int) -> int:
    """The level-``k`` trajectory of the player whose rewards are ``R_me[own, other's]``
    against the player of ``R_you[own, other's]``: level 0 is trajectory ``LEVEL0``; level
    ``m >= 1`` the best response (all candidates, lowest index on ties) to the other's
    level ``m - 1``. The chain starts at the level-0 player ``k`` steps down (``me`` when
    ``k`` is even) and alternates."""
    all_me = np.ones(R_me.shape[0], np.bool_)
    all_you = np.ones(R_you.shape[0], np.bool_)
    c = LEVEL0
    mine = k % 2 == 0  # whether the current trajectory c is one of mine
    for _ in range(k):
        c = best_response(R_you, c, all_you) if mine else best_response(R_me, c, all_me)
        mine = not mine
    return c


@njit(cache=True)
def levelk_matrices(lib_h: Lib, lib_r: Lib, P_av: np.ndarray,
                    work: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The game's reward matrices of the two built libraries: ``R_av`` ``(n_av, n_hv)``
    and ``R_hv`` ``(n_hv, n_av)`` (``persuasive.game.solve_libs`` computes the same, with
    the same kernel; ``P_av``: only shared slots are read)."""
    n_r, n_h = lib_r.win.shape[0], lib_h.win.shape[0]
    w_c, thr = P_av[slot.W_C], P_av[slot.MIN_DIST_SQ]
    along_paths = P_av[slot.CONFLICT] == slot.CONFLICT_ALONG_PATHS
    R_av, R_hv = np.empty((n_r, n_h)), np.empty((n_h, n_r))
    tests = reward_matrix(lib_r.base, lib_r.coll, lib_r.pos, lib_r.win, lib_h.pos, lib_h.win,
                          w_c, thr, along_paths, np.empty((n_r, n_h)), R_av)
    tests += reward_matrix(lib_h.base, lib_h.coll, lib_h.pos, lib_h.win, lib_r.pos, lib_r.win,
                           w_c, thr, along_paths, np.empty((n_h, n_r)), R_hv)
    work[slot.WORK_PAIRS_GAME] += tests
    return R_av, R_hv


@njit(cache=True)
def levelk_step(prm: np.ndarray, s_R: float, v_R: float, s_H: float, v_H: float, lib_h: Lib,
                lib_r: Lib, P_av: np.ndarray, P_hv: np.ndarray, log: np.ndarray,
                work: np.ndarray) -> float:
    """One step of the level-k AV (module docstring); returns its acceleration [m/s^2].

    ``lib_h``, ``lib_r``: the human's and the AV's libraries at the measured states, with
    their reward parts (the game cache's, ``persuasive.game.build``).
    """
    k = int(prm[PRM_LEVEL])
    R_av, R_hv = levelk_matrices(lib_h, lib_r, P_av, work)
    h = level_choice(R_hv, R_av, k - 1)  # the human's level-(k-1) trajectory
    allowed = np.empty(R_av.shape[0], np.bool_)
    n_allowed = shield_allowed(s_R, v_R, s_H, v_H, lib_r, P_av, P_hv, False, allowed)
    c = best_response(R_av, h, allowed)
    if c < 0:  # the shield admits none: the plain best response, which the shield overrides
        allowed[:] = True
        c = best_response(R_av, h, allowed)
    log[COL_TRAJ] = c
    log[COL_HV_TRAJ] = h
    log[COL_REWARD] = R_av[c, h]
    log[COL_N_ALLOWED] = n_allowed
    return lib_r.A[0, c]
