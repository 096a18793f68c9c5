"""The human models' likelihoods of logged driving (docs/method.md §13.2-13.3).

Every model scores the logged HV acceleration ``x_k`` of each step against what it would have
done, under one noise model: the logged acceleration is the model's plus a Gaussian error of
standard deviation ``sigma`` [m/s^2], fitted (bounded below by ``sigma_min``, see §13.4).

- ``lfg`` (the paper's human, §5): the role is hidden; in role ``r`` the human applies
  ``a_role[k, r]``, the first acceleration of the game's trajectory for that role. Emission
  ``N(x_k; a_role[k, r], sigma^2)``; roles follow the forward filter of
  :mod:`persuasive.fitting.filter` with ``Pi(p_a)``. Parameters ``p_a``, ``pi0 = P(r_0 =
  L)``, ``sigma``.
- ``stubborn``: the ``lfg`` with ``p_a = 0`` (the role never changes). ``pi0``, ``sigma``.
- ``noisy`` (Boltzmann-rational LFG, §11.2): in role ``r`` it picks trajectory ``c`` with
  probability ``softmax(beta Q_r)_c`` (exact ties at the maximum on the lowest index), so the
  emission is the mixture ``sum_c P_r(c) N(x_k; a_first[k, c], sigma^2)``; ``beta = inf`` is
  the ``lfg``. Parameters ``p_a``, ``pi0``, ``beta``, ``sigma``.
- ``idm`` (§11.2): deterministic given its parameters and the logged states (its waiting time
  and commitment follow the measured states), scored by the compiled
  ``persuasive.policies.idm.idm_step``; emission ``N(x_k; a_idm, sigma^2)``.

:func:`hmm_loglik` returns, for a batch of ``G`` parameter vectors at once, each run's
log-likelihood given each initial role; :func:`best_initial_role` then maximises over ``pi0``
exactly (the log-likelihood is concave in it). :func:`idm_sse` returns each run's sum of squared
residuals for ``G`` IDM parameter vectors (``sigma`` is then profiled in closed form).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .. import packing as slot
from ..policies.idm import (_SLOW_MPS, PRM_B, PRM_GAP, PRM_IMPATIENCE, idm_branches,
                            idm_commits, idm_times)
from .filter import (emission_lik, filter_loglik, filter_predict, filter_update_lik,
                     role_transition, smooth_roles)

#: Emission kinds of :func:`hmm_loglik`.
EMIT_LFG, EMIT_NOISY = 0, 1

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


@njit(cache=True, inline="always")
def _log_normal(x: float, mu: float, sigma: float) -> float:
    z = (x - mu) / sigma
    return -0.5 * z * z - math.log(sigma) - _LOG_SQRT_2PI


@njit(cache=True, inline="always")
def _log_normal_c(x: float, mu: float, sigma: float, log_c: float) -> float:
    """``log N(x; mu, sigma^2)`` with ``log_c = log(sigma) + log(sqrt(2 pi))`` given."""
    z = (x - mu) / sigma
    return -0.5 * z * z - log_c


@njit(cache=True)
def boltzmann_log_emission(x: float, q: np.ndarray, a_first: np.ndarray, beta: float,
                           sigma: float) -> float:
    """``log sum_c P(c) N(x; a_first[c], sigma^2)`` with ``P(c) ~ exp(beta (q_c - max q))``,
    exact ties at the maximum on the lowest index (the ``noisy`` human's rule,
    ``persuasive.policies.lfg.boltzmann_choice``); ``beta = inf`` keeps only the first
    maximiser."""
    n = q.shape[0]
    q_max, first = q[0], 0
    for c in range(1, n):
        if q[c] > q_max:
            q_max, first = q[c], c
    # log weights lw_c = beta (q_c - max q) (0 for the first maximiser, -inf for the others)
    m = -np.inf
    for c in range(n):
        if q[c] == q_max and c != first:
            continue
        lw = 0.0 if c == first else beta * (q[c] - q_max)
        if lw == -np.inf:
            continue
        v = lw + _log_normal(x, a_first[c], sigma)
        if v > m:
            m = v
    if m == -np.inf:
        return -np.inf
    num, den = 0.0, 0.0
    for c in range(n):
        if q[c] == q_max and c != first:
            continue
        lw = 0.0 if c == first else beta * (q[c] - q_max)
        if lw == -np.inf:
            continue
        den += math.exp(lw)
        num += math.exp(lw + _log_normal(x, a_first[c], sigma) - m)
    return m + math.log(num) - math.log(den)


@njit(cache=True)
def step_log_emissions(kind: int, x: float, a_role: np.ndarray, q: np.ndarray,
                       a_first: np.ndarray, sigma: float, beta: float,
                       out: np.ndarray) -> None:
    """``log p(x | r)`` for ``r`` = L, F at one step into ``out`` ``(2,)`` (the plain
    definition; :func:`hmm_loglik` computes the same faster)."""
    if kind == EMIT_LFG:
        log_c = math.log(sigma) + _LOG_SQRT_2PI
        out[0] = _log_normal_c(x, a_role[0], sigma, log_c)
        out[1] = _log_normal_c(x, a_role[1], sigma, log_c)
    else:
        out[0] = boltzmann_log_emission(x, q[0], a_first, beta, sigma)
        out[1] = boltzmann_log_emission(x, q[1], a_first, beta, sigma)


@njit(cache=True, inline="always")
def _boltzmann_weights(q: np.ndarray, q_max: np.ndarray, first: np.ndarray, beta: float,
                       w: np.ndarray, den: np.ndarray) -> None:
    """The noisy human's unnormalised choice weights ``w`` ``(2, n_traj)`` per role and their
    sums ``den`` ``(2,)``: ``exp(beta (q_c - max q))``, exact ties at the maximum on the first
    maximiser (0 for the others); weights that underflow are 0."""
    for r in range(2):
        qm, f = q_max[r], first[r]
        total = 0.0
        for c in range(q.shape[1]):
            if c == f:
                wc = 1.0
            elif q[r, c] == qm:
                wc = 0.0
            else:
                lw = beta * (q[r, c] - qm)
                wc = math.exp(lw) if lw > -745.0 else 0.0
            w[r, c] = wc
            total += wc
        den[r] = total


@njit(cache=True, inline="always")
def _gauss_terms(x: float, a_first: np.ndarray, same: np.ndarray, inv_s: float,
                 phi: np.ndarray) -> None:
    """``phi_c = exp(-z_c^2 / 2)``, ``z_c = (x - a_first[c]) / sigma`` (0 where it
    underflows); a candidate whose first acceleration equals an earlier one's (``same[c] <
    c``, :func:`first_equal_candidates`) copies its term."""
    for c in range(a_first.shape[0]):
        if same[c] < c:
            phi[c] = phi[same[c]]
            continue
        z = (x - a_first[c]) * inv_s
        zz = z * z
        phi[c] = math.exp(-0.5 * zz) if zz < 1400.0 else 0.0


@njit(cache=True, inline="always")
def first_equal_candidates(a_first: np.ndarray, same: np.ndarray) -> None:
    """``same[c]``: the first candidate whose first acceleration equals candidate ``c``'s
    (``c`` itself where none before it does). Candidates saturated at a vehicle limit share
    one, so a step has about six distinct values among eleven candidates."""
    for c in range(a_first.shape[0]):
        same[c] = c
        for d in range(c):
            if a_first[d] == a_first[c]:
                same[c] = d
                break


@njit(cache=True)
def first_of_equal(values: np.ndarray, idx: np.ndarray) -> int:
    """Number the distinct values of ``values`` ``(G,)`` in order of first appearance: writes
    each row's number into ``idx`` ``(G,)``, returns how many there are."""
    n = 0
    for g in range(values.shape[0]):
        idx[g] = -1
        for h in range(g):
            if values[h] == values[g]:
                idx[g] = idx[h]
                break
        if idx[g] < 0:
            idx[g] = n
            n += 1
    return n


@njit(cache=True)
def row_sharing(sigma: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """What the rows of a parameter batch share, for :func:`hmm_loglik_run`: ``(5, G)`` rows
    ``s_idx``, ``b_idx`` (each row's distinct ``sigma`` and ``beta``, numbered by
    :func:`first_of_equal`), ``s_row``, ``b_row`` (the first row of each distinct value, in
    the first ``n_s`` and ``n_b`` places) and ``pair_row`` (the first row of each row's
    (``sigma``, ``beta``)); computed once per batch, not once per run."""
    G = sigma.shape[0]
    out = np.zeros((5, G), np.int64)
    s_idx, b_idx, s_row, b_row, pair_row = out[0], out[1], out[2], out[3], out[4]
    first_of_equal(sigma, s_idx)
    first_of_equal(beta, b_idx)
    for g in range(G - 1, -1, -1):
        s_row[s_idx[g]] = g
        b_row[b_idx[g]] = g
    for g in range(G):
        pair_row[g] = g
        for h in range(g):
            if s_idx[h] == s_idx[g] and b_idx[h] == b_idx[g]:
                pair_row[g] = h
                break
    return out


@njit(cache=True)
def hmm_loglik_run(kind: int, a: int, b: int, accel: np.ndarray, a_role: np.ndarray,
                   pl: np.ndarray, q: np.ndarray, a_first: np.ndarray, p_a: np.ndarray,
                   sigma: np.ndarray, beta: np.ndarray, inv_s: np.ndarray, log_c: np.ndarray,
                   share: np.ndarray, out: np.ndarray) -> None:
    """:func:`hmm_loglik` of the run in rows ``a:b`` into ``out`` ``(G, 2)``.

    ``noisy``: the Gaussian terms depend on the step and ``sigma`` only, the choice weights on
    the step and ``beta`` only, so each is computed once per step for each distinct value
    among the rows (a Newton stencil has three or so of each), not once per row, and the
    emission once per distinct pair (rows that differ in ``p_a`` only share it)."""
    G = p_a.shape[0]
    alpha = np.empty((2, G, 2))
    logscale = np.zeros((2, G))
    ll = np.empty((G, 2))
    lik = np.empty((G, 2))
    log_ref = np.empty(G)
    T = np.empty((2, 2))
    s_idx, b_idx, s_row, b_row, pair_row = share[0], share[1], share[2], share[3], share[4]
    n_s, n_b = s_idx.max() + 1, b_idx.max() + 1
    phi = np.empty((n_s, a_first.shape[1]))
    w = np.empty((n_b, 2, a_first.shape[1]))
    den = np.empty((n_b, 2))
    q_max = np.empty(2)
    first = np.empty(2, np.int64)
    same = np.empty(a_first.shape[1], np.int64)
    for k in range(a, b):
        x = accel[k]
        if kind == EMIT_NOISY:
            first_equal_candidates(a_first[k], same)
            for r in range(2):
                q_max[r], first[r] = q[k, r, 0], 0
                for c in range(1, q.shape[2]):
                    if q[k, r, c] > q_max[r]:
                        q_max[r], first[r] = q[k, r, c], c
            for u in range(n_s):
                _gauss_terms(x, a_first[k], same, inv_s[s_row[u]], phi[u])
            for u in range(n_b):
                _boltzmann_weights(q[k], q_max, first, beta[b_row[u]], w[u], den[u])
        for g in range(G):
            if kind == EMIT_LFG:
                z0 = (x - a_role[k, 0]) * inv_s[g]
                z1 = (x - a_role[k, 1]) * inv_s[g]
                ll[g, 0] = -0.5 * z0 * z0 - log_c[g]
                ll[g, 1] = -0.5 * z1 * z1 - log_c[g]
            elif pair_row[g] < g:  # a row with this sigma and beta is done: same emission
                ll[g, 0], ll[g, 1] = ll[pair_row[g], 0], ll[pair_row[g], 1]
            else:
                ph, wb, db = phi[s_idx[g]], w[b_idx[g]], den[b_idx[g]]
                for r in range(2):
                    num = 0.0
                    for c in range(ph.shape[0]):
                        if ph[c] > 0.0:
                            num += wb[r, c] * ph[c]
                    if num > 0.0:
                        ll[g, r] = math.log(num / db[r]) - log_c[g]
                    else:  # every term underflowed: the plain log-sum-exp
                        ll[g, r] = boltzmann_log_emission(x, q[k, r], a_first[k], beta[g],
                                                          sigma[g])
        emission_lik(ll, lik, log_ref)
        for r0 in range(2):
            if k == a:
                for g in range(G):
                    alpha[r0, g, 0], alpha[r0, g, 1] = 1.0 - r0, float(r0)
            else:
                filter_predict(alpha[r0], p_a, pl[k - 1, 0], pl[k - 1, 1], T)
            filter_update_lik(alpha[r0], logscale[r0], ll, lik, log_ref)
    for r0 in range(2):
        filter_loglik(alpha[r0], logscale[r0], out[:, r0])


@njit(cache=True, parallel=True)
def hmm_loglik(kind: int, starts: np.ndarray, accel: np.ndarray, a_role: np.ndarray,
               pl: np.ndarray, q: np.ndarray, a_first: np.ndarray, p_a: np.ndarray,
               sigma: np.ndarray, beta: np.ndarray, out: np.ndarray) -> None:
    """Each run's log-likelihood for ``G`` parameter vectors, given each initial role.

    ``kind``: :data:`EMIT_LFG` (``lfg``, ``stubborn`` with ``p_a = 0``) or :data:`EMIT_NOISY`.
    ``p_a``, ``sigma``, ``beta``: ``(G,)``, one parameter vector per row (``beta`` is read by
    ``noisy`` only). Evidence as in :class:`persuasive.fitting.evidence.Evidence`. Writes
    ``out`` ``(n_runs, G, 2)``: ``log p(run i | theta_g, r_0 = L)`` and ``.. r_0 = F``: two
    forward filters per row (:mod:`persuasive.fitting.filter`), one per initial role, fed the
    same emissions. The runs in parallel (:func:`hmm_loglik_serial`: one after the other).
    """
    inv_s = 1.0 / sigma
    log_c = np.log(sigma) + _LOG_SQRT_2PI
    share = row_sharing(sigma, beta)
    for i in prange(starts.shape[0] - 1):
        hmm_loglik_run(kind, starts[i], starts[i + 1], accel, a_role, pl, q, a_first, p_a,
                       sigma, beta, inv_s, log_c, share, out[i])


@njit(cache=True)
def hmm_loglik_serial(kind: int, starts: np.ndarray, accel: np.ndarray, a_role: np.ndarray,
                      pl: np.ndarray, q: np.ndarray, a_first: np.ndarray, p_a: np.ndarray,
                      sigma: np.ndarray, beta: np.ndarray, out: np.ndarray) -> None:
    """:func:`hmm_loglik` on one thread (for small batches, where starting threads costs more
    than it saves)."""
    inv_s = 1.0 / sigma
    log_c = np.log(sigma) + _LOG_SQRT_2PI
    share = row_sharing(sigma, beta)
    for i in range(starts.shape[0] - 1):
        hmm_loglik_run(kind, starts[i], starts[i + 1], accel, a_role, pl, q, a_first, p_a,
                       sigma, beta, inv_s, log_c, share, out[i])


#: The most role paths :func:`path_loglik_run` keeps per step (module docstring of
#: :mod:`persuasive.fitting.evidence`); beyond it the least likely are dropped.
PATH_CAP = 4096


@njit(cache=True)
def path_loglik_run(a: int, b: int, accel: np.ndarray, a_raw: np.ndarray, pl: np.ndarray,
                    off: np.ndarray, W: np.ndarray, p_a: np.ndarray, sigma: np.ndarray,
                    r0: int, out: np.ndarray) -> None:
    """The ``lfg``'s log-likelihood of the run in rows ``a:b`` whose accelerations were
    recorded through a filter, given the initial role ``r0``, for ``G`` rows ``p_a``,
    ``sigma`` ``(G,)``, into ``out`` ``(G,)``.

    The recorded acceleration of step ``k`` is ``sum_j W[k, j] a_{k + off[j]}`` (rows
    ``a:b`` of ``W``; ``off`` ascending, ``off[0] <= 0 <= off[-1]``), where ``a_t =
    a_raw[t, r_t]`` is the LFG's acceleration in the role it held at step ``t`` (steps beyond
    the run's ends stand in by its first and last). So the emission of step ``k`` depends on
    the roles over the window ``k + off[0] .. k + off[-1]``, not on ``r_k`` alone: the forward
    filter runs over *role paths*, the roles of the last ``L = off[-1] - off[0] + 1`` steps as
    bits (bit ``j``: the role ``j`` steps back; 1 = F), and emits step ``k`` once the path
    reaches ``k + off[-1]``. A path grows by the role transition ``Pi(pl, p_a)`` of the step
    (the LFG's, :mod:`persuasive.role_filter`); paths that agree on the last ``L`` steps
    merge. The human's plausible role is 0 or 1, so a role changes only toward it and few
    paths are alive at once; at most :data:`PATH_CAP` are kept (the least likely dropped
    beyond that). Exact otherwise: the filter of a window of the LFG's own role process,
    not the role held over the window."""
    n = b - a
    D = off.shape[0]
    R2 = off[D - 1]
    L = off[D - 1] - off[0] + 1
    mask = (1 << L) - 1
    G = p_a.shape[0]
    cap = min(1 << L, PATH_CAP)
    pat = np.empty(cap, np.int64)
    new_pat = np.empty(cap, np.int64)
    # not zeroed (a path's row is set when the path is made): a run would otherwise clear
    # cap * G entries twice, far more than the few paths it keeps
    alpha = np.empty((cap, G))
    new_alpha = np.empty((cap, G))
    mu = np.empty(cap)
    ll = np.empty(cap)
    ages = np.empty(D, np.int64)
    term = np.empty((D, 2))
    Tg = np.empty((G, 2, 2))
    T = np.empty((2, 2))
    feeds = np.zeros((2, 2), np.bool_)
    logs = np.zeros(G)
    npat = 1
    pat[0] = mask if r0 == 1 else 0
    for g in range(G):
        alpha[0, g] = 1.0
    for t in range(n + R2):
        if 0 < t <= n - 1:
            tp = a + t - 1
            feeds[:, :] = False  # which role changes some row allows at this step
            for g in range(G):
                role_transition(p_a[g], pl[tp, 0], pl[tp, 1], T)
                for rn in range(2):
                    for r in range(2):
                        Tg[g, rn, r] = T[rn, r]
                        feeds[rn, r] = feeds[rn, r] or T[rn, r] > 0.0
            nn = 0
            for i in range(npat):  # every kept path has mass in some row
                bits = pat[i]
                r = bits & 1
                for rn in range(2):
                    if not feeds[rn, r]:
                        continue
                    nb = ((bits << 1) | rn) & mask
                    j = -1
                    for q in range(nn):
                        if new_pat[q] == nb:
                            j = q
                            break
                    if j < 0:
                        if nn == cap:  # full: this path joins the least likely kept one
                            worst, w_val = 0, np.inf
                            for q in range(nn):
                                m = 0.0
                                for g in range(G):
                                    m = max(m, new_alpha[q, g])
                                if m < w_val:
                                    worst, w_val = q, m
                            j = worst
                        else:
                            j = nn
                            nn += 1
                            new_pat[j] = nb
                            for g in range(G):
                                new_alpha[j, g] = 0.0
                    for g in range(G):
                        new_alpha[j, g] += Tg[g, rn, r] * alpha[i, g]
            npat = nn
            for i in range(nn):
                pat[i] = new_pat[i]
                for g in range(G):
                    alpha[i, g] = new_alpha[i, g]
        k = t - R2
        if k < 0:
            continue
        tc = min(t, n - 1)  # the path's last step (it stops growing at the run's end)
        for j in range(D):  # each tap's term in either role, and its step's bit in a path
            c = min(max(k + off[j], 0), n - 1)
            ages[j] = min(tc - c, L - 1)
            term[j, 0] = W[a + k, j] * a_raw[a + c, 0]
            term[j, 1] = W[a + k, j] * a_raw[a + c, 1]
        for i in range(npat):
            bits = pat[i]
            acc = 0.0
            for j in range(D):
                acc += term[j, (bits >> ages[j]) & 1]
            mu[i] = acc
        x = accel[a + k]
        for g in range(G):
            if logs[g] == -np.inf:
                continue
            inv = 1.0 / sigma[g]
            best = -np.inf
            for i in range(npat):
                if alpha[i, g] > 0.0:
                    z = (x - mu[i]) * inv
                    ll[i] = -0.5 * z * z
                    best = max(best, ll[i])
            if best == -np.inf:
                logs[g] = -np.inf
                continue
            tot = 0.0
            for i in range(npat):
                if alpha[i, g] > 0.0:
                    alpha[i, g] *= math.exp(ll[i] - best)
                    tot += alpha[i, g]
            for i in range(npat):
                alpha[i, g] /= tot
            logs[g] += math.log(tot) + best - math.log(sigma[g]) - _LOG_SQRT_2PI
        nn = 0  # drop the paths no row keeps
        for i in range(npat):
            keep = False
            for g in range(G):
                if alpha[i, g] > 0.0:
                    keep = True
                    break
            if keep:
                pat[nn] = pat[i]
                for g in range(G):
                    alpha[nn, g] = alpha[i, g]
                nn += 1
        npat = max(nn, 1)
    for g in range(G):
        out[g] = logs[g]


@njit(cache=True)
def _path_both_roles(r: int, starts: np.ndarray, accel: np.ndarray, a_raw: np.ndarray,
                     pl: np.ndarray, off: np.ndarray, W: np.ndarray, p_a: np.ndarray,
                     sigma: np.ndarray, out: np.ndarray) -> None:
    for r0 in range(2):
        path_loglik_run(starts[r], starts[r + 1], accel, a_raw, pl, off, W, p_a, sigma, r0,
                        out[r, :, r0])


@njit(cache=True, parallel=True)
def path_loglik(runs: np.ndarray, starts: np.ndarray, accel: np.ndarray, a_raw: np.ndarray,
                pl: np.ndarray, off: np.ndarray, W: np.ndarray, p_a: np.ndarray,
                sigma: np.ndarray, out: np.ndarray) -> None:
    """:func:`path_loglik_run` of the runs ``runs`` (indices into ``starts``), both initial
    roles, into ``out[runs[i], :, r0]`` (``out`` as :func:`hmm_loglik`'s); the runs in
    parallel (:func:`path_loglik_serial`: one after the other)."""
    for i in prange(runs.shape[0]):
        _path_both_roles(runs[i], starts, accel, a_raw, pl, off, W, p_a, sigma, out)


@njit(cache=True)
def path_loglik_serial(runs: np.ndarray, starts: np.ndarray, accel: np.ndarray,
                       a_raw: np.ndarray, pl: np.ndarray, off: np.ndarray, W: np.ndarray,
                       p_a: np.ndarray, sigma: np.ndarray, out: np.ndarray) -> None:
    """:func:`path_loglik` on one thread."""
    for i in range(runs.shape[0]):
        _path_both_roles(runs[i], starts, accel, a_raw, pl, off, W, p_a, sigma, out)


@njit(cache=True)
def _pi0_score(table: np.ndarray, g: int, pi0: float) -> float:
    total = 0.0
    for i in range(table.shape[0]):
        a, b = table[i, g, 0], table[i, g, 1]
        m = a if a > b else b
        if m == -np.inf:
            return -np.inf
        v = pi0 * math.exp(a - m) + (1.0 - pi0) * math.exp(b - m)
        if v <= 0.0:
            return -np.inf
        total += m + math.log(v)
    return total


@njit(cache=True)
def _pi0_terms(table: np.ndarray, g: int, A: np.ndarray, B: np.ndarray) -> None:
    """Each run's likelihoods of row ``g`` under either initial role, relative to the larger
    (``A_i = exp(a_i - m_i)``, ``B_i = exp(b_i - m_i)``; both 0 where the run is impossible
    either way): what :func:`_pi0_slope` reads at every point of its bisection."""
    for i in range(table.shape[0]):
        a, b = table[i, g, 0], table[i, g, 1]
        m = a if a > b else b
        if m == -np.inf:
            A[i] = B[i] = 0.0
        else:
            A[i], B[i] = math.exp(a - m), math.exp(b - m)


@njit(cache=True)
def _pi0_slope(A: np.ndarray, B: np.ndarray, pi0: float) -> float:
    """d/d pi0 of the log-likelihood (decreasing in pi0: the log-likelihood is concave), from
    :func:`_pi0_terms`."""
    total = 0.0
    for i in range(A.shape[0]):
        if A[i] == 0.0 and B[i] == 0.0:  # impossible either way (the larger term is 1)
            continue
        d = pi0 * A[i] + (1.0 - pi0) * B[i]
        if d <= 0.0:
            return np.inf if A[i] > B[i] else -np.inf
        total += (A[i] - B[i]) / d
    return total


@njit(cache=True, parallel=True)
def best_initial_role(table: np.ndarray, pi0_in: np.ndarray, ell: np.ndarray,
                      pi0: np.ndarray) -> None:
    """The log-likelihood of each row ``g`` of ``table`` ``(n_runs, G, 2)``
    (:func:`hmm_loglik`) at ``pi0 = P(r_0 = L)``: at ``pi0_in[g]``, or, where that is NaN,
    at the maximiser over [0, 1]. The log-likelihood ``sum_i log(pi0 L_i(L) + (1 - pi0)
    L_i(F))`` is concave in ``pi0``, so its slope's sign change is found by bisection (60
    halvings; each run's two likelihoods are exponentiated once per row, not once per
    halving). Writes the log-likelihood into ``ell`` ``(G,)`` and ``pi0`` into ``pi0``
    ``(G,)``; the rows in parallel."""
    n = table.shape[0]
    for g in prange(table.shape[1]):
        if not math.isnan(pi0_in[g]):
            p = pi0_in[g]
        else:
            A, B = np.empty(n), np.empty(n)
            _pi0_terms(table, g, A, B)
            if _pi0_slope(A, B, 0.0) <= 0.0:
                p = 0.0
            elif _pi0_slope(A, B, 1.0) >= 0.0:
                p = 1.0
            else:
                lo, hi = 0.0, 1.0
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    if _pi0_slope(A, B, mid) > 0.0:
                        lo = mid
                    else:
                        hi = mid
                p = 0.5 * (lo + hi)
        pi0[g] = p
        ell[g] = _pi0_score(table, g, p)


@njit(cache=True, parallel=True)
def smooth_runs(kind: int, starts: np.ndarray, accel: np.ndarray, a_role: np.ndarray,
                pl: np.ndarray, q: np.ndarray, a_first: np.ndarray, p_a: float, pi0: float,
                sigma: float, beta: float, out: np.ndarray, run_ll: np.ndarray) -> None:
    """``P(r_k = L | the whole run)`` at every step of every run (forward-backward,
    :func:`persuasive.fitting.filter.smooth_roles`) into ``out`` ``(n,)``, and each run's
    log-likelihood into ``run_ll`` ``(n_runs,)``."""
    for i in prange(starts.shape[0] - 1):
        a, b = starts[i], starts[i + 1]
        ll = np.empty((b - a, 2))
        e = np.empty(2)
        for k in range(a, b):
            step_log_emissions(kind, accel[k], a_role[k], q[k], a_first[k], sigma, beta, e)
            ll[k - a, 0], ll[k - a, 1] = e[0], e[1]
        run_ll[i] = smooth_roles(ll, pl[a:b], p_a, pi0, out[a:b])


#: Slots of an IDM parameter vector, as ``persuasive.policies.idm`` reads them.
IDM_NAMES = ("desired_speed_mps", "time_gap_s", "max_accel_mps2", "comfort_decel_mps2",
             "delta", "jam_gap_m", "critical_gap_s", "impatience_per_s")


def idm_groups(prm: np.ndarray) -> np.ndarray:
    """For each IDM parameter row of ``prm`` ``(G, 8)``, the first row with the same
    parameters apart from the two gap parameters (:func:`idm_sse` evaluates the car following
    once per such group)."""
    key = np.array(prm, float, copy=True)
    key[:, [PRM_GAP, PRM_IMPATIENCE]] = 0.0
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return first[inverse.ravel()].astype(np.int64)


@njit(cache=True)
def idm_sse_run(a: int, b: int, states: np.ndarray, accel: np.ndarray, P_hv: np.ndarray,
                P_av: np.ndarray, dt: float, prm: np.ndarray, lead: np.ndarray,
                out: np.ndarray) -> None:
    """:func:`idm_sse` of the run in rows ``a:b`` into ``out`` ``(G,)``.

    Along measured states the driver's waiting time and commitment do not depend on its gap
    parameters, and neither do the accelerations of its two decisions: they are computed
    once per group of rows equal apart from those (``lead``, :func:`idm_groups`), and each row
    only decides, step by step, exactly as ``idm_step`` does (the same operations in the same
    order, so the sums are the ones ``idm_step`` gives to the last bit).
    """
    n = b - a
    fixed = np.empty(n, np.bool_)   # committed, or the other has cleared: go whatever the gap
    margin = np.empty(n)            # t_other - t_own
    waited = np.empty(n)            # the waiting time the step's gap shrinks with
    r_go = np.empty(n)
    r_yield = np.empty(n)
    line = P_hv[slot.YIELD_S]
    for g in range(prm.shape[0]):
        if lead[g] != g:
            continue
        committed = False
        waiting = 0.0
        for k in range(a, b):
            s_o, v_o, s, v = states[k, 0], states[k, 1], states[k, 2], states[k, 3]
            t_own, t_other, other_clear = idm_times(s, v, s_o, v_o, P_av)
            committed = committed or idm_commits(s, v, prm[g, PRM_B], line)
            a_go, a_yield = idm_branches(prm[g], s, v, s_o, v_o, P_hv, P_av)
            j = k - a
            fixed[j] = committed or other_clear
            margin[j] = t_other - t_own
            waited[j] = waiting
            r_go[j] = accel[k] - a_go
            r_yield[j] = accel[k] - a_yield
            if v < _SLOW_MPS:
                waiting += dt
        for h in range(g, prm.shape[0]):
            if lead[h] != g:
                continue
            crit, imp = prm[h, PRM_GAP], prm[h, PRM_IMPATIENCE]
            total = 0.0
            for j in range(n):
                gap = crit * max(0.0, 1.0 - imp * waited[j])
                r = r_go[j] if fixed[j] or margin[j] > gap else r_yield[j]
                total += r * r
            out[h] = total


@njit(cache=True, parallel=True)
def idm_sse(starts: np.ndarray, states: np.ndarray, accel: np.ndarray, P_hv: np.ndarray,
            P_av: np.ndarray, dt: np.ndarray, prm: np.ndarray, lead: np.ndarray,
            out: np.ndarray) -> None:
    """Each run's sum of squared residuals ``sum_k (x_k - a_idm,k)^2`` for ``G`` IDM parameter
    vectors ``prm`` ``(G, 8)`` (:data:`IDM_NAMES`) into ``out`` ``(n_runs, G)``; the runs in
    parallel (:func:`idm_sse_serial`: one after the other). ``lead`` ``(G,)``:
    :func:`idm_groups` of ``prm``.

    The driver's state (waiting time, commitment) starts fresh and follows the measured
    states ``states`` ``(n, 4)``; the step is ``persuasive.policies.idm.idm_step``'s with the HV
    as itself (:func:`idm_sse_run`).
    """
    for i in prange(starts.shape[0] - 1):
        idm_sse_run(starts[i], starts[i + 1], states, accel, P_hv[i], P_av[i], dt[i], prm,
                    lead, out[i])


@njit(cache=True)
def idm_sse_serial(starts: np.ndarray, states: np.ndarray, accel: np.ndarray,
                   P_hv: np.ndarray, P_av: np.ndarray, dt: np.ndarray, prm: np.ndarray,
                   lead: np.ndarray, out: np.ndarray) -> None:
    """:func:`idm_sse` on one thread."""
    for i in range(starts.shape[0] - 1):
        idm_sse_run(starts[i], starts[i + 1], states, accel, P_hv[i], P_av[i], dt[i], prm,
                    lead, out[i])


__all__ = ["EMIT_LFG", "EMIT_NOISY", "IDM_NAMES", "PATH_CAP", "best_initial_role",
           "first_of_equal", "path_loglik", "path_loglik_run", "path_loglik_serial",
           "row_sharing",
           "boltzmann_log_emission", "hmm_loglik", "hmm_loglik_run", "hmm_loglik_serial",
           "idm_groups", "idm_sse", "idm_sse_serial",
           "smooth_runs", "step_log_emissions"]
