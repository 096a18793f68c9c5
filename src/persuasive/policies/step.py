"""The compiled side of the policy protocol: one step function that dispatches on the kind.

:func:`policy_step` is what the compiled closed loop (``persuasive.world.run_loop``) and the
Python wrapper (:class:`persuasive.policies.CompiledPolicy`) call for either vehicle. It is
handed the measured states of both vehicles, this step's uniforms of the agent, and, when the
kind needs them, the full prediction of the joint state from the human's view (``lib_h``,
``lib_r``, ``idx``, ``q_values``; ego = HV) and the look-ahead scratch of the MPC. An LFG on
the AV's side reads the same prediction with the roles of ego and other swapped (it is the
same pair of solves).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import packing as slot
from ..library import Lib, as_lib
from . import kinds as kd
from .adversarial import adversary_step, deceptive_step, random_step
from .idm import idm_step
from .levelk import levelk_step
from .lfg import PRM_ROLE, READY, ROLE, lfg_init, lfg_step
from .lfg_rule import first_role
from .planners import cv_step, mpc_init, mpc_step
from .scripted import aggressive_step, replay_step
from .yielding import yield_step

#: Permutation of a full prediction's indices (and Q-value rows) into the other's view.
SWAP = np.array([2, 3, 0, 1], np.int64)


@njit(cache=True)
def policy_init(kind: int, prm: np.ndarray, st: np.ndarray, prior_l: float) -> None:
    """A fresh state of a policy of ``kind`` in ``st`` (``STATE_SIZE`` slots, more for a
    planner with an online posterior over ``p_a``: :func:`persuasive.policies.state_size`)."""
    st[:] = 0.0
    if kind == kd.LFG or kind == kd.STUBBORN or kind == kd.NOISY or kind == kd.LFG_RULE:
        lfg_init(st, int(prm[PRM_ROLE]), prior_l)
    elif kind == kd.PERSUASIVE or kind == kd.PASSIVE:
        mpc_init(st, prm, prior_l)


@njit(cache=True)
def policy_role(kind: int, st: np.ndarray) -> int:
    """The current role of a role-holding policy (0 = L, 1 = F), else -1."""
    if kind == kd.LFG or kind == kd.STUBBORN or kind == kd.NOISY or kind == kd.LFG_RULE:
        return int(st[ROLE])
    return -1


@njit(cache=True)
def policy_step(kind: int, me: int, prm: np.ndarray, st: np.ndarray, k: int, s_av: float,
                v_av: float, s_hv: float, v_hv: float, draws: np.ndarray, human_role: int,
                lib_h: Lib, lib_r: Lib, idx: np.ndarray, q_values: np.ndarray,
                P_av: np.ndarray, P_hv: np.ndarray, disc: np.ndarray, dt: float,
                diag: np.ndarray, lib_h1a: Lib, lib_h1b: Lib, ahead: np.ndarray,
                log: np.ndarray, work: np.ndarray) -> float:
    """One decision of the policy of ``kind`` driving vehicle ``me`` (``AV`` or ``HV``) at step
    ``k``; returns its acceleration [m/s^2] and fills its state ``st`` and ``log`` row.

    ``(s_av, v_av)``, ``(s_hv, v_hv)``: the measured states. ``draws``: this step's uniforms
    of the agent (the role draw first). ``human_role``: the HV's current role when it has one
    (read by quirk Q3 only), else -1. ``work``: the kernels' counters (``packing.WORK_*``).
    """
    if kind == kd.LFG or kind == kd.STUBBORN or kind == kd.NOISY:
        r_choice = draws[1] if kind == kd.NOISY else 0.0
        if me == kd.HV:
            return lfg_step(st, prm, kind == kd.NOISY, s_av, v_av, draws[0], r_choice, lib_h,
                            lib_r, idx, q_values, P_hv[slot.W_S], P_hv[slot.W_V], log)
        return lfg_as_av(st, prm, kind == kd.NOISY, s_hv, v_hv, draws[0], r_choice, lib_h,
                         lib_r, idx, q_values, P_av, log)
    if kind == kd.PERSUASIVE or kind == kd.PASSIVE:
        return mpc_step(st, prm, kind == kd.PERSUASIVE, s_av, v_av, s_hv, v_hv, human_role,
                        lib_h, lib_r, idx, P_av, P_hv, disc, diag, log, lib_h1a, lib_h1b,
                        ahead, work)
    if kind == kd.CV:
        return cv_step(s_av, v_av, s_hv, v_hv, lib_r, P_av, P_hv, diag, log, work)
    if kind == kd.YIELD:
        return yield_step(st, s_hv, lib_r, P_av, P_hv, log)
    if kind == kd.IDM:
        if me == kd.HV:
            return idm_step(st, prm, s_hv, v_hv, s_av, v_av, dt, P_hv, P_av, log)
        return idm_step(st, prm, s_av, v_av, s_hv, v_hv, dt, P_av, P_hv, log)
    if kind == kd.AGGRESSIVE:
        return aggressive_step(P_hv if me == kd.HV else P_av)
    if kind == kd.REPLAY:
        return replay_step(prm, k)
    if kind == kd.ADVERSARY:
        return adversary_step(s_hv, v_hv, s_av, v_av, dt, P_hv, P_av, log)
    if kind == kd.DECEPTIVE:
        return deceptive_step(st, s_hv, v_hv, s_av, v_av, dt, P_hv, P_av, log)
    if kind == kd.RANDOM:
        return random_step(st, prm, draws, dt, P_hv, log)
    # last, so that no other kind's dispatch gets a test longer
    if kind == kd.LEVEL1 or kind == kd.LEVEL2:
        return levelk_step(prm, s_av, v_av, s_hv, v_hv, lib_h, lib_r, P_av, P_hv, log, work)
    if kind == kd.LFG_RULE:  # the rule's role, taken at the encounter's first decision
        if st[READY] == 0.0:
            st[ROLE] = first_role(P_av, s_av, v_av, s_hv, v_hv)
        return lfg_as_av(st, prm, False, s_hv, v_hv, 0.0, 0.0, lib_h, lib_r, idx, q_values,
                         P_av, log)
    raise ValueError("unknown policy kind")


@njit(cache=True)
def lfg_as_av(st: np.ndarray, prm: np.ndarray, noisy: bool, s_hv: float, v_hv: float,
              r: float, r_choice: float, lib_h: Lib, lib_r: Lib, idx: np.ndarray,
              q_values: np.ndarray, P_av: np.ndarray, log: np.ndarray) -> float:
    """An LFG player on the AV's side: :func:`persuasive.policies.lfg.lfg_step` on the
    human's full prediction with ego and other swapped (:data:`SWAP`)."""
    idx_av = np.empty(4, np.int64)
    q_av = np.empty_like(q_values)
    for j in range(4):
        idx_av[j] = idx[SWAP[j]]
        q_av[j, :] = q_values[SWAP[j], :]
    return lfg_step(st, prm, noisy, s_hv, v_hv, r, r_choice, lib_r, lib_h, idx_av, q_av,
                    P_av[slot.W_S], P_av[slot.W_V], log)


@njit(cache=True)
def policy_step_buffers(kind, me, prm, st, k, s_av, v_av, s_hv, v_hv, draws, human_role,
                        buf_h, win_h, buf_r, win_r, idx, q_values, P_av, P_hv, disc, dt, diag,
                        buf_h1a, win_h1a, buf_h1b, win_h1b, ahead, log, work) -> float:
    """:func:`policy_step` on libraries stored as :func:`persuasive.library.lib_buffers`
    (the cheap entry point from Python)."""
    return policy_step(kind, me, prm, st, k, s_av, v_av, s_hv, v_hv, draws, human_role,
                       as_lib(buf_h, win_h), as_lib(buf_r, win_r), idx, q_values, P_av, P_hv,
                       disc, dt, diag, as_lib(buf_h1a, win_h1a), as_lib(buf_h1b, win_h1b),
                       ahead, log, work)
