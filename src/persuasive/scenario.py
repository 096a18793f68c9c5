"""The two-vehicle unsignalled intersection (spec sections 1, 7 and 8).

Two single-lane roads cross at the conflict point (0, 0); the AV drives along +x, the HV along
+y, and each is a 1-D state ``(s, v)`` on its own road. Everything specific to the intersection
lives here: geometry, initial-state sampling, the distance, collision and arrival tests. The
agents and the game only ever see the distance ``sqrt(s_AV^2 + s_HV^2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import Config, ConfigError


class InitialStateError(ConfigError):
    """No admissible initial state within ``scenario.max_init_draws`` draws."""


@dataclass(frozen=True)
class Intersection:
    """Geometry and tests of the intersection, from a :class:`~persuasive.config.Config`."""

    config: Config

    @property
    def stop_distance_m(self) -> float:
        """The crossing line is at ``s = -stop_distance_m`` [m]."""
        return self.config.vehicle.stop_distance_m

    @property
    def min_dist_m(self) -> float:
        return self.config.vehicle.min_dist_m

    def distance(self, s_av, s_hv):
        """Distance between the vehicles [m] (arrays broadcast)."""
        return np.sqrt(np.asarray(s_av) ** 2 + np.asarray(s_hv) ** 2)

    def collides(self, s_av, s_hv):
        """Footprints overlap: both ``|s| <= (length + width) / 2``."""
        half = self.config.vehicle.collision_half_extent_m
        return (np.abs(s_av) <= half) & (np.abs(s_hv) <= half)

    def at_line(self, s):
        """Arrived at the crossing line, with the Q7 tolerance: ``s >= -(stop + tol)``."""
        tol = self.config.effective_quirks.q7_arrival_tolerance_m
        return np.asarray(s) >= -(self.stop_distance_m + tol)

    @staticmethod
    def at_conflict_point(s):
        """Arrived at the conflict point: ``s >= 0``."""
        return np.asarray(s) >= 0.0

    def can_stop(self, s: float, v: float) -> bool:
        """Whether a vehicle at ``(s, v)`` can stop before the safety zone.

        ``v^2 / (2 (-s - min_dist)) < |u_min|``, and the vehicle is outside the zone with a
        speed inside the vehicle's limits.
        """
        veh = self.config.vehicle
        room = -s - self.min_dist_m
        if room <= 0.0 or not veh.v_min_mps <= v <= veh.v_max_mps:
            return False
        return v * v / (2.0 * room) < abs(veh.u_min_mps2)

    def initial_states(self, rng: np.random.RandomState) -> tuple[tuple[float, float], ...]:
        """Draw the initial ``(x_AV, x_HV)``, each ``(s [m], v [m/s])`` (spec section 8).

        Eight uniforms per draw, for the 8-dim state ``[x, vx, y, vy]`` of the AV then of the
        HV; ``U(-w, w) = -w + 2 w r``. While a vehicle cannot stop before the safety zone, the
        eight uniforms are drawn again and *added* to the state already drawn (the reference
        behaviour). Gives up with :class:`InitialStateError` after ``max_init_draws`` draws.
        """
        sc = self.config.scenario
        nominal = np.array([sc.av_s0_m, sc.av_v0_mps, 0.0, 0.0, 0.0, 0.0, sc.hv_s0_m, sc.hv_v0_mps])
        width = np.array([sc.av_s0_halfwidth_m, sc.av_v0_halfwidth_mps, 0.0, 0.0,
                          0.0, 0.0, sc.hv_s0_halfwidth_m, sc.hv_v0_halfwidth_mps])
        state = nominal
        for _ in range(sc.max_init_draws):
            r = rng.random_sample(8)
            state = state + (-width + (2.0 * width) * r)
            x_av = (float(state[0]), float(state[1]))
            x_hv = (float(state[6]), float(state[7]))
            if self.can_stop(*x_av) and self.can_stop(*x_hv):
                return x_av, x_hv
        raise InitialStateError(
            f"scenario: no initial state lets both vehicles stop before the safety zone in "
            f"{sc.max_init_draws} draws (scenario.max_init_draws); narrow the half-widths"
        )


def first_arrival(av_arrived: np.ndarray, hv_arrived: np.ndarray) -> tuple[int, int | None]:
    """Who arrived first: label 1 AV, 2 HV, 3 same step, 0 neither; and the step index.

    ``av_arrived``, ``hv_arrived``: boolean per step (after the step's advance).
    """
    either = np.flatnonzero(av_arrived | hv_arrived)
    if either.size == 0:
        return 0, None
    k = int(either[0])
    return (1 if av_arrived[k] else 0) + (2 if hv_arrived[k] else 0), k
