"""The shield as every loop and adapter applies it: decide, then filter (docs/method.md §12.2).

A step of any world is the same two halves: the AV's policy *decides* (proposes an acceleration
from what it measured), then the shield *filters* the proposal through its one compiled entry
point, :func:`persuasive.safety.shield.shield_filter`, which returns the acceleration to apply and
a verdict. The compiled closed loop (``persuasive.world.run_loop``) calls it directly (through
``shield_filter_one``, its one-conflict buffers in one array); everything in Python (the Python
loop, ``Planner``, the adapter for outside simulators and through it highway-env and SUMO) calls it
through a :class:`ShieldFilter`, which holds the shield's kind (its one encoding: the packed
``SHIELD_*`` id), the step and the buffers, so that a step allocates nothing and every check the
shield makes is written once.

The planner's own features that anticipate the shield are settings of the planner, not of the
shield (``mpc.shield_aware``, ``mpc.confidence_filter``): an outside simulator's per-vehicle
planners are the same planner as in the closed loop; they only leave the filtering to the one
shield over all the vehicles.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .. import packing as slot
from .shield import (N_CONFLICT, OFF, conflict_vector, one_buffer, shield_filter,
                     shield_filter_one, verdict_name)


class ShieldFilter:
    """The shield of one AV: ``kind`` (``persuasive.packing.SHIELD_*``, or its name), applied
    every ``dt_s`` seconds. :meth:`one` filters against the closed loop's one other vehicle
    (its conflict vector from :meth:`closed_loop`); :meth:`among` against any number of
    outside vehicles at once."""

    __slots__ = ("kind", "dt_s", "u_brake", "on", "_buf", "_lead", "_window")

    def __init__(self, kind: float | str, dt_s: float, u_brake: float,
                 conflict: np.ndarray | None = None):
        self.kind = float(slot.SHIELD_KIND_IDS[kind] if isinstance(kind, str) else kind)
        self.dt_s = float(dt_s)
        #: the AV's braking fallback [m/s^2] for a non-finite proposal among no vehicle
        self.u_brake = float(u_brake)
        self.on = self.kind != slot.SHIELD_OFF  #: False: every proposal is applied as is
        self._buf = one_buffer(np.zeros(N_CONFLICT) if conflict is None
                               else np.asarray(conflict, float).reshape(N_CONFLICT))
        self._lead = np.zeros(3)
        self._window = np.empty((1, 3))

    @classmethod
    def closed_loop(cls, P_av: np.ndarray, P_hv: np.ndarray, dt_s: float) -> ShieldFilter:
        """The filter of a two-vehicle world from its packed parameters (kind ``P_av[SHIELD]``,
        the conflict vector of the two paths)."""
        C = np.empty(N_CONFLICT)
        conflict_vector(P_av, P_hv, C)
        return cls(P_av[slot.SHIELD], dt_s, P_av[slot.U_MIN], C)

    def one(self, proposed: float, x_R: Sequence[float], x_H: Sequence[float]
            ) -> tuple[float, int]:
        """Filter ``proposed`` with the AV at ``x_R = (s, v)`` and the other vehicle at
        ``x_H`` (the conflict given at construction): ``(applied, verdict code)``. Raises
        ValueError for a non-finite proposal without a shield (nothing can replace it, and no
        world propagates a non-finite state)."""
        if not self.on:
            return self.unfiltered(proposed)
        return shield_filter_one(self.kind, proposed, x_R[0], x_R[1], self.dt_s, self.u_brake,
                                 x_H[0], x_H[1], self._buf)

    def among(self, proposed: float, v_R: float, s_R: np.ndarray, s_H: np.ndarray,
              v_H: np.ndarray, C: np.ndarray, lead: Sequence[float] = (0.0, 0.0, 0.0)
              ) -> tuple[float, int]:
        """Filter ``proposed`` at AV speed ``v_R`` against ``n`` other vehicles (``s_R[j],
        s_H[j], v_H[j], C[j]``: :func:`~persuasive.safety.shield.shield_filter`; ``lead``
        too): ``(applied, verdict code)``; a non-finite proposal as in :meth:`one`."""
        if not self.on:
            return self.unfiltered(proposed)
        n = s_R.shape[0]
        if self._window.shape[0] < n:
            self._window = np.empty((n, 3))
        self._lead[:] = lead
        a, code = shield_filter(self.kind, proposed, v_R, self.dt_s, self.u_brake, s_R, s_H,
                                v_H, C, self._lead, self._window)
        return float(a), int(code)

    @staticmethod
    def name(code: int) -> str | None:
        """A verdict's name ("admitted", "brake", "go", "uncertified"; None: no shield)."""
        return verdict_name(code)

    @staticmethod
    def unfiltered(proposed: float) -> tuple[float, int]:
        """What no shield does to ``proposed``: ``(proposed, OFF)``; a non-finite proposal
        raises ValueError (nothing can replace it, and no world propagates a non-finite
        state)."""
        if not math.isfinite(proposed):
            raise ValueError(f"the AV's policy proposed a non-finite acceleration "
                             f"({proposed!r}) and no shield replaces it (av.shield = off)")
        return proposed, OFF


__all__ = ["ShieldFilter"]
