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
"""

from __future__ import annotations

from numba import njit


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

