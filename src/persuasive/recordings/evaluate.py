"""Held-out evaluation of the human models on recorded pairs: the next accelerations, and who
passes first (docs/guide/fit.md, "Held-out evaluation on recorded pairs").

**Splits, by recording file.** Pairs of one recording file share their traffic, so a split
never puts one file's pairs on both sides: ``folds`` (K folds of the files, shuffled by
``numpy.random.default_rng(seed)``, each file tested once), ``holdout`` (a share of the files,
at least one, drawn alike, is tested; the rest trains) or ``site`` (several pairs files, each
a site: train on the others, test on one). Everything fitted (the models, the vehicle limits,
the baselines' scales and caps) is fitted on the training files only.

**Views.** Each pair gives two runs, each driver once the human (as
:mod:`persuasive.recordings.logs` writes them, built in memory here): the measured states are
the smoothed ones, the human's acceleration the smoothed one, the configuration the pair's
scenario (kind, angle rounded to 5 degrees, recorded sizes), ``dt = 0.1 s``, corrected mode,
with **vehicle limits from the training data**: per vehicle class, the ``q`` and ``1 - q``
quantiles (``q = 0.01``) of the smoothed accelerations of every training pair's vehicles of
that class (all classes pooled for a class absent there), at most -0.1 and at least 0.1
m/s^2; ``v_max`` the highest training speed rounded up (at least the configured 10 m/s). The
report gives the share of the test steps beyond those limits (the shield's envelope) and
beyond the paper's [-2, 1] m/s^2. One parameter set per model is fitted on all training views
at once, each view re-solved in its own scenario (``persuasive.fitting.fit_models``, point
estimates).

**Next accelerations.** Each fitted model scores the test views at its training estimate: the
log-likelihood of every logged acceleration (the hidden-role models through their forward
filter, ``RoleObjective.run_loglik``; the IDM through its residuals and fitted ``sigma``), per
step. Two baselines score them too, ``sigma`` fitted on the training views: constant speed (``a
= 0``) and constant acceleration (``a_k = a_{k-1}``, ``a_0 = 0``).

**The prediction moment** of a pair: ``after_s`` (1 s) after the first step at which both
vehicles are within ``near_m`` (40 m) of the conflict point and before it (``-near_m <= s <
0``). The smoothing (a centred window, 0.6 s by default) makes a step's values depend on the
samples after it, so what is *seen* at the moment is the pair's steps up to ``lag_steps`` (5 =
0.5 s) before it: no smoothed value seen then uses a sample after the moment (for windows of up
to 11 samples and the files' speeds). A pair is left
out, and counted, when both never approach within ``near_m`` together, when its record ends
before the moment, when the outcome is decided by then (one vehicle has reached the conflict
point, or is inside its occupancy interval, at the moment) or when it has no first passer
(``neither``, ``same time``). Counting the moment forwards from the approach keeps the outcome
open: a horizon counted back from the first arrival gives it away once it is shorter than the
pair's post-encroachment time.

**Which pairs.** ``recordings pairs`` keeps every approaching pair whatever its PET, and at a
site most of them are no interaction: a car waiting on the minor road pairs with every car
that passes on the major one (on the site of ``benchmarks/site_recording.py``, 42,349 pairs,
half with a PET at the conflict area above 19 s, 5 % above 86 s). The evaluation fits and
scores the pairs whose ``pet_area_s`` (:mod:`persuasive.recordings.pairs`: the literature's
PET, at the conflict area with the vehicles' lengths, Allen et al. 1978) is at most
``pet_max_s`` (:data:`PET_MAX_S`, 4 s; ``fit --pet-max``; inf: every pair, those without a
``pet_area_s`` too), 0 included (both footprints in the area at once); the report says how
many pairs were read, selected, and left out per reason (:func:`select_pairs`: a PET above
``pet_max_s``, no PET at the conflict area). The split is then over the recording files that
hold a selected pair. PET selects, never labels: the outcome is who reaches the conflict point
first (the centres, ``t_pass_s``), the statuses above read the pair's steps, its conflict
point and its occupancy intervals (``decided``: a vehicle inside its interval at the moment);
``pet_s``, the PET on the occupancy intervals, is not read.

**P(vehicle 1 passes first).**

- ``lfg``, ``stubborn``, ``noisy``: in the model the leader goes first. Each view's forward
  filter at the training estimate gives the human's ``P(role = L | its accelerations so far)``
  at the last step seen, ``P_1`` for vehicle 1's view and ``P_2`` for vehicle 2's. Taking the
  two views as independent and conditioning on the consistent outcomes (one leads, the other
  follows): ``P = P_1 (1 - P_2) / (P_1 (1 - P_2) + P_2 (1 - P_1))`` (0.5 when both are
  certain of the same role). It is what the model itself knows at the moment, with no
  parameter fitted for the order.
- ``idm``: deterministic, so a forward rollout: both vehicles drive the fitted IDM from the
  last step seen (their gap-acceptance state carried along the steps before), each with its
  own view's lines and limits, at most 30 s; the first to reach the conflict point is
  predicted, with the training share of pairs where the rollout was right (the rules'
  calibration of :mod:`persuasive.recordings.baselines`); 0.5 when neither arrives.
- ``role_belief`` (a baseline: the project's own role belief, online, with no fitted
  parameter): each driver's Bayes belief about the other's role (§5.5) after the last step
  seen; ``P_1`` = vehicle 2's belief that vehicle 1 leads, ``P_2`` = vehicle 1's that vehicle
  2 leads, combined as above.

Scores and intervals: :mod:`persuasive.recordings.scores` (bootstrap over recording files).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .baselines import BASELINE_NAMES, BASELINES, Baselines, Features
from .formats import STEP_S, RecordingError
from .pairs import CROSSING, PAIRS_METADATA
from .scores import PAIR_SCORES, bootstrap, calibration, cluster_weights, log_loss

#: The statuses of a pair at its prediction moment (module docstring).
KEPT = "kept"
NEVER_NEAR = "never both approaching within near_m"
ENDS = "record ends before the moment"
DECIDED = "decided at the moment"
NO_PASSER = "no first passer (neither, same time)"
STATUSES = (KEPT, NEVER_NEAR, ENDS, DECIDED, NO_PASSER)
#: The IDM rollout's horizon [steps of 0.1 s].
ROLLOUT_STEPS = 300
#: The paper's vehicle limits [m/s^2] (persuasive.config.VehicleParams).
PAPER_LIMITS = (-2.0, 1.0)
#: The split kinds.
SPLITS = ("folds", "holdout", "site")
#: Folds when none are asked for (fewer with fewer recording files).
DEFAULT_FOLDS = 5
#: The pairs fitted and scored by default: a PET at the conflict area (``pet_area_s``) of at
#: most this [s] (module docstring, "Which pairs").
PET_MAX_S = 4.0
#: Why a pair of the pairs files is not evaluated (:func:`select_pairs`).
PET_ABOVE = "PET at the conflict area above pet_max_s"
NO_PET = "no PET at the conflict area"


@dataclass(frozen=True)
class EvalParams:
    """The prediction moment, the vehicle limits, the bootstrap (module docstring)."""

    near_m: float = 40.0  #: both within this of the conflict point, approaching [m]
    after_s: float = 1.0  #: the moment: this long after that [s]
    lag_steps: int = 5  #: what is seen ends this many steps before the moment [-]
    accel_quantile: float = 0.01  #: vehicle limits: the q and 1 - q quantiles [-]
    n_boot: int = 1000  #: bootstrap resamples of the recording files [-]
    seed: int = 0  #: the split's and the bootstrap's seed
    sigma_min: float = 1e-3  #: the fit's floor of sigma [m/s^2]
    #: the pairs evaluated: ``pet_area_s`` at most this [s]; inf: every pair
    pet_max_s: float = PET_MAX_S

    def __post_init__(self) -> None:
        checks = (("pet_max_s", self.pet_max_s > 0), ("near_m", self.near_m > 0),
                  ("after_s", self.after_s >= 0),
                  ("lag_steps", self.lag_steps >= 0),
                  ("accel_quantile", 0.0 <= self.accel_quantile < 0.5),
                  ("n_boot", self.n_boot >= 1), ("seed", self.seed >= 0))
        for name, ok in checks:
            if not ok:
                raise RecordingError(f"{name} = {getattr(self, name)!r} is out of range")


@dataclass(frozen=True)
class Split:
    """How the recording files are split: ``kind`` in :data:`SPLITS`; ``k`` folds,
    ``fraction`` tested, or ``test_site`` (``k = None``: :data:`DEFAULT_FOLDS`, at most one per
    file)."""

    kind: str
    k: int | None = None
    fraction: float | None = None
    test_site: str | None = None

    def describe(self) -> str:
        if self.kind == "folds":
            return f"{self.k} folds by recording file"
        if self.kind == "holdout":
            return f"{self.fraction:g} of the recording files held out"
        return f"trained on the other sites, tested on site {self.test_site!r}"


@dataclass(frozen=True)
class PairData:
    """One pair as the evaluation reads it: identity, labels and steps (``(2, n)`` per
    vehicle 1, 2: ``s``, ``v``, ``a``, ``x``, ``y``)."""

    site: str
    file: str  #: the recording file (the cluster of the split and of the bootstrap)
    pair: int
    kind: str
    angle_deg: float
    classes: tuple[str, str]
    lengths_m: tuple[float, float]
    widths_m: tuple[float, float]
    occupancy: np.ndarray = field(repr=False)  #: (2, 2): per vehicle (lo, hi) [m]
    first: str = ""
    pet_s: float = math.nan  #: PET on the occupancy intervals [s] (never read here)
    t_pass_s: tuple[float, float] = (math.nan, math.nan)
    t: np.ndarray = field(default=None, repr=False)
    s: np.ndarray = field(default=None, repr=False)
    v: np.ndarray = field(default=None, repr=False)
    a: np.ndarray = field(default=None, repr=False)
    x: np.ndarray = field(default=None, repr=False)
    y: np.ndarray = field(default=None, repr=False)
    #: the junction's rule from a map (``persuasive.recordings.pairs.MAP_COLUMNS``)
    control: str = "unknown"
    priority: int = 0
    stop_s: tuple[float, float] = (math.nan, math.nan)
    #: PET at the conflict area [s] (selects the pairs evaluated, EvalParams.pet_max_s; NaN
    #: from a file written before it)
    pet_area_s: float = math.nan

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    @property
    def label(self) -> int | None:
        """1: vehicle 1 passed first, 0: vehicle 2, None: neither or the same time."""
        return {"1": 1, "2": 0}.get(self.first)


def is_pairs_file(path: str | Path) -> bool:
    """True when ``path`` is a Parquet file with the pairs metadata
    (:data:`persuasive.recordings.pairs.PAIRS_METADATA`)."""
    import pyarrow.parquet as pq

    try:
        with open(path, "rb") as fh:
            if fh.read(4) != b"PAR1":
                return False
        meta = pq.read_schema(path).metadata or {}
    except Exception:  # noqa: BLE001 - not readable as Parquet: not a pairs file
        return False
    return PAIRS_METADATA in meta


def recording_file(recording: str) -> str:
    """The file a recording came from: an INTERACTION prediction split's ``<file>/case<id>``
    is its file's."""
    return recording.split("/case", 1)[0]


def pairs_of(frame, site: str, prefix: bool) -> list[PairData]:
    """The :class:`PairData` of a pairs frame (:func:`persuasive.recordings.pairs
    .read_pairs`, or :func:`read_sites`'s columns of it), by increasing pair ID, each pair's
    steps by increasing step; ``prefix``: name files ``<site>/<file>`` (several sites).

    One sort of the whole frame and a slice per pair (a ``groupby`` over 42,000 pairs took
    minutes); the values are those of the pair's rows, the pair's own columns read from its
    first step."""
    if len(frame) == 0:
        return []
    pair_col = frame["pair"].to_numpy()
    order = np.lexsort((frame["step"].to_numpy(), pair_col))  # stable: by pair, then step
    ids = pair_col[order]
    cut = np.flatnonzero(ids[1:] != ids[:-1]) + 1
    lo = np.concatenate([[0], cut]).astype(np.int64)
    hi = np.concatenate([cut, [ids.size]]).astype(np.int64)
    head = order[lo]  # each pair's first step: its own columns

    def steps(name):
        return frame[name].to_numpy(float)[order]

    def first(name, cast):
        return [cast(v) for v in frame[name].iloc[head].to_numpy().tolist()]

    t = steps("t_s")
    both = {q: np.stack([steps(f"{q}_1_{u}"), steps(f"{q}_2_{u}")])
            for q, u in (("s", "m"), ("v", "mps"), ("a", "mps2"), ("x", "m"), ("y", "m"))}
    rec = [recording_file(r) for r in first("recording", str)]
    kind, angle, first_ = first("kind", str), first("angle_deg", float), first("first", str)
    cls1, cls2 = first("class_1", str), first("class_2", str)
    len1, len2 = first("length_1_m", float), first("length_2_m", float)
    wid1, wid2 = first("width_1_m", float), first("width_2_m", float)
    occ = np.stack([frame[c].iloc[head].to_numpy(float) for c in (
        "occupancy_1_lo_m", "occupancy_1_hi_m", "occupancy_2_lo_m", "occupancy_2_hi_m")],
        axis=1).reshape(-1, 2, 2)
    pet = first("pet_s", float)
    pet_area = first("pet_area_s", float) if "pet_area_s" in frame else [math.nan] * len(lo)
    tp1, tp2 = first("t_pass_1_s", float), first("t_pass_2_s", float)
    mapped = "control" in frame
    if mapped:
        control, priority = first("control", str), first("priority", int)
        stop1, stop2 = first("stop_1_m", float), first("stop_2_m", float)
    out = []
    for j, (a, b) in enumerate(zip(lo.tolist(), hi.tolist())):
        sl = {q: c[:, a:b].copy() for q, c in both.items()}
        out.append(PairData(
            site=site, file=f"{site}/{rec[j]}" if prefix else rec[j], pair=int(ids[a]),
            kind=kind[j], angle_deg=angle[j], classes=(cls1[j], cls2[j]),
            lengths_m=(len1[j], len2[j]), widths_m=(wid1[j], wid2[j]),
            occupancy=occ[j].copy(), first=first_[j], pet_s=pet[j], pet_area_s=pet_area[j],
            t_pass_s=(tp1[j], tp2[j]), t=t[a:b].copy(), **sl,
            **({"control": control[j], "priority": priority[j],
                "stop_s": (stop1[j], stop2[j])} if mapped else {})))
    return out


def prediction_moment(p: PairData, params: EvalParams) -> tuple[str, int, int]:
    """``(status, k_moment, k_seen)``: the pair's status (:data:`STATUSES`), the step of its
    prediction moment and the last step seen then (-1 where there is none)."""
    near = np.all((p.s >= -params.near_m) & (p.s < 0.0), axis=0)
    if not near.any():
        return NEVER_NEAR, -1, -1
    k0 = int(np.argmax(near))
    k = k0 + int(round(params.after_s / STEP_S))
    seen = k - params.lag_steps
    # the views drop the pair's last step (its state is the run's final one)
    if k >= p.n - 1 or seen < 0:
        return ENDS, -1, -1
    t_k = float(p.t[k])
    passed = any(math.isfinite(tp) and tp <= t_k for tp in p.t_pass_s)
    inside = bool(np.any(p.s[:, k] >= p.occupancy[:, 0]))
    if passed or inside:
        return DECIDED, k, seen
    if p.label is None:
        return NO_PASSER, k, seen
    return KEPT, k, seen


def direction_at(p: PairData, k: int, back: int = 10) -> np.ndarray:
    """Each vehicle's direction of travel at step ``k`` ``(2,)`` [rad]: of its smoothed
    centre's displacement over the ``back`` steps before (fewer at the start; the last steps
    seen only)."""
    j = max(k - back, 0)
    if j == k:
        j, k = k, min(k + 1, p.n - 1)
    return np.arctan2(p.y[:, k] - p.y[:, j], p.x[:, k] - p.x[:, j])


def stop_arrival(p: PairData, k: int) -> np.ndarray:
    """When each vehicle of ``p`` reached its stop line, relative to step ``k`` ``(2,)`` [s]:
    the first step up to ``k`` at which it was within ``ARRIVED_M`` of it (negative or 0), or,
    when it is not there yet, at constant speed from step ``k`` (``V_FLOOR`` at least; the
    steps after ``k`` are not read). A stop line the map does not give is taken at the start
    of the vehicle's occupancy interval."""
    from .baselines import ARRIVED_M, V_FLOOR

    out = np.empty(2)
    for i in range(2):
        line = p.stop_s[i] if math.isfinite(p.stop_s[i]) else float(p.occupancy[i, 0])
        there = np.flatnonzero(p.s[i, :k + 1] >= line - ARRIVED_M)
        if there.size:
            out[i] = float(p.t[there[0]] - p.t[k])
        else:
            out[i] = (line - ARRIVED_M - float(p.s[i, k])) / max(float(p.v[i, k]), V_FLOOR)
    return out


def features_of(pairs: Sequence[PairData], seen: Sequence[int]) -> Features:
    """The :class:`Features` of each pair at its last step seen."""
    n = len(pairs)
    s, v, a, d = (np.zeros((n, 2)) for _ in range(4))
    lo, hi = np.zeros((n, 2)), np.zeros((n, 2))
    merge = np.zeros(n, bool)
    priority, all_way, arrival = np.zeros(n, np.int64), np.zeros(n, bool), np.zeros((n, 2))
    for i, (p, k) in enumerate(zip(pairs, seen)):
        s[i], v[i], a[i] = p.s[:, k], p.v[:, k], p.a[:, k]
        d[i] = direction_at(p, k)
        lo[i], hi[i] = p.occupancy[:, 0], p.occupancy[:, 1]
        merge[i] = p.kind != CROSSING
        priority[i] = p.priority if p.control == "right_of_way" else 0
        all_way[i] = p.control == "all_way_stop"
        if all_way[i]:
            arrival[i] = stop_arrival(p, k)
    mapped = any(p.control != "unknown" for p in pairs)
    return Features(s, v, a, d, lo, hi, merge, *((priority, all_way, arrival) if mapped
                                                  else (None, None, None)))


# -- splits -----------------------------------------------------------------------------------

def fold_tests(files: Sequence[str], split: Split, sites: dict[str, str],
               seed: int) -> list[list[str]]:
    """The test files of each fold (every other file trains). ``sites``: file -> site.
    :class:`RecordingError` for a split the files do not allow."""
    files = sorted(files)
    n = len(files)
    if n < 2:
        raise RecordingError(f"{n} recording file in the pairs; a held-out evaluation needs at "
                             "least 2 (pairs of one file are never split)")
    rng = np.random.default_rng(seed)
    if split.kind == "folds":
        if not (2 <= split.k <= n):
            raise RecordingError(f"--folds = {split.k} is out of range; allowed: 2 to the "
                                 f"number of recording files, {n}")
        order = [files[i] for i in rng.permutation(n)]
        return [sorted(chunk.tolist()) for chunk in np.array_split(np.array(order), split.k)]
    if split.kind == "holdout":
        n_test = min(max(int(round(split.fraction * n)), 1), n - 1)
        return [sorted(files[i] for i in rng.permutation(n)[:n_test])]
    test = sorted(f for f in files if sites[f] == split.test_site)
    if not test:
        known = sorted(set(sites.values()))
        raise RecordingError(f"--test-site = {split.test_site!r} is not a site; allowed: "
                             f"{', '.join(known)} (the pairs files' names)")
    if len(test) == n:
        raise RecordingError("--test-site needs pairs of at least one other site to train on")
    return [test]


# -- vehicle limits and views -----------------------------------------------------------------

def vehicle_limits(pairs: Sequence[PairData], q: float) -> dict[str, tuple[float, float]]:
    """Per vehicle class (and ``"*"``, every class pooled): the ``q`` and ``1 - q``
    quantiles of the smoothed accelerations [m/s^2], at most -0.1 and at least 0.1."""
    by: dict[str, list[np.ndarray]] = {}
    for p in pairs:
        for k in (0, 1):
            by.setdefault(p.classes[k], []).append(p.a[k])
            by.setdefault("*", []).append(p.a[k])
    out = {}
    for cls, parts in by.items():
        a = np.concatenate(parts)
        lo, hi = np.quantile(a, [q, 1.0 - q])
        out[cls] = (float(min(lo, -0.1)), float(max(hi, 0.1)))
    return out


def limit_of(limits: dict, cls: str) -> tuple[float, float]:
    return limits.get(cls, limits["*"])


def speed_cap(pairs: Sequence[PairData], floor: float) -> float:
    """``v_max`` [m/s]: the highest training speed rounded up, at least ``floor``."""
    top = max(float(np.max(p.v)) for p in pairs)
    return float(max(floor, math.ceil(top)))


def envelope_shares(pairs: Sequence[PairData], limits: dict, v_max: float) -> dict:
    """Shares of the test vehicle-steps beyond the fitted limits, beyond the paper's, and above
    ``v_max``; and their count."""
    n = beyond = beyond_paper = fast = 0
    for p in pairs:
        for k in (0, 1):
            lo, hi = limit_of(limits, p.classes[k])
            a = p.a[k]
            n += a.size
            beyond += int(np.sum((a < lo) | (a > hi)))
            beyond_paper += int(np.sum((a < PAPER_LIMITS[0]) | (a > PAPER_LIMITS[1])))
            fast += int(np.sum(p.v[k] > v_max))
    return {"steps": n, "beyond_fitted": beyond, "beyond_paper": beyond_paper,
            "above_v_max": fast}


class ViewBuilder:
    """The runs of each pair's two views (module docstring) under one fold's limits."""

    def __init__(self, mode: str, limits: dict, v_max: float):
        from ..config import Config

        self.limits, self.v_max = limits, v_max
        self.root = Config(mode=mode)
        self._bases: dict = {}

    def base(self, cls_hv: str, cls_av: str):
        key = (cls_hv, cls_av)
        if key not in self._bases:
            over = {"vehicle.v_max_mps": self.v_max}
            for who, cls in (("hv", cls_hv), ("av", cls_av)):
                lo, hi = limit_of(self.limits, cls)
                over[f"{who}.vehicle.u_min_mps2"] = lo
                over[f"{who}.vehicle.u_max_mps2"] = hi
            self._bases[key] = self.root.with_overrides(over)
        return self._bases[key]

    def config(self, p: PairData, human: int):
        """The configuration of vehicle ``human``'s (1 or 2) view."""
        from .logs import pair_config, scenario_angle

        h, o = human - 1, 2 - human
        sizes = {"hv": (p.lengths_m[h], p.widths_m[h]), "av": (p.lengths_m[o], p.widths_m[o])}
        return pair_config(self.base(p.classes[h], p.classes[o]), p.kind,
                           scenario_angle(p.kind, p.angle_deg), sizes, 0.0, p.n - 1)

    def view(self, p: PairData, human: int):
        """The :class:`persuasive.fitting.RunLog` of vehicle ``human`` (1 or 2) as the human."""
        from ..fitting.evidence import RunLog

        h, o = human - 1, 2 - human
        n = p.n - 1
        states = np.stack([p.s[o, :n], p.v[o, :n], p.s[h, :n], p.v[h, :n]], axis=1)
        return RunLog(f"{p.file} pair {p.pair} hv{human}", self.config(p, human), p.pair,
                      None, np.ascontiguousarray(states), np.ascontiguousarray(p.a[h, :n]), {})


#: Views per task of :func:`view_geometries` (a merge's geometry takes 0.4 s).
GEOMETRY_CHUNK = 64


def view_geometries(pairs: Sequence[PairData], mode: str, views: Sequence[tuple[int, int]],
                    limits: dict, v_max: float) -> list[tuple[tuple, object]]:
    """The scenario geometries of the views ``(pair index, human)`` of ``pairs``
    (``persuasive.record.scenario_of``; kept in this process's
    ``persuasive.record.GEOMETRIES`` too) as ``(geometry_key, geometry)``, one per key. They
    do not depend on a fold's vehicle limits: ``limits`` and ``v_max`` are any (a view whose
    starts these limits fail is left to its folds, which build it and report it as before)."""
    from ..config import ConfigError
    from ..record import GEOMETRIES, geometry_key, scenario_of

    builder = ViewBuilder(mode, limits, v_max)
    out, seen = [], set()
    for i, human in views:
        config = builder.config(pairs[i], human)
        key = geometry_key(config)
        if key in seen:
            continue
        try:
            scenario_of(config)
        except ConfigError:
            continue
        geometry = GEOMETRIES.get(key)
        if geometry is not None:
            seen.add(key)
            out.append((key, geometry))
    return out


def _geometry_task(args) -> list[tuple[tuple, object]]:
    (pairs, _status), mode, views, limits, v_max = args
    return view_geometries(pairs, mode, views, limits, v_max)


def remember_geometries(entries: Sequence[tuple[tuple, object]], more: int = 0) -> None:
    """Keep the geometries ``entries`` (of :func:`view_geometries`) in this process's
    ``persuasive.record.GEOMETRIES``, made large enough to hold them and ``more``: every fold
    reads every view's."""
    from ..record import GEOMETRIES

    GEOMETRIES.maxsize = max(GEOMETRIES.maxsize, len(entries) + more + 1024)
    for key, geometry in entries:
        GEOMETRIES.put(key, geometry)


# -- the models on held-out runs --------------------------------------------------------------

def heldout_loglik(ev, fit, sigma_min: float) -> np.ndarray:
    """Each run's log-likelihood under a fitted model at its training estimate ``(n_runs,)``."""
    from ..fitting.estimate import LOG_BETA, RoleObjective

    t = fit.theta
    if fit.model == "idm":
        from ..fitting.idm import FITTED, IDMObjective
        from ..fitting.models import IDM_NAMES

        idm = ev.runs[0].config.hv.idm
        base = np.array([getattr(idm, name) for name in IDM_NAMES], float)
        y = np.array([math.log(t[name]) if log else t[name] for name, *_, log in FITTED])
        sse = IDMObjective(ev, base, sigma_min).sse(y[None])[:, 0]
        sigma = t["sigma"]
        steps = np.diff(ev.starts)
        # the training sigma is held, not re-profiled on the test runs
        return (-steps * math.log(sigma) - 0.5 * steps * math.log(2 * math.pi)
                - sse / (2 * sigma ** 2))
    obj = RoleObjective(ev, fit.model, sigma_min)
    beta = t["beta"]
    u = math.log(beta) if math.isfinite(beta) else obj.hi[LOG_BETA]
    return obj.run_loglik(np.array([t["p_a"], math.log(t["sigma"]), u, t["pi0"]]))


def motion_sigma(accel: np.ndarray, starts: np.ndarray, floor: float) -> tuple[float, float]:
    """ML ``sigma`` [m/s^2] of the constant-speed (``a = 0``) and constant-acceleration
    (``a_k = a_{k-1}``, ``a_0 = 0``) baselines on the runs ``starts``."""
    prev = previous_accel(accel, starts)
    cv = math.sqrt(float(np.mean(accel ** 2))) if accel.size else floor
    ca = math.sqrt(float(np.mean((accel - prev) ** 2))) if accel.size else floor
    return max(cv, floor), max(ca, floor)


def previous_accel(accel: np.ndarray, starts: np.ndarray) -> np.ndarray:
    prev = np.concatenate([[0.0], accel[:-1]]) if accel.size else accel.copy()
    prev[starts[:-1][starts[:-1] < accel.size]] = 0.0
    return prev


def gauss_run_loglik(resid: np.ndarray, starts: np.ndarray, sigma: float) -> np.ndarray:
    """Per run ``sum log N(resid; 0, sigma^2)``."""
    ll = -0.5 * (resid / sigma) ** 2 - math.log(sigma) - 0.5 * math.log(2 * math.pi)
    return np.add.reduceat(ll, starts[:-1]) if resid.size else np.zeros(starts.size - 1)


def role_posteriors(ev, fit, seen: np.ndarray) -> np.ndarray:
    """``P(role = L | accelerations up to step seen[i])`` of each run ``i`` of ``ev`` under a
    fitted hidden-role model: the last step of the forward-backward over the steps seen, which
    is the forward filter's posterior there."""
    from ..fitting.models import EMIT_LFG, EMIT_NOISY, smooth_runs

    rows = [np.arange(ev.starts[i], ev.starts[i] + k + 1) for i, k in enumerate(seen)]
    take = np.concatenate(rows)
    starts = np.concatenate([[0], np.cumsum([r.size for r in rows])]).astype(np.int64)
    out = np.empty(take.size)
    run_ll = np.empty(len(rows))
    t = fit.theta
    kind = EMIT_NOISY if fit.model == "noisy" else EMIT_LFG
    smooth_runs(kind, starts, ev.accel[take], ev.a_role[take], ev.pl[take], ev.q[take],
                ev.a_first[take], float(t["p_a"]), float(t["pi0"]), float(t["sigma"]),
                float(t["beta"]), out, run_ll)
    return out[starts[1:] - 1]


def combine(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """``P(vehicle 1 first)`` from ``P_1`` = P(1 leads) and ``P_2`` = P(2 leads), two
    independent views conditioned on one leading (module docstring); 0.5 where undefined."""
    p1 = np.nan_to_num(np.asarray(p1, float), nan=0.5)
    p2 = np.nan_to_num(np.asarray(p2, float), nan=0.5)
    num = p1 * (1.0 - p2)
    den = num + p2 * (1.0 - p1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), 0.5)


def idm_rollout(p: PairData, seen: int, view1, view2, prm: np.ndarray,
                packed: tuple | None = None) -> int:
    """Who reaches the conflict point first when both drive the IDM ``prm`` ``(8,)`` from step
    ``seen`` (module docstring): 1 (vehicle 1), 0 (vehicle 2) or -1 (neither within
    :data:`ROLLOUT_STEPS`, or both in the same instant). ``packed``: the views' parameter
    vectors ``(P_av1, P_hv1, P_av2, P_hv2)`` where they are known (an evidence's ``P_av``,
    ``P_hv`` rows: ``static_setup`` of the views' configurations, whose scenario geometry
    takes milliseconds to build), else built here."""
    from .. import packing as slot
    from ..kinematics import saturated_step
    from ..policies.idm import idm_step
    from ..record import static_setup

    if packed is None:
        _, P_av1, P_hv1, _ = static_setup(view1.config)
        _, P_av2, P_hv2, _ = static_setup(view2.config)
    else:
        P_av1, P_hv1, P_av2, P_hv2 = packed
    dt = STEP_S
    st1, st2, log = np.zeros(8), np.zeros(8), np.zeros(16)
    s, v = p.s, p.v
    for k in range(seen):  # the states seen: the drivers' waiting and commitment follow them
        idm_step(st1, prm, s[0, k], v[0, k], s[1, k], v[1, k], dt, P_hv1, P_av1, log)
        idm_step(st2, prm, s[1, k], v[1, k], s[0, k], v[0, k], dt, P_hv2, P_av2, log)
    s1, v1, s2, v2 = s[0, seen], v[0, seen], s[1, seen], v[1, seen]
    for _ in range(ROLLOUT_STEPS):
        a1 = idm_step(st1, prm, s1, v1, s2, v2, dt, P_hv1, P_av1, log)
        a2 = idm_step(st2, prm, s2, v2, s1, v1, dt, P_hv2, P_av2, log)
        n1 = saturated_step(s1, v1, a1, dt, P_hv1[slot.V_MIN], P_hv1[slot.V_MAX])
        n2 = saturated_step(s2, v2, a2, dt, P_hv2[slot.V_MIN], P_hv2[slot.V_MAX])
        f1 = -s1 / (n1[0] - s1) if n1[0] >= 0.0 > s1 else math.inf
        f2 = -s2 / (n2[0] - s2) if n2[0] >= 0.0 > s2 else math.inf
        if math.isfinite(f1) or math.isfinite(f2):
            return 1 if f1 < f2 else (0 if f2 < f1 else -1)
        (s1, v1), (s2, v2) = n1, n2
    return -1


# -- the evaluation ---------------------------------------------------------------------------

@dataclass
class FoldResult:
    """What one fold predicted and scored (its test pairs and test runs)."""

    test_files: list[str]
    pair_index: list[int]  #: indices of its kept test pairs in the evaluation's pair list
    predictions: dict[str, np.ndarray]  #: per predictor, P(vehicle 1 first) per kept pair
    run_files: list[str]  #: the recording file of each test run (two per test pair)
    run_steps: np.ndarray
    run_loglik: dict[str, np.ndarray]  #: per model or motion baseline, per test run
    limits: dict
    v_max: float
    envelope: dict
    fits: dict
    baselines: dict


def evaluate_fold(pairs: list[PairData], status: list[tuple[str, int, int]],
                  test_files: set[str], models: Sequence[str], params: EvalParams,
                  mode: str = "corrected") -> FoldResult:
    """Fit on the pairs of the other files, predict and score the pairs of ``test_files``."""
    from ..fitting import evidence_of, fit_models
    from ..fitting.comparison import ROLE_MODELS
    from ..fitting.models import IDM_NAMES

    train = [i for i, p in enumerate(pairs) if p.file not in test_files]
    test = [i for i, p in enumerate(pairs) if p.file in test_files]
    train_pairs = [pairs[i] for i in train]
    limits = vehicle_limits(train_pairs, params.accel_quantile)
    v_max = speed_cap(train_pairs, 10.0)
    builder = ViewBuilder(mode, limits, v_max)
    views = [builder.view(pairs[i], h) for i in train + test for h in (1, 2)]
    n_tr = 2 * len(train)
    # each run's evidence is its own (evidence_of solves the runs apart): the two sides
    # apart hold no copy of the whole
    ev_train = evidence_of(views[:n_tr])
    ev_test = evidence_of(views[n_tr:])
    report = fit_models(ev_train, list(models), params.sigma_min, intervals=False)
    # next accelerations
    run_ll = {m: heldout_loglik(ev_test, report.fits[m], params.sigma_min) for m in models}
    s_cv, s_ca = motion_sigma(ev_train.accel, ev_train.starts, params.sigma_min)
    run_ll["arrive_cv"] = gauss_run_loglik(ev_test.accel, ev_test.starts, s_cv)
    prev = previous_accel(ev_test.accel, ev_test.starts)
    run_ll["arrive_ca"] = gauss_run_loglik(ev_test.accel - prev, ev_test.starts, s_ca)
    # who passes first: the kept pairs of each side
    kept_tr = [j for j, i in enumerate(train) if status[i][0] == KEPT]
    kept_te = [j for j, i in enumerate(test) if status[i][0] == KEPT]
    seen_tr = [status[train[j]][2] for j in kept_tr]
    seen_te = [status[test[j]][2] for j in kept_te]
    y_tr = np.array([pairs[train[j]].label for j in kept_tr], float)
    f_tr = features_of([pairs[train[j]] for j in kept_tr], seen_tr)
    f_te = features_of([pairs[test[j]] for j in kept_te], seen_te)
    base = Baselines.fit(f_tr, y_tr)
    pred = {}
    views_te = [(2 * j, 2 * j + 1) for j in kept_te]  # runs of ev_test: hv1, hv2
    seen2 = np.repeat(np.array(seen_te, np.int64), 2)
    runs2 = [r for pair in views_te for r in pair]
    ev_kept = ev_test.subset(runs2) if runs2 else None
    for m in models:
        fit = report.fits[m]
        if not kept_te:
            pred[m] = np.zeros(0)
        elif m in ROLE_MODELS:
            post = role_posteriors(ev_kept, fit, seen2)
            pred[m] = combine(post[0::2], post[1::2])
        else:
            prm = np.array([fit.theta[name] for name in IDM_NAMES], float)

            def rolls(idx, seen, offset, side, ev):
                # the views' parameter vectors as their evidence packed them
                return np.array([idm_rollout(
                    pairs[side[j]], k, views[offset + 2 * j], views[offset + 2 * j + 1], prm,
                    (ev.P_av[2 * j], ev.P_hv[2 * j], ev.P_av[2 * j + 1], ev.P_hv[2 * j + 1]))
                    for j, k in zip(idx, seen)], np.int64)

            r_tr = rolls(kept_tr, seen_tr, 0, train, ev_train)
            r_te = rolls(kept_te, seen_te, n_tr, test, ev_test)
            known = r_tr >= 0
            hit = float((np.sum(r_tr[known] == y_tr[known]) + 1.0) / (known.sum() + 2.0))
            pred[m] = np.where(r_te < 0, 0.5, np.where(r_te == 1, hit, 1.0 - hit))
    pred.update(base.predict(f_te))
    if kept_te:
        # each driver's belief about the other after the last step seen (row seen + 1 is
        # updated from the states up to `seen` only, docs/method.md §5.5)
        rows = ev_kept.starts[:-1] + seen2 + 1
        b = ev_kept.belief[rows, 0]  # P(the other leads)
        pred["role_belief"] = combine(b[1::2], b[0::2])
    else:
        pred["role_belief"] = np.zeros(0)
    test_pairs = [pairs[i] for i in test]
    return FoldResult(
        test_files=sorted(test_files), pair_index=[test[j] for j in kept_te],
        predictions=pred, run_files=[pairs[i].file for i in test for _ in (1, 2)],
        run_steps=np.diff(ev_test.starts).astype(np.int64), run_loglik=run_ll,
        limits=limits, v_max=v_max, envelope=envelope_shares(test_pairs, limits, v_max),
        fits={m: {k: _plain(v) for k, v in report.fits[m].theta.items()} for m in models},
        baselines=base.to_dict())


def _plain(x: float):
    """A float for JSON: ``"inf"`` for an infinite one (the noisy human's ``beta``)."""
    x = float(x)
    return x if math.isfinite(x) else ("inf" if x > 0 else "-inf")


@dataclass
class Evaluation:
    """A held-out evaluation: the pairs, their statuses, the folds, the pooled scores."""

    split: Split
    params: EvalParams
    models: list[str]
    pairs: list[PairData] = field(repr=False)
    status: list[tuple[str, int, int]] = field(repr=False)
    folds: list[FoldResult] = field(repr=False)
    rows: list[dict]
    strongest: str
    calibration: dict[str, list[dict]]
    #: which pairs of the files were evaluated (:func:`select_pairs`): ``pet_max_s``, the
    #: pairs read, selected, and left out per reason
    selection: dict | None = None

    @property
    def predictors(self) -> list[str]:
        return [*self.models, *BASELINES]

    def to_dict(self) -> dict:
        counts = {s: sum(st[0] == s for st in self.status) for s in STATUSES}
        lead = np.array([min(t for t in p.t_pass_s if math.isfinite(t)) - p.t[st[1]]
                         for p, st in zip(self.pairs, self.status) if st[0] == KEPT])
        env = {k: sum(f.envelope[k] for f in self.folds) for k in self.folds[0].envelope}
        steps = max(env["steps"], 1)
        return {
            "split": {"kind": self.split.kind, "k": self.split.k,
                      "fraction": self.split.fraction, "test_site": self.split.test_site,
                      "seed": self.params.seed, "describe": self.split.describe(),
                      "files": len({p.file for p in self.pairs}),
                      "test_files": [f.test_files for f in self.folds]},
            "moment": {"rule": f"{self.params.after_s:g} s after both vehicles are within "
                               f"{self.params.near_m:g} m of the conflict point and before it",
                       "near_m": self.params.near_m, "after_s": self.params.after_s,
                       "seen_until_s_before": self.params.lag_steps * STEP_S,
                       "lead_time_s_quantiles": {f"{q}%": float(np.percentile(lead, q))
                                                 for q in (5, 50, 95)} if lead.size else {}},
            "selection": self.selection,
            "pairs": {"total": len(self.pairs), "kept": counts[KEPT],
                      "left_out": {s: counts[s] for s in STATUSES if s != KEPT}},
            "limits": {"quantiles": [self.params.accel_quantile,
                                     1.0 - self.params.accel_quantile],
                       "per_fold": [{"accel_mps2": f.limits, "v_max_mps": f.v_max}
                                    for f in self.folds],
                       "test_vehicle_steps": env["steps"],
                       "share_beyond_fitted": env["beyond_fitted"] / steps,
                       "share_beyond_paper": env["beyond_paper"] / steps,
                       "share_above_v_max": env["above_v_max"] / steps},
            "bootstrap": {"unit": "recording file", "resamples": self.params.n_boot,
                          "seed": self.params.seed, "interval": "95 % percentile"},
            "strongest_baseline": self.strongest,
            "rows": self.rows,
            "calibration": self.calibration,
            "fits": [f.fits for f in self.folds],
            "baselines": [f.baselines for f in self.folds],
        }


def select_pairs(pairs: Sequence[PairData], pet_max_s: float
                 ) -> tuple[list[PairData], dict[str, int]]:
    """The pairs evaluated (module docstring, "Which pairs"): those with a ``pet_area_s`` of at
    most ``pet_max_s`` [s] (every pair when it is inf), in their order, and how many are left
    out for each reason (:data:`PET_ABOVE`, :data:`NO_PET`)."""
    if math.isinf(pet_max_s):
        return list(pairs), {PET_ABOVE: 0, NO_PET: 0}
    kept = [p for p in pairs if p.pet_area_s <= pet_max_s]
    no_pet = sum(math.isnan(p.pet_area_s) for p in pairs)
    return kept, {PET_ABOVE: len(pairs) - len(kept) - no_pet, NO_PET: no_pet}


def evaluate(sites: Sequence[tuple[str, object]], split: Split,
             models: Sequence[str] | None = None, params: EvalParams | None = None,
             mode: str = "corrected", workers: int = 1,
             progress: Callable[[int, int], None] | None = None,
             prepare: Callable[[int, int], None] | None = None) -> Evaluation:
    """The held-out evaluation of ``models`` on the pairs frames ``sites`` (``(name,
    frame)`` each, :func:`persuasive.recordings.pairs.read_pairs`); module docstring.
    :class:`RecordingError` for a split the files do not allow or no pair to predict. With
    ``workers > 1`` the folds run on the worker processes of a local Dask cluster
    (``persuasive.sweep.runner.local_client``), the same evaluation bit for bit (a fold
    depends on the pairs, the split and the parameters only); ``progress(done, total)`` after
    each fold. Before the folds, every view's scenario geometry is built once, on the
    workers, and handed to each (:func:`view_geometries`; it does not depend on a fold's
    vehicle limits): ``prepare(done, total)`` in views after each part (without it,
    ``progress(0, folds)`` then)."""
    pairs = [p for name, frame in sites for p in pairs_of(frame, name, len(sites) > 1)]
    return evaluate_pairs(pairs, split, models, params, mode, workers, progress, prepare)


def evaluate_pairs(pairs: Sequence[PairData], split: Split,
                   models: Sequence[str] | None = None, params: EvalParams | None = None,
                   mode: str = "corrected", workers: int = 1,
                   progress: Callable[[int, int], None] | None = None,
                   prepare: Callable[[int, int], None] | None = None) -> Evaluation:
    """:func:`evaluate` of pairs already read (:func:`read_pair_data`)."""
    from ..fitting.estimate import MODELS

    params = params or EvalParams()
    models = [m for m in MODELS if m in (models or MODELS)]
    n_read = len(pairs)
    pairs, dropped = select_pairs(pairs, params.pet_max_s)
    selection = {"pet_max_s": _plain(params.pet_max_s), "read": n_read,
                 "selected": len(pairs), "left_out": dropped}
    if not pairs:
        raise RecordingError(f"no pair to evaluate among the {n_read} pairs: every one has "
                             f"{'no PET or ' * bool(dropped[NO_PET])}a PET at the conflict "
                             f"area above --pet-max = {params.pet_max_s:g} s; allowed: (0, "
                             "inf] s (inf: every pair)")
    status = [prediction_moment(p, params) for p in pairs]
    site_of = {p.file: p.site for p in pairs}
    if split.kind == "folds" and split.k is None:  # the default: 5 folds, or one per file
        split = replace(split, k=min(DEFAULT_FOLDS, len(site_of)))
    tests = fold_tests(list(site_of), split, site_of, params.seed)
    tested = {f for t in tests for f in t}
    kept = [i for i, st in enumerate(status) if st[0] == KEPT and pairs[i].file in tested]
    if not kept:
        counts = {s: sum(st[0] == s for st in status) for s in STATUSES if s != KEPT}
        raise RecordingError(f"no pair left to predict among the {len(pairs)} pairs of the test "
                             "files: " + ", ".join(f"{s} {c}" for s, c in counts.items()))
    done: dict[int, FoldResult] = {}
    # every fold reads every view (its training or its test pairs): their geometries first,
    # once, in parts of GEOMETRY_CHUNK views
    views = [(i, h) for i in range(len(pairs)) for h in (1, 2)]
    parts = [views[j:j + GEOMETRY_CHUNK] for j in range(0, len(views), GEOMETRY_CHUNK)]
    limits, v_max = vehicle_limits(pairs, params.accel_quantile), speed_cap(pairs, 10.0)

    def built(j: int) -> None:
        if prepare is not None:
            prepare(min(j * GEOMETRY_CHUNK, len(views)), len(views))
        elif progress is not None:
            progress(0, len(tests))

    built(0)
    if workers <= 1 or len(tests) <= 1:
        remember_geometries([], len(views))
        for j, part in enumerate(parts):
            view_geometries(pairs, mode, part, limits, v_max)
            built(j + 1)
        if progress is not None:
            progress(0, len(tests))
        for i, t in enumerate(tests):
            done[i] = evaluate_fold(pairs, status, set(t), models, params, mode)
            if progress is not None:
                progress(i + 1, len(tests))
    else:
        from ..sweep.runner import local_client, map_bounded

        with local_client(min(workers, len(tests))) as client:
            # the pairs go to each worker once, not with every fold
            shared = client.scatter((pairs, status), broadcast=True)
            entries: dict = {}
            tasks = [(shared, mode, part, limits, v_max) for part in parts]
            for j, (_, got) in enumerate(map_bounded(client, _geometry_task, tasks,
                                                     in_flight=2 * workers)):
                entries.update(got)
                built(j + 1)
            geometries = client.scatter(list(entries.items()), broadcast=True)
            del entries
            if progress is not None:
                progress(0, len(tests))
            args = [(shared, geometries, set(t), models, params, mode) for t in tests]
            for i, fold in map_bounded(client, _fold_task, args, in_flight=workers):
                done[i] = fold
                if progress is not None:
                    progress(len(done), len(tests))
    folds = [done[i] for i in range(len(tests))]
    return score(split, params, models, pairs, status, folds, selection)


def _fold_task(args) -> FoldResult:
    (pairs, status), geometries, test, models, params, mode = args
    remember_geometries(geometries)
    return evaluate_fold(pairs, status, test, models, params, mode)


def score(split: Split, params: EvalParams, models: list[str], pairs: list[PairData],
          status: list, folds: list[FoldResult], selection: dict | None = None) -> Evaluation:
    """Pool the folds' predictions and scores, with bootstrap intervals over files."""
    predictors = [*models, *BASELINES]
    idx = [i for f in folds for i in f.pair_index]
    y = np.array([pairs[i].label for i in idx], float)
    pred = {k: np.concatenate([f.predictions[k] for f in folds]) for k in predictors}
    pair_files = [pairs[i].file for i in idx]
    run_files = [r for f in folds for r in f.run_files]
    steps = np.concatenate([f.run_steps for f in folds])
    run_ll = {k: np.concatenate([f.run_loglik[k] for f in folds]) for k in folds[0].run_loglik}
    names = sorted(set(run_files))
    w_pairs = cluster_weights(pair_files, params.n_boot, params.seed, names)
    w_runs = cluster_weights(run_files, params.n_boot, params.seed, names)
    ll_base = {k: log_loss(y, pred[k]) for k in BASELINES}
    strongest = min(BASELINES, key=lambda k: (ll_base[k], BASELINES.index(k)))
    rows = []
    for k in predictors:
        row = {"name": k, "kind": "model" if k in models else "baseline",
               "describe": k if k in models else BASELINE_NAMES[k]}
        if k in run_ll:
            ll = run_ll[k]
            with np.errstate(invalid="ignore", divide="ignore"):
                row["loglik_per_step"] = bootstrap(
                    lambda w, ll=ll: (w @ ll) / (w @ steps), w_runs).to_dict()
        for name, fn in PAIR_SCORES.items():
            row[name] = bootstrap(lambda w, p=pred[k], fn=fn: fn(y, p, w), w_pairs).to_dict()
        if k in models:
            row["strongest_baseline"] = strongest
            row["delta_log_loss"] = bootstrap(
                lambda w, p=pred[k], q=pred[strongest]: log_loss(y, p, w) - log_loss(y, q, w),
                w_pairs).to_dict()
        rows.append(row)
    cal = {k: calibration(y, pred[k]) for k in predictors}
    return Evaluation(split, params, models, pairs, status, folds, rows, strongest, cal,
                      selection)


#: The columns of a pairs file the evaluation reads (:func:`pairs_of`); the map's when the
#: file has them.
READ_COLUMNS = ("pair", "recording", "kind", "angle_deg", "class_1", "class_2", "length_1_m",
                "width_1_m", "length_2_m", "width_2_m", "occupancy_1_lo_m", "occupancy_1_hi_m",
                "occupancy_2_lo_m", "occupancy_2_hi_m", "first", "pet_s", "pet_area_s",
                "t_pass_1_s", "t_pass_2_s", "step", "t_s", "s_1_m", "v_1_mps", "a_1_mps2",
                "x_1_m", "y_1_m", "s_2_m", "v_2_mps", "a_2_mps2", "x_2_m", "y_2_m")


def read_pairs_columns(path: str | Path):
    """The columns of the pairs file ``path`` the evaluation reads (:data:`READ_COLUMNS`, the
    map's :data:`persuasive.recordings.pairs.MAP_COLUMNS` when it has them all) as a frame,
    text columns as categories (``persuasive.recordings.pairs.read_pairs`` with ``columns``:
    ``pet_area_s`` NaN for a file written before it), at a fraction of the whole file's
    memory. :class:`RecordingError` (one line naming the file) when it is not a pairs file."""
    import pyarrow.parquet as pq

    from .pairs import MAP_COLUMNS, read_pairs

    try:
        names = set(pq.read_schema(Path(path)).names)
    except Exception:  # noqa: BLE001 - read_pairs says why in one line
        names = set()
    maps = list(MAP_COLUMNS) if all(m in names for m in MAP_COLUMNS) else []
    frame, _ = read_pairs(path, [*READ_COLUMNS, *maps])
    return frame


def _site_names(paths: Sequence[str | Path]) -> list[str]:
    """Each pairs file's site, its file's stem; :class:`RecordingError` for two of one name."""
    out, seen = [], {}
    for path in paths:
        name = Path(path).stem
        if name in seen:
            raise RecordingError(f"pairs files {seen[name]!r} and {str(path)!r} have one name, "
                                 f"{name!r}: each names a site; rename one")
        seen[name] = str(path)
        out.append(name)
    return out


def read_sites(paths: Sequence[str | Path]) -> list[tuple[str, object]]:
    """Each pairs file as ``(site, frame)``, the site its file's stem, the frame the columns
    the evaluation reads (:func:`read_pairs_columns`); :class:`RecordingError` for a file that
    is not a pairs file or two of one name."""
    return [(name, read_pairs_columns(path)) for name, path in zip(_site_names(paths), paths)]


def read_pair_data(paths: Sequence[str | Path]) -> list[PairData]:
    """The :class:`PairData` of every pairs file (what :func:`evaluate` makes of
    :func:`read_sites`), one file's frame in memory at a time."""
    names = _site_names(paths)
    out: list[PairData] = []
    for name, path in zip(names, paths):
        out += pairs_of(read_pairs_columns(path), name, len(paths) > 1)
    return out


__all__ = ["DECIDED", "ENDS", "EvalParams", "Evaluation", "FoldResult", "KEPT", "NEVER_NEAR",
           "NO_PASSER", "NO_PET", "PET_ABOVE", "PET_MAX_S", "PairData", "STATUSES", "SPLITS",
           "Split", "ViewBuilder", "combine", "evaluate", "evaluate_fold", "evaluate_pairs",
           "features_of", "fold_tests", "heldout_loglik", "idm_rollout", "is_pairs_file",
           "motion_sigma", "pairs_of", "prediction_moment", "read_pair_data",
           "read_pairs_columns", "read_sites", "recording_file", "remember_geometries",
           "role_posteriors", "score", "select_pairs", "stop_arrival", "vehicle_limits",
           "view_geometries"]
