"""The straightforward computation: sections 1-6 of the spec in plain NumPy.

This is the reference path the compiled kernels are checked against, bit for bit. It computes
everything the direct way: every reward pair is summed over every sample, every MPC re-solve is
solved on its own (22 per decision), every distance goes through ``sqrt``, and the closed loop
(:func:`simulate`) shares nothing between agents. It is slow (tens of milliseconds per MPC
decision) and meant for tests, teaching and the benchmark's "before".

Arrays here are trajectory-major, ``(n_traj, n_samples)``, the natural reading of the spec.
"""

from __future__ import annotations

import numpy as np

from . import _packed as K
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
    if P[K.Q6]:
        stop = v_lo <= 0.0 and s0 + v0 / abs(u_min) < -P[K.STOP_DIST]
    else:
        stop = v_lo <= 0.0 and s0 + v0 * v0 / (2.0 * abs(u_min)) < -P[K.STOP_DIST]
    v_t = np.concatenate([[v0], np.linspace(v_lo, v_hi, n_mesh)])
    gap = v_t / P[K.KAPPA] + h_st + length
    standing = np.zeros(n_mesh + 1, bool)
    standing[1] = stop
    stop_leader = -P[K.STOP_DIST] + h_st + length
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


def reward_matrix(S, V, A, s0, S_other, disc, P):
    """Section 3: ``R[m, b] = B[m] - w_c C[m, b]`` of own trajectory ``m`` against ``b``.

    Both sums run over every sample and every pair, in sample order.
    """
    B = np.zeros(S.shape[0])
    C = np.zeros((S.shape[0], S_other.shape[0]))
    for k in range(S.shape[1]):
        B = B + disc[k] * ((S[:, k] - s0) - P[K.W_U] * np.abs(A[:, k]))
        d = np.sqrt(S[:, None, k] ** 2 + S_other[None, :, k] ** 2)
        C = C + (d < P[K.MIN_DIST]) * (disc[k] * (1.0 + V[:, None, k]))
    return B[:, None] - P[K.W_C] * C


def solve(M_lead, M_fol, agg_max: bool):
    """Section 4, one solve: ``(leader pick, follower pick)``."""
    Qf = M_fol.min(axis=1)
    F = np.flatnonzero(Qf == Qf.max())
    sub = M_lead[:, F]
    Ql = sub.max(axis=1) if agg_max else sub.min(axis=1)
    return int(np.argmax(Ql)), int(F[0])


def full_prediction(x_e, x_o, P, disc):
    """Section 4: both libraries and ``(ego-L, ego-F, other-L, other-F)``."""
    Se, Ve, Ae, _ = library(x_e[0], x_e[1], P)
    So, Vo, Ao, _ = library(x_o[0], x_o[1], P)
    M_e = reward_matrix(Se, Ve, Ae, x_e[0], So, disc, P)
    M_o = reward_matrix(So, Vo, Ao, x_o[0], Se, disc, P)
    agg_max = bool(P[K.Q5])
    ego_l, other_f = solve(M_e, M_o, agg_max)
    other_l, ego_f = solve(M_o, M_e, agg_max)
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


def mpc(x_R, x_H, q, tie_leader: bool, p_a_hat: float, P, disc):
    """Section 6, one decision, with every re-solve done separately.

    Returns ``(chosen, feasible, diag)`` with ``diag`` as in :mod:`persuasive.mpc`.
    """
    (SH, VH, AH), (SR, VR, AR), (hv_l, hv_f, av_l, av_f) = full_prediction(x_H, x_R, P, disc)
    n_traj, n = SR.shape
    q1, q2, q4 = bool(P[K.Q1]), bool(P[K.Q2]), bool(P[K.Q4])
    w_c, w_u, min_dist = P[K.W_C], P[K.W_U], P[K.MIN_DIST]
    diag = np.empty((n_traj, 10))
    prior = P[K.PRIOR_L]
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
        b_l, b_f = bayes_update(prior, 1.0 - prior, res[0], res[1], P[K.W_S], P[K.W_V])
        pl = plausible_leader(b_l, b_f, tie_leader)
        Pi = transition_matrix(pl, p_a_hat)
        probs = [Pi[j, i] * q[i] for i in range(2) for j in range(2)]
        start = 1 if q1 else 0
        rewards, safe_rows = [], []
        for i, hv_i in enumerate((hv_l, hv_f)):
            x_i = (SH[hv_i, 0], VH[hv_i, 0])
            (LS, _, _), _, sol = full_prediction(x_i, (SR[k, start], VR[k, start]), P, disc)
            for j in range(2):
                path = LS[sol[j]]
                if q1:
                    hv_s = np.concatenate([[x_H[0], x_i[0]], path[: n - 2]])
                else:
                    hv_s = np.concatenate([[x_i[0]], path[: n - 1]])
                safe = np.sqrt(SR[k] ** 2 + hv_s**2) >= min_dist
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
        diag[k] = [expected, p_safe.min(), p_safe.max(), b_l, b_f, pl, *probs]
    threshold = 1.0 - P[K.EPSILON]
    feasible = diag[:, 1] > threshold
    if feasible.any():
        cand = np.flatnonzero(feasible)
        return int(cand[np.argmax(diag[cand, 0])]), True, diag
    return int(np.argmax(diag[:, 0])), False, diag


# -- the closed loop -----------------------------------------------------------------------------


def simulate(config, seed: int) -> dict[str, np.ndarray]:
    """Section 7, one run, with the functions above and nothing shared between agents.

    Returns ``states`` ``(n_steps + 1, 4)`` and per-step ``hv_role``, ``av_role`` (LFG AV),
    ``av_trajectory`` and ``av_feasible`` (MPC), ``hv_belief`` and ``av_belief`` ``(n, 2)``.
    The random stream and the initial state come from the same definitions as the fast path
    (:func:`persuasive.simulation.draw_stream`, :class:`persuasive.scenario.Intersection`).
    """
    from ._packed import discounts, pack
    from .scenario import Intersection
    from .simulation import check_seed, draw_stream

    rng = np.random.RandomState(check_seed(seed))
    x_av, x_hv = Intersection(config).initial_states(rng)
    draws, meas, accel_noise, noisy = draw_stream(rng, config)
    P, disc = pack(config), discounts(config)
    sim, roles = config.simulation, config.roles
    v_min, v_max = P[K.V_MIN], P[K.V_MAX]
    prior = P[K.PRIOR_L]
    q = config.effective_quirks
    p_a, p_a_hat = roles.p_a, config.p_a_hat

    def lfg_agent(role):
        return {"role": role, "initial": role, "b": (prior, 1.0 - prior), "pred": None}

    def lfg_act(agent, x_self, x_other, r):
        if agent["pred"] is None:
            agent["pred"] = (x_other, x_other)
        b_l, b_f = agent["b"]
        pl = plausible_leader(b_l, b_f, agent["role"] == 0)
        Pi = transition_matrix(pl, p_a)
        (Se, Ve, Ae), (So, Vo, _), (e_l, e_f, o_l, o_f) = full_prediction(x_self, x_other, P, disc)
        accel = Ae[e_l if agent["role"] == 0 else e_f, 0]
        if roles.adapt_role:
            if agent["role"] == 0 and r > Pi[0, 0]:
                agent["role"] = 1
            elif agent["role"] == 1 and r > Pi[1, 1]:
                agent["role"] = 0
        (ls, lv), (fs, fv) = agent["pred"]
        agent["b"] = bayes_update(b_l, b_f, (abs(x_other[0] - ls), abs(x_other[1] - lv)),
                                  (abs(x_other[0] - fs), abs(x_other[1] - fv)), P[K.W_S], P[K.W_V])
        agent["pred"] = ((So[o_l, 0], Vo[o_l, 0]), (So[o_f, 0], Vo[o_f, 0]))
        return accel

    hv = lfg_agent(0 if sim.hv_role == "leader" else 1)
    av = lfg_agent(1 - hv["role"]) if sim.av == "lfg" else {"q": (prior, 1.0 - prior), "pred": None}
    n = sim.n_steps
    states = np.empty((n + 1, 4))
    states[0] = (*x_av, *x_hv)
    out = {k: [] for k in ("hv_role", "av_role", "av_trajectory", "av_feasible", "hv_belief",
                           "av_belief")}
    for k in range(n):
        m_av, m_hv = x_av, x_hv
        if noisy:
            m_av = (x_av[0] + meas[k, 0], min(max(x_av[1] + meas[k, 1], v_min), v_max))
            m_hv = (x_hv[0] + meas[k, 2], min(max(x_hv[1] + meas[k, 3], v_min), v_max))
        out["hv_role"].append(hv["role"])
        a_hv = lfg_act(hv, m_hv, m_av, draws[k, 0])
        out["hv_belief"].append(hv["b"])
        if sim.av == "lfg":
            out["av_role"].append(av["role"])
            a_av = lfg_act(av, m_av, m_hv, draws[k, 1])
            out["av_belief"].append(av["b"])
        else:
            if av["pred"] is None:
                av["pred"] = (m_hv, m_hv)
            q_l, q_f = av["q"]
            if q.q3_tie_break_leak:
                tie = hv["role"] if p_a_hat == p_a else hv["initial"]
            else:
                tie = 0 if q_l >= q_f else 1
            c, feasible, _ = mpc(m_av, m_hv, (q_l, q_f), tie == 0, p_a_hat, P, disc)
            (SH, VH, _), (_, _, AR), (h_l, h_f, _, _) = full_prediction(m_hv, m_av, P, disc)
            a_av = AR[c, 0]
            (ls, lv), (fs, fv) = av["pred"]
            av["q"] = bayes_update(q_l, q_f, (abs(m_hv[0] - ls), abs(m_hv[1] - lv)),
                                   (abs(m_hv[0] - fs), abs(m_hv[1] - fv)), P[K.W_S], P[K.W_V])
            av["pred"] = ((SH[h_l, 0], VH[h_l, 0]), (SH[h_f, 0], VH[h_f, 0]))
            out["av_trajectory"].append(c)
            out["av_feasible"].append(feasible)
            out["av_belief"].append(av["q"])
        if noisy:
            a_av, a_hv = a_av + accel_noise[k, 0], a_hv + accel_noise[k, 1]
        s, v = saturated_step([x_av[0], x_hv[0]], [x_av[1], x_hv[1]], [a_av, a_hv],
                              P[K.SAMPLE_DT], v_min, v_max)
        x_av, x_hv = (float(s[0]), float(v[0])), (float(s[1]), float(v[1]))
        states[k + 1] = (*x_av, *x_hv)
    return {"states": states, **{k: np.array(v) for k, v in out.items()}}
