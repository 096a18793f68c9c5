"""The planner's confidence in its human model (docs/method.md §12.3).

Two hypotheses about the human, tracked by a hidden Markov filter (the shape of Fisac et al.,
RSS 2018, with a model/not-model pair instead of a grid over rationality):

- **model**: the human is the planner's leader-follower player. Its role is hidden and moves
  as the model says (docs/method.md §5): from role ``r_k`` to ``r_{k+1}`` with ``Pi(p_a_hat)``
  built from the human's plausible role, which comes from the human's own belief about the
  AV. That belief is not observed, but the model says how the human forms it (Bayes against
  its one-step prediction of the AV, from the same full prediction the planner solves), so
  the planner replays it step by step and knows the plausible role the model's human holds; on
  an exact belief tie the human keeps its role. Its acceleration is its role's predicted
  acceleration plus Gaussian noise of width ``sigma`` (``mpc.confidence_accel_std_mps2``);
- **not the model**: any acceleration within the human's limits, uniformly.

The human may switch between the two with probability ``h`` per step
(``mpc.confidence_switch``), so the filter neither locks in nor forgets at once. With
``pi_rho`` the model's predicted probability of the role the human acted in and
``e_rho = (v_H - v_hat_rho) / dt`` the difference between its observed and predicted
accelerations (the same stored one-step prediction the belief ``q`` is updated against;
saturation included on both sides):

    p^-     = (1 - h) p + h (1 - p)
    L_model = sum_rho pi_rho N(e_rho; 0, sigma^2)
    p'      = p^- L_model / (p^- L_model + (1 - p^-) / (u_max - u_min))
    alpha'  = pi_rho N(e_rho; 0, sigma^2) / L_model          (the role posterior)
    pi'     = Pi(plausible, p_a_hat) alpha'                    (the next role's prediction)

Against the paper's human the model is exact (zero residuals in its true role) and the
confidence stays near its ceiling ``1 - h``; a human that keeps going where the model's human
would have yielded, or that drives like no leader-follower player, drives it down.
"""

from __future__ import annotations

import math

from numba import njit

_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


@njit(cache=True, _nrt=False)
def confidence_update(p: float, pi_l: float, e_l: float, e_f: float, sigma: float,
                      switch: float, width: float) -> tuple[float, float]:
    """One observation: ``(p', alpha_L)``, the confidence in the model and the posterior
    probability that the human acted as a leader (module docstring). ``p`` before it, ``pi_l``
    the predicted probability of the leader role, ``e_l``/``e_f`` the acceleration residuals
    to each role's prediction [m/s^2], ``sigma`` their width, ``switch`` the switching
    probability, ``width`` the human's acceleration range ``u_max - u_min`` [m/s^2]."""
    p_pred = (1.0 - switch) * p + switch * (1.0 - p)
    zl, zf = e_l / sigma, e_f / sigma
    dl = pi_l * math.exp(-0.5 * zl * zl)
    df = (1.0 - pi_l) * math.exp(-0.5 * zf * zf)
    lik_m = (_INV_SQRT_2PI / sigma) * (dl + df)
    num = p_pred * lik_m
    den = num + (1.0 - p_pred) / width
    alpha_l = dl / (dl + df) if dl + df > 0.0 else pi_l
    return (num / den if den > 0.0 else p_pred), alpha_l


#: ``plausible`` value of an exact belief tie (each role then stays).
TIE = 0.5


@njit(cache=True, _nrt=False)
def plausible_of(b_l: float, b_f: float) -> float:
    """The plausible role of a human with belief ``(b_l, b_f)`` about the AV: 1.0 leader
    (it believes the AV follows), 0.0 follower, :data:`TIE` on an exact tie (its own role)."""
    if b_l > b_f:
        return 0.0
    if b_l < b_f:
        return 1.0
    return TIE


@njit(cache=True, _nrt=False)
def role_prediction(alpha_l: float, plausible: float, p_a: float) -> float:
    """The model's probability that the human is a leader at the next step, from the role
    posterior ``alpha_l`` and its plausible role (:func:`plausible_of`; on a tie both roles
    stay), with ``Pi(p_a)`` as ``persuasive.roles.transition_into``."""
    if plausible == TIE:
        return alpha_l
    pl = plausible
    pi_ll = pl + (1.0 - pl) * (1.0 - p_a)  # Pi[L, L]
    pi_lf = pl * p_a  # Pi[L, F]
    return pi_ll * alpha_l + pi_lf * (1.0 - alpha_l)


__all__ = ["TIE", "confidence_update", "plausible_of", "role_prediction"]
