"""Role adaptation: Bayes belief on the other's role, plausible role, transition (docs/method.md §5).

A belief is the pair ``b = (P(other = L), P(other = F))``, kept as two numbers (its sum may
differ from 1 by rounding; ties are tested on the two numbers exactly).

- **Bayes update** (roles assumed constant): posterior ``∝ prior * N(e; 0, W)`` per role of the
  other, with ``e = (e_s, e_v)`` the absolute residuals of the stored prediction of the other
  for that role and ``W = diag(w_s, w_v)``.
- **Plausible role** (maximum likelihood, complementary): ``F`` if ``b_L > b_F``, ``L`` if
  ``b_L < b_F``, the player's own current role if exactly equal. Returned as
  ``P(plausible = L)``, which is 0 or 1.
- **Transition matrix** (columns: current role L, F; rows: next role L, F)::

      Pi = P(pl=L) [[1, p_a], [0, 1 - p_a]] + P(pl=F) [[1 - p_a, 0], [p_a, 1]]

  A leader becomes follower if a uniform draw ``r > Pi[L, L]``; a follower becomes leader if
  ``r > Pi[F, F]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

LEADER, FOLLOWER = 0, 1


@njit(cache=True, _nrt=False)
def gaussian_density(e_s: float, e_v: float, w_s: float, w_v: float) -> float:
    """Bivariate normal density ``N((e_s, e_v); 0, diag(w_s, w_v))``."""
    return math.exp(-0.5 * (e_s * e_s / w_s + e_v * e_v / w_v)) / (
        2.0 * math.pi * math.sqrt(w_s * w_v)
    )


#: Smallest normal double: a product below it has lost precision (or underflowed to 0).
_TINY = 2.2250738585072014e-308


@njit(cache=True, _nrt=False)
def bayes_update(b_l: float, b_f: float, e_ls: float, e_lv: float, e_fs: float, e_fv: float,
                 w_s: float, w_v: float) -> tuple[float, float]:
    """Posterior ``(P(L), P(F))`` from the prior ``(b_l, b_f)`` and the residuals per role.

    ``e_ls, e_lv``: residuals [m, m/s] of the prediction made for the other as leader;
    ``e_fs, e_fv``: as follower. Computed as written, prior times density, normalised; when
    both products are subnormal or zero (residuals of metres), the densities are first divided
    by the larger one, which keeps the prior's digits and never gives NaN.
    """
    pl = b_l * gaussian_density(e_ls, e_lv, w_s, w_v)
    pf = b_f * gaussian_density(e_fs, e_fv, w_s, w_v)
    if pl >= _TINY or pf >= _TINY:
        z = pl + pf
        return pl / z, pf / z
    ql = 0.5 * (e_ls * e_ls / w_s + e_lv * e_lv / w_v)
    qf = 0.5 * (e_fs * e_fs / w_s + e_fv * e_fv / w_v)
    m = min(ql, qf)
    pl = b_l * (1.0 if ql == m else math.exp(m - ql))
    pf = b_f * (1.0 if qf == m else math.exp(m - qf))
    z = pl + pf
    if z > 0.0:
        return pl / z, pf / z
    return b_l, b_f  # the only role the evidence favours has prior 0: the prior stands


@njit(cache=True, _nrt=False)
def plausible_leader(b_l: float, b_f: float, own_role: int) -> float:
    """``P(plausible role = L)``: 0 if ``b_l > b_f``, 1 if ``b_l < b_f``, own role on a tie."""
    if b_l > b_f:
        return 0.0
    if b_l < b_f:
        return 1.0
    return 1.0 if own_role == LEADER else 0.0


@njit(cache=True, _nrt=False)
def transition_into(p_plausible_l: float, p_a: float, out: np.ndarray) -> None:
    """Write ``Pi(p_a)`` for ``P(plausible = L) = p_plausible_l`` into ``out`` (2, 2)."""
    pf = 1.0 - p_plausible_l
    out[0, 0] = p_plausible_l * 1.0 + pf * (1.0 - p_a)
    out[0, 1] = p_plausible_l * p_a + pf * 0.0
    out[1, 0] = p_plausible_l * 0.0 + pf * p_a
    out[1, 1] = p_plausible_l * (1.0 - p_a) + pf * 1.0


def transition_matrix(p_plausible_l: float, p_a: float) -> np.ndarray:
    """The role transition matrix ``Pi`` (2, 2), column-stochastic."""
    out = np.empty((2, 2))
    transition_into(float(p_plausible_l), float(p_a), out)
    return out


@njit(cache=True, _nrt=False)
def next_role(role: int, r: float, Pi: np.ndarray) -> int:
    """The role after a draw ``r`` in (0, 1): a leader leaves if ``r > Pi[L, L]``, etc."""
    if role == LEADER:
        return FOLLOWER if r > Pi[0, 0] else LEADER
    return LEADER if r > Pi[1, 1] else FOLLOWER
