"""One validated, frozen configuration for the method, the scenario and the simulation.

Every concern has its own frozen dataclass; :class:`Config` groups them. Defaults are the
paper's values (docs/method.md §1-8). Units are in the field names (``_m``, ``_mps``, ``_mps2``,
``_s``) and in each field's comment. Validation happens once, at construction, and raises
:class:`ConfigError` with a one-line message naming the field, its value and the allowed range.

Two execution modes exist (docs/method.md §9): ``"paper"`` keeps the reference implementation's
quirks Q1..Q7, ``"corrected"`` fixes Q1, Q2, Q3 and Q5. Each quirk can also be switched on its
own in :class:`Quirks` (``None`` means "as the mode says").
"""

from __future__ import annotations

import functools
import hashlib
import math
import tomllib
from dataclasses import MISSING, asdict, dataclass, field, fields, is_dataclass, replace
from numbers import Integral
from pathlib import Path
from typing import Any, Literal, get_args

Role = Literal["leader", "follower"]
Mode = Literal["paper", "corrected"]
AVKind = Literal["persuasive", "passive", "cv", "lfg", "yield", "level1", "level2",
                 "lfg-rule"]
HVKind = Literal["lfg", "stubborn", "noisy", "idm", "aggressive", "replay", "adversary",
                 "deceptive", "random", "person"]
ShieldKind = Literal["off", "worst-case", "responsive", "responsibility"]
ScenarioKind = Literal["intersection", "crossing", "left-turn", "merge"]
NoiseKind = Literal["none", "uniform", "gaussian"]
StreamLayout = Literal["legacy", "per-agent"]

ROLES: tuple[str, ...] = get_args(Role)
MODES: tuple[str, ...] = get_args(Mode)
AV_KINDS: tuple[str, ...] = get_args(AVKind)
HV_KINDS: tuple[str, ...] = get_args(HVKind)
#: The human kinds the simulation runs by itself (all but ``person``).
SIMULATED_HV_KINDS: tuple[str, ...] = tuple(k for k in HV_KINDS if k != "person")
SCENARIO_KINDS: tuple[str, ...] = get_args(ScenarioKind)
#: The scenarios of many vehicles (``persuasive.many``): ``scenario.kind`` takes these after
#: the two-vehicle :data:`SCENARIO_KINDS`, and the ``[junction]`` section describes it.
MANY_SCENARIO_KINDS: tuple[str, ...] = ("junction",)
NOISE_KINDS: tuple[str, ...] = get_args(NoiseKind)
STREAM_LAYOUTS: tuple[str, ...] = get_args(StreamLayout)
SHIELD_KINDS: tuple[str, ...] = get_args(ShieldKind)
#: Other names accepted for AV kinds (``mpc`` was the persuasive planner's first name).
AV_KIND_ALIASES = {"mpc": "persuasive"}


class ConfigError(ValueError):
    """An out-of-range or inconsistent parameter; the message is one line."""


#: The online posterior's prior over p_a, Beta(a, b) (mean 0.7), and its grid size.
DEFAULT_P_A_PRIOR = (7.0, 3.0)
DEFAULT_P_A_GRID = 21

#: Smallest accepted chance-constraint level ``mpc.epsilon``.
EPSILON_MIN = 1e-12

#: Corrected mode's default liveness and clearance (issue 39: the defaults are the measured
#: best, docs/method.md §12.14). The yield lines foresight picks one of per run [m]
#: (``av.yield_line_choices_m``; with a shield on, no fixed ``av.yield_line_m`` and a fixed
#: ``mpc.p_a_hat``), and the shield's clearance between the footprints [m]
#: (``av.shield_margin_m``; with a shield on). Paper mode keeps neither (the published runs).
DEFAULT_YIELD_LINE_CHOICES_M = (0.0, 3.75, 8.0)
DEFAULT_SHIELD_MARGIN_M = 0.1
#: The named ablation of those defaults: corrected mode as it shipped before them, the
#: shield's line at the interval and no clearance (``--set "av.yield_line_choices_m=[]"
#: --set av.shield_margin_m=0``; docs/results.md keeps its tables under this name).
LINE_AT_INTERVAL = {"av.yield_line_choices_m": [], "av.shield_margin_m": 0.0}


def _fail(name: str, value: Any, allowed: str) -> None:
    raise ConfigError(f"{name} = {value!r} is out of range; allowed: {allowed}")


def _number(name: str, value: Any, *, integer: bool = False) -> float:
    """Return ``value`` if it is a finite real number (an int when ``integer``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        kind = "an integer" if integer else "a finite number"
        raise ConfigError(f"{name} = {value!r} is not {kind}")
    if integer and not isinstance(value, int):
        raise ConfigError(f"{name} = {value!r} is not an integer")
    if not math.isfinite(value):
        _fail(name, value, "a finite number")
    return value


def _in_range(
    name: str,
    value: Any,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
) -> None:
    """``value`` is a number in the interval, or :class:`ConfigError` naming the interval; a
    NaN or an infinity is out of range too, "a finite number in" the interval."""
    left = "(" if lo_open or lo == -math.inf else "["
    right = ")" if hi_open or hi == math.inf else "]"
    interval = f"{left}{lo:g}, {hi:g}{right}"
    if isinstance(value, float) and not math.isfinite(value) and not integer:
        _fail(name, value, f"a finite number in {interval}")
    _number(name, value, integer=integer)
    too_low = value <= lo if lo_open else value < lo
    too_high = value >= hi if hi_open else value > hi
    if too_low or too_high:
        _fail(name, value, interval)


def _choice(name: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        _fail(name, value, " | ".join(allowed))


def _flag(name: str, value: Any) -> None:
    if not isinstance(value, bool):
        raise ConfigError(f"{name} = {value!r} is not a boolean (true | false)")


@dataclass(frozen=True)
class VehicleParams:
    """Vehicle geometry and actuation limits (docs/method.md §1)."""

    length_m: float = 5.0  #: vehicle length [m]
    width_m: float = 2.5  #: vehicle width [m]
    lane_width_m: float = 4.0  #: lane width [m]
    safety_factor: float = 1.5  #: safe set ``d >= safety_factor * length_m`` [-]
    v_min_mps: float = 0.0  #: lowest speed [m/s]
    v_max_mps: float = 10.0  #: highest speed [m/s]
    u_min_mps2: float = -2.0  #: strongest braking [m/s^2], negative
    u_max_mps2: float = 1.0  #: strongest acceleration [m/s^2], positive

    def __post_init__(self) -> None:
        p = "vehicle."
        _in_range(p + "length_m", self.length_m, 0.0, lo_open=True)
        _in_range(p + "width_m", self.width_m, 0.0, lo_open=True)
        _in_range(p + "lane_width_m", self.lane_width_m, 0.0, lo_open=True)
        _in_range(p + "safety_factor", self.safety_factor, 0.0, lo_open=True)
        _in_range(p + "v_min_mps", self.v_min_mps, 0.0)
        _in_range(p + "v_max_mps", self.v_max_mps, self.v_min_mps, lo_open=True)
        _in_range(p + "u_min_mps2", self.u_min_mps2, hi=0.0, hi_open=True)
        _in_range(p + "u_max_mps2", self.u_max_mps2, 0.0, lo_open=True)

    @property
    def stop_distance_m(self) -> float:
        """Distance of the crossing line before the conflict point [m] (6.5 m)."""
        return self.lane_width_m + self.length_m / 2

    @property
    def min_dist_m(self) -> float:
        """Safety distance between the vehicles [m] (7.5 m)."""
        return self.safety_factor * self.length_m

    @property
    def collision_half_extent_m(self) -> float:
        """Footprints overlap when both ``|s| <= (length + width) / 2`` [m] (3.75 m)."""
        return (self.length_m + self.width_m) / 2


@dataclass(frozen=True)
class LibraryParams:
    """The OVM trajectory library, the action set U (docs/method.md §2)."""

    n_samples: int = 50  #: samples per trajectory [-]
    sample_dt_s: float = 0.1  #: time between samples [s]
    n_mesh: int = 10  #: target speeds in the mesh; the library holds n_mesh + 1 trajectories
    alpha: float = 0.4  #: OVM headway gain [1/s]
    beta: float = 0.5  #: OVM speed-difference gain [1/s]
    kappa: float = 0.6  #: OVM speed per metre of headway [1/s]
    h_st_m: float = 5.0  #: standstill headway [m]

    def __post_init__(self) -> None:
        p = "library."
        _in_range(p + "n_samples", self.n_samples, 3, 10_000, integer=True)
        _in_range(p + "sample_dt_s", self.sample_dt_s, 0.0, 10.0, lo_open=True)
        _in_range(p + "n_mesh", self.n_mesh, 2, 1000, integer=True)
        _in_range(p + "alpha", self.alpha, 0.0)
        _in_range(p + "beta", self.beta, 0.0)
        _in_range(p + "kappa", self.kappa, 0.0, lo_open=True)
        _in_range(p + "h_st_m", self.h_st_m, 0.0)

    @property
    def horizon_s(self) -> float:
        """Trajectory length ``T = n_samples * sample_dt_s`` [s] (5 s)."""
        return self.n_samples * self.sample_dt_s

    @property
    def n_traj(self) -> int:
        """Number of candidate trajectories ``|U| = n_mesh + 1``."""
        return self.n_mesh + 1


@dataclass(frozen=True)
class RewardParams:
    """Step rewards and discounting (docs/method.md §3)."""

    w_c: float = 100.0  #: weight of the collision term [-]
    w_u: float = 0.1  #: weight of the acceleration effort [s^2]
    discount: float = 0.99  #: discount ``lambda`` per sample [-]

    def __post_init__(self) -> None:
        _in_range("reward.w_c", self.w_c, 0.0)
        _in_range("reward.w_u", self.w_u, 0.0)
        _in_range("reward.discount", self.discount, 0.0, 1.0, lo_open=True)


@dataclass(frozen=True)
class RoleParams:
    """Role adaptation of an LFG player (docs/method.md §5)."""

    p_a: float = 1.0  #: the human's willingness to change role [-], in [0, 1]
    adapt_role: bool = True  #: False fixes every LFG player's role
    prior_leader: float = 0.5  #: initial belief that the other leads [-]
    w_s_m2: float = 0.03  #: residual variance of the position, ``W[0, 0]`` [m^2]
    w_v_m2ps2: float = 0.01  #: residual variance of the speed, ``W[1, 1]`` [m^2/s^2]

    def __post_init__(self) -> None:
        _in_range("roles.p_a", self.p_a, 0.0, 1.0)
        _flag("roles.adapt_role", self.adapt_role)
        _in_range("roles.prior_leader", self.prior_leader, 0.0, 1.0, lo_open=True, hi_open=True)
        _in_range("roles.w_s_m2", self.w_s_m2, 0.0, lo_open=True)
        _in_range("roles.w_v_m2ps2", self.w_v_m2ps2, 0.0, lo_open=True)


@dataclass(frozen=True)
class MPCParams:
    """The persuasive branch MPC of the AV (docs/method.md §6)."""

    epsilon: float = 0.02  #: chance-constraint level: P(safe) > 1 - epsilon at every sample [-]
    #: the AV's estimate of p_a [-]; None means equal to roles.p_a; "online": a posterior over
    #: p_a on a grid, updated every step (docs/method.md §13.9)
    p_a_hat: float | str | None = None
    #: online only: the Beta(a, b) prior over p_a [-], both > 0; unset means (7, 3), mean 0.7
    p_a_prior: tuple[float, float] | None = None
    #: online only: points of the grid over p_a on [0, 1] (integer in [2, 101]); unset means 21
    p_a_grid: int | None = None
    # The planner's own features that anticipate the shield (docs/method.md §12.3); settings of
    # the planner, not of the shield, so that a planner whose proposals another loop filters
    # (an outside simulator's per-vehicle planners) is the same planner:
    #: with a shield on (``av.shield``), candidates whose first step it would reject count as
    #: infeasible
    shield_aware: bool = True
    #: the model-confidence filter: track how well the model explains the human and plan for
    #: the worst case when it does not; unset means on exactly when a shield is on
    confidence_filter: bool | None = None
    #: below this model confidence P(model) the planner stops persuading and only takes
    #: candidates that yield before the conflict or cross it whatever the human does [-]; 0: never
    confidence_threshold: float = 0.2
    #: width of the model's acceleration prediction in the confidence filter [m/s^2]
    confidence_accel_std_mps2: float = 0.3
    #: probability per step that the human switches between following the model and not [-]
    confidence_switch: float = 0.05

    def __post_init__(self) -> None:
        # below 1e-12 the threshold 1 - epsilon rounds to (nearly) 1.0 and no candidate is ever
        # feasible; the bound keeps the constraint meaningful
        _in_range("mpc.epsilon", self.epsilon, EPSILON_MIN, 1.0, hi_open=True)
        if isinstance(self.p_a_hat, str):
            if self.p_a_hat != "online":
                _fail("mpc.p_a_hat", self.p_a_hat, 'a number in [0, 1] or "online"')
        elif self.p_a_hat is not None:
            # NaN fails the comparison too, so it is named with the range, not as "not finite"
            if isinstance(self.p_a_hat, bool) or not isinstance(self.p_a_hat, (int, float)) \
                    or not 0.0 <= self.p_a_hat <= 1.0:
                _fail("mpc.p_a_hat", self.p_a_hat, 'a number in [0, 1] or "online"')
        if self.p_a_prior is not None:
            prior = self.p_a_prior
            if (not isinstance(prior, (tuple, list)) or len(prior) != 2
                    or any(isinstance(x, bool) or not isinstance(x, (int, float))
                           or not math.isfinite(x) or x <= 0.0 for x in prior)):
                _fail("mpc.p_a_prior", prior, "two finite numbers [a, b] > 0 (Beta(a, b))")
            object.__setattr__(self, "p_a_prior", tuple(float(x) for x in prior))
        if self.p_a_grid is not None:
            _in_range("mpc.p_a_grid", self.p_a_grid, 2, 101, integer=True)
        _flag("mpc.shield_aware", self.shield_aware)
        if self.confidence_filter is not None:
            _flag("mpc.confidence_filter", self.confidence_filter)
        _in_range("mpc.confidence_threshold", self.confidence_threshold, 0.0, 1.0)
        _in_range("mpc.confidence_accel_std_mps2", self.confidence_accel_std_mps2, 0.0,
                  lo_open=True)
        _in_range("mpc.confidence_switch", self.confidence_switch, 0.0, 0.5)


#: The angles [deg] at which the crossing and the merge mean what they say, and why: at a
#: flatter angle the roads run side by side over several vehicle lengths (the conflict zone
#: reaches ``min_dist / sin(angle)``, more than 29 m at 15 degrees, from the conflict point),
#: the crossing lines recede as ``1 / sin(angle)`` and the vehicles start tens of metres
#: back, never reaching the conflict in a run.
ANGLE_RANGES_DEG = {
    "crossing": (15.0, 165.0, "flatter roads run side by side instead of crossing"),
    "merge": (15.0, 90.0, "a flatter ramp runs beside the lane instead of joining it"),
}


@dataclass(frozen=True)
class ScenarioParams:
    """The scenario and its initial-state sampling (docs/method.md §8 and §10).

    ``kind`` selects the geometry (``persuasive.scenarios``). The initial state is the
    nominal one plus ``U(-w, w)`` per entry; only the listed entries can have a non-zero
    half-width (the lateral entries of the 8-dim state are always exact). A nominal position
    left unset is the scenario's: 13.5 m before the vehicle's yield line (``-20 m`` at the
    paper's intersection).
    """

    #: intersection | crossing | left-turn | merge (two vehicles) | junction (N vehicles, the
    #: ``[junction]`` section; ``persuasive.many``)
    kind: str = "intersection"
    #: crossing: angle between the paths [deg] (90, in [15, 165]); merge: ramp angle (30, in
    #: [15, 90])
    angle_deg: float | None = None
    turn_radius_m: float | None = None  #: left-turn: radius of the AV's arc [m] (1.5 lane widths)
    av_s0_m: float | None = None  #: AV nominal initial position along its path [m]
    av_v0_mps: float = 4.0  #: AV nominal initial speed [m/s]
    hv_s0_m: float | None = None  #: HV nominal initial position along its path [m]
    hv_v0_mps: float = 4.0  #: HV nominal initial speed [m/s]
    av_s0_halfwidth_m: float = 0.0  #: half-width of the AV position disturbance [m]
    av_v0_halfwidth_mps: float = 0.0  #: half-width of the AV speed disturbance [m/s]
    hv_s0_halfwidth_m: float = 5.0  #: half-width of the HV position disturbance [m]
    hv_v0_halfwidth_mps: float = 1.0  #: half-width of the HV speed disturbance [m/s]
    max_init_draws: int = 100  #: draws of the disturbance before giving up [-]

    def __post_init__(self) -> None:
        p = "scenario."
        _choice(p + "kind", self.kind, (*SCENARIO_KINDS, *MANY_SCENARIO_KINDS))
        if self.angle_deg is not None:
            _in_range(p + "angle_deg", self.angle_deg, 0.0, 180.0, lo_open=True, hi_open=True)
            if self.kind in ANGLE_RANGES_DEG:
                lo, hi, why = ANGLE_RANGES_DEG[self.kind]
                if not lo <= self.angle_deg <= hi:
                    _fail(p + "angle_deg", self.angle_deg,
                          f"[{lo:g}, {hi:g}] degrees for a {self.kind} ({why})")
        if self.turn_radius_m is not None:
            _in_range(p + "turn_radius_m", self.turn_radius_m, 0.0, lo_open=True)
        for name in ("av_s0_m", "hv_s0_m"):
            if getattr(self, name) is not None:
                _in_range(p + name, getattr(self, name))
        for name in ("av_v0_mps", "hv_v0_mps"):
            _in_range(p + name, getattr(self, name), 0.0)
        for name in (
            "av_s0_halfwidth_m",
            "av_v0_halfwidth_mps",
            "hv_s0_halfwidth_m",
            "hv_v0_halfwidth_mps",
        ):
            _in_range(p + name, getattr(self, name), 0.0)
        _in_range(p + "max_init_draws", self.max_init_draws, 1, 1_000_000, integer=True)


@dataclass(frozen=True)
class SimulationParams:
    """The closed loop (docs/method.md §7)."""

    dt_s: float = 0.1  #: simulation step [s]; must equal library.sample_dt_s
    n_steps: int = 61  #: decision steps per run [-]
    measurement_noise: NoiseKind = "none"  #: distribution of the measurement noise
    noise_s_m: float = 0.0  #: position noise: half-width (uniform) or std (gaussian) [m]
    noise_v_mps: float = 0.0  #: speed noise: half-width (uniform) or std (gaussian) [m/s]
    accel_noise_mps2: float = 0.0  #: half-width of the uniform acceleration error [m/s^2]
    #: random streams: "legacy" (one MT19937 stream, the reference's order; paper mode) or
    #: "per-agent" (independent streams per agent and for the initial state; corrected mode)
    streams: StreamLayout | None = None
    #: repeated interactions with one human per seed (docs/method.md §13.9): the same human,
    #: fresh initial states, the AV's online posterior over p_a carried over; unset means 1
    interactions: int | None = None

    def __post_init__(self) -> None:
        p = "simulation."
        if self.interactions is not None:
            _in_range(p + "interactions", self.interactions, 1, 1000, integer=True)
        _in_range(p + "dt_s", self.dt_s, 0.0, 10.0, lo_open=True)
        _in_range(p + "n_steps", self.n_steps, 1, 100_000, integer=True)
        _choice(p + "measurement_noise", self.measurement_noise, NOISE_KINDS)
        _in_range(p + "noise_s_m", self.noise_s_m, 0.0)
        _in_range(p + "noise_v_mps", self.noise_v_mps, 0.0)
        _in_range(p + "accel_noise_mps2", self.accel_noise_mps2, 0.0)
        if self.streams is not None:
            _choice(p + "streams", self.streams, STREAM_LAYOUTS)


@dataclass(frozen=True)
class VehicleOverrides:
    """One vehicle's own size and limits; unset fields take ``[vehicle]``'s."""

    length_m: float | None = None  #: vehicle length [m]
    width_m: float | None = None  #: vehicle width [m]
    v_max_mps: float | None = None  #: highest speed [m/s]
    u_min_mps2: float | None = None  #: strongest braking [m/s^2], negative
    u_max_mps2: float | None = None  #: strongest acceleration [m/s^2], positive

    def resolve(self, base: VehicleParams, name: str) -> VehicleParams:
        """``base`` with the set fields applied (validated as a whole, named ``name``)."""
        changes = {k: v for k, v in asdict(self).items() if v is not None}
        if not changes:
            return base
        try:
            return replace(base, **changes)
        except ConfigError as exc:
            raise ConfigError(str(exc).replace("vehicle.", f"{name}.vehicle.", 1)) from None


@dataclass(frozen=True)
class AVParams:
    """The AV's planner (docs/method.md §6, §11).

    ``persuasive``: the paper's branch MPC (alias ``mpc``); ``passive``: the same MPC with no
    role transition at T1; ``cv``: the MPC's candidates and chance constraint against a
    constant-velocity human; ``lfg``: an adaptive-role LFG player (the 2-LFG case); ``yield``:
    yields until the human has cleared the conflict, then goes; ``level1``, ``level2``: a
    level-k player (``persuasive.policies.levelk``), the best response to the human's
    level-(k-1) trajectory; ``lfg-rule``: Li et al.'s LFG player whose role comes from the
    traffic rule (``persuasive.policies.lfg_rule``; ``responsibility.right_of_way``, first
    come when unset), pairwise over many vehicles.
    """

    #: persuasive | passive | cv | lfg | yield | level1 | level2 | lfg-rule
    kind: AVKind = "persuasive"
    role: Role | None = None  #: initial role of an LFG AV; unset: the other of hv.role
    #: the safety shield around the planner (docs/method.md §12): off | worst-case |
    #: responsive | responsibility (§12.13, the ``[responsibility]`` rule); unset: off in
    #: paper mode, worst-case in corrected mode
    shield: ShieldKind | None = None
    #: responsive shield: the human may do anything for this long, then brakes [s]
    shield_response_s: float = 1.0
    #: the shield's yield line: the AV yields standing this far before the start of its
    #: occupancy interval [m] (docs/method.md §12.8); past the point where it can no longer
    #: stand there it commits and prefers driving through; unset: 0, at the interval
    yield_line_m: float | None = None
    #: foresight: candidate yield lines [m], one picked per run by predicting the run with the
    #: AV's own model of the human for each (docs/method.md §12.12); ``[]``: off (a line at
    #: the interval, unless ``yield_line_m``); unset: [0, 3.75, 8] in corrected mode with a
    #: shield on, no ``yield_line_m`` and a fixed ``mpc.p_a_hat``, else off
    #: (:attr:`Config.yield_line_choices`)
    yield_line_choices_m: tuple[float, ...] | None = None
    #: the shield's clearance between the two footprints [m]: kept in its occupancy test and
    #: the follower's gap, so that a position error up to it does not turn a certified state
    #: into contact (docs/method.md §12.2); unset: 0.1 in corrected mode, 0 in paper mode
    #: (:attr:`Config.shield_margin_m`)
    shield_margin_m: float | None = None
    vehicle: VehicleOverrides = field(default_factory=VehicleOverrides)

    def __post_init__(self) -> None:
        if self.kind in AV_KIND_ALIASES:
            object.__setattr__(self, "kind", AV_KIND_ALIASES[self.kind])
        _choice("av.kind", self.kind, AV_KINDS)
        if self.role is not None:
            _choice("av.role", self.role, ROLES)
        if self.shield is not None:
            _choice("av.shield", self.shield, SHIELD_KINDS)
        _in_range("av.shield_response_s", self.shield_response_s, 0.0, 60.0)
        if self.shield_margin_m is not None:
            _in_range("av.shield_margin_m", self.shield_margin_m, 0.0, 5.0)
        if self.yield_line_m is not None:
            _in_range("av.yield_line_m", self.yield_line_m, 0.0, 100.0)
        if self.yield_line_choices_m is not None:
            lines = self.yield_line_choices_m
            if (not isinstance(lines, (tuple, list)) or not 0 <= len(lines) <= 8
                    or any(isinstance(x, bool) or not isinstance(x, (int, float))
                           or not 0.0 <= x <= 100.0 for x in lines)):
                _fail("av.yield_line_choices_m", lines,
                      "0 to 8 numbers in [0, 100] (none: foresight off)")
            if self.yield_line_m is not None and len(lines) > 0:
                raise ConfigError("av.yield_line_choices_m and av.yield_line_m are exclusive: "
                                  "set one line, or the lines to choose among")
            object.__setattr__(self, "yield_line_choices_m", tuple(float(x) for x in lines))


@dataclass(frozen=True)
class NoisyParams:
    """The Boltzmann-rational LFG human (``hv.kind = "noisy"``).

    The default 0.1 is a visibly imperfect driver: the values of the best few candidates of
    the paper's games lie a few reward units apart (discounted metres), so it departs from the
    game's answer on a noticeable share of steps, where 0.5 almost never does
    (``tests/test_policies.py`` pins both)."""

    beta: float = 0.1  #: rationality [1/reward]: P(trajectory) ~ exp(beta Q); large = the LFG

    def __post_init__(self) -> None:
        _in_range("hv.noisy.beta", self.beta, 0.0)


@dataclass(frozen=True)
class IDMParams:
    """The IDM driver with gap acceptance at the conflict (``hv.kind = "idm"``)."""

    desired_speed_mps: float = 10.0  #: IDM desired speed v0 [m/s]
    time_gap_s: float = 1.5  #: IDM time gap T [s]
    max_accel_mps2: float = 1.0  #: IDM maximum acceleration a [m/s^2]
    comfort_decel_mps2: float = 1.5  #: IDM comfortable deceleration b [m/s^2]
    delta: float = 4.0  #: IDM acceleration exponent [-]
    jam_gap_m: float = 2.0  #: IDM jam distance s0 [m]
    critical_gap_s: float = 1.0  #: accepted gap: the AV must reach the conflict this much later [s]
    impatience_per_s: float = 0.0  #: the gap shrinks by this fraction per second of waiting [1/s]

    def __post_init__(self) -> None:
        p = "hv.idm."
        _in_range(p + "desired_speed_mps", self.desired_speed_mps, 0.0, lo_open=True)
        _in_range(p + "time_gap_s", self.time_gap_s, 0.0)
        _in_range(p + "max_accel_mps2", self.max_accel_mps2, 0.0, lo_open=True)
        _in_range(p + "comfort_decel_mps2", self.comfort_decel_mps2, 0.0, lo_open=True)
        _in_range(p + "delta", self.delta, 0.0, lo_open=True)
        _in_range(p + "jam_gap_m", self.jam_gap_m, 0.0)
        _in_range(p + "critical_gap_s", self.critical_gap_s, 0.0)
        _in_range(p + "impatience_per_s", self.impatience_per_s, 0.0)


@dataclass(frozen=True)
class ReplayParams:
    """A recorded trajectory replayed open loop (``hv.kind = "replay"``)."""

    file: str = ""  #: per-step log (.parquet or .csv) from ``simulate --out`` or a recorded trial
    vehicle: Literal["hv", "av"] = "hv"  #: whose accelerations in the log to replay

    def __post_init__(self) -> None:
        if not isinstance(self.file, str):
            raise ConfigError(f"hv.replay.file = {self.file!r} is not a file name")
        _choice("hv.replay.vehicle", self.vehicle, ("hv", "av"))


@dataclass(frozen=True)
class RandomHumanParams:
    """The random human (``hv.kind = "random"``): uniform accelerations within the vehicle's
    limits, each held for a uniform random time."""

    hold_min_s: float = 0.1  #: shortest hold of one acceleration [s]
    hold_max_s: float = 2.0  #: longest hold [s]

    def __post_init__(self) -> None:
        _in_range("hv.random.hold_min_s", self.hold_min_s, 0.0, lo_open=True)
        _in_range("hv.random.hold_max_s", self.hold_max_s, self.hold_min_s, 3600.0)


@dataclass(frozen=True)
class HVParams:
    """The human driver model (docs/method.md §5, §11).

    ``lfg``: the paper's adaptive-role LFG human; ``stubborn``: the LFG with ``p_a = 0``;
    ``noisy``: a Boltzmann-rational LFG; ``idm``: an IDM driver with gap acceptance;
    ``aggressive``: full throttle, never yields; ``replay``: a recorded trajectory, open loop;
    ``adversary``: aims at the conflict to arrive when the AV does; ``deceptive``: yields until the
    AV commits, then accelerates fully; ``random``: bounded random accelerations held for random
    times (docs/method.md §12.4); ``person``: a person at the controls (``persuasive drive``; a
    Python policy, not a compiled kind: ``simulate`` cannot run it, and records of the browser page
    carry it).
    """

    kind: HVKind = "lfg"  #: lfg | stubborn | noisy | idm | aggressive | replay | adversary |
    #: deceptive | random | person
    role: Role = "leader"  #: initial role of an LFG-type human
    noisy: NoisyParams = field(default_factory=NoisyParams)
    idm: IDMParams = field(default_factory=IDMParams)
    replay: ReplayParams = field(default_factory=ReplayParams)
    random: RandomHumanParams = field(default_factory=RandomHumanParams)
    vehicle: VehicleOverrides = field(default_factory=VehicleOverrides)
    #: a named human envelope (:data:`HUMAN_ENVELOPES`: ``sumo`` | ``real-driver``) for the
    #: human's braking, acceleration and top speed: what the simulated human can do and what
    #: the shield assumes of it (and, in a replay, of the recorded driver); unset: the
    #: ``[vehicle]`` and ``[hv.vehicle]`` limits (the paper's). Not with those three fields
    #: of ``[hv.vehicle]`` set
    envelope: str | None = None

    def __post_init__(self) -> None:
        _choice("hv.kind", self.kind, HV_KINDS)
        _choice("hv.role", self.role, ROLES)
        if self.envelope is not None:
            _choice("hv.envelope", self.envelope, tuple(HUMAN_ENVELOPES))
            both = [f for f in ENVELOPE_FIELDS if getattr(self.vehicle, f) is not None]
            if both:
                raise ConfigError(f"hv.envelope = {self.envelope!r} sets hv.vehicle.{both[0]}, "
                                  "which is set too; allowed: one of the two")
        if self.kind == "replay" and not self.replay.file:
            raise ConfigError("hv.replay.file is required with hv.kind = 'replay'")


#: The named human envelopes (docs/method.md §12.2): ``hv.envelope`` names one, and
#: ``persuasive recordings envelope`` measures recorded drivers against each. Per name:
#: ``(u_min [m/s^2], u_max [m/s^2], v_max [m/s], source)``.
HUMAN_ENVELOPES: dict[str, tuple[float, float, float, str]] = {
    "sumo": (-4.5, 2.6, 200.0 / 3.6,
             "SUMO's default vehicle type DEFAULT_VEHTYPE (vClass passenger): accel 2.6, "
             "decel 4.5 m/s^2, maxSpeed 200 km/h = 55.56 m/s (SUMO's documentation, 'Vehicle "
             "Type Parameter Defaults' and 'Definition of Vehicles, Vehicle Types, and "
             "Routes'; read back through TraCI from SUMO 1.28.0); its emergencyDecel of 9 "
             "m/s^2 is not the envelope"),
    "real-driver": (-3.7, 3.5, 16.5,
                    "the p99.9 of real drivers in the INTERACTION dataset, "
                    "DR_USA_Intersection_GL and DR_USA_Intersection_MA (13,500 cars over 6.1 h, "
                    "speeds smoothed with a 1-s Savitzky-Golay filter): acceleration p99.9 "
                    "3.4-3.5, braking p99.9 3.4-3.7 m/s^2 (the larger of the two sites), speed "
                    "p99.9 16.1 m/s rounded up to the next 0.5 m/s (maxima 5.4, 5.5 m/s^2 and "
                    "19.7 m/s)"),
}
#: The vehicle fields a named envelope sets.
ENVELOPE_FIELDS = ("u_min_mps2", "u_max_mps2", "v_max_mps")


#: Quirk values of each mode (docs/method.md §9). Q4, Q6 and Q7 are kept in both modes.
_MODE_QUIRKS: dict[str, dict[str, Any]] = {
    "paper": dict(
        q1_branch_time_offset=True,
        q2_belief_offset=True,
        q3_tie_break_leak=True,
        q4_undiscounted_collision=True,
        q5_leader_agg_max=True,
        q6_time_like_stop_test=True,
        q7_arrival_tolerance_m=0.2,
    ),
    "corrected": dict(
        q1_branch_time_offset=False,
        q2_belief_offset=False,
        q3_tie_break_leak=False,
        q4_undiscounted_collision=True,
        q5_leader_agg_max=False,
        q6_time_like_stop_test=True,
        q7_arrival_tolerance_m=0.2,
    ),
}


@dataclass(frozen=True)
class ResponsibilityParams:
    """What a driver in a shared lane is assumed to do when another enters ahead of it: the
    responsibility rule of the shield's cut-in (docs/method.md §12.10), after RSS's safe
    longitudinal distance (Shalev-Shwartz, Shammah, Shashua 2017, "On a Formal Model of Safe
    and Scalable Self-driving Cars", Definition 1).

    The AV enters a lane ahead of a vehicle only with a gap from which that vehicle, holding at
    most ``follower_accel_mps2`` for ``reaction_s`` and then braking at
    ``follower_brake_mps2``, keeps the gap even if the AV brakes at ``front_brake_mps2`` from
    the moment it enters; in the lane it then brakes no harder than that. These are assumptions
    about the *human* (a rule of the road, not a physical limit), so they live here, not under
    ``[av]``. Every field unset gives the default named beside it.
    """

    #: the follower's reaction time ``rho`` [s]; unset: 1.0
    reaction_s: float | None = None
    #: the follower's acceleration during ``rho`` [m/s^2]; unset: its own ``u_max``
    follower_accel_mps2: float | None = None
    #: the follower's braking after ``rho`` [m/s^2], positive; unset: 4.5 (SUMO's ``decel``
    #: of a passenger car); never taken harder than the follower's own ``|u_min|``
    follower_brake_mps2: float | None = None
    #: the AV's hardest braking in the lane ahead of a follower [m/s^2], positive (its in-lane
    #: fallback); unset: the follower's braking as taken; never harder than the AV's own
    front_brake_mps2: float | None = None
    #: who has the right of way at the conflict of our own scenarios under the
    #: ``responsibility`` shield (docs/method.md §12.13): "av" or "hv"; unset: neither (the
    #: paper's unsignalled intersection), so that each must respond. Outside simulators read
    #: it from their own road (highway-env's lane priorities)
    right_of_way: Literal["av", "hv"] | None = None

    def __post_init__(self) -> None:
        p = "responsibility."
        if self.reaction_s is not None:
            _in_range(p + "reaction_s", self.reaction_s, 0.0, 10.0)
        if self.follower_accel_mps2 is not None:
            _in_range(p + "follower_accel_mps2", self.follower_accel_mps2, 0.0, 20.0)
        for name in ("follower_brake_mps2", "front_brake_mps2"):
            if getattr(self, name) is not None:
                _in_range(p + name, getattr(self, name), 0.0, 20.0, lo_open=True)
        if self.right_of_way not in (None, "av", "hv"):
            raise ConfigError(f"{p}right_of_way = {self.right_of_way!r} is not allowed; "
                              f"allowed: av, hv (unset: neither)")

    def resolved(self, follower: VehicleParams, front: VehicleParams
                 ) -> tuple[float, float, float, float]:
        """``(rho [s], follower's acceleration during rho, follower's braking, front's
        braking)`` [m/s^2, both brakings positive] for these two vehicles."""
        rho = 1.0 if self.reaction_s is None else self.reaction_s
        acc = follower.u_max_mps2 if self.follower_accel_mps2 is None else self.follower_accel_mps2
        brake = min(4.5 if self.follower_brake_mps2 is None else self.follower_brake_mps2,
                    -follower.u_min_mps2)
        front_brake = brake if self.front_brake_mps2 is None else self.front_brake_mps2
        return rho, acc, brake, min(front_brake, -front.u_min_mps2)


# -- the junction of many vehicles (persuasive.many) -----------------------------------------

#: Arms, anticlockwise from east.
ARMS = ("east", "north", "west", "south")
MOVEMENTS = ("left", "straight", "right")
PRIORITIES = ("major", "first-come", "right-before-left")
#: How the humans arrive (:attr:`JunctionSpec.arrival`).
ARRIVALS = ("placed", "poisson")
#: Whom a human plays against (:attr:`JunctionSpec.opponents`).
OPPONENTS = ("next", "all")
#: How the junction's AV plans against its humans (``persuasive.many.joint``).
AV_PLANS = ("pairwise", "joint")
#: The joint plan's chance constraint (``persuasive.many.joint``).
JOINT_BOUNDS = ("product", "union")
#: Where the junction's AV yields (:attr:`JunctionSpec.av_line`).
AV_LINES = ("stop", "outside", "foresight")
#: How the junction's AV starts (:attr:`JunctionSpec.av_start`).
AV_STARTS = ("stoppable", "drawn")
#: Named variants: the fields of :class:`JunctionSpec` each sets.
VARIANTS: dict[str, dict[str, Any]] = {
    "major": {"priority": "major", "mix": (0.25, 0.5, 0.25)},
    "all-way": {"priority": "first-come", "mix": (0.25, 0.5, 0.25)},
    "right-before-left": {"priority": "right-before-left", "mix": (0.25, 0.5, 0.25)},
    "left-heavy": {"priority": "first-come", "mix": (0.6, 0.3, 0.1)},
}
#: The vehicle length a spec's fit is checked with [m] (``persuasive.many.junction.arrivals``
#: checks the real one).
FIT_LENGTH_M = 5.0


@dataclass(frozen=True)
class JunctionSpec:
    """A four-way junction and its arrivals (``persuasive.many.junction``'s module docstring;
    here, in the parameters layer, so that :class:`Config` checks its ``[junction]`` section
    without importing ``persuasive.many``). Lengths in metres, speeds in m/s; ``mix`` is the
    (left, straight, right) share of the humans' movements."""

    n_vehicles: int = 4  #: vehicles in the run, the AV included (>= 1)
    lanes: int = 1  #: lanes per direction on every arm (1 or 2)
    lane_width_m: float = 4.0
    #: inbound lane length before the stop line [m] (None: long enough for every vehicle in
    #: one lane, at least 100 m)
    approach_m: float | None = None
    exit_m: float = 40.0  #: exit lane length after the box [m]
    priority: str = "major"
    mix: tuple[float, float, float] = (0.25, 0.5, 0.25)
    av_arm: int = 3  #: the AV's arm (0 east, 1 north, 2 west, 3 south)
    av_movement: str = "straight"
    #: the first vehicle's centre in a lane starts this far before the stop line [m]
    first_m: tuple[float, float] = (10.0, 30.0)
    #: the bumper gap to the vehicle ahead in the lane [m]
    gap_m: tuple[float, float] = (6.0, 20.0)
    v0_mps: tuple[float, float] = (3.0, 5.0)  #: initial speeds
    #: the humans' kinds and their shares (any simulated human kind of the project)
    hv_kinds: tuple[tuple[str, float], ...] = (("lfg", 1.0),)
    duration_s: float = 30.0  #: run length [s]
    #: whom a human plays its pair game against: ``next``, the vehicle it conflicts with next;
    #: ``all``, every vehicle of an uncleared conflict within the prediction's reach (the
    #: lowest of the answers, as Li et al.'s concurrent pairwise games)
    opponents: str = "next"
    #: how the humans arrive: ``placed``, all on the road at the start, queued in their lanes;
    #: ``poisson``, a Poisson flow of ``flow_veh_h`` per arm, each entering at the start of its
    #: approach at its arrival time (later while its lane's entry is blocked)
    arrival: str = "placed"
    flow_veh_h: float = 600.0  #: vehicles per hour on each arm (``arrival = "poisson"``)
    #: when the AV enters at the start of its approach, into the flow [s] (``poisson``)
    av_arrival_s: float = 10.0
    #: how the AV plans against the humans it conflicts with: ``pairwise``, one planner per
    #: human and the lowest acceleration (part 1, as the adapters); ``joint``, one plan
    #: against all of them (``persuasive.many.joint``)
    av_plan: str = "pairwise"
    #: the joint plan's chance constraint: ``product`` (the humans' branches independent) or
    #: ``union`` (Boole's inequality)
    joint_bound: str = "product"
    #: where the AV yields at each crossing and merge: ``stop``, at the box's stop line (or
    #: the occupancy interval's start, where that comes first; part 1); ``outside``, outside
    #: the junction (before the occupancy interval of every route that crosses or merges
    #: with its own) and outside the human's keep-out circle (the pair game's safety
    #: distance, 7.5 m, before the conflict point); ``foresight``, the one of the two the
    #: AV's predictions of the run favour (placed arrivals only) (docs/method.md §15.9)
    av_line: str = "outside"
    #: the AV's initial speed: ``stoppable``, capped so that it can stop 1 m before the first
    #: line it may yield at (``persuasive.many.world.drawn_arrivals``); ``drawn``, as drawn
    #: from ``v0_mps`` (before the cap: the tables of docs/results.md §16-§16.4)
    av_start: str = "stoppable"

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ConfigError:
            return ConfigError(f"junction.{name} = {getattr(self, name)!r} is out of range; "
                               f"allowed: {allowed}")

        if isinstance(self.n_vehicles, bool) or not isinstance(self.n_vehicles, Integral) or \
                not 1 <= self.n_vehicles <= 64:
            raise bad("n_vehicles", "an integer in [1, 64] (the AV included)")
        if self.lanes not in (1, 2):
            raise bad("lanes", "1 | 2")
        if not 2.0 <= self.lane_width_m <= 6.0:
            raise bad("lane_width_m", "[2, 6] m")
        if not 10.0 <= self.exit_m <= 1000.0:
            raise bad("exit_m", "[10, 1000] m")
        if self.priority not in PRIORITIES:
            raise bad("priority", " | ".join(PRIORITIES))
        mix = tuple(float(m) for m in self.mix)
        if len(mix) != 3 or not all(math.isfinite(m) and m >= 0.0 for m in mix) or \
                not sum(mix) > 0.0:
            raise bad("mix", "three shares (left, straight, right) >= 0 with a positive sum")
        object.__setattr__(self, "mix", mix)
        if self.av_arm not in (0, 1, 2, 3):
            raise bad("av_arm", "0 (east) | 1 (north) | 2 (west) | 3 (south)")
        if self.av_movement not in MOVEMENTS:
            raise bad("av_movement", " | ".join(MOVEMENTS))
        for name, lo_min in (("first_m", 0.0), ("gap_m", 0.5), ("v0_mps", 0.0)):
            pair = tuple(float(x) for x in getattr(self, name))
            if len(pair) != 2 or not (lo_min <= pair[0] <= pair[1]) or \
                    not math.isfinite(pair[1]):
                raise bad(name, f"(lo, hi) with {lo_min:g} <= lo <= hi, finite")
            object.__setattr__(self, name, pair)
        need = self.first_m[1] + (self.n_vehicles - 1) * (FIT_LENGTH_M + self.gap_m[1]) \
            + 0.5 * FIT_LENGTH_M
        if self.approach_m is None:
            object.__setattr__(self, "approach_m", float(max(100.0, 10.0 * math.ceil(need / 10.0))))
        if not 20.0 <= self.approach_m <= 5000.0:
            raise bad("approach_m", "[20, 5000] m")
        if self.first_m[1] + 5.0 > self.approach_m:
            raise ConfigError(f"junction.first_m = {self.first_m!r} does not fit on an approach "
                              f"of junction.approach_m = {self.approach_m:g} m; allowed: hi <= "
                              "approach_m - 5")
        # every vehicle in one lane must fit (5-m vehicles; arrivals checks the real length)
        if need > self.approach_m:
            raise ConfigError(f"junction.n_vehicles = {self.n_vehicles} does not fit on an "
                              f"approach of junction.approach_m = {self.approach_m:g} m (all in "
                              f"one lane need {need:g} m); allowed: n_vehicles <= "
                              f"{self.max_vehicles()}, or a longer approach_m or smaller gap_m")
        kinds = _junction_kinds(self.hv_kinds)
        object.__setattr__(self, "hv_kinds", kinds)
        if self.arrival not in ARRIVALS:
            raise bad("arrival", " | ".join(ARRIVALS))
        if not (isinstance(self.flow_veh_h, (int, float)) and 1.0 <= self.flow_veh_h <= 3600.0):
            raise bad("flow_veh_h", "[1, 3600] vehicles per hour per arm")
        if not (isinstance(self.av_arrival_s, (int, float)) and 0.0 <= self.av_arrival_s and
                (self.arrival != "poisson" or self.av_arrival_s < self.duration_s)):
            raise bad("av_arrival_s", "[0, duration_s) s")
        if self.opponents not in OPPONENTS:
            raise bad("opponents", " | ".join(OPPONENTS))
        if self.av_plan not in AV_PLANS:
            raise bad("av_plan", " | ".join(AV_PLANS))
        if self.joint_bound not in JOINT_BOUNDS:
            raise bad("joint_bound", " | ".join(JOINT_BOUNDS))
        if self.av_line not in AV_LINES:
            raise bad("av_line", " | ".join(AV_LINES))
        if self.av_start not in AV_STARTS:
            raise bad("av_start", " | ".join(AV_STARTS))
        if not 1.0 <= self.duration_s <= 3600.0:
            raise bad("duration_s", "[1, 3600] s")

    @classmethod
    def of(cls, variant: str | None = None, **fields_: Any) -> JunctionSpec:
        """A spec from a named variant (:data:`VARIANTS`) and fields set over it."""
        base: dict[str, Any] = {}
        if variant is not None:
            if variant not in VARIANTS:
                raise ConfigError(f"junction.variant = {variant!r} is out of range; allowed: "
                                  f"{' | '.join(VARIANTS)}")
            base.update(VARIANTS[variant])
        known = {f.name for f in fields(cls)}
        for name in fields_:
            if name not in known:
                raise ConfigError(f"junction.{name} is not a parameter; allowed: "
                                  f"{' | '.join(sorted(known))}")
        base.update(fields_)
        return cls(**base)

    def max_vehicles(self) -> int:
        """The most vehicles that fit in one lane of this approach."""
        room = self.approach_m - self.first_m[1] - 0.5 * FIT_LENGTH_M
        return max(1, 1 + int(room // (FIT_LENGTH_M + self.gap_m[1])))

    @property
    def half_m(self) -> float:
        """Half the side of the junction's box [m]."""
        return self.lanes * self.lane_width_m

    def with_(self, **changes: Any) -> JunctionSpec:
        return replace(self, **changes)


def _junction_kinds(value) -> tuple[tuple[str, float], ...]:
    if isinstance(value, str):  # "lfg:0.8,aggressive:0.2" or "idm"
        items = []
        for part in value.split(","):
            name, _, share = part.strip().partition(":")
            try:
                items.append((name.strip(), float(share) if share else 1.0))
            except ValueError:
                raise ConfigError(f"junction.hv_kinds = {value!r} is not KIND[:SHARE],...") \
                    from None
        value = items
    elif isinstance(value, dict):
        value = list(value.items())
    out = []
    for item in value:
        name, share = (item, 1.0) if isinstance(item, str) else item
        if name not in SIMULATED_HV_KINDS or name == "replay":
            allowed = " | ".join(k for k in SIMULATED_HV_KINDS if k != "replay")
            raise ConfigError(f"junction.hv_kinds has {name!r}; allowed: {allowed}")
        share = float(share)
        if not (math.isfinite(share) and share >= 0.0):
            raise ConfigError(f"junction.hv_kinds share of {name!r} = {share!r} is out of "
                              "range; allowed: >= 0")
        out.append((str(name), share))
    if not out or not sum(s for _, s in out) > 0.0:
        raise ConfigError("junction.hv_kinds needs at least one kind with a positive share")
    return tuple(out)


@dataclass(frozen=True)
class JunctionParams:
    """The four-way unsignalised junction of ``scenario.kind = "junction"`` (docs/method.md
    §15; :class:`JunctionSpec` holds the meaning and checks of every field). Every field unset
    takes the named variant's value, else the spec's default
    (``variant`` unset: ``major``); the section is read only with ``scenario.kind =
    "junction"``. Lengths in metres, speeds in m/s, times in s."""

    #: major | all-way | right-before-left | left-heavy (``persuasive.many.junction.VARIANTS``)
    variant: str | None = None
    n_vehicles: int | None = None  #: vehicles in a run, the AV included; unset: 4
    lanes: int | None = None  #: lanes per direction on every arm (1 or 2); unset: 1
    lane_width_m: float | None = None  #: unset: 4
    approach_m: float | None = None  #: unset: long enough for every vehicle in one lane
    exit_m: float | None = None  #: unset: 40
    priority: str | None = None  #: major | first-come | right-before-left; unset: the variant's
    mix: tuple[float, float, float] | None = None  #: (left, straight, right) shares of the humans
    av_arm: str | None = None  #: east | north | west | south; unset: south
    av_movement: str | None = None  #: left | straight | right; unset: straight
    first_m: tuple[float, float] | None = None  #: the first vehicle's distance range to the line
    gap_m: tuple[float, float] | None = None  #: bumper gaps in a lane
    v0_mps: tuple[float, float] | None = None  #: initial speeds
    hv_kinds: str | None = None  #: the humans' kinds and shares, "lfg:0.8,aggressive:0.2"
    duration_s: float | None = None  #: run length; unset: 30
    opponents: str | None = None  #: next | all: whom each human plays; unset: next
    arrival: str | None = None  #: placed | poisson; unset: placed
    flow_veh_h: float | None = None  #: vehicles per hour on each arm (poisson); unset: 600
    av_arrival_s: float | None = None  #: when the AV enters (poisson); unset: 10
    av_plan: str | None = None  #: pairwise | joint: how the AV plans; unset: pairwise
    joint_bound: str | None = None  #: product | union: the joint chance constraint; unset: product
    av_line: str | None = None  #: stop | outside | foresight (where it yields); unset: outside
    av_start: str | None = None  #: stoppable | drawn (the AV's initial speed); unset: stoppable

    def __post_init__(self) -> None:
        for name in ("mix", "first_m", "gap_m", "v0_mps"):
            value = getattr(self, name)
            if value is not None:
                if not isinstance(value, (list, tuple)) or any(
                        isinstance(x, bool) or not isinstance(x, (int, float)) for x in value):
                    _fail(f"junction.{name}", value, "a list of numbers")
                object.__setattr__(self, name, tuple(float(x) for x in value))
        if self.av_arm is not None:
            _choice("junction.av_arm", self.av_arm, ARMS)
        for name in ("n_vehicles", "lanes"):
            if getattr(self, name) is not None:
                _number(f"junction.{name}", getattr(self, name), integer=True)

    @property
    def is_set(self) -> bool:
        """Whether any field is set."""
        return any(getattr(self, f.name) is not None for f in fields(self))

    def spec(self) -> JunctionSpec:
        """The :class:`JunctionSpec` of this section: its variant (unset: ``major``) with every
        set field over it; the arm by name."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        variant = values.pop("variant") or "major"
        set_ = {k: v for k, v in values.items() if v is not None}
        if "av_arm" in set_:
            set_["av_arm"] = ARMS.index(set_["av_arm"])
        return JunctionSpec.of(variant, **set_)


@dataclass(frozen=True)
class Quirks:
    """Reference-implementation quirks Q1..Q7 (docs/method.md §9); ``None`` follows the mode."""

    q1_branch_time_offset: bool | None = None  #: Q1: the MPC's HV branches lag by one sample
    q2_belief_offset: bool | None = None  #: Q2: the human's belief at T1 compares shifted samples
    q3_tie_break_leak: bool | None = None  #: Q3: belief ties read the HV's true/initial role
    q4_undiscounted_collision: bool | None = None  #: Q4: MPC collision term not discounted
    q5_leader_agg_max: bool | None = None  #: Q5: the leader aggregates tied followers with max
    q6_time_like_stop_test: bool | None = None  #: Q6: stop offered if s0 + v0/|u_min| < -stop
    q7_arrival_tolerance_m: float | None = None  #: Q7: crossing-line arrival tolerance [m]

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            if f.name == "q7_arrival_tolerance_m":
                _in_range("quirks." + f.name, value, 0.0)
            else:
                _flag("quirks." + f.name, value)

    def resolved(self, mode: str) -> Quirks:
        """Every quirk set: the explicit ones as given, the others as ``mode`` says."""
        base = _MODE_QUIRKS[mode]
        return Quirks(**{k: (v if (v := getattr(self, k)) is not None else base[k]) for k in base})


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The table of a TOML file; a file that cannot be read or parsed is a one-line
    :class:`ConfigError` naming ``what`` (e.g. "grid file") and the path."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{what} {str(path)!r} cannot be read: "
                          f"{(exc.strerror or str(exc)).lower()}") from None
    except UnicodeDecodeError as exc:  # TOML is UTF-8 text
        raise ConfigError(f"{what} {str(path)!r} is not UTF-8 text (byte "
                          f"0x{exc.object[exc.start]:02x} at offset {exc.start}); TOML files "
                          "must be UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} {str(path)!r} is not valid TOML: {exc}") from None


@dataclass(frozen=True)
class Config:
    """All parameters of one closed-loop run, the paper's values by default."""

    mode: Mode = "paper"
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    library: LibraryParams = field(default_factory=LibraryParams)
    reward: RewardParams = field(default_factory=RewardParams)
    roles: RoleParams = field(default_factory=RoleParams)
    mpc: MPCParams = field(default_factory=MPCParams)
    scenario: ScenarioParams = field(default_factory=ScenarioParams)
    simulation: SimulationParams = field(default_factory=SimulationParams)
    av: AVParams = field(default_factory=AVParams)
    hv: HVParams = field(default_factory=HVParams)
    quirks: Quirks = field(default_factory=Quirks)
    responsibility: ResponsibilityParams = field(default_factory=ResponsibilityParams)
    junction: JunctionParams = field(default_factory=JunctionParams)

    def __post_init__(self) -> None:
        _choice("mode", self.mode, MODES)
        for name, section_cls in _SECTIONS.items():
            if not isinstance(getattr(self, name), section_cls):
                raise ConfigError(f"{name} is not a {section_cls.__name__}")
        if self.scenario.kind in MANY_SCENARIO_KINDS:
            if (self.simulation.interactions or 1) > 1:
                _fail("simulation.interactions", self.simulation.interactions,
                      f"1 with scenario.kind = {self.scenario.kind} (repeated interactions "
                      "are of one human with the AV)")
            self.junction_spec  # noqa: B018 -- checked whole here, one line naming the field
        elif self.junction.is_set:
            raise ConfigError("[junction] is read only with scenario.kind = \"junction\"; "
                              f"scenario.kind = {self.scenario.kind!r} is a two-vehicle scenario")
        if self.simulation.dt_s != self.library.sample_dt_s:
            _fail(
                "simulation.dt_s",
                self.simulation.dt_s,
                f"equal to library.sample_dt_s = {self.library.sample_dt_s!r} "
                "(predictions are one sample ahead)",
            )
        s = self.scenario
        for who in ("av", "hv"):
            v = self.vehicle_of(who)
            name = f"{who}_v0_mps"
            v0, hw = getattr(s, name), getattr(s, f"{who}_v0_halfwidth_mps")
            if v0 - hw < v.v_min_mps or v0 + hw > v.v_max_mps:
                _fail(
                    f"scenario.{name}",
                    v0,
                    f"[{v.v_min_mps:g}, {v.v_max_mps:g}] with its half-width {hw:g} "
                    f"(the {who.upper()}'s speed limits)",
                )
        if self.av.yield_line_choices_m:  # set explicitly (the default never conflicts)
            if self.shield == "off":
                raise ConfigError("av.yield_line_choices_m chooses the shield's yield line: it "
                                  "needs av.shield = worst-case, responsive or responsibility")
            if self.p_a_online:
                raise ConfigError('av.yield_line_choices_m predicts with a fixed p_a: it needs '
                                  'a number for mpc.p_a_hat, not "online"')
        w = self.simulation.accel_noise_mps2
        if w > 0.0 and self.shield != "off":  # the shield's fallbacks must still brake and go
            av = self.vehicle_of("av")
            most = min(-av.u_min_mps2, av.u_max_mps2)
            if not w < most:
                _fail("simulation.accel_noise_mps2", w,
                      f"[0, {most:g}) with a shield on (below the AV's braking and throttle, "
                      "so that its fallbacks still brake and go)")
            if self.scenario.kind == "merge":
                brake = self.responsibility_rule[3]
                if not w < brake:
                    _fail("simulation.accel_noise_mps2", w,
                          f"[0, {brake:g}) with a shield on in a merge (below the AV's braking "
                          "in the lane, responsibility.front_brake_mps2, so that it still "
                          "brakes)")

    # -- derived -----------------------------------------------------------------------------

    @functools.cached_property
    def junction_spec(self):
        """The junction of ``scenario.kind = "junction"`` as a
        ``persuasive.many.junction.JunctionSpec`` (``[junction]`` over its variant), or None
        for a two-vehicle scenario."""
        if self.scenario.kind != "junction":
            return None
        return self.junction.spec()

    @property
    def responsibility_rule(self) -> tuple[float, float, float, float]:
        """The cut-in rule in force with the HV following the AV (:class:`ResponsibilityParams`
        resolved): ``(rho, follower's acceleration, follower's braking, AV's braking)``."""
        return self.responsibility.resolved(self.vehicle_of("hv"), self.vehicle_of("av"))

    @functools.cached_property
    def effective_quirks(self) -> Quirks:
        """The quirks in force: the mode's, with any explicit switch applied."""
        return self.quirks.resolved(self.mode)

    @functools.cached_property
    def _vehicles(self) -> dict[str, VehicleParams]:
        out = {who: getattr(self, who).vehicle.resolve(self.vehicle, who) for who in ("av", "hv")}
        if self.hv.envelope is not None:  # the named envelope's limits (HVParams.envelope)
            u_min, u_max, v_max, _ = HUMAN_ENVELOPES[self.hv.envelope]
            try:
                out["hv"] = replace(out["hv"], u_min_mps2=u_min, u_max_mps2=u_max,
                                    v_max_mps=v_max)
            except ConfigError as exc:
                raise ConfigError(f"hv.envelope = {self.hv.envelope!r}: {exc}") from None
        return out

    def vehicle_of(self, who: str) -> VehicleParams:
        """The size and limits of the ``"av"`` or ``"hv"``: ``[vehicle]`` with its overrides."""
        return self._vehicles[who]

    @property
    def streams(self) -> str:
        """The random-stream layout in force: as set, else "legacy" in paper mode and
        "per-agent" otherwise."""
        if self.simulation.streams is not None:
            return self.simulation.streams
        return "legacy" if self.mode == "paper" else "per-agent"

    @property
    def shield(self) -> str:
        """The safety shield in force: ``av.shield`` as set, else "off" in paper mode (the
        published tables) and "worst-case" in corrected mode."""
        if self.av.shield is not None:
            return self.av.shield
        return "off" if self.mode == "paper" else "worst-case"

    @property
    def yield_line_choices(self) -> tuple[float, ...] | None:
        """The yield lines foresight picks among, in force (docs/method.md §12.12), or None
        (foresight off): ``av.yield_line_choices_m`` as set (``[]``: off); unset, corrected
        mode's default :data:`DEFAULT_YIELD_LINE_CHOICES_M` where it was measured best and
        applies (the worst-case shield, no fixed ``av.yield_line_m``, a fixed
        ``mpc.p_a_hat``), else off: under the shields that trust the human to respond it
        was measured worse (docs/method.md §12.14: against the `aggressive` human the
        `responsibility` shield with foresight collided in 13 of 200 runs, without it in
        none). Outside simulators never run it (``persuasive.envs.external``)."""
        lines = self.av.yield_line_choices_m
        if lines is not None:
            return lines if lines else None
        if (self.mode == "corrected" and self.shield == "worst-case"
                and self.av.yield_line_m is None and not self.p_a_online):
            return DEFAULT_YIELD_LINE_CHOICES_M
        return None

    @property
    def shield_margin_m(self) -> float:
        """The shield's clearance in force [m]: ``av.shield_margin_m`` as set, else
        :data:`DEFAULT_SHIELD_MARGIN_M` under corrected mode's worst-case shield, where it
        was measured best, and 0 otherwise (paper mode; the shields that trust the human to
        respond, where it was measured worse: docs/method.md §12.14; only a shield reads
        it)."""
        if self.av.shield_margin_m is not None:
            return self.av.shield_margin_m
        if self.mode == "corrected" and self.shield == "worst-case":
            return DEFAULT_SHIELD_MARGIN_M
        return 0.0

    @property
    def confidence_filter(self) -> bool:
        """The planner's model-confidence filter is on: ``mpc.confidence_filter`` as set,
        else on exactly when a shield is (:attr:`shield`), as before the setting existed."""
        if self.mpc.confidence_filter is not None:
            return self.mpc.confidence_filter
        return self.shield != "off"

    @property
    def p_a_online(self) -> bool:
        """The AV keeps a posterior over ``p_a`` (``mpc.p_a_hat = "online"``)."""
        return self.mpc.p_a_hat == "online"

    @property
    def p_a_prior(self) -> tuple[float, float]:
        """The Beta prior ``(a, b)`` of the online posterior (``mpc.p_a_prior``, or (7, 3))."""
        return self.mpc.p_a_prior if self.mpc.p_a_prior is not None else DEFAULT_P_A_PRIOR

    @property
    def p_a_grid(self) -> int:
        """The online posterior's grid size (``mpc.p_a_grid``, or 21)."""
        return self.mpc.p_a_grid if self.mpc.p_a_grid is not None else DEFAULT_P_A_GRID

    @property
    def p_a_hat(self) -> float:
        """The AV's estimate of ``p_a`` (``mpc.p_a_hat``, or ``roles.p_a`` when unset); online,
        the prior's mean ``a / (a + b)`` (the estimate the planner starts from)."""
        if self.mpc.p_a_hat is None:
            return self.roles.p_a
        if self.p_a_online:
            a, b = self.p_a_prior
            return a / (a + b)
        return self.mpc.p_a_hat

    # -- building ----------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (TOML/JSON friendly); unset optional values are left out, and
        so is a section whose every value is unset (``[responsibility]`` and ``[junction]`` by
        default: the
        configurations written before it existed keep their text and digests)."""
        sections = {name: _section_dict(getattr(self, name)) for name in _SECTIONS}
        return {"mode": self.mode, **{k: v for k, v in sections.items()
                                      if v or k not in _OPTIONAL_SECTIONS}}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Config:
        """Build from a nested dict as written in a TOML file; unknown keys are errors."""
        if not isinstance(data, dict):
            raise ConfigError("configuration must be a table of sections")
        kwargs: dict[str, Any] = {}
        for key, value in data.items():
            if key == "mode":
                kwargs["mode"] = value
                continue
            if key == "simulation" and isinstance(value, dict):
                for old, new in _MOVED.items():
                    if old in value:
                        raise ConfigError(f"simulation.{old} moved to {new} "
                                          f"(e.g. {new} = {value[old]!r})")
            if key not in _SECTIONS:
                raise ConfigError(f"unknown section {key!r}; allowed: "
                                  f"{', '.join(['mode', *_SECTIONS])}")
            kwargs[key] = _build_section(key, _SECTIONS[key], value)
        return cls(**kwargs)

    @classmethod
    def from_toml(cls, path: str | Path) -> Config:
        """Read a TOML file (sections as in :meth:`to_dict`)."""
        return cls.from_dict(read_toml(path, "config file"))

    def to_toml(self) -> str:
        """The whole configuration as TOML text: every field written out, defaults included.

        ``Config.from_dict(tomllib.loads(c.to_toml())) == c``; the text is canonical (fixed
        order, fixed number format), so equal configurations give equal text.
        """
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    def digest(self, *extra: Any) -> str:
        """A short hash (10 hex digits) of :meth:`to_toml` and of ``extra`` (e.g. a seed range).

        Equal configurations (and extras) give equal digests, in any process and version of
        Python.
        """
        h = hashlib.sha256(self.to_toml().encode("utf-8") + self.resolved_defaults().encode())
        for item in extra:
            h.update(b"\0" + repr(item).encode("utf-8"))
        return h.hexdigest()[:10]

    def resolved_defaults(self) -> str:
        """The mode's defaults that an unset field stands for and that its text does not
        say (corrected mode's foresight and clearance, issue 39), as canonical text for the
        identities of runs (:meth:`digest`, a sweep's grid): empty in paper mode, so that
        its digests (and the published runs' folders) are those from before these defaults
        existed, and a results folder of corrected-mode runs made under the old defaults is
        not resumed under the new ones."""
        if self.mode == "paper" or self.shield == "off":  # (nothing reads them then)
            return ""
        lines = self.yield_line_choices
        return (f"\0defaults: yield_line_choices_m={list(lines) if lines else []}, "
                f"shield_margin_m={self.shield_margin_m!r}")

    def with_overrides(self, overrides: dict[str, Any]) -> Config:
        """A copy with ``{"section.field": value}`` (or ``{"mode": ...}``) applied.

        Nested sections take longer paths (``"hv.idm.time_gap_s"``).
        """
        data = self.to_dict()
        # Quirks left to the mode must stay unset, so that a new mode sets them.
        data["quirks"] = {k: v for k, v in asdict(self.quirks).items() if v is not None}
        for dotted, value in overrides.items():
            if dotted == "mode":
                data["mode"] = value
                continue
            *path, name = dotted.split(".")
            if not path or not name:
                raise ConfigError(f"{dotted!r} is not of the form section.field "
                                  "(e.g. mpc.epsilon)")
            if path[0] not in _SECTIONS:
                raise ConfigError(f"unknown section {path[0]!r} in {dotted!r}; allowed: "
                                  f"{', '.join(['mode', *_SECTIONS])}")
            table, cls = data.setdefault(path[0], {}), _SECTIONS[path[0]]
            for i, part in enumerate(path[1:], start=1):
                sub = _subsections(cls).get(part)
                if sub is None:
                    raise ConfigError(f"unknown section {'.'.join(path[:i + 1])!r} in "
                                      f"{dotted!r}; allowed: {_allowed_keys(cls)}")
                table, cls = table.setdefault(part, {}), sub
            table[name] = value
        return Config.from_dict(data)


def _subsections(section_cls: type) -> dict[str, type]:
    """The nested sections of a section class, by field name."""
    return {f.name: f.default_factory().__class__ for f in fields(section_cls)
            if f.default_factory is not MISSING}


def _allowed_keys(section_cls: type) -> str:
    return ", ".join(f.name for f in fields(section_cls))


def _section_dict(section: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in fields(section):
        value = getattr(section, f.name)
        if is_dataclass(value):
            out[f.name] = _section_dict(value)
        elif value is not None:
            out[f.name] = value
    return out


def _build_section(name: str, section_cls: type, value: Any) -> Any:
    if not isinstance(value, dict):
        raise ConfigError(f"[{name}] must be a table of parameters")
    known = {f.name for f in fields(section_cls)}
    subs = _subsections(section_cls)
    kwargs = {}
    for key, item in value.items():
        if key not in known:
            raise ConfigError(f"{name}.{key}: unknown key; allowed: {_allowed_keys(section_cls)}")
        kwargs[key] = (_build_section(f"{name}.{key}", subs[key], item) if key in subs
                       else item)
    return section_cls(**_coerce(section_cls, kwargs))


def _coerce(section_cls: type, values: dict[str, Any]) -> dict[str, Any]:
    """Accept TOML integers for float fields (``epsilon = 1`` means 1.0)."""
    out = dict(values)
    for f in fields(section_cls):
        if f.name in out and isinstance(out[f.name], int) and not isinstance(out[f.name], bool):
            default = f.default if f.default is not MISSING else None
            if isinstance(default, float) or "float" in str(f.type):
                out[f.name] = float(out[f.name])
    return out


#: The sections of :class:`Config`, by name.
_SECTIONS: dict[str, type] = {
    "vehicle": VehicleParams,
    "library": LibraryParams,
    "reward": RewardParams,
    "roles": RoleParams,
    "mpc": MPCParams,
    "scenario": ScenarioParams,
    "simulation": SimulationParams,
    "av": AVParams,
    "hv": HVParams,
    "quirks": Quirks,
    "responsibility": ResponsibilityParams,
    "junction": JunctionParams,
}
#: Sections left out of :meth:`Config.to_dict` while every value in them is unset (the
#: configurations written before they existed keep their text and digests).
_OPTIONAL_SECTIONS = ("responsibility", "junction")

#: Fields that moved, for a helpful message when an old configuration names them.
_MOVED = {"av": "av.kind", "hv_role": "hv.role"}


__all__ = [
    "DEFAULT_SHIELD_MARGIN_M",
    "DEFAULT_YIELD_LINE_CHOICES_M",
    "LINE_AT_INTERVAL",
    "AVParams",
    "Config",
    "ConfigError",
    "HVParams",
    "IDMParams",
    "JunctionParams",
    "JunctionSpec",
    "MANY_SCENARIO_KINDS",
    "LibraryParams",
    "NoisyParams",
    "RandomHumanParams",
    "ReplayParams",
    "VehicleOverrides",
    "MPCParams",
    "Quirks",
    "RewardParams",
    "RoleParams",
    "ScenarioParams",
    "SimulationParams",
    "VehicleParams",
]
