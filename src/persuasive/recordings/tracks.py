"""Smoothed vehicle tracks: positions, arc length, speed and acceleration at 10 Hz
(docs/guide/recordings.md).

From the tidy table of :mod:`persuasive.recordings.formats`, the vehicle tracks (classes
:data:`~persuasive.recordings.formats.VEHICLE_CLASSES`, at least ``min_track_s`` long) are
smoothed with a **Savitzky-Golay filter** (a least-squares polynomial over a sliding window;
``window`` samples, default 7 = 0.6 s at 10 Hz, ``order`` 3; at a track's first and last
``window // 2`` samples, the polynomial of the first and last full window, as
``scipy.signal.savgol_filter``'s ``mode="interp"``):

- ``x, y``: the smoothed centre [m];
- ``s``: the arc length travelled along the smoothed positions, ``s_0 = 0``, ``s_k = s_{k-1} +
  |p_k - p_{k-1}|`` [m] (non-decreasing: the track is its own path);
- ``v``, ``a`` (``speed = "file"``, the default): the file's speed (``hypot(vx, vy)``), smoothed
  by the same filter and floored at 0 [m/s], and the filter's first derivative of it [m/s^2];
  (``speed = "positions"``): the filter's first and second derivatives of ``s`` (``dt =
  0.1 s``). A recording's velocities are its own estimates (INTERACTION's and inD's come from
  their trackers); differentiating positions instead bends a speed that changes its slope
  within the window by up to 0.2 m/s (a step of 3 m/s^2 in the acceleration, the window of
  1 s), and the games of the fit are solved at that speed (docs/guide/recordings.md, "The
  round trip, replicated").

At a track's first and last samples (:func:`edge_samples`) the values are the edge windows'
polynomials, extrapolated: a slope there can overshoot (1.6 m/s^2 at the first sample of a
driver at 0.8 that brakes 0.3 s later). The pairs keep them (the fit's measurement model is
exact there too, :func:`acceleration_band`); the replay's envelope test leaves them out.

What the recorded acceleration is, as a function of the true one, is a linear filter
(:func:`acceleration_kernel`: the filter above applied to the speed or the position that the
acceleration integrates to); the fit passes the models' accelerations through it before it
compares them with the recorded ones (``persuasive.fitting.evidence.observe_through``).

The filter is applied to all tracks at once (a matrix product over sliding windows of the
concatenated samples, each track's ends by its own edge windows), with no loop per track.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .formats import STEP_S, VEHICLE_CLASSES, RecordingError


#: Where a track's speed and acceleration come from (:class:`SmoothingParams`).
SPEED_SOURCES = ("file", "positions")


@dataclass(frozen=True)
class SmoothingParams:
    """The Savitzky-Golay filter and which tracks are kept."""

    #: samples in the filter's window (odd; 7 = 0.6 s at 10 Hz; chosen by the round trip,
    #: docs/guide/recordings.md "The round trip, replicated") [-]
    window: int = 7
    order: int = 3  #: the polynomial's degree [-]
    min_track_s: float = 2.0  #: shorter vehicle tracks are left out [s]
    #: where speed and acceleration come from: "file" (the file's speed, smoothed, and its
    #: derivative) or "positions" (the derivatives of the smoothed arc length)
    speed: str = "file"

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
        if self.speed not in SPEED_SOURCES:
            raise RecordingError(f"speed = {self.speed!r} is out of range; allowed: "
                                 f"{', '.join(SPEED_SOURCES)}")


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
    params: SmoothingParams = field(default_factory=SmoothingParams)  #: the filter

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
    if params.speed == "file":
        speed = take("speed_mps")[keep]
        v = np.maximum(savgol(speed, new_starts, w, p), 0.0) if s.size else s
        a = savgol(speed, new_starts, w, p, 1) if s.size else s
    else:
        v = np.maximum(savgol(s, new_starts, w, p, 1), 0.0) if s.size else s
        a = savgol(s, new_starts, w, p, 2) if s.size else s
    seg = np.repeat(np.arange(n_kept.shape[0]), n_kept)
    med_len = _median_by(length, seg, n_kept.shape[0])
    med_wid = _median_by(width, seg, n_kept.shape[0])
    return Tracks(rec_names[rec_codes[first]], track[first], cls[first], med_len, med_wid,
                  new_starts, t, xs, ys, s, v, a, heading, params)


def _recorded_accel(params: SmoothingParams, accel: np.ndarray) -> np.ndarray:
    """The pipeline's acceleration of one straight track (all its samples) that drove
    ``accel`` (held over each 0.1 s step; the last sample's is not driven) from 10 m/s."""
    window, order, dt = params.window, params.order, STEP_S
    starts = np.array([0, accel.shape[0]], np.int64)
    v = 10.0 + np.concatenate([[0.0], np.cumsum(accel[:-1]) * dt])
    if params.speed == "file":
        return savgol(v, starts, window, order, 1)
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * dt + 0.5 * accel[:-1] * dt * dt)])
    return savgol(savgol(s, starts, window, order), starts, window, order, 2)


_RESPONSES: dict[tuple, tuple[np.ndarray, int]] = {}


def _responses(params: SmoothingParams, n: int) -> tuple[np.ndarray, int]:
    """``(R, reach)``: ``R`` ``(n, n)``, the pipeline's acceleration at sample ``k`` of an
    ``n``-sample track is ``sum_i R[k, i] a_i`` (the filter is linear; its edge windows
    included), and ``reach`` the largest ``|i - k|`` with a weight. Cached."""
    key = (params.window, params.order, params.speed, n)
    found = _RESPONSES.get(key)
    if found is None:
        base = _recorded_accel(params, np.zeros(n))
        R = np.empty((n, n))
        for i in range(n):
            impulse = np.zeros(n)
            impulse[i] = 1.0
            R[:, i] = _recorded_accel(params, impulse) - base
        R[np.abs(R) < 1e-9] = 0.0  # rounding of positions of hundreds of metres
        rows, cols = np.nonzero(R)
        found = _RESPONSES[key] = (R, int(np.max(np.abs(cols - rows), initial=0)))
    return found


def acceleration_band(params: SmoothingParams | None, n_track: int, first: int,
                      n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The recorded acceleration of samples ``first .. first + n_steps - 1`` of an
    ``n_track``-sample track as a band over the true ones: ``(offsets (m,), weights
    (n_steps, m))`` with the recorded value at step ``k`` ``sum_j weights[k, j]
    a_{k + offsets[j]}`` (steps counted from ``first``; weights 0 beyond the track). Exact
    everywhere, the track's edge windows included: the filter of a long track is the same at
    every sample more than ``4 window`` from both ends (:func:`acceleration_kernel`), and its
    first and last ``4 window`` samples see only their end. ``n_track = 0``: the track is not
    known (a pairs file written before it was recorded): every step is taken as interior."""
    params = params or SmoothingParams()
    long_n = 8 * params.window + 1
    R, reach = _responses(params, long_n if n_track <= 0 or n_track > long_n else n_track)
    L = R.shape[0]
    mid = L // 2
    j = first + np.arange(n_steps)
    if n_track <= 0:
        src = np.full(n_steps, mid)
    elif n_track <= long_n:
        src = j
    else:  # rows of the long track: its start, its end, or its middle (the interior)
        src = np.where(j < mid, j, np.where(n_track - 1 - j < mid, L - (n_track - j), mid))
    offsets = np.arange(-reach, reach + 1)
    cols = src[:, None] + offsets[None, :]
    inside = (cols >= 0) & (cols < L)
    weights = np.where(inside, R[src[:, None], np.clip(cols, 0, L - 1)], 0.0)
    return offsets, weights


def edge_samples(params: SmoothingParams | None = None) -> int:
    """How many of a track's first (and last) samples have a speed that the edge windows'
    polynomials reach: ``window // 2`` for the file's speeds, twice that for speeds from the
    positions (the centres are smoothed, then the arc length differentiated)."""
    params = params or SmoothingParams()
    return (params.window // 2) * (1 if params.speed == "file" else 2)


def acceleration_kernel(params: SmoothingParams | None = None) -> dict[int, float]:
    """``{d: w_d}``: a track's smoothed acceleration at step ``k`` is ``sum_d w_d a_{k+d}`` for
    the true accelerations ``a`` (held over each 0.1 s step), away from the track's first and
    last :func:`edge_samples`, where the filter takes the edge windows' polynomials (module
    docstring). Found by the pipeline's own filter on a unit impulse: for ``speed =
    "file"``, the speed it integrates to, filtered and differentiated once; for
    ``"positions"``, the position, smoothed (as the centres are), then differentiated twice.
    The weights sum to 1 (a constant acceleration is recorded as it is)."""
    params = params or SmoothingParams()
    R, _ = _responses(params, 8 * params.window + 1)
    mid = R.shape[0] // 2
    return {int(i - mid): float(R[mid, i]) for i in np.flatnonzero(R[mid])}


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


__all__ = ["SPEED_SOURCES", "SmoothingParams", "Tracks", "acceleration_band",
           "acceleration_kernel", "edge_samples", "savgol", "savgol_matrix", "smooth_tracks"]
