"""Our own simulator's runs, and SUMO's, as recordings: ``simulate --out`` logs and SUMO's
floating-car data (``--fcd-output``) written in the INTERACTION format, for round trips
through the recordings' pipeline (docs/guide/recordings.md). SUMO's files are read as
:mod:`persuasive.recordings.sumo_fcd` says (:func:`export_fcd`); the runs as follows.

Run ``r`` (in the order given) becomes ``vehicle_tracks_<r>.csv`` (three digits): one file per
run, since two runs share their times and place and would otherwise be paired with each
other. Track 1 is the AV, track 2 the HV, both ``car``; frame ``k`` (``frame_id = k + 1``,
``timestamp_ms = 100 k``) is the run's state ``x_k``, ``k = 0..N`` (the final state
included). The centre is the scenario's position of the vehicle's path coordinate
(``Scenario.positions``, as the top-view figure draws it), plus **uniform measurement noise**
``U(-noise_m, noise_m)`` on ``x`` and on ``y``, independently, drawn from
``numpy.random.default_rng(seed)`` (one generator for all runs, in order); ``vx, vy`` are the
speed along the path's heading, with uniform noise ``U(-noise_mps, noise_mps)`` on the speed
(:func:`persuasive.recordings.formats.noisy_speed`; none by default), ``psi_rad`` the path's
heading, ``length`` and ``width`` the configuration's vehicle. The runs' step must be
INTERACTION's frame, 0.1 s. A track's draws are its ``x`` noise, its ``y`` noise, then (only
when ``noise_mps > 0``) its speed noise, track by track: without speed noise a seed gives the
files it gave before the speed noise existed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .formats import INTERACTION_COLUMNS, RecordingError, noisy_speed, write_interaction


def run_rows(record, rng: np.random.Generator, noise_m: float,
             noise_mps: float = 0.0) -> dict[str, np.ndarray]:
    """The INTERACTION rows of one :class:`persuasive.record.RunRecord` (module docstring)."""
    config = record.config
    if abs(config.simulation.dt_s - 0.1) > 1e-12:
        raise RecordingError(f"run step simulation.dt_s = {config.simulation.dt_s:g} s; "
                             "allowed: 0.1 s (INTERACTION's frame)")
    scene = record.scenario
    n = record.states.shape[0]
    cols: dict[str, list] = {c: [] for c in INTERACTION_COLUMNS}
    for track, (who, j) in enumerate((("av", 0), ("hv", 2)), start=1):
        s, v = record.states[:, j], record.states[:, j + 1]
        x, y, heading = scene.positions(who, s)
        x = np.asarray(x, float) + rng.uniform(-noise_m, noise_m, n)
        y = np.asarray(y, float) + rng.uniform(-noise_m, noise_m, n)
        heading = np.asarray(heading, float)
        v = noisy_speed(np.asarray(v, float), rng, noise_mps)
        veh = config.vehicle_of(who)
        cols["track_id"].append(np.full(n, track, np.int64))
        cols["frame_id"].append(np.arange(1, n + 1, dtype=np.int64))
        cols["timestamp_ms"].append(np.arange(n, dtype=np.int64) * 100)
        cols["agent_type"].append(np.full(n, "car", dtype=object))
        cols["x"].append(x)
        cols["y"].append(y)
        cols["vx"].append(v * np.cos(heading))
        cols["vy"].append(v * np.sin(heading))
        cols["psi_rad"].append(heading)
        cols["length"].append(np.full(n, veh.length_m))
        cols["width"].append(np.full(n, veh.width_m))
    return {c: np.concatenate(parts) for c, parts in cols.items()}


def _check_export(noise_m: float, count: int, what: str, noise_mps: float = 0.0) -> None:
    """The checks every export makes first: the noises' sizes and at most 1000 inputs (three
    digits in the names); :class:`RecordingError` otherwise."""
    if not (np.isfinite(noise_m) and noise_m >= 0.0):
        raise RecordingError(f"--noise-m = {noise_m!r} is out of range; allowed: a number "
                             ">= 0 m")
    if not (np.isfinite(noise_mps) and noise_mps >= 0.0):
        raise RecordingError(f"--noise-mps = {noise_mps!r} is out of range; allowed: a number "
                             ">= 0 m/s")
    if count > 1000:
        raise RecordingError(f"{count} {what} given; allowed: at most 1000 "
                             "(vehicle_tracks_000 to _999)")


def export_runs(runs: Sequence[str | Path], folder: str | Path, noise_m: float = 0.0,
                seed: int = 0, noise_mps: float = 0.0, map_rule: str | None = None
                ) -> list[str]:
    """Write each run log of ``runs`` into ``folder`` (existing) as
    ``vehicle_tracks_<r>.csv``; the names written. ``map_rule``
    (``persuasive.recordings.lanelet_map.MAP_RULES``): also ``map.osm``, the runs' scenario as
    a Lanelet2 map with that rule (every run must be of one scenario geometry). Raises
    :class:`persuasive.config.ConfigError` (a run that cannot be read) or
    :class:`RecordingError` before writing anything."""
    from ..record import load_record

    _check_export(noise_m, len(runs), "runs", noise_mps)
    records = [load_record(r) for r in runs]
    if map_rule is not None:
        from ..fitting.evidence import describe_scenario, scenario_key
        from .lanelet_map import _lanelet2

        _lanelet2()
        keys = {scenario_key(rec.config) for rec in records}
        if len(keys) > 1:
            raise RecordingError("--map-rule draws one map: the runs are of "
                                 f"{len(keys)} scenario geometries "
                                 f"({', '.join(sorted(describe_scenario(k) for k in keys))})")
    rng = np.random.default_rng(seed)
    rows = [run_rows(rec, rng, noise_m, noise_mps) for rec in records]
    names = []
    for r, cols in enumerate(rows):
        name = f"vehicle_tracks_{r:03d}.csv"
        write_interaction(Path(folder) / name, cols)
        names.append(name)
    if map_rule is not None:
        from .lanelet_map import write_map

        write_map(Path(folder) / "map.osm", records[0].scenario, map_rule)
        names.append("map.osm")
    return names


def export_fcd(files: Sequence[str | Path], folder: str | Path, noise_m: float = 0.0,
               seed: int = 0, types: Sequence[str | Path] = (),
               noise_mps: float = 0.0) -> list[str]:
    """Write each SUMO fcd file of ``files`` into ``folder`` (existing) as
    ``vehicle_tracks_<r>.csv`` (three digits, in the order given), with the SUMO ID of each
    track in ``vehicle_ids_<r>.csv`` (``track_id, sumo_id``); the track files' names. Every
    file is read (:func:`persuasive.recordings.sumo_fcd.read_fcd`, one generator seeded with
    ``seed`` for the noise, files in order) before anything is written;
    :class:`RecordingError` otherwise."""
    import pandas as pd

    from .._files import atomic_write
    from .sumo_fcd import read_fcd, read_types

    _check_export(noise_m, len(files), "fcd files", noise_mps)
    vtypes = read_types(types)
    rng = np.random.default_rng(seed)
    read = [read_fcd(f, vtypes, rng, noise_m, noise_mps) for f in files]
    names = []
    for r, (cols, ids) in enumerate(read):
        name = f"vehicle_tracks_{r:03d}.csv"
        write_interaction(Path(folder) / name, cols)
        table = pd.DataFrame({"track_id": np.arange(1, len(ids) + 1), "sumo_id": ids})
        atomic_write(Path(folder) / f"vehicle_ids_{r:03d}.csv",
                     lambda p, table=table: table.to_csv(p, index=False))
        names.append(name)
    return names


__all__ = ["export_fcd", "export_runs", "run_rows"]
