"""The planner's online posterior over the human's ``p_a`` (docs/method.md §13.9).

With ``mpc.p_a_hat = "online"`` the persuasive planner does not assume the human's willingness
to change role: it keeps a posterior over ``p_a`` on a grid ``p_g = g / (G - 1)``,
``g = 0..G-1`` (``mpc.p_a_grid``, 21 points by default), and plans every step with its mean.
``Pi`` is linear in ``p_a`` (docs/method.md §5.2), so the one-step role prediction with the
mean is the prediction averaged over the posterior.

**The model.** The hidden Markov model is the one the confidence filter of §12.3 tracks, with
the forward filter of §13.2 (:mod:`persuasive.role_filter`, the same compiled functions the
fit runs):

- hidden state: the human's role ``r_k`` at decision step ``k`` (the role it acts in);
- transition ``r_k -> r_{k+1}``: ``Pi(pl_k, p_g)``, with ``pl_k`` the plausible role of the
  model human's own belief about the AV, which the planner replays step by step (§12.3; on an
  exact belief tie each role stays);
- emission of ``r_k``: the human's acceleration at step ``k``, seen one step later, against
  the planner's one-step prediction for role ``r``: ``e_r = (v_H - v_hat_r) / dt`` [m/s^2],
  ``N(e_r; 0, sigma^2)`` with ``sigma = mpc.confidence_accel_std_mps2``.

**State.** Two filter rows per grid value, one per initial role (row ``2 g`` starts from
``r_0 = L``, row ``2 g + 1`` from ``r_0 = F``; the filter's docstring says why), each the
scaled forward variables ``alpha (2G, 2)`` and ``logscale (2G,)``. Every step after the first
takes the emission into every row (:func:`persuasive.role_filter.filter_update_lik`, one
``exp`` for all rows: the emission does not depend on ``p_a``) and then advances them through
that step's transition (:func:`persuasive.role_filter.filter_predict`). The posterior is

    P(p_g | data) ∝ w_g (pi0 exp(ll_{g,L}) + (1 - pi0) exp(ll_{g,F}))

with ``w_g`` the prior mass of grid point ``g``, ``pi0`` the planner's prior that the human
starts as leader (``roles.prior_leader``) and ``ll`` the rows' log-likelihoods
(:func:`persuasive.role_filter.filter_loglik`).

**The prior.** ``w_g`` is the mass of the Beta(a, b) prior (``mpc.p_a_prior``, (7, 3) by
default, mean 0.7) on grid point ``g``'s cell, the interval of points nearer to ``p_g`` than to
any other (half cells at 0 and 1): a Beta density can be infinite or zero at the ends, its
cell masses are finite and sum to 1. Across interactions with the same human the posterior
marginal over ``p_a`` at the end of one interaction is the next one's ``w`` (the role starts
afresh from ``pi0``): :func:`persuasive.simulation.simulate_interactions` and
:meth:`persuasive.planner.Planner.reset`.

**Layout** (the planner's parameter and state vectors, from offsets the planner gives):
parameters ``[G, p_rows (2G), w (G), p_grid (G)]``; state ``[p_a_hat, alpha (4G), logscale
(2G), posterior (G)]`` and scratch (the rows' log-likelihoods ``(2G,)`` and the emission's
and transition's 9 numbers), so that a step allocates nothing.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .role_filter import emission_lik, filter_loglik, filter_predict, filter_update_lik

#: Values of a plausible role: ``persuasive.safety.confidence.plausible_of``'s tie marker.
_TIE = 0.5
_LOG_NORM = 0.5 * math.log(2.0 * math.pi)


def prior_masses(a: float, b: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The grid ``p_g = g / (n - 1)`` ``(n,)`` and the Beta(a, b) prior's mass on each point's
    cell (edges half-way between the points, half cells at 0 and 1) ``(n,)``, summing to 1."""
    from scipy.special import betainc

    grid = np.linspace(0.0, 1.0, n)
    edges = np.concatenate([[0.0], 0.5 * (grid[1:] + grid[:-1]), [1.0]])
    cdf = betainc(a, b, edges)
    cdf[0], cdf[-1] = 0.0, 1.0
    masses = np.diff(cdf)
    return grid, masses / masses.sum()


def online_params(grid: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """The online block of the planner's parameter vector: ``[G, p_rows, w, p_grid]``."""
    grid = np.asarray(grid, np.float64)
    prior = np.asarray(prior, np.float64)
    if grid.ndim != 1 or prior.shape != grid.shape or grid.size < 2:
        raise ValueError("grid and prior must be (G,) arrays with G >= 2")
    return np.concatenate([[float(grid.size)], np.repeat(grid, 2), prior, grid])


def params_size(n: int) -> int:
    """Length of the online parameter block for ``n`` grid points."""
    return 1 + 4 * n


def state_size(n: int) -> int:
    """Length of the online state block for ``n`` grid points."""
    return 1 + 9 * n + 9


@njit(cache=True, _nrt=False)
def online_init(st: np.ndarray, o: int, prm: np.ndarray, q: int, pi0: float) -> None:
    """A fresh online state at ``st[o:]`` from the parameter block at ``prm[q:]``: every row
    from its initial role, and the prior mean as ``p_a_hat``."""
    n = int(prm[q])
    alpha = st[o + 1:o + 1 + 4 * n].reshape((2 * n, 2))
    logscale = st[o + 1 + 4 * n:o + 1 + 6 * n]
    for g in range(n):
        alpha[2 * g, 0], alpha[2 * g, 1] = 1.0, 0.0
        alpha[2 * g + 1, 0], alpha[2 * g + 1, 1] = 0.0, 1.0
        logscale[2 * g] = logscale[2 * g + 1] = 0.0
    st[o] = online_mean(st, o, prm, q, pi0)


@njit(cache=True, _nrt=False)
def online_mean(st: np.ndarray, o: int, prm: np.ndarray, q: int, pi0: float) -> float:
    """The posterior over the grid into the state's ``posterior`` slots, and its mean.

    The posterior is normalised before the mean is taken, so that a prior on one point gives
    exactly that point (``1.0 * p``)."""
    n = int(prm[q])
    alpha = st[o + 1:o + 1 + 4 * n].reshape((2 * n, 2))
    logscale = st[o + 1 + 4 * n:o + 1 + 6 * n]
    post = st[o + 1 + 6 * n:o + 1 + 7 * n]
    w = prm[q + 1 + 2 * n:q + 1 + 3 * n]
    grid = prm[q + 1 + 3 * n:q + 1 + 4 * n]
    ll = st[o + 1 + 7 * n:o + 1 + 9 * n]
    filter_loglik(alpha, logscale, ll)
    m = -np.inf
    for g in range(n):
        if w[g] > 0.0:
            if pi0 > 0.0 and ll[2 * g] > m:
                m = ll[2 * g]
            if pi0 < 1.0 and ll[2 * g + 1] > m:
                m = ll[2 * g + 1]
    total = 0.0
    for g in range(n):
        v = 0.0
        if w[g] > 0.0 and m > -np.inf:
            if pi0 > 0.0:
                v += pi0 * math.exp(ll[2 * g] - m)
            if pi0 < 1.0:
                v += (1.0 - pi0) * math.exp(ll[2 * g + 1] - m)
            v *= w[g]
        post[g] = v
        total += v
    if not total > 0.0:  # data impossible under every grid point: keep the prior
        for g in range(n):
            post[g] = w[g]
            total += w[g]
    mean = 0.0
    for g in range(n):
        post[g] = post[g] / total
        mean += post[g] * grid[g]
    return mean


@njit(cache=True, _nrt=False)
def online_step(st: np.ndarray, o: int, prm: np.ndarray, q: int, e_l: float, e_f: float,
                sigma: float, plausible: float, pi0: float) -> float:
    """Take one observation into the online state at ``st[o:]`` and return the new mean.

    ``e_l``, ``e_f``: the human's acceleration residuals [m/s^2] to the planner's one-step
    predictions for each role (the emission of the role it acted in at the previous step);
    ``sigma``: their width; ``plausible``: the model human's plausible role at that step (1.0
    leader, 0.0 follower, 0.5 an exact belief tie, ``persuasive.safety.confidence
    .plausible_of``); ``pi0``: the prior that the human started as leader."""
    n = int(prm[q])
    alpha = st[o + 1:o + 1 + 4 * n].reshape((2 * n, 2))
    logscale = st[o + 1 + 4 * n:o + 1 + 6 * n]
    p_rows = prm[q + 1:q + 1 + 2 * n]
    scratch = st[o + 1 + 9 * n:o + 10 + 9 * n]
    log_lik = scratch[0:2].reshape((1, 2))
    lik = scratch[2:4].reshape((1, 2))
    log_ref = scratch[4:5]
    zl, zf = e_l / sigma, e_f / sigma
    c = math.log(sigma) + _LOG_NORM
    log_lik[0, 0] = -0.5 * zl * zl - c
    log_lik[0, 1] = -0.5 * zf * zf - c
    emission_lik(log_lik, lik, log_ref)
    filter_update_lik(alpha, logscale, log_lik, lik, log_ref)
    pl_if_leader = 1.0 if plausible == _TIE else plausible
    pl_if_follower = 0.0 if plausible == _TIE else plausible
    filter_predict(alpha, p_rows, pl_if_leader, pl_if_follower, scratch[5:9].reshape((2, 2)))
    st[o] = online_mean(st, o, prm, q, pi0)
    return st[o]


@njit(cache=True, _nrt=False)
def online_replay(st: np.ndarray, o: int, prm: np.ndarray, q: int, obs: np.ndarray,
                  sigma: float, pi0: float, means: np.ndarray) -> None:
    """:func:`online_step` over a sequence ``obs`` ``(n, 3)`` of ``(e_l, e_f, plausible)``,
    the mean after each into ``means`` ``(n,)`` (the bench times the update with it)."""
    for k in range(obs.shape[0]):
        means[k] = online_step(st, o, prm, q, obs[k, 0], obs[k, 1], sigma, obs[k, 2], pi0)


def prior_view(prm: np.ndarray, q: int) -> np.ndarray:
    """The prior masses ``w`` ``(G,)`` of the parameter block at ``prm[q:]``, a view (writing
    into it sets the prior of the next encounter)."""
    n = int(prm[q])
    return prm[q + 1 + 2 * n:q + 1 + 3 * n]


def grid_view(prm: np.ndarray, q: int) -> np.ndarray:
    """The grid ``p_g`` ``(G,)`` of the parameter block at ``prm[q:]``, a view."""
    n = int(prm[q])
    return prm[q + 1 + 3 * n:q + 1 + 4 * n]


def posterior_of(state: np.ndarray, o: int, n: int) -> np.ndarray:
    """A copy of the posterior over the grid ``(n,)`` held in a state at offset ``o``."""
    return np.array(state[o + 1 + 6 * n:o + 1 + 7 * n])


__all__ = ["grid_view", "online_init", "online_mean", "online_params", "online_replay",
           "online_step", "params_size", "posterior_of", "prior_masses", "prior_view",
           "state_size"]
