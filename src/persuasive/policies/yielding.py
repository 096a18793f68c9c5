"""The always-yielding AV (``yield``, docs/method.md §11).

Until the human has cleared the conflict (its position past its clearing position, e.g.
``min_dist`` past the conflict point at the intersection), the AV takes the most progressive
candidate of its library (largest final position; ties: lowest index) that never passes its
yield line; if none does (it is too close to stop), the candidate that ends furthest back.
Once the human has cleared (measured once, then for good), it takes the most progressive
candidate. No prediction, no belief, no safety check of its own.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import packing as slot
from ..library import Lib

RELEASED = 0  #: state slot: the human has cleared the conflict
COL_TRAJ, COL_RELEASED, COL_N_ADMISSIBLE = range(3)


@njit(cache=True, _nrt=False)
def yield_step(st: np.ndarray, s_H: float, lib_r: Lib, P_av: np.ndarray, P_hv: np.ndarray,
               log: np.ndarray) -> float:
    """One step; returns the AV's acceleration [m/s^2]."""
    if s_H >= P_hv[slot.CLEAR_S]:
        st[RELEASED] = 1.0
    S = lib_r.S
    n, n_traj = S.shape
    line = P_av[slot.YIELD_S]
    best, n_ok = -1, 0
    if st[RELEASED] != 0.0:
        for c in range(n_traj):
            if best < 0 or S[n - 1, c] > S[n - 1, best]:
                best = c
    else:
        for c in range(n_traj):
            stays = True
            for m in range(n):
                if S[m, c] > line:
                    stays = False
                    break
            if stays:
                n_ok += 1
                if best < 0 or S[n - 1, c] > S[n - 1, best]:
                    best = c
        if best < 0:
            for c in range(n_traj):
                if best < 0 or S[n - 1, c] < S[n - 1, best]:
                    best = c
    log[COL_TRAJ] = best
    log[COL_RELEASED] = st[RELEASED]
    log[COL_N_ADMISSIBLE] = n_ok
    return lib_r.A[0, best]
