"""Recorded tracks in, and out: the readers of the INTERACTION and inD track files, one tidy
table, and the INTERACTION writer (docs/guide/recordings.md).

Every reader returns one pandas table with one row per vehicle and 10 Hz step,
:data:`TIDY_COLUMNS`:

- ``recording``: the recording, the file's stem (``vehicle_tracks_000``, ``07``); in
  INTERACTION's prediction splits ``<stem>/case<case_id>`` (each case is a scene of its own);
- ``track``: the track's ID within its recording;
- ``t_s`` [s]: time in the recording, a multiple of 0.1 s;
- ``x_m``, ``y_m`` [m]: the centre, in the recording's map frame;
- ``speed_mps`` [m/s]: ``hypot(vx, vy)`` of the file's velocity;
- ``heading_rad`` [rad]: the file's heading (INTERACTION ``psi_rad``, inD ``heading`` in
  degrees);
- ``length_m``, ``width_m`` [m]: the footprint;
- ``agent_class``: the file's class, lower case (``car``, ``truck``, ``truck_bus``, ...).

**INTERACTION** (``vehicle_tracks_NNN.csv``): the header ``track_id, frame_id, timestamp_ms,
agent_type, x, y, vx, vy, psi_rad, length, width`` (metres, 100 ms frames); the prediction
splits put ``case_id`` first, and ``(case_id, track_id)`` is then the track.

**inD** (``NN_tracks.csv`` beside ``NN_tracksMeta.csv``): ``recordingId, trackId, frame,
xCenter, yCenter, heading [deg], width, length, xVelocity, yVelocity, ...`` at 25 Hz (40 ms
frames); the class (``car``, ``truck_bus``, ``pedestrian``, ``bicycle``) is in tracksMeta. Its
25 Hz samples are resampled to 10 Hz in two stated steps: an anti-alias **moving average over
3 frames** (120 ms, centred; at a track's ends over the frames it has), whose gain is 0.54
at 5 Hz (the 10 Hz Nyquist frequency) and 0 at 8.3 Hz, then **linear interpolation at every
time that is a multiple of 100 ms** inside the track (frame ``f`` is at ``f * 40 ms``, so these fall on a frame or halfway
between two). Headings are averaged and interpolated as unit vectors.

Files are read by ``pyarrow.csv`` (columnar, multi-threaded) and checked with array
operations, no Python loop per row. A file that cannot be used raises
:class:`RecordingError`, one line naming the file and the named check it fails:
``not a track file`` (unknown header), ``missing columns``, ``non-finite`` (a NaN, an infinite
or an empty value), ``speed`` (above :data:`MAX_SPEED_MPS`), ``frame step`` (a track whose
consecutive samples are not exactly one frame apart: 100 ms in INTERACTION, 40 ms in inD) and
``one vehicle`` (fewer than two vehicle tracks: no pair can be found).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

#: The tidy table's columns, in order (module docstring).
TIDY_COLUMNS = ("recording", "track", "t_s", "x_m", "y_m", "speed_mps", "heading_rad",
                "length_m", "width_m", "agent_class")
#: Classes that count as vehicles (pairs are made of these; pedestrians and bicycles never).
VEHICLE_CLASSES = ("car", "truck", "bus", "truck_bus", "van")
#: The plausibility bound on speed [m/s] (252 km/h): above it a value is a unit or tracking
#: error.
MAX_SPEED_MPS = 70.0
#: The tidy table's step [s] (10 Hz, INTERACTION's frame).
STEP_S = 0.1

#: INTERACTION's columns (``case_id`` first in the prediction splits).
INTERACTION_COLUMNS = ("track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y", "vx",
                       "vy", "psi_rad", "length", "width")
INTERACTION_FRAME_MS = 100
#: The inD columns the reader uses (the files have more), and tracksMeta's.
IND_COLUMNS = ("recordingId", "trackId", "frame", "xCenter", "yCenter", "heading", "width",
               "length", "xVelocity", "yVelocity")
IND_META_COLUMNS = ("trackId", "class")
IND_FRAME_MS = 40
#: The anti-alias moving average of the inD resampling [frames].
IND_AVERAGE_FRAMES = 3


class RecordingError(ValueError):
    """A recording that cannot be used; the one-line message names the file and the check."""


@dataclass(frozen=True)
class TrackFile:
    """One track file found among the inputs: its path and format (``"interaction"`` or
    ``"ind"``)."""

    path: Path
    format: str


def _header(path: Path) -> list[str]:
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            line = fh.readline()
    except OSError as exc:
        reason = (exc.strerror or str(exc)).lower()
        raise RecordingError(f"track file {str(path)!r} cannot be read: {reason}") from None
    return [c.strip().strip('"') for c in line.strip().split(",")]


def file_head(path: str | Path, n: int, what: str) -> bytes:
    """The first ``n`` bytes of file ``path``; :class:`RecordingError` naming it as ``what``
    (``"pairs file"``, ``"map file"``) when it cannot be read."""
    try:
        with open(path, "rb") as fh:
            return fh.read(n)
    except OSError as exc:
        raise RecordingError(f"{what} {str(path)!r} cannot be read: "
                             f"{(exc.strerror or str(exc)).lower()}") from None


def _format_of(path: Path) -> str:
    """The format of a track file from its header; :class:`RecordingError` when it is none."""
    cols = _header(path)
    if "track_id" in cols and "timestamp_ms" in cols:
        missing = [c for c in INTERACTION_COLUMNS if c not in cols]
        if missing:
            raise RecordingError(f"track file {str(path)!r}: missing columns "
                                 f"{', '.join(missing)} (INTERACTION format)")
        return "interaction"
    if "trackId" in cols and "xCenter" in cols:
        missing = [c for c in IND_COLUMNS if c not in cols]
        if missing:
            raise RecordingError(f"track file {str(path)!r}: missing columns "
                                 f"{', '.join(missing)} (inD format)")
        return "ind"
    raise RecordingError(f"track file {str(path)!r} is not a track file: its header holds "
                         "neither INTERACTION's columns (track_id, frame_id, timestamp_ms, "
                         "...) nor inD's (recordingId, trackId, frame, xCenter, ...)")


def find_track_files(paths: Sequence[str | Path]) -> list[TrackFile]:
    """The track files among ``paths``: files are taken as given; a folder contributes its
    ``vehicle_tracks_*.csv`` and ``*_tracks.csv`` files (sorted). :class:`RecordingError` for
    a path that does not exist, a folder without track files, a file that is not one."""
    if not paths:
        raise RecordingError("no track file given: name INTERACTION vehicle_tracks_NNN.csv "
                             "or inD NN_tracks.csv files, or folders holding them")
    out: list[TrackFile] = []
    seen: set[Path] = set()
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted({*p.glob("vehicle_tracks_*.csv"), *p.glob("*_tracks.csv")})
            if not found:
                raise RecordingError(f"folder {str(p)!r} holds no track file "
                                     "(vehicle_tracks_*.csv or *_tracks.csv)")
        elif p.exists():
            found = [p]
        else:
            raise RecordingError(f"track file {str(p)!r} does not exist")
        for f in found:
            key = f.resolve()
            if key in seen:
                continue
            seen.add(key)
            out.append(TrackFile(f, _format_of(f)))
    return out


def _read_csv(path: Path):
    import pyarrow as pa
    import pyarrow.csv as pacsv

    try:
        return pacsv.read_csv(path)
    except (pa.ArrowInvalid, pa.ArrowTypeError, OSError, ValueError) as exc:
        text = str(exc).strip().splitlines()
        raise RecordingError(f"track file {str(path)!r} cannot be parsed: "
                             f"{text[0] if text else type(exc).__name__}") from None


def _floats(table, name: str, path: Path) -> np.ndarray:
    import pyarrow as pa
    import pyarrow.compute as pc

    col = table.column(name)
    if not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)
            or pa.types.is_null(col.type)):
        raise RecordingError(f"track file {str(path)!r}: non-finite: column {name} holds "
                             "text, not numbers")
    return pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)


def _ints(table, name: str, path: Path) -> np.ndarray:
    x = _floats(table, name, path)
    bad = ~np.isfinite(x)
    if bad.any():
        raise RecordingError(f"track file {str(path)!r}: non-finite: column {name} has an "
                             f"empty or non-finite value at data row {int(np.argmax(bad)) + 1}")
    return x.astype(np.int64)


def _strings(table, name: str) -> np.ndarray:
    import pyarrow as pa
    import pyarrow.compute as pc

    col = table.column(name)
    if not pa.types.is_string(col.type):
        col = pc.cast(col, pa.string())
    return np.asarray(pc.utf8_lower(pc.fill_null(col, "")).to_numpy(zero_copy_only=False),
                      dtype=object)


def _check_finite(path: Path, cols: dict[str, np.ndarray], rows: np.ndarray | None = None
                  ) -> None:
    for name, x in cols.items():
        bad = ~np.isfinite(x)
        if bad.any():
            i = int(np.argmax(bad))
            where = f"data row {int(rows[i]) + 1}" if rows is not None else f"sample {i}"
            raise RecordingError(f"track file {str(path)!r}: non-finite: {name} = {x[i]} at "
                                 f"{where}; allowed: finite numbers")


def _check_speed(path: Path, speed: np.ndarray, track: np.ndarray, t: np.ndarray) -> None:
    bad = speed > MAX_SPEED_MPS
    if bad.any():
        i = int(np.argmax(bad))
        raise RecordingError(f"track file {str(path)!r}: speed: track {track[i]} moves at "
                             f"{speed[i]:.1f} m/s at t = {t[i]:.2f} s; allowed: at most "
                             f"{MAX_SPEED_MPS:g} m/s")


def _order(keys: Sequence[np.ndarray]) -> np.ndarray | None:
    """The permutation that sorts by ``keys`` (the first key outermost), or None when the
    rows are already in that order."""
    order = np.lexsort(tuple(reversed(keys)))
    return None if np.array_equal(order, np.arange(order.size)) else order


def _group_starts(*keys: np.ndarray) -> np.ndarray:
    """Row indices where a run of equal ``keys`` begins, plus the end (sorted rows)."""
    n = keys[0].shape[0]
    change = np.zeros(n, bool)
    if n:
        change[0] = True
        for k in keys:
            change[1:] |= k[1:] != k[:-1]
    return np.concatenate([np.flatnonzero(change), [n]]).astype(np.int64)


def _check_steps(path: Path, t_units: np.ndarray, starts: np.ndarray, track: np.ndarray,
                 step: int, unit: str, frame_ms: int) -> None:
    d = np.diff(t_units)
    inside = np.ones(d.shape[0], bool)
    inside[starts[1:-1] - 1] = False  # a new track starts: not a step
    bad = inside & (d != step)
    if bad.any():
        i = int(np.argmax(bad))
        raise RecordingError(f"track file {str(path)!r}: frame step: track {track[i]} goes "
                             f"from {unit} {t_units[i]} to {t_units[i + 1]}; allowed: steps of "
                             f"exactly one frame ({frame_ms} ms)")


def _check_pairable(path: Path, recording: np.ndarray, track: np.ndarray,
                    agent_class: np.ndarray) -> None:
    import pandas as pd

    vehicle = np.isin(agent_class, VEHICLE_CLASSES)
    rec = pd.factorize(recording[vehicle])[0].astype(np.int64)
    ids = track[vehicle]
    key = rec * (int(ids.max()) + 1 if ids.size else 1) + ids
    n = np.unique(key).size
    if n < 2:
        found = f"one vehicle only (track {ids[0]})" if n else "no vehicle"
        raise RecordingError(f"track file {str(path)!r}: one vehicle: it holds {found} of "
                             f"the classes {', '.join(VEHICLE_CLASSES)}; a pair needs two")


def read_interaction(path: str | Path):
    """An INTERACTION track file as the tidy table (module docstring)."""
    import pandas as pd

    path = Path(path)
    table = _read_csv(path)
    names = table.column_names
    missing = [c for c in INTERACTION_COLUMNS if c not in names]
    if missing:
        raise RecordingError(f"track file {str(path)!r}: missing columns "
                             f"{', '.join(missing)} (INTERACTION format)")
    track = _ints(table, "track_id", path)
    stamp = _ints(table, "timestamp_ms", path)
    stem = path.stem
    if "case_id" in names:
        case = _ints(table, "case_id", path)
        recording = np.char.add(f"{stem}/case", case.astype(str)).astype(object)
        keys = [case, track, stamp]
    else:
        case = None
        recording = np.full(track.shape[0], stem, dtype=object)
        keys = [track, stamp]
    cols = {c: _floats(table, c, path) for c in ("x", "y", "vx", "vy", "psi_rad", "length",
                                                 "width")}
    agent = _strings(table, "agent_type")
    _check_finite(path, cols, np.arange(track.shape[0]))
    order = _order(keys)
    if order is not None:
        track, stamp, recording, agent = track[order], stamp[order], recording[order], \
            agent[order]
        cols = {k: v[order] for k, v in cols.items()}
        if case is not None:
            case = case[order]
    starts = _group_starts(*([case, track] if case is not None else [track]))
    t_s = stamp / 1000.0
    _check_steps(path, stamp, starts, track, INTERACTION_FRAME_MS, "timestamp_ms",
                 INTERACTION_FRAME_MS)
    speed = np.hypot(cols["vx"], cols["vy"])
    _check_speed(path, speed, track, t_s)
    _check_pairable(path, recording, track, agent)
    return pd.DataFrame({"recording": recording, "track": track, "t_s": t_s,
                         "x_m": cols["x"], "y_m": cols["y"], "speed_mps": speed,
                         "heading_rad": cols["psi_rad"], "length_m": cols["length"],
                         "width_m": cols["width"], "agent_class": agent},
                        columns=list(TIDY_COLUMNS))


def _ind_meta(path: Path) -> Path:
    stem = path.name[: -len("_tracks.csv")] if path.name.endswith("_tracks.csv") else path.stem
    return path.with_name(f"{stem}_tracksMeta.csv")


def _moving_average(x: np.ndarray, starts: np.ndarray, frames: int) -> np.ndarray:
    """Centred moving average over ``frames`` (odd) samples within each track (sorted rows,
    ``starts`` as :func:`_group_starts`); at a track's ends, over the samples it has."""
    half = frames // 2
    n = x.shape[0]
    idx = np.arange(n)
    track_of = np.repeat(np.arange(starts.shape[0] - 1), np.diff(starts))
    lo = np.maximum(idx - half, starts[track_of])
    hi = np.minimum(idx + half, starts[track_of + 1] - 1)
    c = np.concatenate([[0.0], np.cumsum(x)])
    return (c[hi + 1] - c[lo]) / (hi - lo + 1)


def read_ind(path: str | Path):
    """An inD ``NN_tracks.csv`` (with its ``NN_tracksMeta.csv``) as the tidy table at 10 Hz
    (module docstring: a 3-frame moving average, then linear interpolation at the multiples
    of 100 ms)."""
    import pandas as pd

    path = Path(path)
    meta_path = _ind_meta(path)
    if not meta_path.is_file():
        raise RecordingError(f"track file {str(path)!r}: missing columns class (its "
                             f"tracksMeta file {str(meta_path)!r} does not exist)")
    table = _read_csv(path)
    missing = [c for c in IND_COLUMNS if c not in table.column_names]
    if missing:
        raise RecordingError(f"track file {str(path)!r}: missing columns "
                             f"{', '.join(missing)} (inD format)")
    meta = _read_csv(meta_path)
    missing = [c for c in IND_META_COLUMNS if c not in meta.column_names]
    if missing:
        raise RecordingError(f"track file {str(meta_path)!r}: missing columns "
                             f"{', '.join(missing)} (inD tracksMeta)")
    track = _ints(table, "trackId", path)
    frame = _ints(table, "frame", path)
    cols = {c: _floats(table, c, path) for c in ("xCenter", "yCenter", "heading", "width",
                                                 "length", "xVelocity", "yVelocity")}
    _check_finite(path, cols, np.arange(track.shape[0]))
    order = _order([track, frame])
    if order is not None:
        track, frame = track[order], frame[order]
        cols = {k: v[order] for k, v in cols.items()}
    starts = _group_starts(track)
    _check_steps(path, frame, starts, track, 1, "frame", IND_FRAME_MS)
    speed = np.hypot(cols["xVelocity"], cols["yVelocity"])
    _check_speed(path, speed, track, frame * IND_FRAME_MS / 1000.0)
    meta_track = _ints(meta, "trackId", meta_path)
    meta_class = _strings(meta, "class")
    lookup = dict(zip(meta_track.tolist(), meta_class.tolist()))
    unknown = sorted(set(np.unique(track).tolist()) - set(lookup))
    if unknown:
        raise RecordingError(f"track file {str(path)!r}: missing columns class for track "
                             f"{unknown[0]} (not in {str(meta_path)!r})")
    # anti-alias: a moving average over 3 frames, headings as unit vectors
    heading = np.radians(cols["heading"])
    smooth = {name: _moving_average(x, starts, IND_AVERAGE_FRAMES) for name, x in (
        ("x", cols["xCenter"]), ("y", cols["yCenter"]), ("speed", speed),
        ("cos", np.cos(heading)), ("sin", np.sin(heading)), ("length", cols["length"]),
        ("width", cols["width"]))}
    # the 10 Hz grid: times k * 100 ms inside each track, at frame 2.5 k
    first, last = frame[starts[:-1]], frame[starts[1:] - 1]
    k_lo = -((-first * IND_FRAME_MS) // 100)  # ceil
    k_hi = (last * IND_FRAME_MS) // 100
    counts = np.maximum(k_hi - k_lo + 1, 0)
    which = np.repeat(np.arange(first.shape[0]), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + \
        np.repeat(k_lo, counts)
    pos = k * 100 / IND_FRAME_MS - first[which]  # fractional row within the track
    i0 = np.floor(pos).astype(np.int64)
    frac = pos - i0
    row0 = starts[which] + i0
    row1 = np.minimum(row0 + 1, starts[which + 1] - 1)
    out = {name: x[row0] * (1.0 - frac) + x[row1] * frac for name, x in smooth.items()}
    tracks = track[starts[:-1]][which]
    recording = np.full(tracks.shape[0], f"{path.name[:-len('_tracks.csv')]}"
                        if path.name.endswith("_tracks.csv") else path.stem, dtype=object)
    agent = np.array([lookup[t] for t in track[starts[:-1]].tolist()], dtype=object)[which]
    _check_pairable(path, recording, tracks, agent)
    return pd.DataFrame({"recording": recording, "track": tracks, "t_s": np.round(k * 0.1, 1),
                         "x_m": out["x"], "y_m": out["y"], "speed_mps": out["speed"],
                         "heading_rad": np.arctan2(out["sin"], out["cos"]),
                         "length_m": out["length"], "width_m": out["width"],
                         "agent_class": agent}, columns=list(TIDY_COLUMNS))


def read_tracks(paths: Sequence[str | Path]):
    """Every track file among ``paths`` (:func:`find_track_files`) as one tidy table, sorted
    by recording, track and time. :class:`RecordingError` names the first bad file; two files
    holding the same recording name are refused (their tracks would be mixed)."""
    import pandas as pd

    frames, owner = [], {}
    for f in find_track_files(paths):
        frame = read_interaction(f.path) if f.format == "interaction" else read_ind(f.path)
        for name in pd.unique(frame["recording"]):
            if name in owner:
                raise RecordingError(f"track file {str(f.path)!r} holds recording {name!r}, "
                                     f"as {str(owner[name])!r} does; rename one of them")
            owner[name] = f.path
        frames.append(frame)
    return pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]


def write_interaction(path: str | Path, rows: dict[str, Iterable]) -> None:
    """Write an INTERACTION track file (atomically) from columns named as
    :data:`INTERACTION_COLUMNS`; numbers with millimetre resolution, as the dataset's."""
    import pandas as pd

    from .._files import atomic_write

    frame = pd.DataFrame({c: rows[c] for c in INTERACTION_COLUMNS})
    atomic_write(path, lambda p: frame.to_csv(p, index=False, float_format="%.3f"))


def noisy_speed(speed: np.ndarray, rng: np.random.Generator, noise_mps: float) -> np.ndarray:
    """``speed`` [m/s] with uniform noise ``U(-noise_mps, noise_mps)`` drawn from ``rng``, floored
    at 0 (a speed is a magnitude); ``speed`` itself, and nothing drawn, when ``noise_mps`` is
    0. A recording's velocities are its tracker's estimates, not exact: the noise stands for
    their error."""
    if noise_mps == 0.0:
        return speed
    return np.maximum(speed + rng.uniform(-noise_mps, noise_mps, speed.shape[0]), 0.0)


__all__ = ["IND_AVERAGE_FRAMES", "INTERACTION_COLUMNS", "IND_COLUMNS", "MAX_SPEED_MPS",
           "RecordingError", "STEP_S", "TIDY_COLUMNS", "TrackFile", "VEHICLE_CLASSES",
           "file_head", "find_track_files", "noisy_speed", "read_ind", "read_interaction",
           "read_tracks", "write_interaction"]
