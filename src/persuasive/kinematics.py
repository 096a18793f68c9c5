"""Longitudinal kinematics: the constant-acceleration step with speed saturation (docs/method.md §1).

A vehicle is a 1-D state ``(s, v)``: ``s`` [m] the signed distance along its own road to the
conflict point (negative before it), ``v`` [m/s] its speed. One step of length ``dt`` [s] with
acceleration ``a`` [m/s^2]:

- ``v' = v + a dt``;
- if ``v' > v_max``: accelerate to ``v_max`` (reached at ``t1 = (v_max - v) / a``), then cruise:
  ``ds = (v_max^2 - v^2) / (2a) + v_max (dt - t1)``;
- else if ``v' < v_min``: the same with ``v_min`` (the vehicle stops and stays stopped);
- else ``ds = v dt + a dt^2 / 2``.

``a = 0`` always takes the last branch, so nothing divides by zero.

:func:`check_state` checks a state handed in from outside (a planner's caller, a Python
policy's observation): a pair of finite numbers, the speed within the vehicle's limits.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .config import ConfigError


@njit(cache=True, inline="always")
def saturated_step(
    s: float, v: float, a: float, dt: float, v_min: float, v_max: float
) -> tuple[float, float]:
    """Advance ``(s [m], v [m/s])`` by ``dt`` [s] at acceleration ``a`` [m/s^2].

    Returns the new ``(s, v)``. The speed never leaves ``[v_min, v_max]`` (given that it
    starts inside).
    """
    v_new = v + a * dt
    if v_new > v_max:
        t1 = (v_max - v) / a
        ds = (v_max * v_max - v * v) / (2.0 * a) + v_max * (dt - t1)
        return s + ds, v_max
    if v_new < v_min:
        t1 = (v_min - v) / a
        ds = (v_min * v_min - v * v) / (2.0 * a) + v_min * (dt - t1)
        return s + ds, v_min
    return s + (v * dt + a * dt * dt / 2.0), v_new


def check_state(name: str, x, vehicle) -> tuple[float, float]:
    """``x`` as ``(s [m], v [m/s])``, or :class:`ConfigError`: it must be a pair of finite
    numbers with the speed inside the vehicle's ``[v_min, v_max]``."""
    try:
        s, v = (float(x[0]), float(x[1]))
        if len(x) != 2:
            raise ValueError
    except (TypeError, ValueError, IndexError):
        raise ConfigError(f"{name} = {x!r} is not a state (s [m], v [m/s])") from None
    if not (np.isfinite(s) and np.isfinite(v)) or not vehicle.v_min_mps <= v <= vehicle.v_max_mps:
        raise ConfigError(f"{name} = ({s!r}, {v!r}) is out of range; allowed: finite s, "
                          f"v in [{vehicle.v_min_mps:g}, {vehicle.v_max_mps:g}] m/s")
    return s, v
