"""Pairs as fit logs: each recorded pair, from each driver's view, as the per-step Parquet log
``persuasive fit`` reads (docs/method.md §13.1, docs/guide/recordings.md).

A pair of :mod:`persuasive.recordings.pairs` becomes two logs: vehicle 2 as the human
(``hv_*``) and vehicle 1 as the other (``av_*``), then the other way round. A log holds the
columns of ``simulate --out`` that a fit and :func:`persuasive.record.load_record` read:
``step``, ``t_s``, both vehicles' ``*_s_m``, ``*_v_mps`` (the smoothed track relative to the
conflict point; the measured ones, ``*_meas_*``, are the same values: a recording has no
other measurement), ``*_accel_mps2`` (the smoothed acceleration), ``distance_m`` and the
vehicles' ``*_x_m``, ``*_y_m``, ``*_heading_rad`` on the scenario's paths, and the
recorded centres as ``*_rec_x_m``, ``*_rec_y_m``. Rows are the pair's steps but the last,
whose state is the run's final state, so that step ``k`` decides at state ``k`` as in the
closed loop.

The configuration in its metadata is the scenario form of the pair:

- ``scenario.kind``: ``crossing`` with ``scenario.angle_deg`` the pair's crossing angle
  rounded to a multiple of ``angle_step_deg`` (default 5) and clipped to the crossing's
  allowed range (``persuasive.config.ANGLE_RANGES_DEG``: [15, 165]), or ``merge`` with the
  merging vehicle's angle treated alike ([15, 90]). Rounding puts pairs at nearly equal angles
  in one scenario, so that they can be fitted together (a fit takes one scenario: the kind and
  its angle). The merge's geometry (the AV on the ramp) fits the view with vehicle 1, the
  merging vehicle, as ``av``; in the other view the human is the merging one, on the lane's
  path: the two roads are straight and meet at the merge point, so the distance between the
  vehicles, which the game reads, is the same either way;
- ``mode``: corrected (no reference quirks) unless asked otherwise;
- each vehicle's ``length_m`` and ``width_m``: the recorded ones (``av.vehicle``,
  ``hv.vehicle``); ``vehicle.v_max_mps``: the configuration's, raised to the pair's highest
  smoothed speed where that is above it, so that no recorded state lies above it (not rounded
  up: the LFG's library eases its acceleration as it nears the limit, and a limit raised by a
  millimetre per second of smoothing to the next whole m/s predicted full throttle where the
  driver was easing off);
- ``simulation.dt_s = 0.1`` (the pairs' step) and ``simulation.n_steps`` the log's rows.

The file is named ``<kind>-<angle>-p<pair>-hv<1|2>.parquet``, so that one scenario's logs are
one glob: ``persuasive fit DIR/crossing-90-*.parquet``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import ANGLE_RANGES_DEG, Config
from .formats import STEP_S, RecordingError
from .pairs import PAIR_COLUMNS, TRACK_COLUMNS

#: Default rounding of a pair's angle [deg].
ANGLE_STEP_DEG = 5.0


@dataclass(frozen=True)
class LogFile:
    """One log written: its file name, scenario kind and angle, pair and the human's vehicle
    (1 or 2)."""

    name: str
    kind: str
    angle_deg: float
    pair: int
    human: int
    n_steps: int


def scenario_angle(kind: str, angle_deg: float, step_deg: float = ANGLE_STEP_DEG) -> float:
    """The scenario's ``angle_deg`` of a pair: rounded to a multiple of ``step_deg``, clipped
    to the kind's allowed range."""
    lo, hi, _ = ANGLE_RANGES_DEG[kind]
    rounded = step_deg * round(angle_deg / step_deg) if step_deg > 0 else angle_deg
    return float(min(max(rounded, lo), hi))


def pair_config(base: Config, kind: str, angle_deg: float, sizes: dict, v_max: float,
                n_steps: int) -> Config:
    """The configuration of one view of a pair (module docstring); ``sizes``: ``{"av":
    (length, width), "hv": (length, width)}`` [m]."""
    overrides = {"scenario.kind": kind, "scenario.angle_deg": angle_deg,
                 "simulation.dt_s": STEP_S, "library.sample_dt_s": STEP_S,
                 "simulation.n_steps": int(n_steps),
                 "vehicle.v_max_mps": float(max(base.vehicle.v_max_mps, v_max))}
    for who, (length, width) in sizes.items():
        overrides[f"{who}.vehicle.length_m"] = float(length)
        overrides[f"{who}.vehicle.width_m"] = float(width)
    return base.with_overrides(overrides)


def view_log(pair_rows, human: int, base: Config, step_deg: float = ANGLE_STEP_DEG,
             smoothing: dict | None = None):
    """``(config, frame, meta)`` of one view of one pair: vehicle ``human`` (1 or 2) as the
    ``hv``. ``pair_rows``: the pair's rows of the pairs file, in step order. ``smoothing``:
    the tracks' filter (the pairs file's ``frame.attrs["smoothing"]``), kept in the metadata
    as ``recording.smoothing`` for the fit's measurement model
    (``persuasive.fitting.evidence.observe_through``); None: unknown, no measurement model."""
    import pandas as pd

    from ..record import static_setup

    other = 3 - human
    first = pair_rows.iloc[0]
    kind = str(first["kind"])
    angle = scenario_angle(kind, float(first["angle_deg"]), step_deg)
    n = len(pair_rows)
    if n < 2:
        raise RecordingError(f"pair {int(first['pair'])} has {n} step; a log needs two")
    col = {who: {q: pair_rows[f"{q}_{k}_{unit}"].to_numpy(float)
                 for q, unit in (("s", "m"), ("v", "mps"), ("a", "mps2"), ("x", "m"),
                                 ("y", "m"))}
           for who, k in (("hv", human), ("av", other))}
    sizes = {who: (float(first[f"length_{k}_m"]), float(first[f"width_{k}_m"]))
             for who, k in (("hv", human), ("av", other))}
    v_max = max(float(np.max(col["hv"]["v"])), float(np.max(col["av"]["v"])))
    config = pair_config(base, kind, angle, sizes, v_max, n - 1)
    scenario = static_setup(config)[0]
    rows = slice(0, n - 1)
    log = {"step": np.arange(n - 1, dtype=np.int64),
           "t_s": np.arange(n - 1) * STEP_S,
           "av_s_m": col["av"]["s"][rows], "av_v_mps": col["av"]["v"][rows],
           "hv_s_m": col["hv"]["s"][rows], "hv_v_mps": col["hv"]["v"][rows]}
    log["distance_m"] = scenario.distance(log["av_s_m"], log["hv_s_m"])
    for who in ("av", "hv"):
        x, y, heading = scenario.positions(who, log[f"{who}_s_m"])
        log[f"{who}_x_m"], log[f"{who}_y_m"], log[f"{who}_heading_rad"] = x, y, heading
    for who in ("av", "hv"):
        log[f"{who}_meas_s_m"] = log[f"{who}_s_m"]
        log[f"{who}_meas_v_mps"] = log[f"{who}_v_mps"]
    for who in ("av", "hv"):
        log[f"{who}_accel_mps2"] = col[who]["a"][rows]
    for who in ("av", "hv"):
        log[f"{who}_rec_x_m"] = col[who]["x"][rows]
        log[f"{who}_rec_y_m"] = col[who]["y"][rows]
    pair_info = {c: _plain(first[c]) for c in PAIR_COLUMNS}
    pair_info.update({c: _plain(first[c]) for c in TRACK_COLUMNS if c in pair_rows})
    pair_info.update({"human": human, "t0_s": float(pair_rows["t_s"].iloc[0]),
                      "scenario_angle_deg": angle})
    if smoothing is not None:
        pair_info["smoothing"] = dict(smoothing)
    from .._version import __version__

    last = n - 1
    meta = {"config_toml": config.to_toml(), "seed": int(first["pair"]),
            "streams": config.streams,
            "final_state": [float(col["av"]["s"][last]), float(col["av"]["v"][last]),
                            float(col["hv"]["s"][last]), float(col["hv"]["v"][last])],
            "version": __version__, "recording": pair_info}
    return config, pd.DataFrame(log), meta


def _plain(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return None if math.isnan(value) else float(value)
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if value is None or (hasattr(value, "__class__") and str(value) == "<NA>"):
        return None
    return value


def log_name(kind: str, angle_deg: float, pair: int, human: int) -> str:
    return f"{kind}-{angle_deg:g}-p{pair:05d}-hv{human}.parquet"


def write_logs(frame, folder: str | Path, base: Config | None = None,
               step_deg: float = ANGLE_STEP_DEG) -> list[LogFile]:
    """Write every pair of a pairs frame (:func:`persuasive.recordings.pairs.read_pairs`),
    from both views, into ``folder`` (an existing folder; the caller makes it atomic)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..record import RECORD_METADATA

    base = base if base is not None else Config(mode="corrected")
    folder = Path(folder)
    written: list[LogFile] = []
    smoothing = frame.attrs.get("smoothing")
    for pair_id, rows in frame.groupby("pair", sort=True):
        rows = rows.sort_values("step")
        for human in (1, 2):
            config, log, meta = view_log(rows, human, base, step_deg, smoothing)
            angle = config.scenario.angle_deg
            name = log_name(config.scenario.kind, angle, int(pair_id), human)
            table = pa.Table.from_pandas(log, preserve_index=False)
            table = table.replace_schema_metadata({RECORD_METADATA: json.dumps(meta)})
            pq.write_table(table, folder / name)
            written.append(LogFile(name, config.scenario.kind, angle, int(pair_id), human,
                                   len(log)))
    return written


def groups(written: list[LogFile]) -> dict[tuple[str, float], list[LogFile]]:
    """The logs by scenario (kind, angle): one fit each."""
    out: dict[tuple[str, float], list[LogFile]] = {}
    for w in written:
        out.setdefault((w.kind, w.angle_deg), []).append(w)
    return dict(sorted(out.items()))


__all__ = ["ANGLE_STEP_DEG", "LogFile", "groups", "log_name", "pair_config", "scenario_angle",
           "view_log", "write_logs"]
