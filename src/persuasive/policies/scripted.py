"""Humans that do not react: ``aggressive`` and ``replay`` (docs/method.md §11).

- ``aggressive``: full throttle (``u_max``) at every step; it never yields (the speed
  saturates at ``v_max``).
- ``replay``: a recorded trajectory, open loop: the recorded acceleration of each step (from a
  per-step log written by ``persuasive simulate --out`` or a recorded trial), from the
  recorded initial state; after the recording ends, it coasts (zero acceleration).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import packing as slot

#: Parameter slots of a replay: the number of recorded steps, then the accelerations.
PRM_N = 0


@njit(cache=True, _nrt=False)
def aggressive_step(P_self: np.ndarray) -> float:
    return P_self[slot.U_MAX]


@njit(cache=True, _nrt=False)
def replay_step(prm: np.ndarray, k: int) -> float:
    """The recorded acceleration of step ``k`` [m/s^2] (0 past the end of the recording)."""
    n = int(prm[PRM_N])
    return prm[1 + k] if k < n else 0.0
