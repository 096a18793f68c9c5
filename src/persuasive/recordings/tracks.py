"""Smoothed vehicle tracks: positions, arc length, speed and acceleration at 10 Hz
(docs/guide/recordings.md).

From the tidy table of :mod:`persuasive.recordings.formats`, the vehicle tracks (classes
:data:`~persuasive.recordings.formats.VEHICLE_CLASSES`, at least ``min_track_s`` long) are
smoothed with a **Savitzky-Golay filter** (a least-squares polynomial over a sliding window;
``window`` samples, default 11 = 1.0 s at 10 Hz, ``order`` 3; at a track's first and last
``window // 2`` samples, the polynomial of the first and last full window, as
``scipy.signal.savgol_filter``'s ``mode="interp"``):

- ``x, y``: the smoothed centre [m];
- ``s``: the arc length travelled along the smoothed positions, ``s_0 = 0``, ``s_k = s_{k-1} +
  |p_k - p_{k-1}|`` [m] (non-decreasing: the track is its own path);
- ``v``: the filter's first derivative of ``s``, floored at 0 [m/s]; ``a``: its second
  derivative [m/s^2] (``dt = 0.1 s``).

The filter is applied to all tracks at once (a matrix product over sliding windows of the
concatenated samples, each track's ends by its own edge windows), with no loop per track.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .formats import STEP_S, VEHICLE_CLASSES, RecordingError


@dataclass(frozen=True)
class SmoothingParams:
    """The Savitzky-Golay filter and which tracks are kept."""

    window: int = 11  #: samples in the filter's window (odd; 11 = 1.0 s at 10 Hz) [-]
    order: int = 3  #: the polynomial's degree [-]
    min_track_s: float = 2.0  #: shorter vehicle tracks are left out [s]

    def __post_init__(self) -> None:
        if not (isinstance(self.window, int) and self.window >= 3 and self.window % 2 == 1):
            raise RecordingError(f"smoothing window = {self.window!r} is out of range; "
                                 "allowed: an odd integer >= 3")
        if not (isinstance(self.order, int) and 1 <= self.order < self.window):
            raise RecordingError(f"smoothing order = {self.order!r} is out of range; allowed: "
                                 f"integer in [1, {self.window - 1}]")
        if not (np.isfinite(self.min_track_s) and self.min_track_s >= (self.window - 1)
                * STEP_S):
            raise RecordingError(f"min_track_s = {self.min_track_s!r} is out of range; "
                                 f"allowed: at least the window, {(self.window - 1) * STEP_S:g} s")


@dataclass(frozen=True)
class Tracks:
    """Smoothed vehicle tracks, stored one after the other: track ``i`` is samples
    ``starts[i]:starts[i + 1]`` (module docstring). Per track: ``recording``, ``track``
    (IDs), ``agent_class``, ``length_m``, ``width_m`` (the median over the track), ``source``
    (the recording's index in ``recordings``); per sample ``(n,)``: ``t`` [s], ``x``, ``y``,
    ``s`` [m], ``v`` [m/s], ``a`` [m/s^2], ``heading`` [rad] (the file's)."""

    recording: np.ndarray
    track: np.ndarray
    agent_class: np.ndarray
    length_m: np.ndarray
    width_m: np.ndarray
    starts: np.ndarray
    t: np.ndarray = field(repr=False)
    x: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    s: np.ndarray = field(repr=False)
    v: np.ndarray = field(repr=False)
    a: np.ndarray = field(repr=False)
    heading: np.ndarray = field(repr=False)

    @property
    def n_tracks(self) -> int:
        return int(self.starts.shape[0] - 1)

    def rows(self, i: int) -> slice:
        return slice(int(self.starts[i]), int(self.starts[i + 1]))


def savgol_matrix(window: int, order: int, deriv: int, delta: float) -> np.ndarray:
    """``(window, window)``: row ``r`` gives the ``deriv``-th derivative, at window position
    ``r``, of the least-squares polynomial of degree ``order`` through a window of samples
    ``delta`` apart (row ``window // 2`` is the centred filter)."""
    u = np.arange(window) - window // 2
    A = np.vander(u.astype(float), order + 1, increasing=True)  # (window, order + 1)
    P = np.linalg.pinv(A)  # coefficients from samples
    D = np.zeros((window, order + 1))
    for j in range(deriv, order + 1):
        fall = np.prod(np.arange(j - deriv + 1, j + 1)) if deriv else 1.0
        D[:, j] = fall * u.astype(float) ** (j - deriv)
    return D @ P / delta ** deriv


def savgol(x: np.ndarray, starts: np.ndarray, window: int, order: int, deriv: int = 0,
           delta: float = STEP_S) -> np.ndarray:
    """The Savitzky-Golay filter of every track of ``x`` at once (each track at least
    ``window`` samples; ``starts`` as :attr:`Tracks.starts`)."""
    from numpy.lib.stride_tricks import sliding_window_view

    M = savgol_matrix(window, order, deriv, delta)
    h = window // 2
    out = np.empty_like(x, dtype=float)
    win = sliding_window_view(x, window)  # (n - window + 1, window)
    centre = win @ M[h]
    out[h:x.shape[0] - h] = centre
    first, last = starts[:-1], starts[1:] - window
    out[(first[:, None] + np.arange(h)).ravel()] = (win[first] @ M[:h].T).ravel()
    out[(last[:, None] + np.arange(h + 1, window)).ravel()] = (win[last] @ M[h + 1:].T).ravel()
    return out


def smooth_tracks(table, params: SmoothingParams | None = None) -> Tracks:
    """The smoothed vehicle tracks of a tidy table (module docstring)."""
    params = params or SmoothingParams()
    rec_codes, rec_names = _codes(table["recording"].to_numpy())
    track = table["track"].to_numpy(np.int64)
    cls = table["agent_class"].to_numpy()
    t = table["t_s"].to_numpy(float)
    order = np.lexsort((t, track, rec_codes))
    if not np.array_equal(order, np.arange(order.size)):
        rec_codes, track, cls, t = rec_codes[order], track[order], cls[order], t[order]
    else:
        order = None
    take = (lambda c: table[c].to_numpy(float)) if order is None else \
        (lambda c: table[c].to_numpy(float)[order])
    change = np.ones(t.shape[0], bool)
    change[1:] = (rec_codes[1:] != rec_codes[:-1]) | (track[1:] != track[:-1])
    starts = np.concatenate([np.flatnonzero(change), [t.shape[0]]]).astype(np.int64)
    counts = np.diff(starts)
    vehicle = np.isin(cls[starts[:-1]], VEHICLE_CLASSES)
    long_enough = counts >= int(round(params.min_track_s / STEP_S)) + 1
    keep_track = vehicle & long_enough
    keep = np.repeat(keep_track, counts)
    x, y = take("x_m")[keep], take("y_m")[keep]
    heading, length, width = take("heading_rad")[keep], take("length_m")[keep], \
        take("width_m")[keep]
    t = t[keep]
    first = starts[:-1][keep_track]
    n_kept = np.diff(np.concatenate([[0], np.cumsum(counts[keep_track])])).astype(np.int64)
    new_starts = np.concatenate([[0], np.cumsum(n_kept)]).astype(np.int64)
    w, p = params.window, params.order
    xs = savgol(x, new_starts, w, p) if x.size else x
    ys = savgol(y, new_starts, w, p) if y.size else y
    step = np.hypot(np.diff(xs), np.diff(ys)) if xs.size else xs
    chord = np.concatenate([[0.0], step]) if xs.size else xs
    chord[new_starts[:-1]] = 0.0
    c = np.cumsum(chord)
    s = c - np.repeat(c[new_starts[:-1]], n_kept)
    v = np.maximum(savgol(s, new_starts, w, p, 1), 0.0) if s.size else s
    a = savgol(s, new_starts, w, p, 2) if s.size else s
    seg = np.repeat(np.arange(n_kept.shape[0]), n_kept)
    med_len = _median_by(length, seg, n_kept.shape[0])
    med_wid = _median_by(width, seg, n_kept.shape[0])
    return Tracks(rec_names[rec_codes[first]], track[first], cls[first], med_len, med_wid,
                  new_starts, t, xs, ys, s, v, a, heading)


def _codes(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer codes of ``values`` in order of first appearance, and the names."""
    import pandas as pd

    codes, names = pd.factorize(values, sort=False)
    return codes.astype(np.int64), np.asarray(names, dtype=object)


def _median_by(x: np.ndarray, group: np.ndarray, n: int) -> np.ndarray:
    import pandas as pd

    if n == 0:
        return np.zeros(0)
    return pd.Series(x).groupby(group).median().reindex(range(n)).to_numpy(float)


__all__ = ["SmoothingParams", "Tracks", "savgol", "savgol_matrix", "smooth_tracks"]
