"""The scenario template (docs/method.md §10): two paths, their conflict, initial states.

A scenario module builds a :class:`Scenario` from a configuration; this module holds what
every scenario shares: the initial-state draw with its retry rule (§8), the tests of the
closed loop's outcome (arrival at each line, footprint collision, clearing the conflict), the
distance between the vehicles, and who arrived first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import packing as slot
from ..config import Config, ConfigError
from ..geometry import Path, footprints_overlap


class InitialStateError(ConfigError):
    """No admissible initial state within ``scenario.max_init_draws`` draws."""


#: Distance [m] of the nominal start before the yield line when ``scenario.*_s0_m`` is unset:
#: the paper starts 13.5 m before its crossing line (-20 m with the line at -6.5 m)...
NOMINAL_LEAD_M = 13.5
#: ... which is 12.5 m before its safety zone (-7.5 m): the start is never closer than that to
#: the conflict zone (shallow crossings have long zones).
NOMINAL_ZONE_LEAD_M = 12.5


@dataclass(frozen=True)
class Scenario:
    """Two paths in conflict and everything that depends on the geometry.

    ``av`` and ``hv`` are the vehicles' :class:`~persuasive.geometry.Path` (with their lines
    and zones); ``conflict`` the kind of distance (``persuasive.packing.CONFLICT_*``);
    ``lane_width_m`` is used for drawing the roads; ``lane_shared``: past ``s = 0`` both
    paths are one lane (a vehicle ahead there is a leader to car-following models).
    """

    kind: str
    config: Config
    av: Path
    hv: Path
    conflict: int
    min_dist_m: float
    lane_width_m: float
    lane_shared: bool = False  #: the paths share one lane past ``s = 0`` (a merge)

    # -- the initial state (§8) ----------------------------------------------------------------

    def nominal_state(self) -> np.ndarray:
        """The nominal 8-dim initial state ``[x, vx, y, vy]`` of the AV then the HV, where
        ``x`` is the position along the vehicle's own path."""
        sc = self.config.scenario
        return np.array([self.nominal_s0("av"), sc.av_v0_mps, 0.0, 0.0,
                         0.0, 0.0, self.nominal_s0("hv"), sc.hv_v0_mps])

    def nominal_s0(self, who: str) -> float:
        """The nominal initial position of ``"av"`` or ``"hv"`` [m]: as configured, else
        13.5 m before its yield line or 12.5 m before its conflict zone, whichever is further
        (-20 m at the paper's intersection)."""
        s0 = getattr(self.config.scenario, f"{who}_s0_m")
        if s0 is not None:
            return s0
        path = getattr(self, who)
        return min(path.yield_s - NOMINAL_LEAD_M, path.zone[0] - NOMINAL_ZONE_LEAD_M)

    def can_stop(self, who: str, s: float, v: float) -> bool:
        """Whether the vehicle ``who`` at ``(s, v)`` can stop before its conflict zone.

        ``v^2 / (2 (zone_lo - s)) < |u_min|`` for a vehicle outside the zone (``zone_lo - s >
        0``) with a speed inside its limits (``zone_lo = -min_dist`` at the intersection).
        """
        path = getattr(self, who)
        veh = path.vehicle
        room = path.zone[0] - s
        if not room > 0.0 or not veh.v_min_mps <= v <= veh.v_max_mps:
            return False
        return v * v / (2.0 * room) < abs(veh.u_min_mps2)

    def av_stands_before_occupancy(self, s: float, v: float) -> bool:
        """Whether the AV at ``(s, v)`` can still stand before its occupancy interval by
        braking at its ``u_min``: the test of the shield's ``yields_before`` (the same reach
        time, on the widened interval the kernels read), which puts the state in the shield's
        invariant set ``S`` (braking for ever is certified, docs/method.md §12.2). An AV that
        never conflicts (an empty interval) always does."""
        from ..safety.shield import reach_time

        lo = slot.widened(*self.av.shield_interval)[0]
        if lo == math.inf:
            return True
        veh = self.av.vehicle
        # its weakest braking under acceleration noise (the shield's own test)
        u = veh.u_min_mps2 + self.config.simulation.accel_noise_mps2
        return reach_time(float(s), float(v), u, lo, veh.v_min_mps, veh.v_max_mps) == math.inf

    def initial_states(self, uniform: Callable[[int], np.ndarray]) -> tuple[tuple[float, float],
                                                                             tuple[float, float]]:
        """Draw the initial ``(x_AV, x_HV)``, each ``(s [m], v [m/s])`` (§8).

        ``uniform(8)`` returns eight uniforms in [0, 1) (the run's stream: ``random_sample`` of
        the legacy stream, or ``random`` of the initial state's own stream). Eight uniforms per
        draw, for the 8-dim state; ``U(-w, w) = -w + 2 w r``. While a vehicle cannot stop
        before its conflict zone, or the AV cannot stand before its occupancy interval
        (:meth:`av_stands_before_occupancy`: every initial state is in the shield's invariant
        set, also where the interval starts before the zone, on a wide left turn or with a
        small ``vehicle.safety_factor``; at the default geometries the first rule implies it,
        so their draws are unchanged), eight more are drawn and *added* to the state already
        drawn (the reference behaviour). Gives up with :class:`InitialStateError` after
        ``scenario.max_init_draws`` draws.
        """
        sc = self.config.scenario
        width = np.array([sc.av_s0_halfwidth_m, sc.av_v0_halfwidth_mps, 0.0, 0.0,
                          0.0, 0.0, sc.hv_s0_halfwidth_m, sc.hv_v0_halfwidth_mps])
        state = self.nominal_state()
        for _ in range(sc.max_init_draws):
            r = uniform(8)
            state = state + (-width + (2.0 * width) * r)
            x_av = (float(state[0]), float(state[1]))
            x_hv = (float(state[6]), float(state[7]))
            if self.can_stop("av", *x_av) and self.can_stop("hv", *x_hv) and \
                    self.av_stands_before_occupancy(*x_av):
                return x_av, x_hv
        raise InitialStateError(
            f"scenario: no initial state lets both vehicles stop before the conflict zone (and "
            f"the AV before its occupancy interval) in {sc.max_init_draws} draws "
            f"(scenario.max_init_draws); narrow the half-widths"
        )

    def check_starts(self) -> None:
        """A clear error when a vehicle's every nominal start lies inside its conflict zone,
        or when the AV's nominal state can stop before its conflict zone but not before its
        occupancy interval, which then starts before the zone (a wide left turn, a small
        ``vehicle.safety_factor``): the draw would rely on its random steps alone to find a
        state in the shield's invariant set."""
        sc = self.config.scenario
        for who in ("av", "hv"):
            s0, hw = self.nominal_s0(who), getattr(sc, f"{who}_s0_halfwidth_m")
            lo = getattr(self, who).zone[0]
            if s0 - hw >= lo:
                raise ConfigError(
                    f"scenario.{who}_s0_m = {s0:g} (half-width {hw:g}) puts every initial "
                    f"position of the {who.upper()} inside its conflict zone, which starts at "
                    f"{lo:.2f} m in the {self.kind} scenario; allowed: below {lo + hw:.2f} m")
        s0, v0 = self.nominal_s0("av"), sc.av_v0_mps
        # the geometry's case: a start that stops before the zone but not before the interval
        if self.can_stop("av", s0, v0) and not self.av_stands_before_occupancy(s0, v0):
            lo = slot.widened(*self.av.shield_interval)[0]
            u = abs(self.av.vehicle.u_min_mps2)
            raise ConfigError(
                f"scenario.av_s0_m = {s0:g} at scenario.av_v0_mps = {v0:g}: the AV cannot stop "
                f"before its occupancy interval, which starts at {lo:.2f} m in the {self.kind} "
                f"scenario (braking at {u:g} m/s^2 takes {v0 * v0 / (2.0 * u):.2f} m); "
                f"allowed: below {lo - v0 * v0 / (2.0 * u):.2f} m, or a slower start")

    # -- the outcome's tests (§7) --------------------------------------------------------------

    def positions(self, who: str, s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x, y, heading_rad)`` of ``who`` at path positions ``s``."""
        path = getattr(self, who)
        x, y = path.xy(s)
        return x, y, path.heading(s)

    def distance(self, s_av, s_hv) -> np.ndarray:
        """Distance between the vehicles [m] (arrays broadcast), as the kernels compute it:
        ``sqrt(s_av^2 + s_hv^2)`` for a conflict along the paths, else between the centres."""
        s_av, s_hv = np.asarray(s_av, float), np.asarray(s_hv, float)
        if self.conflict == slot.CONFLICT_ALONG_PATHS:
            return np.sqrt(s_av ** 2 + s_hv ** 2)
        xa, ya = self.av.xy(s_av)
        xh, yh = self.hv.xy(s_hv)
        return np.sqrt((xa - xh) ** 2 + (ya - yh) ** 2)

    def collides(self, s_av, s_hv) -> np.ndarray:
        """The footprints (oriented rectangles) overlap, elementwise."""
        s_av, s_hv = np.asarray(s_av, float), np.asarray(s_hv, float)
        xa, ya = self.av.xy(s_av)
        xh, yh = self.hv.xy(s_hv)
        va, vh = self.av.vehicle, self.hv.vehicle
        return footprints_overlap(xa, ya, self.av.direction(s_av), va.length_m, va.width_m,
                                  xh, yh, self.hv.direction(s_hv), vh.length_m, vh.width_m)

    def at_line(self, who: str, s) -> np.ndarray:
        """Arrived at the vehicle's first-arrival line, with the Q7 tolerance:
        ``s >= first_s - tol`` (at the intersection ``-(6.5 + 0.2)``)."""
        tol = self.config.effective_quirks.q7_arrival_tolerance_m
        return np.asarray(s) >= getattr(self, who).first_s - tol

    @staticmethod
    def at_conflict_point(s) -> np.ndarray:
        """Arrived at the path's reference point: ``s >= 0``."""
        return np.asarray(s) >= 0.0

    def cleared(self, who: str, s) -> np.ndarray:
        """Past the position where the vehicle stops conflicting with the other path."""
        return np.asarray(s) >= getattr(self, who).clear_s

    def extent(self) -> tuple[float, float, float, float]:
        """A box ``(x_lo, x_hi, y_lo, y_hi)`` [m] around the conflict, for drawing."""
        pts = np.concatenate([p.polyline(p.yield_s - 20.0, max(p.clear_s, 0.0) + 20.0)
                              for p in (self.av, self.hv) if math.isfinite(p.yield_s)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def shape(config: Config, who: str):
    """The :class:`~persuasive.geometry.VehicleShape` of ``"av"`` or ``"hv"``."""
    from ..geometry import VehicleShape

    v = config.vehicle_of(who)
    return VehicleShape(v.length_m, v.width_m, v.v_min_mps, v.v_max_mps, v.u_min_mps2,
                        v.u_max_mps2)


def crossing_occupancies(paths: dict) -> dict:
    """Each path's occupancy interval against the other's whole path (two paths that cross:
    the intersection, the crossing, the left turn)."""
    from ..geometry import occupancy_interval

    return {"av": occupancy_interval(paths["av"], paths["hv"]),
            "hv": occupancy_interval(paths["hv"], paths["av"])}


def with_occupancies(paths: dict, occupancies: Callable[[dict], dict], config: Config
                     ) -> dict:
    """``paths`` (``{"av": Path, "hv": Path}``) with their occupancy intervals
    ``occupancies(paths)`` and the shield's, the same on both paths' footprints enlarged by
    half the clearance ``av.shield_margin_m`` (unset or 0: none, the same intervals;
    docs/method.md §12.2)."""
    from dataclasses import replace

    occ = occupancies(paths)
    margin = config.shield_margin_m
    shield = None
    if margin > 0.0:
        shield = occupancies({k: p.inflated(0.5 * margin) for k, p in paths.items()})
    return {k: replace(p, occupancy=occ[k], shield_occupancy=None if shield is None
                       else shield[k]) for k, p in paths.items()}


def pair_min_dist(config: Config) -> float:
    """The safety distance of the pair: ``safety_factor * (l_AV + l_HV) / 2`` (7.5 m)."""
    la, lh = config.vehicle_of("av").length_m, config.vehicle_of("hv").length_m
    return config.vehicle.safety_factor * ((la + lh) / 2)


def first_arrival(av_arrived: np.ndarray, hv_arrived: np.ndarray) -> tuple[int, int | None]:
    """Who arrived first: label 1 AV, 2 HV, 3 same step, 0 neither; and the step index.

    ``av_arrived``, ``hv_arrived``: boolean per step (after the step's advance).
    """
    either = np.flatnonzero(av_arrived | hv_arrived)
    if either.size == 0:
        return 0, None
    k = int(either[0])
    return (1 if av_arrived[k] else 0) + (2 if hv_arrived[k] else 0), k
