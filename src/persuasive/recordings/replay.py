"""The planner in a recorded driver's seat: each recorded pair replayed with the AV in place of
one of its two vehicles (docs/guide/recordings.md, "Replay").

**A run.** For a pair of :mod:`persuasive.recordings.pairs` and a *seat* (the vehicle, 1 or 2,
whose place the AV takes), the configuration is the pair's view with the other vehicle as the
human (:func:`persuasive.recordings.logs.view_log`: the scenario form of the pair, the recorded
sizes, ``v_max`` raised to the pair's highest speed, ``dt = 0.1 s``), with the AV kind and
shield asked for, no noise, and ``simulation.n_steps`` the recorded steps plus ``extra_s``.
The closed loop (the compiled loop of :func:`persuasive.simulation.simulate`) starts from the
**recorded first state of both vehicles**: the AV at the replaced vehicle's ``(s, v)``, the
human at its own. The human is

- ``replay``: the recorded driver, open loop (``hv.kind = "replay"``): at step ``k`` the
  acceleration ``(v_{k+1} - v_k) / dt`` of its smoothed speeds, so that the replay reproduces
  the recorded speeds exactly (positions up to the trapezoid rule's error: within 1 cm over
  120 steps of our own runs exported with 5 cm of noise), then coasting once the recording
  ends; it does not react to the AV;
- ``fitted``: the human model ``model`` (``lfg``, ``stubborn``, ``noisy``, ``idm``) with the
  parameters fitted (point estimates, ``persuasive.fitting.fit_models``) on **both views of
  every pair of the other recordings** of the pairs file (leave one recording out: a driver is
  never replayed against a model fitted on its own recording); the parameters are taken to be
  the drivers', whatever the pair's angle. Its initial role is the likelier one under the
  fitted ``pi0`` (leader on a tie); it runs without noise.

**The envelope** (the shield's assumption about the human, docs/method.md §12.2): each step of
the recorded driver's replayed acceleration within the human vehicle's ``[u_min, u_max]`` and
its speed within ``[v_min, v_max]`` of the run's configuration, to ``ENVELOPE_TOL``. The
recorded driver is tested whichever ``other`` drives; its steps beyond are counted. (``v_max``
of a pair's configuration is raised to the pair's highest speed, so only an acceleration can
leave the envelope.) Steps that read one of its track's first or last samples
(``persuasive.recordings.tracks.edge_samples``) are not tested: there the filter's values are
its edge windows' extrapolations, not the driver's. Each run keeps its tested steps' extremes
(the strongest braking and acceleration, the lowest and highest speed), so the summary also
says, per named envelope of :mod:`persuasive.recordings.envelope` (``paper``, ``sumo``,
``real-driver``, each with its own ``v_max``), in how many runs the premise held: the driver
within that envelope on every tested step and the start certified (:func:`premise_by_envelope`).

**Whether the start is certified.** The AV's recorded start is in the shield's invariant set
``S`` when it can stand before its occupancy interval by braking
(:meth:`persuasive.scenarios.Scenario.av_stands_before_occupancy`) or the shield had a
certified choice at the first step (:func:`start_in_s`); the guarantee is claimed from such
starts only.

**Invalid runs** (a non-reactive replay only). A replayed driver drove as it did in the
presence of the recorded vehicle; where that vehicle's timing shaped its drive and the AV does
not reproduce it, the run says nothing about the AV. The rule: a run is *invalid* when

1. ``yielded``: in the recording the replayed driver passed the conflict point after the
   replaced vehicle (its timing was set by that vehicle), and in the replay the AV did not pass
   it first: the driver now arrives where the AV still is, or waits for a car that is not
   there; or
2. ``rear-end``: the replayed driver drove into the AV from behind (a rear-end by the human,
   docs/method.md §12.6), which a driver who saw the AV would not have done.

Times are compared on valid runs only; collisions are reported on all runs, valid or not.

**Which pairs.** A pairs file holds every approaching pair, most of them no interaction at
all at a busy junction (a minor-road car waiting at its line pairs with every major-road car
that passes it). ``recordings replay`` therefore replays by default only the pairs that interact:
those whose post-encroachment time at the conflict area (``pet_area_s``, Allen et al. 1978;
the time from the first vehicle's rear leaving the area to the other's front reaching it) is
at most :data:`DEFAULT_PET_AREA_MAX_S` (4 s, the held-out evaluation's bound too, ``fit
--pet-max``; ``--pet-max``, ``inf``: every pair). A pair whose
PET is unknown (the second never reached the area while recorded, or a pairs file written
before the column) is replayed. In the library the bound is
``ReplaySettings.pet_area_max_s``, ``inf`` unless given: a frame handed in is replayed
whole, as before. The pairs left out are counted, with the reason, in
:attr:`ReplayResult.selection` and the summary (:func:`select_pairs`).

**Times.** The AV's time to clear (``RunOutcome.av_time_to_clear_s``) beside the replaced
vehicle's own, the first recorded step at which its ``s`` is past the scenario's clearing
position (NaN when it did not clear while recorded); the summary gives restricted means, a
time that is NaN counted as the run's horizon, over the valid runs.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..config import AV_KINDS, SHIELD_KINDS, Config
from ..safety.measures import restricted_mean
# the envelope test lives with the envelopes (one concept, one module); kept importable here
from .envelope import ENVELOPE_TOL, ENVELOPES, envelope_excess
from .evaluate import PET_MAX_S
from .formats import STEP_S, RecordingError
from .logs import ANGLE_STEP_DEG, view_log
from .tracks import SmoothingParams, edge_samples

#: Who drives the other vehicle.
OTHERS = ("replay", "fitted")
#: The human models a ``fitted`` other can be.
FITTED_MODELS = ("lfg", "stubborn", "noisy", "idm")
#: Reasons of an invalid run (module docstring).
INVALID_YIELDED, INVALID_REAR_END = "yielded", "rear-end"
#: The pairs replayed by default: post-encroachment time at the conflict area at most this [s]
#: (module docstring, "Which pairs"; the held-out evaluation's bound, ``fit --pet-max``): an
#: accepted gap at an unsignalised junction is some 4-7 s between arrivals, which leaves a PET
#: at the area of a few seconds; two vehicles further apart there did not interact.
DEFAULT_PET_AREA_MAX_S = PET_MAX_S


@dataclass(frozen=True)
class ReplaySettings:
    """What ``recordings replay`` runs (module docstring)."""

    av: str = "persuasive"  #: the AV kind (``persuasive.config.AV_KINDS``)
    shield: str = "worst-case"  #: the shield (``persuasive.config.SHIELD_KINDS``)
    other: str = "replay"  #: ``replay`` (the recorded driver) or ``fitted`` (a fitted model)
    model: str = "lfg"  #: the fitted model of ``other = "fitted"``
    extra_s: float = 10.0  #: the run goes on this long after the recording ends [s]
    seats: tuple[int, ...] = (1, 2)  #: the vehicles whose place the AV takes, in turn
    mode: str = "corrected"  #: the configuration's mode (docs/method.md §9)
    angle_step_deg: float = ANGLE_STEP_DEG  #: the pair's angle rounded to this [deg]
    #: the human envelope the shield assumes of the other vehicle and the premise tests the
    #: recorded driver against: ``paper`` (the configuration's ``hv`` limits) or a name of
    #: ``persuasive.config.HUMAN_ENVELOPES`` (``hv.envelope``)
    envelope: str = "paper"
    #: replay the pairs whose PET at the conflict area is at most this [s] (``inf``: every
    #: pair; a pair without one is replayed; module docstring, "Which pairs"); the command's
    #: default is :data:`DEFAULT_PET_AREA_MAX_S`
    pet_area_max_s: float = math.inf

    def __post_init__(self) -> None:
        from ..config import HUMAN_ENVELOPES

        pet = self.pet_area_max_s
        if isinstance(pet, bool) or not isinstance(pet, (int, float)) or math.isnan(pet) \
                or not pet > 0.0:
            raise RecordingError(f"--pet-max = {pet!r} is out of range; allowed: (0, inf] s "
                                 "(inf: every pair)")

        if self.envelope != "paper" and self.envelope not in HUMAN_ENVELOPES:
            raise RecordingError(f"--envelope = {self.envelope!r} is not allowed; allowed: "
                                 f"{', '.join(('paper', *HUMAN_ENVELOPES))}")
        for name, value, allowed in (("--av", self.av, AV_KINDS),
                                     ("--shield", self.shield, SHIELD_KINDS),
                                     ("--other", self.other, OTHERS),
                                     ("--model", self.model, FITTED_MODELS)):
            if value not in allowed:
                raise RecordingError(f"{name} = {value!r} is not allowed; allowed: "
                                     f"{', '.join(allowed)}")
        if not (isinstance(self.extra_s, (int, float)) and math.isfinite(self.extra_s)
                and 0.0 <= self.extra_s <= 600.0):
            raise RecordingError(f"--extra-s = {self.extra_s!r} is out of range; allowed: "
                                 "[0, 600] s")
        if not self.seats or any(s not in (1, 2) for s in self.seats) or \
                len(set(self.seats)) != len(self.seats):
            raise RecordingError(f"seats = {self.seats!r} is not allowed; allowed: 1, 2 or "
                                 "both, each once")


@dataclass(frozen=True)
class SeatRun:
    """One replayed run: a pair with the AV in vehicle ``seat``'s place (module docstring)."""

    pair: int
    recording: str
    kind: str  #: crossing or merge
    angle_deg: float  #: the scenario's (rounded) angle [deg]
    seat: int  #: the vehicle the AV replaces (1 or 2); the other is the human
    steps: int  #: closed-loop steps (recorded steps + extra)
    recorded_steps: int  #: the recording's steps of the pair
    start_certified: bool  #: the AV's start is in the shield's invariant set
    # the recorded driver of the other vehicle against the envelope
    envelope_steps: int  #: replayed steps tested
    excess_steps: int  #: steps beyond the envelope
    within_envelope: bool
    accel_min_mps2: float  #: the replayed driver's strongest braking (signed) [m/s^2]
    accel_max_mps2: float  #: its strongest acceleration [m/s^2]
    u_min_mps2: float  #: the envelope it was tested against [m/s^2]
    u_max_mps2: float
    # the closed loop's outcome
    collision: bool
    collision_caused_by_av: bool
    rear_end_by_human: bool
    uncertified_steps: int
    guarantee_held: bool
    shield_interventions: int
    min_gap_m: float
    first_recorded: str  #: who passed the conflict point first: "replaced", "other", ...
    first_replay: str  #: the same in the replay ("AV", "other", "neither", "same step")
    av_clear_s: float  #: the AV's time to clear [s] (NaN: never)
    recorded_clear_s: float  #: the replaced vehicle's own while recorded [s] (NaN: never)
    other_clear_s: float  #: the human's time to clear in the replay [s]
    valid: bool
    invalid_reason: str  #: "" when valid, else :data:`INVALID_YIELDED` / ``REAR_END``
    #: the map's right of way in this run (:func:`seat_right_of_way`): "av", "hv", or ""
    #: (the base configuration's: neither)
    right_of_way: str = ""
    fitted: dict = field(default_factory=dict)  #: the fitted model's parameters, if any
    # the tested steps' extremes, against which any envelope is judged (:func:`within`;
    # NaN when no step was tested)
    tested_accel_min_mps2: float = math.nan  #: the strongest tested braking (signed) [m/s^2]
    tested_accel_max_mps2: float = math.nan  #: the strongest tested acceleration [m/s^2]
    tested_v_min_mps: float = math.nan  #: the lowest speed at a tested step's end [m/s]
    tested_v_max_mps: float = math.nan  #: the highest [m/s]


@dataclass(frozen=True)
class ReplayResult:
    """Every replayed run, the settings, and the fits of a ``fitted`` other (per recording
    left out)."""

    runs: list[SeatRun]
    settings: ReplaySettings
    fits: dict[str, dict] = field(default_factory=dict)
    #: which pairs of the file were replayed and which left out, and why (:func:`select_pairs`)
    selection: dict = field(default_factory=dict)

    def frame(self):
        """One row per run (the fields of :class:`SeatRun`; ``fitted`` as JSON text)."""
        import json

        import pandas as pd

        rows = []
        for r in self.runs:
            row = asdict(r)
            row["fitted"] = json.dumps(row["fitted"], sort_keys=True)
            rows.append(row)
        return pd.DataFrame(rows, columns=list(SeatRun.__dataclass_fields__))

    def summary(self) -> dict:
        """What ``recordings replay`` prints (see :func:`summarise`), with the pairs left
        out (``selection``: :func:`select_pairs`)."""
        return {**summarise(self.runs, self.settings), "selection": self.selection}


def _share(k: int, n: int) -> float | None:
    return k / n if n else None


def within(run: SeatRun, envelope) -> bool:
    """Whether the run's recorded driver stayed within ``envelope`` (any object with
    ``u_min_mps2, u_max_mps2, v_min_mps, v_max_mps``, such as
    :class:`persuasive.recordings.envelope.Envelope`) on every tested step, by
    :func:`envelope_excess`'s test (to :data:`ENVELOPE_TOL`) applied to the run's tested
    extremes; a run with no tested step is within every envelope."""
    if run.envelope_steps == 0:
        return True
    tol = ENVELOPE_TOL
    return bool(run.tested_accel_min_mps2 >= envelope.u_min_mps2 - tol
                and run.tested_accel_max_mps2 <= envelope.u_max_mps2 + tol
                and run.tested_v_min_mps >= envelope.v_min_mps - tol
                and run.tested_v_max_mps <= envelope.v_max_mps + tol)


def premise_by_envelope(runs: Sequence[SeatRun], envelopes=None) -> dict:
    """Per envelope, the runs whose guarantee's premise held: the recorded driver within it on
    every tested step (:func:`within`) and the start certified. ``configured``: the run's
    own configuration's envelope (``within_envelope``; ``v_max`` raised to the pair's highest
    speed), then each of ``envelopes`` (default: the named ones,
    :data:`persuasive.recordings.envelope.ENVELOPES`) with its numbers. Each entry:
    ``within_envelope`` (runs whose driver stayed within), ``runs`` (the premise held) and
    ``share`` (of all runs; None without runs)."""
    runs = list(runs)
    envelopes = ENVELOPES.values() if envelopes is None else envelopes
    n = len(runs)
    inside = [r.within_envelope for r in runs]
    held = sum(w and r.start_certified for w, r in zip(inside, runs))
    out = {"configured": {"within_envelope": sum(inside), "runs": held,
                          "share": _share(held, n)}}
    for env in envelopes:
        inside = [within(r, env) for r in runs]
        held = sum(w and r.start_certified for w, r in zip(inside, runs))
        out[env.name] = {"u_min_mps2": env.u_min_mps2, "u_max_mps2": env.u_max_mps2,
                         "v_max_mps": env.v_max_mps if math.isfinite(env.v_max_mps) else None,
                         "within_envelope": sum(inside), "runs": held,
                         "share": _share(held, n)}
    return out


def summarise(runs: Sequence[SeatRun], settings: ReplaySettings) -> dict:
    """Counts over the runs: collisions (AV-caused or not, split by the envelope and the
    start), the shield's uncertified steps, the envelope's excesses, the runs whose premise
    held under each named envelope (:func:`premise_by_envelope`), the invalid runs, who
    passed first and the times to clear over the valid runs."""
    runs = list(runs)
    premises = [r for r in runs if r.within_envelope and r.start_certified]
    outside = [r for r in runs if not (r.within_envelope and r.start_certified)]

    def collisions(rs):
        return {"runs": len(rs), "collisions": sum(r.collision for r in rs),
                "av_caused": sum(r.collision_caused_by_av for r in rs),
                "rear_end_by_human": sum(r.rear_end_by_human for r in rs)}

    valid = [r for r in runs if r.valid]
    firsts: dict[str, int] = {}
    rec_firsts: dict[str, int] = {}
    for r in valid:
        firsts[r.first_replay] = firsts.get(r.first_replay, 0) + 1
        rec_firsts[r.first_recorded] = rec_firsts.get(r.first_recorded, 0) + 1
    horizon = [r.steps * STEP_S for r in valid]
    both = [r for r in valid if not (math.isnan(r.av_clear_s) or math.isnan(r.recorded_clear_s))]
    reasons: dict[str, int] = {}
    for r in runs:
        if not r.valid:
            reasons[r.invalid_reason] = reasons.get(r.invalid_reason, 0) + 1
    steps = sum(r.envelope_steps for r in runs)
    excess = sum(r.excess_steps for r in runs)
    return {
        "av": settings.av, "shield": settings.shield, "other": settings.other,
        "human_envelope": settings.envelope,
        "model": settings.model if settings.other == "fitted" else None,
        "runs": len(runs), "pairs": len({r.pair for r in runs}),
        "collisions": collisions(runs),
        "within_envelope_certified_start": collisions(premises),
        "beyond_envelope_or_uncertified_start": collisions(outside),
        "beyond_envelope": collisions([r for r in runs if not r.within_envelope]),
        "uncertified_start": collisions([r for r in runs if not r.start_certified]),
        "uncertified_steps": sum(r.uncertified_steps for r in runs),
        "runs_with_uncertified_steps": sum(r.uncertified_steps > 0 for r in runs),
        "guarantee_held": sum(r.guarantee_held for r in runs),
        "envelope": {"steps": steps, "excess_steps": excess,
                     "excess_share": _share(excess, steps),
                     "runs_beyond": sum(not r.within_envelope for r in runs),
                     "accel_min_mps2": min((r.accel_min_mps2 for r in runs), default=None),
                     "accel_max_mps2": max((r.accel_max_mps2 for r in runs), default=None)},
        "right_of_way": {"av": sum(r.right_of_way == "av" for r in runs),
                         "hv": sum(r.right_of_way == "hv" for r in runs),
                         "neither": sum(r.right_of_way == "" for r in runs)},
        "invalid": reasons, "valid": len(valid),
        "first_replay": firsts, "first_recorded": rec_firsts,
        "av_clear_s_rmean": restricted_mean([r.av_clear_s for r in valid], horizon),
        "recorded_clear_s_rmean": restricted_mean([r.recorded_clear_s for r in valid], horizon),
        "both_cleared": len(both),
        "clear_s_paired_diff_mean": float(np.mean([r.av_clear_s - r.recorded_clear_s
                                                   for r in both])) if both else None,
        "premise_by_envelope": premise_by_envelope(runs),
    }


# -- one run ------------------------------------------------------------------------------------


def run_from(config: Config, x0, hv_prm: np.ndarray | None = None, seed: int = 0):
    """One closed loop of ``config`` from the initial state ``x0 = (s_av, v_av, s_hv, v_hv)``
    (the configuration's own draw replaced); ``hv_prm``: the human's parameter vector, in
    place of the configuration's (a replay given in memory): ``simulate(config, seed, x0=...,
    hv_prm=...)``."""
    from ..simulation import simulate

    return simulate(config, seed, x0=x0, hv_prm=hv_prm)


def replay_accelerations(v: np.ndarray, dt: float = STEP_S) -> np.ndarray:
    """The open-loop accelerations that reproduce the speeds ``v`` ``(n,)`` step by step:
    ``(v_{k+1} - v_k) / dt``, ``(n - 1,)`` [m/s^2]."""
    return np.diff(np.asarray(v, float)) / dt


def start_in_s(record, s0: float, v0: float) -> bool:
    """Whether the AV's start ``(s0, v0)`` is in the shield's invariant set ``S``: it can
    stand before its occupancy interval by braking (braking for ever is certified), or the
    shield had a certified choice at the first step (docs/method.md §12.2)."""
    from ..safety.shield import UNCERTIFIED

    if record.scenario.av_stands_before_occupancy(s0, v0):
        return True
    verdict = record.log.get("shield_verdict")
    return bool(verdict is not None and len(verdict) and 0 <= verdict[0] != UNCERTIFIED)


def _recorded_first(first: str, seat: int) -> str:
    if first in ("1", "2"):
        return "replaced" if int(first) == seat else "other"
    return first


def _first_time(hit: np.ndarray) -> float:
    """The time of the first state ``x_{k+1}`` flagged in ``hit`` (states from ``x_1``), as
    :func:`persuasive.record.outcome` times arrivals [s]; NaN when none is."""
    k = np.flatnonzero(hit)
    return float((k[0] + 1) * STEP_S) if k.size else math.nan


def edge_steps(rows, human: int, edge: int) -> np.ndarray:
    """``(n - 1,)`` bool: the pair's steps ``k`` whose replayed acceleration (from the speeds
    at ``k`` and ``k + 1``) reads one of vehicle ``human``'s track's first or last ``edge``
    samples (``persuasive.recordings.tracks.edge_samples``; all False for a pairs file that
    does not say where its steps lie in the tracks)."""
    n = len(rows) - 1
    k0, n_track = f"track_k0_{human}", f"track_n_{human}"
    if k0 not in rows or edge <= 0:
        return np.zeros(n, bool)
    k = int(rows[k0].iloc[0]) + np.arange(n)
    return (k < edge) | (k + 1 > int(rows[n_track].iloc[0]) - 1 - edge)


def seat_right_of_way(rows, seat: int) -> str | None:
    """The right of way of the run with the AV in vehicle ``seat``'s place, from the pair's
    map (``control`` and ``priority``, :mod:`persuasive.recordings.lanelet_map`): ``"av"``
    when the map gives it to the replaced vehicle, ``"hv"`` when to the other, None where the
    map gives it to neither (``none``, an all-way stop) or no map was read (``unknown``, or a
    pairs file without the map's columns)."""
    if "control" not in rows or str(rows["control"].iloc[0]) != "right_of_way":
        return None
    priority = int(rows["priority"].iloc[0])
    if priority not in (1, 2):
        return None
    return "av" if priority == seat else "hv"


def run_seat(rows, seat: int, settings: ReplaySettings, base: Config, source: str = "",
             fitted: dict | None = None, edge: int = 0) -> SeatRun:
    """The run of one pair (its rows of the pairs file, in step order) with the AV in vehicle
    ``seat``'s place (module docstring). ``fitted``: the config overrides and parameters of a
    ``fitted`` other (:func:`fitted_overrides`); ``edge``: the samples at each end of a track
    its envelope test leaves out (:func:`edge_steps`)."""
    from ..record import ARRIVAL_LABELS

    human = 3 - seat
    config, _, _ = view_log(rows, human, base, settings.angle_step_deg)
    n = len(rows)
    extra = int(round(settings.extra_s / STEP_S))
    overrides = {"av.kind": settings.av, "av.shield": settings.shield,
                 "simulation.n_steps": n - 1 + extra,
                 "simulation.measurement_noise": "none", "simulation.accel_noise_mps2": 0.0}
    # the map's right of way (None: the base configuration's), which the responsibility
    # shield reads (docs/method.md §12.13)
    right_of_way = seat_right_of_way(rows, seat)
    if right_of_way is not None:
        overrides["responsibility.right_of_way"] = right_of_way
    # the draw is replaced by the recorded start; a draw without spread never retries
    for who in ("av", "hv"):
        overrides[f"scenario.{who}_s0_halfwidth_m"] = 0.0
        overrides[f"scenario.{who}_v0_halfwidth_mps"] = 0.0
    s_av, v_av = rows[f"s_{seat}_m"].to_numpy(float), rows[f"v_{seat}_mps"].to_numpy(float)
    s_hv, v_hv = rows[f"s_{human}_m"].to_numpy(float), rows[f"v_{human}_mps"].to_numpy(float)
    a_rec = replay_accelerations(v_hv)
    hv_prm = None
    params: dict = {}
    if settings.other == "replay":
        overrides.update({"hv.kind": "replay", "hv.replay.file": source or "pairs",
                          "hv.replay.vehicle": "hv"})
        hv_prm = np.concatenate([[float(a_rec.size)], a_rec])
    else:
        overrides.update(fitted["overrides"])
        params = dict(fitted["params"])
    config = config.with_overrides(overrides)
    record = run_from(config, (s_av[0], v_av[0], s_hv[0], v_hv[0]), hv_prm,
                      seed=int(rows["pair"].iloc[0]))
    out = record.outcome
    scenario = record.scenario
    veh = config.vehicle_of("hv")
    tested = ~edge_steps(rows, human, edge)
    excess = envelope_excess(a_rec, v_hv, veh) & tested
    a_tested, v_tested = a_rec[tested], v_hv[1:][tested]
    extremes = (float(a_tested.min()), float(a_tested.max()), float(v_tested.min()),
                float(v_tested.max())) if a_tested.size else (math.nan,) * 4
    first_rec = _recorded_first(str(rows["first"].iloc[0]), seat)
    label = ARRIVAL_LABELS[out.first_at_conflict_point]
    first_replay = {"HV": "other"}.get(label, label)
    reason = ""
    if settings.other == "replay":
        if first_rec == "replaced" and out.first_at_conflict_point != 1:
            reason = INVALID_YIELDED
        elif out.rear_end_by_human:
            reason = INVALID_REAR_END
    recorded_clear = _first_time(scenario.cleared("av", s_av[1:]))
    first = rows.iloc[0]
    return SeatRun(
        pair=int(first["pair"]), recording=str(first["recording"]), kind=config.scenario.kind,
        angle_deg=float(config.scenario.angle_deg), seat=seat, steps=config.simulation.n_steps,
        recorded_steps=n,
        start_certified=start_in_s(record, s_av[0], v_av[0]),
        envelope_steps=int(tested.sum()), excess_steps=int(excess.sum()),
        within_envelope=not bool(excess.any()),
        accel_min_mps2=float(a_rec.min()), accel_max_mps2=float(a_rec.max()),
        u_min_mps2=veh.u_min_mps2, u_max_mps2=veh.u_max_mps2,
        collision=out.collision, collision_caused_by_av=out.collision_caused_by_av,
        rear_end_by_human=out.rear_end_by_human, uncertified_steps=out.uncertified_steps,
        guarantee_held=out.guarantee_held, shield_interventions=out.shield_interventions,
        min_gap_m=out.min_gap_m, first_recorded=first_rec, first_replay=first_replay,
        av_clear_s=out.av_time_to_clear_s, recorded_clear_s=recorded_clear,
        other_clear_s=out.hv_time_to_clear_s, valid=not reason, invalid_reason=reason,
        right_of_way=right_of_way or "", fitted=params,
        tested_accel_min_mps2=extremes[0], tested_accel_max_mps2=extremes[1],
        tested_v_min_mps=extremes[2], tested_v_max_mps=extremes[3])


# -- the fitted other ---------------------------------------------------------------------------


def pair_run_logs(frame, base: Config, step_deg: float = ANGLE_STEP_DEG) -> list:
    """Both views of every pair of a pairs frame as :class:`persuasive.fitting.RunLog` (what
    ``recordings logs`` writes, in memory)."""
    from ..fitting.evidence import RunLog

    out = []
    smoothing = frame.attrs.get("smoothing")
    for pair_id, rows in frame.groupby("pair", sort=True):
        rows = rows.sort_values("step")
        for human in (1, 2):
            config, log, meta = view_log(rows, human, base, step_deg, smoothing)
            states = log[["av_meas_s_m", "av_meas_v_mps", "hv_meas_s_m",
                          "hv_meas_v_mps"]].to_numpy(float)
            out.append(RunLog(f"pair {int(pair_id)} vehicle {human}", config, int(pair_id),
                              None, states, log["hv_accel_mps2"].to_numpy(float), meta))
    return out


def fitted_overrides(model: str, theta: dict) -> dict:
    """The configuration overrides of a fitted human (point estimates ``theta``) and its
    parameters as reported."""
    if model == "idm":
        names = ("desired_speed_mps", "time_gap_s", "max_accel_mps2", "comfort_decel_mps2",
                 "critical_gap_s", "impatience_per_s")
        over = {"hv.kind": "idm", **{f"hv.idm.{k}": float(theta[k]) for k in names}}
        return {"overrides": over, "params": {k: float(theta[k]) for k in names}}
    role = "leader" if float(theta["pi0"]) >= 0.5 else "follower"
    over = {"hv.kind": model, "hv.role": role}
    params = {"pi0": float(theta["pi0"]), "role": role}
    if model in ("lfg", "noisy"):
        over["roles.p_a"] = float(theta["p_a"])
        params["p_a"] = float(theta["p_a"])
    if model == "noisy":
        over["hv.noisy.beta"] = float(theta["beta"])
        params["beta"] = float(theta["beta"])
    return {"overrides": over, "params": params}


def fit_left_out(frame, settings: ReplaySettings, base: Config) -> dict[str, dict]:
    """Per recording of the pairs frame, the model fitted on the pairs of every other
    recording (:func:`fitted_overrides`). :class:`RecordingError` with fewer than two
    recordings."""
    from ..fitting import evidence_of, fit_models

    recordings = sorted(frame["recording"].unique())
    if len(recordings) < 2:
        raise RecordingError(f"--other fitted needs pairs of at least two recordings (the "
                             f"model is fitted on the recordings other than the replayed "
                             f"one); the pairs file holds {len(recordings)}: "
                             f"{', '.join(map(str, recordings))}")
    logs = pair_run_logs(frame, base, settings.angle_step_deg)
    rec_of = {int(p): str(r) for p, r in frame.groupby("pair")["recording"].first().items()}
    ev = evidence_of(logs)
    out = {}
    for rec in recordings:
        keep = [i for i, log in enumerate(logs) if rec_of[log.seed] != rec]
        report = fit_models(ev.subset(keep), [settings.model], intervals=False)
        fit = report.fits[settings.model]
        entry = fitted_overrides(settings.model, fit.theta)
        entry["params"]["sigma"] = float(fit.theta["sigma"])
        entry["params"]["fitted_runs"] = len(keep)
        out[rec] = entry
    return out


def select_pairs(frame, pet_area_max_s: float = DEFAULT_PET_AREA_MAX_S):
    """The rows of the pairs that interact (module docstring, "Which pairs"): a pair is left
    out when its ``pet_area_s`` is known and above ``pet_area_max_s``. Returns the kept
    rows (``frame.attrs`` kept) and what was done: ``pet_area_max_s`` (None for ``inf``),
    ``pairs`` (in the file), ``replayed``, ``left_out`` (``{reason: pairs}``, the reason
    ``"pet_area_s > <bound> s"``; empty when none), ``unknown_pet`` (pairs replayed
    without a PET at the area)."""
    pet = frame.groupby("pair", sort=True)["pet_area_s"].first() if "pet_area_s" in frame \
        else None
    n = int(frame["pair"].nunique()) if len(frame) else 0
    bound = None if math.isinf(pet_area_max_s) else float(pet_area_max_s)
    if pet is None:
        return frame, {"pet_area_max_s": bound, "pairs": n, "replayed": n, "left_out": {},
                       "unknown_pet": n}
    values = pet.to_numpy(float)
    out = ~np.isnan(values) & (values > pet_area_max_s)
    left = int(out.sum())
    info = {"pet_area_max_s": bound, "pairs": n, "replayed": n - left,
            "left_out": {f"pet_area_s > {pet_area_max_s:g} s": left} if left else {},
            "unknown_pet": int(np.isnan(values).sum())}
    if not left:
        return frame, info
    kept = frame[frame["pair"].isin(pet.index[~out])]
    kept.attrs = dict(frame.attrs)
    return kept, info


def replay_pairs(frame, settings: ReplaySettings | None = None, base: Config | None = None,
                 source: str = "", workers: int = 1,
                 progress: Callable[[int, int], None] | None = None) -> ReplayResult:
    """Every pair of a pairs frame (:func:`persuasive.recordings.pairs.read_pairs`) that
    interacts (:func:`select_pairs` with ``settings.pet_area_max_s``; the rest are counted in
    the result's ``selection``) replayed with the AV in each seat of ``settings.seats``
    (module docstring), in pair order; with
    ``workers > 1`` the pairs run on the worker processes of a local Dask cluster
    (``persuasive.sweep.runner.local_client``), the same runs bit for bit (each pair's runs
    depend on that pair, the settings and, with a fitted other, the fits made here first);
    ``progress(done, total)`` after each pair."""
    settings = settings or ReplaySettings()
    base = base if base is not None else Config(mode=settings.mode)
    if settings.envelope != "paper":
        base = base.with_overrides({"hv.envelope": settings.envelope})
    # the fits read every pair of the file (the models are the recordings' drivers)
    fits = fit_left_out(frame, settings, base) if settings.other == "fitted" else {}
    smoothing = frame.attrs.get("smoothing")
    frame, selection = select_pairs(frame, settings.pet_area_max_s)
    edge = edge_samples(SmoothingParams(**smoothing) if smoothing else None)
    tasks = []
    for _, rows in frame.groupby("pair", sort=True):
        rows = rows.sort_values("step")
        if len(rows) < 2:
            raise RecordingError(f"pair {int(rows['pair'].iloc[0])} has {len(rows)} step; a "
                                 "replay needs two")
        tasks.append(rows)
    by_pair: dict[int, list[SeatRun]] = {}
    if workers <= 1 or len(tasks) <= 1:
        for i, rows in enumerate(tasks):
            by_pair[i] = _replay_pair(rows, settings, base, source, fits, edge)
            if progress is not None:
                progress(i + 1, len(tasks))
    else:
        from ..sweep.runner import local_client, map_bounded

        data = base.to_dict()
        args = [(rows, settings, data, source, fits, edge) for rows in tasks]
        with local_client(min(workers, len(tasks))) as client:
            for i, got in map_bounded(client, _replay_task, args):
                by_pair[i] = got
                if progress is not None:
                    progress(len(by_pair), len(tasks))
    runs = [run for i in range(len(tasks)) for run in by_pair[i]]
    return ReplayResult(runs, settings, {k: v["params"] for k, v in fits.items()}, selection)


def _replay_pair(rows, settings: ReplaySettings, base: Config, source: str, fits: dict,
                 edge: int) -> list[SeatRun]:
    """One pair's runs, one per seat of ``settings.seats``."""
    rec = str(rows["recording"].iloc[0])
    return [run_seat(rows, seat, settings, base, source, fits.get(rec), edge)
            for seat in settings.seats]


def _replay_task(args) -> list[SeatRun]:
    rows, settings, data, source, fits, edge = args
    return _replay_pair(rows, settings, Config.from_dict(data), source, fits, edge)


__all__ = ["DEFAULT_PET_AREA_MAX_S", "ENVELOPE_TOL", "FITTED_MODELS", "INVALID_REAR_END",
           "INVALID_YIELDED", "OTHERS", "ReplayResult", "ReplaySettings", "SeatRun",
           "edge_steps", "envelope_excess", "fit_left_out", "fitted_overrides",
           "pair_run_logs", "premise_by_envelope", "replay_accelerations", "replay_pairs",
           "run_from", "run_seat", "seat_right_of_way", "select_pairs", "summarise", "within"]
