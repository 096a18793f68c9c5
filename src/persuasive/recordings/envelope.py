"""The human envelope from recordings: how hard recorded drivers accelerate and brake and how
fast they drive, per agent class, against named candidate envelopes (docs/guide/recordings.md,
"The human envelope from recordings"; docs/method.md §12.2).

The worst-case shield assumes the human's acceleration stays within its vehicle's ``[u_min,
u_max]`` and its speed within ``[v_min, v_max]`` (§12.2, assumption 2). This module measures
what recorded drivers do against that assumption.

**Steps.** Every track of every class (``car``, ``truck``, ``bicycle``, ``pedestrian``, ... as
the readers name them) at least ``min_track_s`` long is smoothed as the pairs are
(:func:`persuasive.recordings.tracks.smooth_tracks` with its :class:`SmoothingParams`). A
*step* is the replay's: from sample ``k`` to ``k + 1`` of a track, with the acceleration
``a_k = (v_{k+1} - v_k) / dt`` of the smoothed speeds and the speed ``v_{k+1}``
(:func:`persuasive.recordings.replay.replay_accelerations`). A step that reads one of the
track's first or last :func:`~persuasive.recordings.tracks.edge_samples` samples is not
tested (the filter's edge windows extrapolate there), the rule of the replay's envelope test
(:func:`persuasive.recordings.replay.edge_steps`). So the share of steps beyond an envelope
here is the replay's per-step test (:func:`envelope_excess`, tolerance :data:`ENVELOPE_TOL`;
the replay imports both from here) applied to every track of the recordings, not only to the
stretches that make pairs.

**Quantiles** (p50, p90, p99, p99.9 and the maximum) of the speed, of the acceleration's
positive part ``max(a, 0)`` and of the braking, the negative part ``max(-a, 0)`` reported
positive, over the tested steps of a class. The quantile ``q`` of ``n`` values is the
smallest value ``x`` with at least ``ceil(q n)`` values at or below it (numpy's
``inverted_cdf``), taken on a grid of :data:`RESOLUTION` (0.001 m/s, m/s^2) and rounded up to
it (a value within ``ENVELOPE_TOL`` above a grid point counts at the point), never above the
maximum: an upper bound, within 0.001 of the exact one. So the envelope ``[-braking_q,
accel_q]`` leaves at most ``1 - q`` of the steps beyond on each side by the replay's test.
Values above :data:`HIST_TOP` (100 m/s, 100 m/s^2: tracking errors) share one bin; a
quantile that falls in it is reported as the maximum. ``q`` of the braking's positive part is
``-q_{1-q}`` of ``a`` where that is negative: each side's tail of the whole distribution.

**Memory.** Files are read and smoothed one at a time; what is kept across them is a
histogram per class and quantity (3 x 100,001 counts) and exact counts per class and envelope,
so memory is bounded by the largest file, not by the site.

**Candidate envelopes** (:data:`ENVELOPES`), each ``(u_min, u_max, v_max)`` with its source:

- ``paper``: the project's default human vehicle, ``Config().vehicle_of("hv")`` (the paper's
  ``[-2, 1]`` m/s^2, ``v`` up to 10 m/s);
- ``sumo``: SUMO's default passenger car (``DEFAULT_VEHTYPE``: ``accel`` 2.6, ``decel`` 4.5
  m/s^2, ``maxSpeed`` 200 km/h);
- ``real-driver``: the p99.9 of real drivers at two unsignalised US intersections of the
  INTERACTION dataset (below).

Their numbers and sources are in :data:`ENVELOPES` and docs/method.md §12.2. A recording
set's own estimate at a quantile is an envelope too (:meth:`EnvelopeEstimate.envelope_at`),
printed as ``[hv.vehicle]`` overrides (:func:`toml_snippet`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from .formats import STEP_S, VEHICLE_CLASSES, RecordingError
from .tracks import SmoothingParams, edge_samples, smooth_tracks

#: The quantiles every class reports (the maximum besides), by name.
QUANTILES = (("p50", 0.5), ("p90", 0.9), ("p99", 0.99), ("p99.9", 0.999))
#: The quantities of a class, by key: speed [m/s], acceleration and braking [m/s^2].
QUANTITIES = ("speed_mps", "accel_mps2", "braking_mps2")
#: The grid of the quantiles [m/s, m/s^2].
RESOLUTION = 1e-3
#: Values above this share the histograms' last bin [m/s, m/s^2].
HIST_TOP = 100.0
#: The pooled group of every vehicle class (:data:`VEHICLE_CLASSES`) in a result.
VEHICLES = "vehicles"
_PER_UNIT = int(round(1.0 / RESOLUTION))
_N_BINS = int(round(HIST_TOP * _PER_UNIT)) + 1  # the last one: above HIST_TOP
#: A value within this many bins above a grid point counts at the point (ENVELOPE_TOL).
_GRID_TOL = 1e-9 * _PER_UNIT


#: Tolerance of the envelope test [m/s^2, m/s]: float rounding of the speed differences.
ENVELOPE_TOL = 1e-9


def envelope_excess(a: np.ndarray, v: np.ndarray, vehicle) -> np.ndarray:
    """Per replayed step, whether the driver left the envelope: its acceleration ``a[k]``
    outside ``[u_min, u_max]`` or its speed ``v[k + 1]`` outside ``[v_min, v_max]`` (both to
    :data:`ENVELOPE_TOL`); ``(n - 1,)`` bool for ``a`` ``(n - 1,)`` and ``v`` ``(n,)``.
    ``vehicle``: a :class:`persuasive.config.VehicleParams` or an :class:`Envelope` (the
    replay's test, ``persuasive.recordings.replay``, and this module's)."""
    tol = ENVELOPE_TOL
    return ((a < vehicle.u_min_mps2 - tol) | (a > vehicle.u_max_mps2 + tol)
            | (v[1:] < vehicle.v_min_mps - tol) | (v[1:] > vehicle.v_max_mps + tol))


def short(x: float) -> str:
    """``x`` to 2 decimals, without trailing zeros (``55.56``, ``-2``, ``3.5``)."""
    text = f"{x:.2f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


@dataclass(frozen=True)
class Envelope:
    """A candidate envelope of the human: acceleration in ``[u_min_mps2, u_max_mps2]``, speed
    in ``[v_min_mps, v_max_mps]`` (``v_max_mps = inf``: the speed is not bounded). Its field
    names are :class:`persuasive.config.VehicleParams`', so the replay's test
    (:func:`envelope_excess`) takes it as it is."""

    name: str
    u_min_mps2: float  #: strongest braking [m/s^2], negative
    u_max_mps2: float  #: strongest acceleration [m/s^2], positive
    v_max_mps: float  #: highest speed [m/s] (inf: none)
    source: str = ""  #: where the numbers come from
    v_min_mps: float = 0.0  #: lowest speed [m/s] (a speed is a magnitude)

    def __post_init__(self) -> None:
        what = f"envelope {self.name!r}"
        if not (math.isfinite(self.u_min_mps2) and self.u_min_mps2 < 0.0):
            raise RecordingError(f"{what}: u_min = {self.u_min_mps2!r} is out of range; "
                                 "allowed: a finite number < 0 m/s^2")
        if not (math.isfinite(self.u_max_mps2) and self.u_max_mps2 > 0.0):
            raise RecordingError(f"{what}: u_max = {self.u_max_mps2!r} is out of range; "
                                 "allowed: a finite number > 0 m/s^2")
        if not self.v_max_mps > self.v_min_mps >= 0.0:
            raise RecordingError(f"{what}: v_max = {self.v_max_mps!r} is out of range; "
                                 f"allowed: a number > {self.v_min_mps:g} m/s")

    def text(self) -> str:
        """``u in [-2, 1] m/s^2, v <= 10 m/s`` (no speed bound: the first part only; numbers
        to 2 decimals)."""
        v = f", v <= {short(self.v_max_mps)} m/s" if math.isfinite(self.v_max_mps) else ""
        return f"u in [{short(self.u_min_mps2)}, {short(self.u_max_mps2)}] m/s^2{v}"

    def to_dict(self) -> dict:
        return {"u_min_mps2": self.u_min_mps2, "u_max_mps2": self.u_max_mps2,
                "v_max_mps": self.v_max_mps if math.isfinite(self.v_max_mps) else None,
                "source": self.source}


def _paper() -> Envelope:
    from ..config import Config

    hv = Config().vehicle_of("hv")
    return Envelope("paper", hv.u_min_mps2, hv.u_max_mps2, hv.v_max_mps,
                    "the project's default human vehicle, Config().vehicle_of('hv') "
                    "([vehicle] and [hv.vehicle]; the paper's limits, docs/method.md §1)",
                    hv.v_min_mps)


def _named(name: str) -> Envelope:
    """A named envelope of the configuration (``persuasive.config.HUMAN_ENVELOPES``, what
    ``hv.envelope`` sets)."""
    from ..config import HUMAN_ENVELOPES

    u_min, u_max, v_max, source = HUMAN_ENVELOPES[name]
    return Envelope(name, u_min, u_max, v_max, source)


#: The named candidate envelopes (module docstring), read-only: the paper's and those of the
#: configuration's ``hv.envelope``.
ENVELOPES: Mapping[str, Envelope] = MappingProxyType({e.name: e for e in (
    _paper(), _named("sumo"), _named("real-driver"))})


def parse_bound(text: str) -> Envelope:
    """An envelope from ``U_MIN,U_MAX[,V_MAX]`` (``--bound``; m/s^2 and m/s, no speed bound
    when ``V_MAX`` is left out); :class:`RecordingError` naming ``--bound`` and the allowed
    form otherwise."""
    allowed = ("allowed: U_MIN,U_MAX[,V_MAX] with U_MIN < 0 < U_MAX [m/s^2] and V_MAX > 0 "
               "[m/s], e.g. -3,2 or -3,2,15")
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise RecordingError(f"--bound = {text!r} is not allowed; {allowed}")
    u_min, u_max = values[0], values[1]
    v_max = values[2] if len(values) == 3 else math.inf
    if not (u_min < 0.0 < u_max and v_max > 0.0):
        raise RecordingError(f"--bound = {text!r} is out of range; {allowed}")
    name = ",".join(f"{v:g}" for v in values)
    return Envelope(name, u_min, u_max, v_max, f"--bound {text}")


def candidate_envelopes(bounds: Iterable[str] = ()) -> tuple[Envelope, ...]:
    """:data:`ENVELOPES` and the user's ``--bound`` candidates (:func:`parse_bound`), each
    name once."""
    out = list(ENVELOPES.values())
    for b in bounds:
        env = parse_bound(b)
        if env.name not in {e.name for e in out}:
            out.append(env)
    return tuple(out)


# -- one class's statistics ---------------------------------------------------------------------


def grid_bins(x: np.ndarray) -> np.ndarray:
    """The histogram bin of each value ``x >= 0``: ``ceil(x / RESOLUTION)`` (a value within
    ``ENVELOPE_TOL`` above a grid point in that point's bin), values above :data:`HIST_TOP` in
    the last."""
    b = np.ceil(np.asarray(x, float) * _PER_UNIT - _GRID_TOL)
    return np.clip(b, 0, _N_BINS - 1).astype(np.int64)


def hist_quantile(hist: np.ndarray, q: float, top: float) -> float | None:
    """The quantile ``q`` of the values counted in ``hist`` (module docstring; ``top``: their
    maximum), None when there are none."""
    n = int(hist.sum())
    if n == 0:
        return None
    k = max(1, math.ceil(round(q * n, 6)))
    b = int(np.searchsorted(np.cumsum(hist), k))
    return float(top) if b >= _N_BINS - 1 else min(b / _PER_UNIT, float(top))


@dataclass(frozen=True)
class ClassEnvelope:
    """What the tested steps of one class (or of :data:`VEHICLES`, every vehicle class) did.
    ``beyond[name]``: per candidate envelope, the steps beyond it (``steps``), of them those
    braking harder than ``u_min`` (``braking``), accelerating harder than ``u_max``
    (``acceleration``), faster than ``v_max`` (``speed``), and the tracks with a step beyond
    (``tracks``); a step can count on two sides (braking and speed)."""

    agent_class: str
    tracks: int  #: tracks smoothed and tested
    short_tracks: int  #: tracks left out, shorter than ``min_track_s``
    steps: int  #: tested steps
    edge_steps: int  #: steps not tested: they read a track's edge samples
    maxima: dict[str, float]  #: the largest value of each of :data:`QUANTITIES`
    beyond: dict[str, dict[str, int]]
    hists: dict[str, np.ndarray] = field(repr=False)  #: ``(_N_BINS,)`` counts per quantity

    def quantile(self, quantity: str, q: float) -> float | None:
        """The quantile ``q`` of ``quantity`` (one of :data:`QUANTITIES`; module docstring)."""
        return hist_quantile(self.hists[quantity], q, self.maxima[quantity])

    def quantiles(self, quantity: str) -> dict[str, float | None]:
        """``{"p50": ..., "p90": ..., "p99": ..., "p99.9": ..., "max": ...}``."""
        out = {name: self.quantile(quantity, q) for name, q in QUANTILES}
        out["max"] = self.maxima[quantity] if self.steps else None
        return out

    def share_beyond(self, name: str) -> float | None:
        return self.beyond[name]["steps"] / self.steps if self.steps else None

    def to_dict(self, q: float) -> dict:
        return {"tracks": self.tracks, "short_tracks": self.short_tracks,
                "steps": self.steps, "edge_steps": self.edge_steps,
                **{k: self.quantiles(k) for k in QUANTITIES},
                "at_quantile": {k: self.quantile(k, q) for k in QUANTITIES},
                "beyond": {name: {**counts, "share": self.share_beyond(name)}
                           for name, counts in self.beyond.items()}}


@dataclass(frozen=True)
class EnvelopeEstimate:
    """The envelope statistics of a set of recordings: per class (and :data:`VEHICLES`,
    the vehicle classes pooled) a :class:`ClassEnvelope`; the candidates tested; the files,
    the smoothing and its edge samples."""

    classes: dict[str, ClassEnvelope]
    envelopes: tuple[Envelope, ...]
    files: tuple[str, ...]
    smoothing: SmoothingParams
    edge_samples: int

    def envelope_at(self, q: float, group: str = VEHICLES) -> Envelope | None:
        """The envelope of ``group`` at quantile ``q``: ``u_min = -braking_q``, ``u_max =
        accel_q``, ``v_max = speed_q`` (None when the group has no tested step or one of them
        is 0, which no vehicle's limits allow)."""
        c = self.classes.get(group)
        if c is None or not c.steps:
            return None
        speed, acc, brake = (c.quantile(k, q) for k in QUANTITIES)
        if not (speed > 0.0 and acc > 0.0 and brake > 0.0):
            return None
        return Envelope(f"{group}@{q:g}", -brake, acc, speed,
                        f"recordings envelope: quantile {q:g} of the {c.steps} tested steps "
                        f"of {group} in {len(self.files)} file"
                        f"{'s' * (len(self.files) != 1)}")

    def to_dict(self, q: float) -> dict:
        """The whole result, JSON-ready but for non-finite floats
        (:func:`persuasive._files.json_safe`)."""
        from dataclasses import asdict

        est = self.envelope_at(q)
        return {"files": list(self.files), "smoothing": asdict(self.smoothing),
                "edge_samples": self.edge_samples, "resolution": RESOLUTION,
                "quantile": q,
                "envelopes": {e.name: e.to_dict() for e in self.envelopes},
                "classes": {k: c.to_dict(q) for k, c in self.classes.items()},
                "estimate": None if est is None else {
                    "class": VEHICLES, "quantile": q, **est.to_dict(),
                    "toml": toml_snippet(est)}}


def toml_snippet(env: Envelope, digits: int = 2) -> str:
    """``env`` as ``[hv.vehicle]`` overrides of a configuration file, each limit rounded
    outward to ``digits`` decimals (braking and acceleration up in size, the speed up)."""
    scale = 10 ** digits

    def up(x: float) -> float:
        return math.ceil(round(x * scale, 6)) / scale

    return (f"# {env.source}; rounded outward to {10.0 ** -digits:g}\n"
            "[hv.vehicle]\n"
            f"u_min_mps2 = {-up(-env.u_min_mps2):.{digits}f}\n"
            f"u_max_mps2 = {up(env.u_max_mps2):.{digits}f}\n"
            f"v_max_mps = {up(env.v_max_mps):.{digits}f}\n")


# -- reading --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FileSteps:
    """The tested steps of one file, by class: ``cls`` ``(m,)`` class index into ``names``,
    ``a`` [m/s^2], ``v`` [m/s] (the speed at the step's end), ``track`` (the track's index in
    the file); per class: tracks kept, tracks too short, steps left out at the edges."""

    names: list[str]
    cls: np.ndarray
    a: np.ndarray
    v: np.ndarray
    track: np.ndarray
    tracks: np.ndarray
    short: np.ndarray
    edge: np.ndarray


def file_steps(table, params: SmoothingParams) -> FileSteps:
    """The tested steps of one tidy table (module docstring): every class smoothed as the
    vehicles are, the replay's steps, its edge rule."""
    import pandas as pd

    ids = table[["recording", "track", "agent_class"]].drop_duplicates(["recording", "track"])
    lookup = pd.Series(ids["agent_class"].to_numpy(), index=pd.MultiIndex.from_arrays(
        [ids["recording"].to_numpy(), ids["track"].to_numpy()]))
    names = sorted(set(ids["agent_class"].tolist()))

    def codes(values) -> np.ndarray:
        return pd.Categorical(np.asarray(values, dtype=object), categories=names).codes.astype(
            np.int64)

    all_tracks = np.bincount(codes(ids["agent_class"]), minlength=len(names))
    # smooth_tracks keeps the vehicle classes only: every track is smoothed as a car, then
    # given its class back (the filter does not depend on the class)
    table = table.assign(agent_class=VEHICLE_CLASSES[0])
    tr = smooth_tracks(table, params)
    n_tr = tr.n_tracks
    track_cls = codes(lookup.reindex(pd.MultiIndex.from_arrays([tr.recording, tr.track]))
                      ) if n_tr else np.zeros(0, np.int64)
    kept = np.bincount(track_cls, minlength=len(names))
    counts = np.diff(tr.starts)
    n = tr.v.shape[0]
    if n < 2:
        empty = np.zeros(0)
        return FileSteps(names, empty.astype(np.int64), empty, empty, empty.astype(np.int64),
                      kept, all_tracks - kept, np.zeros(len(names), np.int64))
    # step j reads samples j and j + 1 of one track
    track_of = np.repeat(np.arange(n_tr), counts)[:-1]
    same = np.ones(n - 1, bool)
    same[tr.starts[1:-1] - 1] = False
    k = np.arange(n - 1) - tr.starts[track_of]
    edge = edge_samples(params)
    inner = (k >= edge) & (k + 1 <= counts[track_of] - 1 - edge)
    tested = same & inner
    a = np.diff(tr.v) / STEP_S
    edge_counts = np.bincount(track_cls[track_of[same & ~inner]], minlength=len(names))
    return FileSteps(names, track_cls[track_of[tested]], a[tested], tr.v[1:][tested],
                  track_of[tested], kept, all_tracks - kept, edge_counts)


def _fcd_table(path: Path, types: dict):
    """One SUMO fcd file as the tidy table (``persuasive.recordings.sumo_fcd``, no noise)."""
    import pandas as pd

    from .formats import TIDY_COLUMNS
    from .sumo_fcd import read_fcd

    rows, _ = read_fcd(path, types, np.random.default_rng(0))
    return pd.DataFrame({"recording": path.stem, "track": rows["track_id"],
                         "t_s": rows["timestamp_ms"] / 1000.0, "x_m": rows["x"],
                         "y_m": rows["y"], "speed_mps": np.hypot(rows["vx"], rows["vy"]),
                         "heading_rad": rows["psi_rad"], "length_m": rows["length"],
                         "width_m": rows["width"],
                         "agent_class": np.char.lower(rows["agent_type"].astype(str))
                         .astype(object)}, columns=list(TIDY_COLUMNS))


def recording_files(paths: Sequence[str | Path]) -> list[tuple[Path, str]]:
    """``(path, format)`` of every recording among ``paths``: SUMO fcd files (``.xml``,
    format ``"fcd"``) and the track files :func:`persuasive.recordings.formats
    .find_track_files` finds (``"interaction"``, ``"ind"``); each file once.
    :class:`RecordingError` for a path that does not exist or is not a recording."""
    from .formats import find_track_files

    if not paths:
        raise RecordingError("no recording given: name INTERACTION vehicle_tracks_NNN.csv, "
                             "inD NN_tracks.csv or SUMO fcd .xml files, or folders of track "
                             "files")
    out: list[tuple[Path, str]] = []
    seen: set[Path] = set()
    for p in map(Path, paths):
        if p.suffix.lower() == ".xml" and not p.is_dir():
            if not p.is_file():
                raise RecordingError(f"fcd file {str(p)!r} does not exist")
            found = [(p, "fcd")]
        else:
            found = [(f.path, f.format) for f in find_track_files([p])]
        for f, fmt in found:
            key = f.resolve()
            if key not in seen:
                seen.add(key)
                out.append((f, fmt))
    return out


def read_recording(path: Path, fmt: str, types: dict | None = None):
    """One recording as the tidy table (its format's reader)."""
    from .formats import read_ind, read_interaction

    if fmt == "fcd":
        from .sumo_fcd import read_types

        return _fcd_table(path, types if types is not None else read_types([]))
    return read_interaction(path) if fmt == "interaction" else read_ind(path)


# -- the estimate --------------------------------------------------------------------------------


class _Acc:
    """One class's running counts over the files."""

    def __init__(self, envelopes: Sequence[Envelope]) -> None:
        self.hists = {k: np.zeros(_N_BINS, np.int64) for k in QUANTITIES}
        self.maxima = {k: 0.0 for k in QUANTITIES}
        self.tracks = self.short = self.steps = self.edge = 0
        self.beyond = {e.name: dict.fromkeys(("steps", "braking", "acceleration", "speed",
                                              "tracks"), 0) for e in envelopes}

    def add(self, other: _Acc) -> None:
        for k in QUANTITIES:
            self.hists[k] += other.hists[k]
            self.maxima[k] = max(self.maxima[k], other.maxima[k])
        self.tracks += other.tracks
        self.short += other.short
        self.steps += other.steps
        self.edge += other.edge
        for name, counts in other.beyond.items():
            for key, value in counts.items():
                self.beyond[name][key] += value

    def result(self, name: str) -> ClassEnvelope:
        return ClassEnvelope(name, self.tracks, self.short, self.steps, self.edge,
                             dict(self.maxima), {k: dict(v) for k, v in self.beyond.items()},
                             {k: h.copy() for k, h in self.hists.items()})


def _accumulate(accs: dict[str, _Acc], st: FileSteps, envelopes: Sequence[Envelope]) -> None:
    """Add one file's steps to the running counts, every class at once."""
    m = len(st.names)
    for i, name in enumerate(st.names):
        acc = accs.setdefault(name, _Acc(envelopes))
        acc.tracks += int(st.tracks[i])
        acc.short += int(st.short[i])
        acc.edge += int(st.edge[i])
    if not st.a.size:
        return
    steps = np.bincount(st.cls, minlength=m)
    values = {"speed_mps": st.v, "accel_mps2": np.maximum(st.a, 0.0),
              "braking_mps2": np.maximum(-st.a, 0.0)}
    maxima = {}
    for key, x in values.items():
        flat = np.bincount(st.cls * _N_BINS + grid_bins(x), minlength=m * _N_BINS)
        hist = flat.reshape(m, _N_BINS)
        top = np.full(m, -np.inf)
        np.maximum.at(top, st.cls, x)
        maxima[key] = top
        for i, name in enumerate(st.names):
            accs[name].hists[key] += hist[i]
    # the replay's test: a[k] with v[k + 1] (the step's end); envelope_excess reads v[1:]
    v_pad = np.concatenate([[0.0], st.v])
    n_tracks = int(st.track.max()) + 1
    tol = ENVELOPE_TOL
    for env in envelopes:
        out = envelope_excess(st.a, v_pad, env)
        sides = {"steps": out, "braking": st.a < env.u_min_mps2 - tol,
                 "acceleration": st.a > env.u_max_mps2 + tol,
                 "speed": st.v > env.v_max_mps + tol}
        counts = {key: np.bincount(st.cls[s], minlength=m) for key, s in sides.items()}
        # a track is beyond when any of its steps is; the track's class is its steps'
        hit = np.zeros(n_tracks, bool)
        hit[st.track[out]] = True
        track_cls = np.full(n_tracks, -1)
        track_cls[st.track] = st.cls
        counts["tracks"] = np.bincount(track_cls[hit], minlength=m)
        for i, name in enumerate(st.names):
            for key, c in counts.items():
                accs[name].beyond[env.name][key] += int(c[i])
    for i, name in enumerate(st.names):
        accs[name].steps += int(steps[i])
        for key in QUANTITIES:
            if steps[i]:
                accs[name].maxima[key] = max(accs[name].maxima[key], float(maxima[key][i]))


def estimate_envelope(paths: Sequence[str | Path], envelopes: Sequence[Envelope] | None = None,
                      smoothing: SmoothingParams | None = None, types: Sequence[str] = (),
                      progress: Callable[[int, int], None] | None = None
                      ) -> EnvelopeEstimate:
    """The envelope statistics of the recordings among ``paths`` (:func:`recording_files`),
    read one file at a time (module docstring), against ``envelopes`` (default: every one
    of :data:`ENVELOPES`). ``types``: SUMO route or additional files whose vTypes the fcd
    files use; ``progress(done, total)`` after each file."""
    envelopes = tuple(ENVELOPES.values()) if envelopes is None else tuple(envelopes)
    smoothing = smoothing or SmoothingParams()
    files = recording_files(paths)
    fcd_types = None
    if any(fmt == "fcd" for _, fmt in files):
        from .sumo_fcd import read_types

        fcd_types = read_types(types)
    accs: dict[str, _Acc] = {}
    for i, (path, fmt) in enumerate(files):
        table = read_recording(path, fmt, fcd_types)
        _accumulate(accs, file_steps(table, smoothing), envelopes)
        del table
        if progress is not None:
            progress(i + 1, len(files))
    classes = {name: accs[name].result(name) for name in sorted(accs)}
    pooled = [accs[c] for c in sorted(accs) if c in VEHICLE_CLASSES]
    if pooled:
        total = _Acc(envelopes)
        for acc in pooled:
            total.add(acc)
        classes[VEHICLES] = total.result(VEHICLES)
    return EnvelopeEstimate(classes, envelopes, tuple(str(p) for p, _ in files), smoothing,
                            edge_samples(smoothing))


__all__ = ["ENVELOPES", "ENVELOPE_TOL", "HIST_TOP", "QUANTILES", "QUANTITIES", "RESOLUTION",
           "VEHICLES", "ClassEnvelope", "Envelope", "EnvelopeEstimate", "FileSteps",
           "candidate_envelopes", "envelope_excess", "estimate_envelope", "file_steps",
           "grid_bins", "hist_quantile", "parse_bound", "read_recording", "recording_files",
           "short", "toml_snippet"]
