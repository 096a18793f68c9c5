"""The straightforward computation: docs/method.md §1-7 in plain NumPy.

This is the reference path the compiled kernels are checked against, bit for bit. It computes
everything the direct way: every reward pair is summed over every sample, every MPC re-solve is
solved on its own (22 per decision), every distance goes through ``sqrt``, and the closed loop
(:func:`simulate`) shares nothing between agents; the distance of a euclidean conflict is
computed from every sample's position on its path. It is slow (tens of milliseconds per MPC
decision) and meant for tests, teaching and the benchmark's "before". It covers the paper's
agents (the LFG human, possibly stubborn; the LFG or persuasive/passive MPC AV) in every
scenario.

Arrays here are trajectory-major, ``(n_traj, n_samples)``, the natural reading of docs/method.md.
"""

from __future__ import annotations

import numpy as np

from . import packing as K
from .geometry import path_point
from .roles import bayes_update as _bayes_kernel

__all__ = [
    "bayes_update",
    "full_prediction",
    "library",
    "mpc",
    "plausible_leader",
    "reward_matrix",
    "saturated_step",
    "simulate",
    "solve",
    "transition_matrix",
]


def saturated_step(s, v, a, dt, v_min, v_max):
    """Section 1, vectorised: ``(s', v')`` for arrays ``s, v, a`` (same shape)."""
    s, v, a = np.asarray(s, float), np.asarray(v, float), np.asarray(a, float)
    v_new = v + a * dt
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t1_hi = (v_max - v) / a
        ds_hi = (v_max * v_max - v * v) / (2.0 * a) + v_max * (dt - t1_hi)
        t1_lo = (v_min - v) / a
        ds_lo = (v_min * v_min - v * v) / (2.0 * a) + v_min * (dt - t1_lo)
    ds = v * dt + a * dt * dt / 2.0
    hi, lo = v_new > v_max, v_new < v_min
    ds = np.where(hi, ds_hi, np.where(lo, ds_lo, ds))
    v_out = np.where(hi, v_max, np.where(lo, v_min, v_new))
    return s + ds, v_out


def library(s0: float, v0: float, P: np.ndarray):
    """Section 2: ``(S, V, A)``, each ``(n_traj, n)``, and whether the stop is offered."""
    n, n_mesh = int(P[K.N_SAMPLES]), int(P[K.N_MESH])
    v_min, v_max, u_min, u_max = P[K.V_MIN], P[K.V_MAX], P[K.U_MIN], P[K.U_MAX]
    length, h_st = P[K.LENGTH], P[K.H_ST]
    T = P[K.HORIZON]
    v_hi = min(v_max, v0 + u_max * T)
    v_lo = max(v_min, v0 + u_min * T)
    if P[K.QUIRK_TIME_LIKE_STOP_TEST]:
        stop = v_lo <= 0.0 and s0 + v0 / abs(u_min) < P[K.YIELD_S]
    else:
        stop = v_lo <= 0.0 and s0 + v0 * v0 / (2.0 * abs(u_min)) < P[K.YIELD_S]
    v_t = np.concatenate([[v0], np.linspace(v_lo, v_hi, n_mesh)])
    gap = v_t / P[K.KAPPA] + h_st + length
    standing = np.zeros(n_mesh + 1, bool)
    standing[1] = stop
    stop_leader = P[K.YIELD_S] + h_st + length
    s = np.full(n_mesh + 1, float(s0))
    v = np.full(n_mesh + 1, float(v0))
    S, V, A = (np.empty((n_mesh + 1, n)) for _ in range(3))
    for k in range(n):
        h = np.where(standing, stop_leader - s - length, (s + gap) - s - length)
        h_c = np.clip(h, h_st, P[K.H_GO])
        v1_c = np.clip(v_t, 0.0, v_max)
        a = P[K.ALPHA] * (P[K.KAPPA] * (h_c - h_st) - v) + P[K.BETA] * (v1_c - v)
        a = np.clip(a, u_min, u_max)
        s, v = saturated_step(s, v, a, P[K.SAMPLE_DT], v_min, v_max)
        S[:, k], V[:, k], A[:, k] = s, v, a
    return S, V, A, stop


def positions(S, P):
    """Positions ``(X, Y)`` of path positions ``S`` (any shape) on the path of ``P``, one at a
    time with the scalar path function."""
    S = np.asarray(S, float)
    X, Y = np.empty_like(S), np.empty_like(S)
    for i, s in np.ndenumerate(S):
        X[i], Y[i] = path_point.py_func(P, K.PATH_B1, float(s))
    return X, Y


def distances(S_own, S_other, P_own, P_other):
    """Distances ``d[m, b, k]`` between own sample ``(m, k)`` and other sample ``(b, k)``
    (arrays ``(n_own, n)`` and ``(n_other, n)``), as the scenario's conflict defines them."""
    if P_own[K.CONFLICT] == K.CONFLICT_ALONG_PATHS:
        return np.sqrt(S_own[:, None, :] ** 2 + S_other[None, :, :] ** 2)
    Xo, Yo = positions(S_own, P_own)
    Xt, Yt = positions(S_other, P_other)
    return np.sqrt((Xo[:, None, :] - Xt[None, :, :]) ** 2 + (Yo[:, None, :] - Yt[None, :, :]) ** 2)


def reward_matrix(S, V, A, s0, S_other, disc, P, P_other):
    """§3: ``R[m, b] = B[m] - w_c C[m, b]`` of own trajectory ``m`` against ``b``.

    Both sums run over every sample and every pair, in sample order.
    """
    d_all = distances(S, S_other, P, P_other)
    B = np.zeros(S.shape[0])
    C = np.zeros((S.shape[0], S_other.shape[0]))
    for k in range(S.shape[1]):
        B = B + disc[k] * ((S[:, k] - s0) - P[K.W_U] * np.abs(A[:, k]))
        C = C + (d_all[:, :, k] < P[K.MIN_DIST]) * (disc[k] * (1.0 + V[:, None, k]))
    return B[:, None] - P[K.W_C] * C


def solve(M_lead, M_fol, agg_max: bool):
    """Section 4, one solve: ``(leader pick, follower pick)``."""
    Qf = M_fol.min(axis=1)
    F = np.flatnonzero(Qf == Qf.max())
    sub = M_lead[:, F]
    Ql = sub.max(axis=1) if agg_max else sub.min(axis=1)
    return int(np.argmax(Ql)), int(F[0])


def full_prediction(x_e, x_o, P_e, P_o, disc):
    """§4: both libraries and ``(ego-L, ego-F, other-L, other-F)``."""
    Se, Ve, Ae, _ = library(x_e[0], x_e[1], P_e)
    So, Vo, Ao, _ = library(x_o[0], x_o[1], P_o)
    R_e = reward_matrix(Se, Ve, Ae, x_e[0], So, disc, P_e, P_o)
    R_o = reward_matrix(So, Vo, Ao, x_o[0], Se, disc, P_o, P_e)
    agg_max = bool(P_e[K.QUIRK_LEADER_AGG_MAX])
    ego_l, other_f = solve(R_e, R_o, agg_max)
    other_l, ego_f = solve(R_o, R_e, agg_max)
    return (Se, Ve, Ae), (So, Vo, Ao), (ego_l, ego_f, other_l, other_f)


def bayes_update(b_l, b_f, e_l, e_f, w_s, w_v):
    """Section 5 step 5 with residual 2-vectors ``e_l, e_f``; scalar libm arithmetic."""
    return _bayes_kernel.py_func(b_l, b_f, e_l[0], e_l[1], e_f[0], e_f[1], w_s, w_v)


def plausible_leader(b_l, b_f, own_leader: bool) -> float:
    if b_l > b_f:
        return 0.0
    if b_l < b_f:
        return 1.0
    return 1.0 if own_leader else 0.0


def transition_matrix(pl: float, p_a: float) -> np.ndarray:
    pf = 1.0 - pl
    to_leader = np.array([[1.0, p_a], [0.0, 1.0 - p_a]])
    to_follower = np.array([[1.0 - p_a, 0.0], [p_a, 1.0]])
    return pl * to_leader + pf * to_follower


def mpc(x_R, x_H, q, tie_leader: bool, p_a_hat: float, P_av, P_hv, disc, persuade=True,
        candidates=None, branches=None):
    """§6, one decision, with every re-solve done separately.

    ``persuade=False``: the passive planner (``Pi_hat`` the identity). Returns ``(chosen,
    feasible, diag)`` with ``diag`` as in :mod:`persuasive.mpc`. ``candidates``: trajectories
    ``(S, V, A)`` ``(n_traj, n)`` evaluated in place of the AV's library (which still makes the
    human's full prediction; ``persuasive.many.joint``). ``branches``: a list that receives,
    per candidate, its branch probabilities ``(4,)`` and per-sample safety ``(4, n)``.
    """
    (SH, VH, AH), (SR, VR, AR), (hv_l, hv_f, av_l, av_f) = full_prediction(x_H, x_R, P_hv, P_av,
                                                                        disc)
    if candidates is not None:
        SR, VR, AR = (np.asarray(x, float) for x in candidates)
    n_traj, n = SR.shape
    q1 = bool(P_av[K.QUIRK_BRANCH_OFFSET])
    q2 = bool(P_av[K.QUIRK_BELIEF_OFFSET])
    q4 = bool(P_av[K.QUIRK_UNDISCOUNTED_COLLISION])
    w_c, w_u, min_dist = P_av[K.W_C], P_av[K.W_U], P_av[K.MIN_DIST]
    diag = np.empty((n_traj, 10))
    prior = P_av[K.PRIOR_L]
    for k in range(n_traj):
        res = []
        for x in (av_l, av_f):
            if q2:
                cand = np.array([[SR[k, 0], VR[k, 0]], [SR[k, 1], VR[k, 1]]])
                expd = np.array([[x_R[0], x_R[1]], [SR[x, 0], VR[x, 0]]])
            else:
                cand = np.array([[x_R[0], x_R[1]], [SR[k, 0], VR[k, 0]]])
                expd = np.array([[x_R[0], x_R[1]], [SR[x, 0], VR[x, 0]]])
            err = np.abs(cand - expd)
            res.append(((err[0, 0] + err[1, 0]) / 2.0, (err[0, 1] + err[1, 1]) / 2.0))
        if persuade:
            b_l, b_f = bayes_update(prior, 1.0 - prior, res[0], res[1], P_av[K.W_S], P_av[K.W_V])
            pl = plausible_leader(b_l, b_f, tie_leader)
            Pi = transition_matrix(pl, p_a_hat)
        else:
            b_l = b_f = pl = np.nan
            Pi = np.eye(2)
        probs = [Pi[j, i] * q[i] for i in range(2) for j in range(2)]
        start = 1 if q1 else 0
        rewards, safe_rows = [], []
        for i, hv_i in enumerate((hv_l, hv_f)):
            x_i = (SH[hv_i, 0], VH[hv_i, 0])
            (LS, _, _), _, sol = full_prediction(x_i, (SR[k, start], VR[k, start]), P_hv, P_av,
                                                 disc)
            for j in range(2):
                path = LS[sol[j]]
                if q1:
                    hv_s = np.concatenate([[x_H[0], x_i[0]], path[: n - 2]])
                else:
                    hv_s = np.concatenate([[x_i[0]], path[: n - 1]])
                d = distances(SR[k:k + 1], hv_s[None, :], P_av, P_hv)[0, 0]
                safe = d >= min_dist
                B, C = 0.0, 0.0
                for m in range(n):
                    B += disc[m] * ((SR[k, m] - x_R[0]) - w_u * abs(AR[k, m]))
                    weight = (1.0 + VR[k, m]) if q4 else disc[m] * (1.0 + VR[k, m])
                    C += (not safe[m]) * weight
                R = B - w_c * C
                rewards.append(R)
                safe_rows.append(safe.astype(float))
        expected = 0.0
        for p, R in zip(probs, rewards):
            expected += p * R
        p_safe = np.zeros(n)
        for p, row in zip(probs, safe_rows):
            p_safe = p_safe + p * row
        if branches is not None:
            branches.append((np.array(probs), np.array(safe_rows)))
        diag[k] = [expected, p_safe.min(), p_safe.max(), b_l, b_f, pl, *probs]
    threshold = 1.0 - P_av[K.EPSILON]
    feasible = diag[:, 1] > threshold
    if feasible.any():
        cand = np.flatnonzero(feasible)
        return int(cand[np.argmax(diag[cand, 0])]), True, diag
    return int(np.argmax(diag[:, 0])), False, diag


# -- the closed loop -----------------------------------------------------------------------------


def simulate(config, seed: int) -> dict[str, np.ndarray]:
    """§7, one run, with the functions above and nothing shared between agents.

    The human is an LFG player (``lfg`` or ``stubborn``); the AV an LFG player or the
    persuasive or passive MPC. Returns ``states`` ``(n_steps + 1, 4)`` and per-step
    ``hv_role``, ``av_role`` (LFG AV), ``av_trajectory`` and ``av_feasible`` (MPC),
    ``hv_belief`` and ``av_belief`` ``(n, 2)``. The random streams, the scenario and the
    initial state come from the same definitions as the fast path
    (:func:`persuasive.record.setup`).
    """
    from .record import setup
    from .world import predicted_summary

    if config.hv.kind not in ("lfg", "stubborn") or config.av.kind not in (
            "lfg", "persuasive", "passive"):
        raise ValueError("the reference loop covers the LFG human and the LFG or MPC AV")
    # foresight's pick (if in force) is made before the first step, from the compiled
    # predictions: the loop below is the reference for the steps, not for that choice
    s = setup(config, seed, predict=predicted_summary)
    st = s.streams
    P_av, P_hv, disc = s.P_av, s.P_hv, s.disc
    meas, accel_noise, noisy = st.meas_noise, st.accel_noise, st.noisy
    x_av, x_hv = (float(s.x0[0]), float(s.x0[1])), (float(s.x0[2]), float(s.x0[3]))
    sim, roles = config.simulation, config.roles
    prior = P_av[K.PRIOR_L]
    q = config.effective_quirks
    p_a_hv = 0.0 if config.hv.kind == "stubborn" else roles.p_a
    p_a_hat = config.p_a_hat

    def lfg_agent(role, p_a, P_self, P_other):
        return {"role": role, "initial": role, "b": (prior, 1.0 - prior), "pred": None,
                "p_a": p_a, "P": (P_self, P_other)}

    def lfg_act(agent, x_self, x_other, r):
        if agent["pred"] is None:
            agent["pred"] = (x_other, x_other)
        b_l, b_f = agent["b"]
        pl = plausible_leader(b_l, b_f, agent["role"] == 0)
        Pi = transition_matrix(pl, agent["p_a"])
        (Se, Ve, Ae), (So, Vo, _), (e_l, e_f, o_l, o_f) = full_prediction(
            x_self, x_other, *agent["P"], disc)
        accel = Ae[e_l if agent["role"] == 0 else e_f, 0]
        if roles.adapt_role:
            if agent["role"] == 0 and r > Pi[0, 0]:
                agent["role"] = 1
            elif agent["role"] == 1 and r > Pi[1, 1]:
                agent["role"] = 0
        (ls, lv), (fs, fv) = agent["pred"]
        agent["b"] = bayes_update(b_l, b_f, (abs(x_other[0] - ls), abs(x_other[1] - lv)),
                                  (abs(x_other[0] - fs), abs(x_other[1] - fv)), P_av[K.W_S],
                                  P_av[K.W_V])
        agent["pred"] = ((So[o_l, 0], Vo[o_l, 0]), (So[o_f, 0], Vo[o_f, 0]))
        return accel

    hv = lfg_agent(0 if config.hv.role == "leader" else 1, p_a_hv, P_hv, P_av)
    if config.av.kind == "lfg":
        av_role = (1 - hv["role"]) if config.av.role is None else \
            (0 if config.av.role == "leader" else 1)
        av = lfg_agent(av_role, roles.p_a, P_av, P_hv)
    else:
        av = {"q": (prior, 1.0 - prior), "pred": None}
    n = sim.n_steps
    states = np.empty((n + 1, 4))
    states[0] = (*x_av, *x_hv)
    out = {k: [] for k in ("hv_role", "av_role", "av_trajectory", "av_feasible", "hv_belief",
                           "av_belief")}
    for k in range(n):
        m_av, m_hv = x_av, x_hv
        if noisy:
            m_av = (x_av[0] + meas[k, 0], min(max(x_av[1] + meas[k, 1], P_av[K.V_MIN]),
                                              P_av[K.V_MAX]))
            m_hv = (x_hv[0] + meas[k, 2], min(max(x_hv[1] + meas[k, 3], P_hv[K.V_MIN]),
                                              P_hv[K.V_MAX]))
        out["hv_role"].append(hv["role"])
        a_hv = lfg_act(hv, m_hv, m_av, st.draws_hv[k, 0])
        out["hv_belief"].append(hv["b"])
        if config.av.kind == "lfg":
            out["av_role"].append(av["role"])
            a_av = lfg_act(av, m_av, m_hv, st.draws_av[k, 0])
            out["av_belief"].append(av["b"])
        else:
            if av["pred"] is None:
                av["pred"] = (m_hv, m_hv)
            q_l, q_f = av["q"]
            if q.q3_tie_break_leak:
                tie = hv["role"] if p_a_hat == roles.p_a else hv["initial"]
            else:
                tie = 0 if q_l >= q_f else 1
            c, feasible, _ = mpc(m_av, m_hv, (q_l, q_f), tie == 0, p_a_hat, P_av, P_hv, disc,
                                 persuade=config.av.kind == "persuasive")
            (SH, VH, _), (_, _, AR), (h_l, h_f, _, _) = full_prediction(m_hv, m_av, P_hv, P_av,
                                                                        disc)
            a_av = AR[c, 0]
            (ls, lv), (fs, fv) = av["pred"]
            av["q"] = bayes_update(q_l, q_f, (abs(m_hv[0] - ls), abs(m_hv[1] - lv)),
                                   (abs(m_hv[0] - fs), abs(m_hv[1] - fv)), P_av[K.W_S],
                                   P_av[K.W_V])
            av["pred"] = ((SH[h_l, 0], VH[h_l, 0]), (SH[h_f, 0], VH[h_f, 0]))
            out["av_trajectory"].append(c)
            out["av_feasible"].append(feasible)
            out["av_belief"].append(av["q"])
        if noisy:
            a_av, a_hv = a_av + accel_noise[k, 0], a_hv + accel_noise[k, 1]
        s_av, v_av = saturated_step([x_av[0]], [x_av[1]], [a_av], P_av[K.SAMPLE_DT],
                                    P_av[K.V_MIN], P_av[K.V_MAX])
        s_hv, v_hv = saturated_step([x_hv[0]], [x_hv[1]], [a_hv], P_hv[K.SAMPLE_DT],
                                    P_hv[K.V_MIN], P_hv[K.V_MAX])
        x_av, x_hv = (float(s_av[0]), float(v_av[0])), (float(s_hv[0]), float(v_hv[0]))
        states[k + 1] = (*x_av, *x_hv)
    return {"states": states, **{k: np.array(v) for k, v in out.items()}}
