"""The forward filter over the human's hidden role (docs/method.md §13.2), written once.

The human's role ``r_k`` in {L, F} at decision step ``k`` (the role it acts in) is a hidden
Markov chain. Its transition from step ``k`` to ``k + 1`` is the LFG's own adaptation (§5.2,
§5.4): column ``r`` of ``Pi(pl_k(r), p_a)``, where ``pl_k(r)`` is the human's
``P(plausible = L)`` at step ``k`` when its own role is ``r``. The two columns come from the
same belief and differ only on an exact belief tie (§5.1), where the plausible role is the
human's own role and ``Pi``'s column for it is the identity: no change::

    T_k[r', r] = Pi(pl_k(r), p_a)[r', r]            (column-stochastic)

The emission of step ``k`` is ``p(obs_k | r_k = r)``, handed in as log-likelihoods (the models
of :mod:`persuasive.fitting.models` compute them).

**State**, for a grid of ``G`` parameter vectors at once (one row per ``p_a`` value, or per
``(p_a, sigma)`` pair): the scaled forward variables

- ``alpha`` ``(G, 2)``: ``p(obs_0..k, r_k = L)``, ``p(obs_0..k, r_k = F)``, divided by
  ``exp(logscale)``;
- ``logscale`` ``(G,)``: the log of that scale.

Each emission enters relative to the likelier role (one ``exp`` per step and row), and ``alpha`` is
brought back to a sum in [0.5, 1) by an exact power of two whenever its sum leaves ``[2^-200,
2^200]``, so no rounding is added and nothing underflows. :func:`filter_loglik` reads the
log-likelihood so far, ``logscale + log(alpha_L + alpha_F)``, and :func:`filter_posterior` the
role's posterior ``alpha_L / (alpha_L + alpha_F)``.

**Steps.** :func:`filter_start` takes the first emission with a prior ``P(r_0 = L)``;
:func:`filter_step` predicts with the previous step's transition, then takes this step's
emission. An offline fit calls them over whole runs (:func:`persuasive.fitting.models
.hmm_loglik`); an online posterior over ``p_a`` calls :func:`filter_step` once per decision,
keeping ``alpha`` and ``logscale`` between decisions: ``P(p_a = p_g | data)`` is proportional to
the grid's prior times ``exp(filter_loglik[g])``. With ``p_a = 0`` the transition is the
identity and the filter is the LFG's own Bayes belief about a constant role (§5.5):
``persuasive.roles.bayes_update`` is one :func:`filter_update` with Gaussian emissions (tested).

:func:`smooth_roles` runs forward and backward for one parameter vector and returns
``P(r_k = L | all observations)``.

**One filter per initial role.** A role whose share of ``alpha`` underflows (below ``e^-745``
of the other's) is dropped; it comes back only if a transition feeds it. That is exact
whenever both roles are fed (``p_a > 0`` and a chance to change) or a filter starts from a
known role, but a single filter started from a mixed prior could drop the initial role that
later steps favour (with ``p_a = 0`` nothing feeds it again). So the offline likelihood runs
one filter per initial role and mixes them by ``pi0`` (which also makes the maximisation over
``pi0`` exact), and the planner's online posterior (:mod:`persuasive.online`, docs/method.md
§13.9) keeps two rows per ``p_a`` value, one per initial role, weighted by its prior.

This module sits below the policies (it imports only :mod:`persuasive.roles`) so that the
planner runs it; :mod:`persuasive.fitting.filter` re-exports it for the fit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .roles import transition_into

#: Below this sum an update is redone in the log domain (the product may have lost digits).
_TINY = 2.0 ** -900
#: ``alpha`` is renormalised when its sum leaves ``[_LO, _HI]``.
_LO, _HI = 2.0 ** -200, 2.0 ** 200
_LN2 = math.log(2.0)


@njit(cache=True, _nrt=False)
def role_transition(p_a: float, pl_if_leader: float, pl_if_follower: float,
                    out: np.ndarray) -> None:
    """``T[r', r]`` ``(2, 2)`` into ``out``: column L of ``Pi(pl_if_leader, p_a)`` and column F
    of ``Pi(pl_if_follower, p_a)`` (docs/method.md §5.2)."""
    transition_into(pl_if_leader, p_a, out)
    t_ll, t_fl = out[0, 0], out[1, 0]
    transition_into(pl_if_follower, p_a, out)
    out[0, 0], out[1, 0] = t_ll, t_fl


@njit(cache=True, _nrt=False)
def _normalise(alpha: np.ndarray, logscale: np.ndarray, g: int) -> None:
    """Bring ``alpha[g]``'s sum into [0.5, 1) by an exact power of two, once it has left
    ``[2^-200, 2^200]``."""
    s = alpha[g, 0] + alpha[g, 1]
    if s > 0.0 and (s < _LO or s > _HI):
        e = math.frexp(s)[1]
        if e != 0:
            f = math.ldexp(1.0, -e)
            alpha[g, 0] *= f
            alpha[g, 1] *= f
            logscale[g] += e * _LN2


@njit(cache=True, _nrt=False)
def filter_update_lik(alpha: np.ndarray, logscale: np.ndarray, log_lik: np.ndarray,
                      lik: np.ndarray, log_ref: np.ndarray) -> None:
    """Take one emission ``log_lik`` ``(G, 2)`` (``(1, 2)``: shared by every row), split by
    :func:`emission_lik` into ``lik`` (the likelier role's entry 1) and ``log_ref``:
    ``alpha[g, r] *= lik[g, r]``, ``logscale[g] += log_ref[g]``, then ``alpha[g]`` is brought
    back to a sum in [0.5, 1) by an exact power of two if its sum has left
    ``[2^-200, 2^200]``. An offline pass splits each emission once and takes it into the
    filters of both initial roles.

    When the product is tiny (the roles that have mass are much less likely than the other),
    the update is redone in the log domain relative to the roles that have mass, so that only
    an observation impossible under every role with mass empties ``alpha``.
    """
    shared = lik.shape[0] == 1
    for g in range(alpha.shape[0]):
        j = 0 if shared else g
        a0, a1 = alpha[g, 0], alpha[g, 1]
        if log_ref[j] == -np.inf or not (a0 + a1 > 0.0):
            alpha[g, 0] = alpha[g, 1] = 0.0
            continue
        b0, b1 = a0 * lik[j, 0], a1 * lik[j, 1]
        if b0 + b1 >= _TINY:
            alpha[g, 0], alpha[g, 1] = b0, b1
            logscale[g] += log_ref[j]
        else:
            l0 = math.log(a0) + log_lik[j, 0] if a0 > 0.0 else -np.inf
            l1 = math.log(a1) + log_lik[j, 1] if a1 > 0.0 else -np.inf
            m = l0 if l0 > l1 else l1
            if m == -np.inf or math.isnan(m):
                alpha[g, 0] = alpha[g, 1] = 0.0
                continue
            alpha[g, 0] = math.exp(l0 - m)
            alpha[g, 1] = math.exp(l1 - m)
            logscale[g] += m
        _normalise(alpha, logscale, g)


@njit(cache=True, _nrt=False)
def emission_lik(log_lik: np.ndarray, lik: np.ndarray, log_ref: np.ndarray) -> None:
    """Split log-likelihoods ``(G, 2)`` into ``lik`` (the likelier role's entry 1, the other's
    ``exp`` of the difference) and ``log_ref`` (the larger log-likelihood)."""
    for g in range(log_lik.shape[0]):
        l0, l1 = log_lik[g, 0], log_lik[g, 1]
        m = l0 if l0 > l1 else l1
        if m == -np.inf or math.isnan(m):
            lik[g, 0] = lik[g, 1] = 0.0
            log_ref[g] = -np.inf
        elif l0 == m:
            lik[g, 0], lik[g, 1] = 1.0, math.exp(l1 - m)
            log_ref[g] = m
        else:
            lik[g, 0], lik[g, 1] = math.exp(l0 - m), 1.0
            log_ref[g] = m


@njit(cache=True)
def filter_update(alpha: np.ndarray, logscale: np.ndarray, log_lik: np.ndarray) -> None:
    """Take one emission ``log p(obs_k | r)``, ``log_lik`` ``(G, 2)`` (or ``(1, 2)`` shared by
    every row), into the forward variables."""
    lik = np.empty(log_lik.shape)
    log_ref = np.empty(log_lik.shape[0])
    emission_lik(log_lik, lik, log_ref)
    filter_update_lik(alpha, logscale, log_lik, lik, log_ref)


@njit(cache=True, _nrt=False)
def filter_predict(alpha: np.ndarray, p_a: np.ndarray, pl_if_leader: float,
                   pl_if_follower: float, T: np.ndarray) -> None:
    """Advance ``alpha`` ``(G, 2)`` through one step's transition ``T`` (column-stochastic, so
    the scale is unchanged), with ``p_a[g]`` per row (``p_a``: ``(G,)``, or ``(1,)`` shared)
    and the human's ``P(plausible = L)`` of that step per own role. ``T``: ``(2, 2)``
    scratch."""
    shared = p_a.shape[0] == 1
    if shared:
        role_transition(p_a[0], pl_if_leader, pl_if_follower, T)
    for g in range(alpha.shape[0]):
        if not shared:
            role_transition(p_a[g], pl_if_leader, pl_if_follower, T)
        a0, a1 = alpha[g, 0], alpha[g, 1]
        alpha[g, 0] = T[0, 0] * a0 + T[0, 1] * a1
        alpha[g, 1] = T[1, 0] * a0 + T[1, 1] * a1


@njit(cache=True)
def filter_start(alpha: np.ndarray, logscale: np.ndarray, prior_leader: float,
                 log_lik: np.ndarray) -> None:
    """Start the filter at step 0: prior ``P(r_0 = L) = prior_leader``, then the first
    emission ``log_lik`` (``(G, 2)`` or ``(1, 2)``)."""
    for g in range(alpha.shape[0]):
        alpha[g, 0], alpha[g, 1] = prior_leader, 1.0 - prior_leader
        logscale[g] = 0.0
    filter_update(alpha, logscale, log_lik)


@njit(cache=True)
def filter_step(alpha: np.ndarray, logscale: np.ndarray, p_a: np.ndarray, pl_if_leader: float,
                pl_if_follower: float, log_lik: np.ndarray) -> None:
    """One step of the forward filter: the transition of the *previous* step, then this
    step's emission.

    Parameters
    ----------
    alpha : (G, 2) array
        Scaled ``p(obs_0..k-1, r_{k-1} = L, F)`` per row, overwritten with those of step ``k``.
    logscale : (G,) array
        Their log-scale, updated.
    p_a : (G,) or (1,) array
        The human's willingness to change role, per row.
    pl_if_leader, pl_if_follower : float
        The human's ``P(plausible = L)`` at step ``k - 1`` if its own role is L, F (0 or 1;
        different only on an exact belief tie).
    log_lik : (G, 2) or (1, 2) array
        ``log p(obs_k | r_k = L), log p(obs_k | r_k = F)``.
    """
    filter_predict(alpha, p_a, pl_if_leader, pl_if_follower, np.empty((2, 2)))
    filter_update(alpha, logscale, log_lik)


@njit(cache=True, _nrt=False)
def filter_loglik(alpha: np.ndarray, logscale: np.ndarray, out: np.ndarray) -> None:
    """``log p(obs_0..k)`` per row into ``out`` ``(G,)`` (``-inf`` when impossible)."""
    for g in range(alpha.shape[0]):
        s = alpha[g, 0] + alpha[g, 1]
        out[g] = logscale[g] + math.log(s) if s > 0.0 else -np.inf


@njit(cache=True, _nrt=False)
def filter_posterior(alpha: np.ndarray, out: np.ndarray) -> None:
    """``P(r_k = L | obs_0..k)`` per row into ``out`` ``(G,)`` (NaN when impossible)."""
    for g in range(alpha.shape[0]):
        s = alpha[g, 0] + alpha[g, 1]
        out[g] = alpha[g, 0] / s if s > 0.0 else np.nan


@njit(cache=True)
def _smooth_from(log_lik: np.ndarray, pl: np.ndarray, p_a: float, prior_leader: float,
                 out: np.ndarray) -> float:
    """Forward-backward from one prior; ``out``: ``P(r_k = L | data)``; returns the
    log-likelihood (``-inf``: ``out`` untouched)."""
    n = log_lik.shape[0]
    filt = np.empty((n, 2))
    alpha = np.empty((1, 2))
    logscale = np.zeros(1)
    pa = np.full(1, p_a)
    post = np.empty(1)
    for k in range(n):
        if k == 0:
            filter_start(alpha, logscale, prior_leader, log_lik[0:1])
        else:
            filter_step(alpha, logscale, pa, pl[k - 1, 0], pl[k - 1, 1], log_lik[k:k + 1])
        filter_posterior(alpha, post)
        filt[k, 0], filt[k, 1] = post[0], 1.0 - post[0]
    ll = np.empty(1)
    filter_loglik(alpha, logscale, ll)
    if ll[0] == -np.inf:
        return -np.inf
    T = np.empty((2, 2))
    s0, s1 = filt[n - 1, 0], filt[n - 1, 1]
    out[n - 1] = s0
    for k in range(n - 2, -1, -1):
        role_transition(p_a, pl[k, 0], pl[k, 1], T)
        f0, f1 = filt[k, 0], filt[k, 1]
        pred0 = T[0, 0] * f0 + T[0, 1] * f1
        pred1 = T[1, 0] * f0 + T[1, 1] * f1
        c0 = s0 / pred0 if pred0 > 0.0 else 0.0
        c1 = s1 / pred1 if pred1 > 0.0 else 0.0
        s0 = f0 * (T[0, 0] * c0 + T[1, 0] * c1)
        s1 = f1 * (T[0, 1] * c0 + T[1, 1] * c1)
        z = s0 + s1
        s0, s1 = s0 / z, s1 / z
        out[k] = s0
    return ll[0]


@njit(cache=True)
def smooth_roles(log_lik: np.ndarray, pl: np.ndarray, p_a: float, prior_leader: float,
                 out: np.ndarray) -> float:
    """Forward-backward over one run for one parameter vector.

    ``log_lik`` ``(n, 2)``: the emissions per step and role; ``pl`` ``(n, 2)``: the human's
    ``P(plausible = L)`` per step and own role. Writes ``P(r_k = L | obs_0..n-1)`` into
    ``out`` ``(n,)`` and returns the run's log-likelihood (``-inf`` when impossible; ``out``
    is then NaN).

    One pass per initial role, mixed by their weights: a filter keeps a role whose share
    underflows (``e^-745``) only if a transition feeds it again, so a single filter started
    from a mixed prior could drop the initial role the later steps favour (with ``p_a = 0``
    nothing ever feeds it); started from a known role, each pass keeps every path that
    matters.
    """
    n = log_lik.shape[0]
    post = np.empty((2, n))
    lls = np.empty(2)
    for r0 in range(2):
        prior = 1.0 - r0
        weight = prior_leader if r0 == 0 else 1.0 - prior_leader
        lls[r0] = _smooth_from(log_lik, pl, p_a, prior, post[r0]) if weight > 0.0 else -np.inf
        if lls[r0] > -np.inf:
            lls[r0] += math.log(weight)
    m = max(lls[0], lls[1])
    if m == -np.inf:
        out[:] = np.nan
        return -np.inf
    w0, w1 = math.exp(lls[0] - m), math.exp(lls[1] - m)
    for k in range(n):
        v = 0.0
        if w0 > 0.0:
            v += w0 * post[0, k]
        if w1 > 0.0:
            v += w1 * post[1, k]
        out[k] = v / (w0 + w1)
    return m + math.log(w0 + w1)


__all__ = ["emission_lik", "filter_loglik", "filter_posterior", "filter_predict",
           "filter_start", "filter_step", "filter_update", "filter_update_lik",
           "role_transition", "smooth_roles"]
