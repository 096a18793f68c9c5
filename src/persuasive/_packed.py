"""Parameters packed into one float64 vector for the compiled kernels.

Numba kernels take plain arrays; this module fixes, once, which slot holds which parameter
(the slot names are compile-time constants inside the kernels) and packs a :class:`Config`.
Boolean quirks are stored as 0.0 / 1.0.
"""

from __future__ import annotations

import math

import numpy as np

from .config import Config

# Vehicle (spec section 1)
V_MIN, V_MAX, U_MIN, U_MAX, LENGTH, STOP_DIST, MIN_DIST = range(7)
# Trajectory library (spec section 2)
N_SAMPLES, SAMPLE_DT, N_MESH, ALPHA, BETA, KAPPA, H_ST, H_GO, HORIZON = range(7, 16)
# Rewards (spec section 3)
W_C, W_U = range(16, 18)
# Roles (spec section 5) and MPC (spec section 6)
W_S, W_V, PRIOR_L, EPSILON = range(18, 22)
# Quirks (spec section 9)
Q1, Q2, Q4, Q5, Q6 = range(22, 27)
# ``sqrt(x) < min_dist`` exactly when ``x < MIN_DIST_SQ`` (see :func:`sqrt_threshold`)
MIN_DIST_SQ = 27
N_SLOTS = 28


def sqrt_threshold(c: float) -> float:
    """The smallest double ``x`` with ``sqrt(x) >= c``, for ``c > 0``.

    IEEE ``sqrt`` is correctly rounded, hence monotone, so ``sqrt(x) < c`` holds exactly when
    ``x < sqrt_threshold(c)``: distance tests can compare squares and still agree, bit for bit,
    with the spec's ``d = sqrt(s^2 + s'^2) < min_dist``.
    """
    x = c * c
    while math.sqrt(x) < c:
        x = math.nextafter(x, math.inf)
    while math.sqrt(math.nextafter(x, -math.inf)) >= c:
        x = math.nextafter(x, -math.inf)
    return x


def pack(config: Config) -> np.ndarray:
    """The kernel parameter vector of ``config``: shape ``(N_SLOTS,)``, float64."""
    v, lib, rw, roles, q = (
        config.vehicle,
        config.library,
        config.reward,
        config.roles,
        config.effective_quirks,
    )
    p = np.empty(N_SLOTS)
    p[V_MIN], p[V_MAX], p[U_MIN], p[U_MAX] = v.v_min_mps, v.v_max_mps, v.u_min_mps2, v.u_max_mps2
    p[LENGTH], p[STOP_DIST], p[MIN_DIST] = v.length_m, v.stop_distance_m, v.min_dist_m
    p[N_SAMPLES], p[SAMPLE_DT], p[N_MESH] = lib.n_samples, lib.sample_dt_s, lib.n_mesh
    p[ALPHA], p[BETA], p[KAPPA], p[H_ST] = lib.alpha, lib.beta, lib.kappa, lib.h_st_m
    p[H_GO] = lib.h_st_m + v.v_max_mps / lib.kappa
    p[HORIZON] = lib.horizon_s
    p[W_C], p[W_U] = rw.w_c, rw.w_u
    p[W_S], p[W_V], p[PRIOR_L] = roles.w_s_m2, roles.w_v_m2ps2, roles.prior_leader
    p[EPSILON] = config.mpc.epsilon
    p[MIN_DIST_SQ] = sqrt_threshold(v.min_dist_m)
    p[Q1], p[Q2] = q.q1_branch_time_offset, q.q2_belief_offset
    p[Q4], p[Q5], p[Q6] = q.q4_undiscounted_collision, q.q5_leader_agg_max, q.q6_time_like_stop_test
    return p


def discounts(config: Config) -> np.ndarray:
    """``lambda ** (k - 1)`` for samples ``k = 1..n``: shape ``(n_samples,)``.

    Computed once here and passed to every kernel so that all code paths use the same values.
    """
    return config.reward.discount ** np.arange(config.library.n_samples, dtype=np.float64)
